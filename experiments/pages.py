"""The pages generated beside the campaign's runs (``REPLICATION.md``, ``STATIC_ANT.md``): each names the runs it
was written from in a line of its own, ``<!-- runs: ... -->``, and is either written or checked against what the
runs' files give now (``settle``)."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

RUNS_LINE = re.compile(r"<!-- runs: (.*?) -->")


def runs_line(names) -> str:
    return f"<!-- runs: {' '.join(names)} -->"


def covered(text: str) -> set[str]:
    """The runs a page was written from (its ``<!-- runs: ... -->`` line)."""
    match = RUNS_LINE.search(text)
    return set(match[1].split()) if match else set()


def settle(page: Path, generated: str, check: bool, command: str, write: Callable[[], None],
           behind: Callable[[str], str | None], outputs: tuple[Path, ...] = ()) -> int:
    """Without ``check``: ``write`` the page (and its ``outputs``) where it differs from ``generated`` or one of
    them is missing; exit code 0. With ``check``: 0 where the page is ``generated``, or only behind it
    (``behind(current)`` says how, in words; None: it is not), saying so; 1 where it differs otherwise."""
    current = page.read_text() if page.is_file() else None
    if not check:
        if current != generated or not all(path.exists() for path in outputs):
            write()
        return 0
    if current == generated:
        return 0
    lag = behind(current) if current is not None else None
    if lag:
        print(f"{page} is behind {lag}; {command} catches it up")
        return 0
    print(f"{page} differs from what the runs' files give; {command} rewrites it")
    return 1
