"""The optional extras the tests use, and the one way a test skips where an extra is missing.

A base install (``pip install -r requirements.txt``) runs the whole suite: a test that needs an extra
calls ``need("ray")`` (or ``need_module_level`` at the top of a file) and is skipped, with a reason
naming the extra and its install command, where any of the extra's modules is missing. The tests of
"a missing extra gives one line" do not use these: they run everywhere, hiding the extra where it is
installed.
"""

from __future__ import annotations

import importlib.util

import pytest

# extra (requirements-<extra>.txt) -> the modules the tests need of it
EXTRAS = {
    "reservoirs": ("reservoirpy", "scipy", "optuna", "stable_baselines3", "cmaes"),
    "ray": ("ray",),
    "atari": ("ale_py",),
    "tensorboard": ("tensorboard",),
    "wandb": ("wandb",),
    "mlflow": ("mlflow", "sqlalchemy", "alembic"),
    "strategies": ("cmaes",),
    "stats": ("rliable", "arch", "pandas"),
    "bench": ("evotorch",),
    "original": ("gym", "pkg_resources"),
}


def missing(extra: str) -> list[str]:
    return [module for module in EXTRAS[extra] if importlib.util.find_spec(module) is None]


def reason(extra: str) -> str:
    return (f"needs the {extra} extra ({', '.join(missing(extra))} not installed): "
            f"pip install -r requirements-{extra}.txt")


def need(extra: str) -> None:
    """Skip the calling test unless every module of ``extra`` can be imported."""
    if missing(extra):
        pytest.skip(reason(extra))


def need_module_level(extra: str) -> None:
    """Skip the whole test file (call it before the file imports the extra)."""
    if missing(extra):
        pytest.skip(reason(extra), allow_module_level=True)
