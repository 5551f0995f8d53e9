"""What ``scripts/<script>.py`` runs: the extra checked first (one line and exit code 2 if it is
missing), then ``reservoirs.commands``, which needs it.
"""

from __future__ import annotations

import signal
import sys

from reservoir_extra import EXTRA_MODULES, INSTALL_HINT, TEST_MODULES, missing_packages


def run_script(script: str, argv: list[str] | None = None) -> int:
    """Entry point of ``scripts/<script>.py``: one line and exit code 2 if the optional extra is missing.

    A SIGTERM (what cluster schedulers send) stops a script as Ctrl-C does, so that optuna marks the
    trial it interrupts as failed instead of leaving it running in the journal forever.
    """
    signal.signal(signal.SIGTERM, _interrupt)
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:  # a background job of a script: Ctrl-C's meaning back
        signal.signal(signal.SIGINT, signal.default_int_handler)
    missing = missing_packages(TEST_MODULES if script.startswith("test") else EXTRA_MODULES)
    if missing:
        print(f"{script}.py: error: the ER-MRL scripts need {', '.join(missing)}, not installed here; {INSTALL_HINT}",
              file=sys.stderr)
        return 2
    from reservoirs.commands import main  # only now: it imports the extra's packages

    return main(script, argv)


def _interrupt(signum, frame):
    raise KeyboardInterrupt
