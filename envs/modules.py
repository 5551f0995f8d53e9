"""Which modules a run's recorded settings may make this process import.

A run folder's config.json names modules: ``env.recipe_modules`` (custom recipes, ``envs.recipes``)
and the ``module:`` part of a custom environment id (Gymnasium's ``module:EnvId``, ``envs.make``).
A resume imports them, so config.json could name any module with side effects on import. A folder
someone hands you is data: a name is imported only if it is a plain dotted module name
(``package.module``: no path, no relative import) outside Python's standard library
(``sys.stdlib_module_names``), and the resume says which modules it imports.
"""

from __future__ import annotations

import re
import sys

from envs.make import EnvironmentError_

PLAIN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*")


def recorded_modules(env_ids: tuple[str, ...], recipe_modules: tuple[str, ...]) -> tuple[str, ...]:
    """The modules settings name, in import order, each once."""
    named = [env_id.partition(":")[0] for env_id in env_ids if ":" in env_id] + list(recipe_modules)
    return tuple(dict.fromkeys(named))


class UnsafeModule(EnvironmentError_):
    """A recorded module name that is refused (a user error: one line, exit code 2)."""


def check_module_name(name: str, source: str) -> None:
    """Refuse a module ``source`` names that is not a plain dotted name outside the standard library."""
    if not isinstance(name, str) or not PLAIN_NAME.fullmatch(name):
        raise UnsafeModule(f"{source} names the module {name!r}, which is not a plain dotted module name "
                           "(package.module); refused to import it")
    top = name.split(".")[0]
    if top in sys.stdlib_module_names or top in sys.builtin_module_names or top == "__main__":
        raise UnsafeModule(f"{source} names the module {name!r}, of Python's standard library, as a custom "
                           "environment or recipe module; refused to import it (a custom module is your own package)")


def resume_imports(env_ids: tuple[str, ...], recipe_modules: tuple[str, ...], source: str) -> str | None:
    """Check every module these settings make a resume import (``check_module_name``); the line to print
    before importing them, or None where they name none."""
    modules = recorded_modules(env_ids, recipe_modules)
    for name in modules:
        check_module_name(name, source)
    return f"importing {', '.join(modules)}, as {source} names" if modules else None
