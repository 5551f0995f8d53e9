"""Ctrl-C and SIGTERM during training: the first one finishes the generation, the second stops at once.

At once, but never between a generation's metrics row and its checkpoint: while the loop writes a
generation's files (``Interrupts.held``) a second signal waits for them, so a run stopped at once
keeps files that agree with each other (the metrics rows of the generations its checkpoint holds).

A cluster scheduler sends SIGTERM before it kills a job, so it is handled like Ctrl-C: the run
finishes its generation, saves, and stops with a resume command.

A job a non-interactive shell starts in the background (``cmd &`` in a script) inherits SIGINT
ignored, and Python then installs no handler of its own; ``honour_sigint`` gives such a process
Python's usual one, so ``kill -INT`` stops it as Ctrl-C stops a foreground run.
"""

from __future__ import annotations

import contextlib
import signal
import sys


class Interrupts:
    """While entered: ``requested`` turns True at the first signal; the second raises KeyboardInterrupt."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.requested = False
        self._held = False
        self._pending = False  # a second signal came while held
        self._previous: dict = {}

    def __enter__(self) -> Interrupts:
        self._previous = {signum: signal.signal(signum, self._handle) for signum in self.SIGNALS}
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    @contextlib.contextmanager
    def held(self):
        """A second signal within waits for the block's end, then stops the run at once."""
        self._held = True
        try:
            yield
        finally:
            self._held = False
        if self._pending:
            raise KeyboardInterrupt

    def _handle(self, signum, frame) -> None:
        if self.requested:
            if self._held:
                self._pending = True
                return
            raise KeyboardInterrupt
        self.requested = True
        name = "interrupt" if signum == signal.SIGINT else signal.Signals(signum).name
        print(f"\n{name}: finishing this generation, then saving (Ctrl-C again to stop at once)",
              file=sys.stderr, flush=True)


def honour_sigint() -> None:
    """Raise KeyboardInterrupt on SIGINT even where the process was started with SIGINT ignored."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
