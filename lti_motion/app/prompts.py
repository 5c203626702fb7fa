"""The one question the command line asks a person: is the robot in place?"""

from __future__ import annotations

__all__ = ["wait_until_placed"]

_PROMPT = "press Enter when it is there (Ctrl-C stops the robot) "


def wait_until_placed() -> None:
    """Wait for Enter on standard input.

    Raises
    ------
    ValueError
        When standard input is closed (a script, a service, CI): one line saying to give
        ``--yes``, instead of an ``EOFError`` traceback.
    """
    try:
        input(_PROMPT)
    except EOFError:
        raise ValueError("standard input is closed, so nobody can confirm the robot is in "
                         "place: put it there first and give --yes") from None
