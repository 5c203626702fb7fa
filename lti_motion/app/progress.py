"""Progress of the command line's long silent steps, on one line of standard error.

The library reports progress through callbacks (``progress=``) and logs; the command
line shows it with a :class:`StatusLine`: one line of standard error rewritten in place
(``\\r``) and wiped before the command prints its next line, so that what a command
prints on standard output (the demo's table, the monitor's summary) is the same with or
without it. Shown only on a terminal: a log file gets no carriage returns.
"""

from __future__ import annotations

import sys
from typing import TextIO

__all__ = ["StatusLine"]


class StatusLine:
    """One transient status line (see the module notes).

    Parameters
    ----------
    stream : text file, optional
        Where it goes (default standard error).
    always : bool
        Keyword-only: show it also when ``stream`` is not a terminal.
    """

    def __init__(self, stream: TextIO | None = None, *, always: bool = False) -> None:
        self._stream = sys.stderr if stream is None else stream
        self._on = always or self._stream.isatty()
        self._width = 0

    def show(self, text: str) -> None:
        """Show ``text`` over the previous status."""
        if self._on:
            self._stream.write(f"\r{text:<{self._width}}")
            self._stream.flush()
            self._width = len(text)

    def clear(self) -> None:
        """Wipe the status, if one is shown."""
        if self._on and self._width:
            self._stream.write("\r" + " " * self._width + "\r")
            self._stream.flush()
            self._width = 0

    def print(self, line: str) -> None:
        """A command's own output line (standard output), the status wiped first."""
        self.clear()
        print(line, flush=self._on)

    def phase_one(self, stage: str, done: int, total: int) -> None:
        """:func:`~fusion.monitoring.fit_nominal`'s ``progress``; wiped when it is done."""
        if stage == "dynamics null":
            if done >= total:
                self.clear()
            else:
                self.show("  phase I: fitting the dynamics null (maximum likelihood) ...")
        else:
            self.show(f"  phase I: {stage} of nominal drive {done} of {total} ...")

    def route(self, label: str, t_s: float, home: int, n: int) -> None:
        """:func:`~lti_motion.app.demo.run_demo`'s ``progress``: an estimator's route."""
        self.show(f"   {label}: {t_s:.0f} s of the route driven, {home} of {n} robots home")
