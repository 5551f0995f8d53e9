"""How the scripts fail: one line naming the problem and what would be valid, exit code 2.

Errors a user can cause are raised, anywhere below, as ValueError subclasses that say what is wrong
(a bad value, a missing or corrupt file, an unknown environment); the scripts catch them here and
print them as one line. Nothing is created or overwritten before the inputs are checked.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

import envs
from envs.headless import explain_gl_failure
from es.backends import BackendUnavailable
from es.files import FileFormatError
from es.runfolder import RunFolderError


class UserError(ValueError):
    """A problem the user can fix (bad value, missing file); reported in one line, exit code 2."""


USER_ERRORS = (UserError, FileFormatError, RunFolderError, BackendUnavailable, envs.EnvironmentError_)


class Parser(argparse.ArgumentParser):
    """argparse whose errors are one line and exit code 2, and which takes no abbreviations: a
    ``--gen 4`` read as ``--generations`` would be silently ignored on resume."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


@contextlib.contextmanager
def explained(what: str):
    """Turn a setup failure into a UserError: a ValueError already says what is wrong (incompatible
    environments, a wrong-sized file); anything else (a custom environment whose constructor
    raises, a worker that cannot start) is named with ``what`` and its type."""
    try:
        yield
    except USER_ERRORS:
        raise
    except ValueError as error:
        raise UserError(str(error)) from None
    except Exception as error:
        reason = explain_gl_failure(error)  # MuJoCo under a MUJOCO_GL whose library does not load
        raise UserError(str(reason) if reason is not None else f"{what}: {type(error).__name__}: {error}") from None


def say(line: str) -> None:
    """Print a line of output. If whoever reads it has gone (``| head``), the rest of the output is
    discarded and the work goes on: a run is not lost because its reader stopped reading."""
    try:
        print(line, flush=True)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # also what the interpreter flushes at exit
        os.close(devnull)
