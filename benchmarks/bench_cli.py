"""Start-up of the command line: wall time of ``lti-motion --help`` in a fresh process.

Baseline: the bare interpreter (``python -c pass``), the floor no import can go under.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from benchmarks.harness import Figure, benchmark, median_seconds


def _command() -> list[str]:
    """The installed ``lti-motion`` script beside this interpreter, else its entry point."""
    script = Path(sys.executable).with_name("lti-motion")
    if script.is_file():
        return [str(script), "--help"]
    return [sys.executable, "-c", "from lti_motion.app.cli import main; main(['--help'])"]


@benchmark("cli")
def cli_startup() -> list[Figure]:
    command = _command()

    def help_() -> None:
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)

    def bare() -> None:
        subprocess.run([sys.executable, "-c", "pass"], check=True)

    t_help = median_seconds(help_, repeat=11, warmup=2)
    t_bare = median_seconds(bare, repeat=11, warmup=2)
    return [Figure("cli.help_wall_s", t_help, "s", target=0.3, better="lower",
                   baseline="python -c pass", baseline_value=t_bare)]
