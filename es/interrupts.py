"""Ctrl-C and SIGTERM during training: the first one finishes the generation, the second stops at once.

A cluster scheduler sends SIGTERM before it kills a job, so it is handled like Ctrl-C: the run
finishes its generation, saves, and stops with a resume command.

A job a non-interactive shell starts in the background (``cmd &`` in a script) inherits SIGINT
ignored, and Python then installs no handler of its own; ``honour_sigint`` gives such a process
Python's usual one, so ``kill -INT`` stops it as Ctrl-C stops a foreground run.
"""

from __future__ import annotations

import signal
import sys


class Interrupts:
    """While entered: ``requested`` turns True at the first signal; the second raises KeyboardInterrupt."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.requested = False
        self._previous: dict = {}

    def __enter__(self) -> Interrupts:
        self._previous = {signum: signal.signal(signum, self._handle) for signum in self.SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        name = "interrupt" if signum == signal.SIGINT else signal.Signals(signum).name
        print(f"\n{name}: finishing this generation, then saving (Ctrl-C again to stop at once)",
              file=sys.stderr, flush=True)


def honour_sigint() -> None:
    """Raise KeyboardInterrupt on SIGINT even where the process was started with SIGINT ignored."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
