"""The scripts' flags, made from the settings' declarations (``settings.setting``), and the value types of
the flags that are not settings (evaluation's outputs, the ER-MRL scripts).

``add_settings`` adds a script's setting flags: each once, with its help and its default said once. A
setting flag's default is ``argparse.SUPPRESS``, so that the parsed namespace holds exactly the settings
the user gave (``given``): a new run lays them over an experiment file and the defaults, a resume and an
evaluation over what the run recorded. ``flag_table`` gives the rows of the docs' flag tables.
"""

from __future__ import annotations

import argparse

import numpy as np

from cli.config import SECTIONS, declared
from es.settings import original_threads as threads_value  # the ER-MRL and experiment scripts' too
from settings import EPISODE_SEED_RANGE, SEED_RANGE, Option, chosen, expected, options, requirement


def converter(item: Option):
    """The argparse type of a setting's flag: its declared ``parse``, else its field's type."""
    if item.spec.parse is not None:
        return item.spec.parse
    base = item.base_type()
    return base if base in (int, float) else None


def shown_default(item: Option, default=None, note: str = "") -> str:
    """The default as --help says it ("" for a flag that is off by default), after ``note`` if any."""
    shown = item.spec.shown_default or (default if default is not None else item.default)
    shown = "off" if item.base_type() is bool or shown is None else str(shown)
    if shown == "off" and not note:
        return ""
    return f"{note}, {shown}" if note else shown


def help_text(item: Option, default: str) -> str:
    """The help, then what the setting needs and its range, with the default said once."""
    text = item.spec.help
    if item.choices is not None and item.spec.metavar:  # argparse lists them only without a metavar
        text = f"{text}: {', '.join(map(str, item.choices))}"
    found = requirement(item, declared())
    if found is not None:
        text = f"{text}; with {found[0]}"
    if item.spec.low is not None:
        text = f"{text}; {expected(item)}"
    return f"{text} (default: {default})" if default else text


HELP_ORDER = ("env", "es", "run", "policy", "log")  # --help as the original's: the environment first


def script_options(script: str, kind: str) -> list[Option]:
    """The settings whose flags ``script`` ("train" or "evaluate") has for a policy ``kind``: not those of
    another kind's plug-ins."""
    ordered = [item for section in HELP_ORDER for item in options(SECTIONS[section])]
    return [item for item in ordered if item.flag and script in item.spec.scripts
            and chosen(item, {"kind": kind}, ordered)]


def add_settings(parser: argparse.ArgumentParser, script: str, kind: str, defaults: dict | None = None,
                 evaluation_note: str = "") -> None:
    """The setting flags of ``script`` for ``kind``; ``defaults``: a script's own default of a setting (the
    training folder), ``evaluation_note``: what the evaluate scripts' help adds (their values come from the run)."""
    groups: dict[str | None, argparse._ActionsContainer] = {None: parser}
    parser.set_defaults(setting_flags=tuple(item.name for item in script_options(script, kind)))
    for item in script_options(script, kind):
        group = item.spec.group
        if group not in groups:
            groups[group] = parser.add_argument_group(group)
        add = groups[group].add_argument
        default = shown_default(item, (defaults or {}).get(item.name), evaluation_note if item.spec.evaluation else "")
        text = help_text(item, default)
        common = {"dest": item.name, "default": argparse.SUPPRESS, "help": text}
        if item.base_type() is bool and item.spec.parse is None:
            action = add(f"--{item.flag}", action="store_true", **common)
        elif item.many:  # --logger wandb mlflow; given twice, or with an alias, the values add up
            action = add(f"--{item.flag}", nargs="+", action="extend", choices=item.choices, metavar=item.spec.metavar,
                         **common)
        else:
            action = add(f"--{item.flag}", type=converter(item), choices=item.choices, metavar=item.spec.metavar,
                         **common)
        action.shown_default = default  # for the docs' tables: argparse's default is SUPPRESS
        action.plain_help = help_text(item, "")  # the help without its default
        for alias, value in item.spec.aliases.items():
            alias_action = add(f"--{alias}", dest=item.name, action="append_const" if item.many else "store_const",
                               const=value, default=argparse.SUPPRESS, help=f"the same as --{item.flag} {value}")
            alias_action.shown_default, alias_action.plain_help = "", alias_action.help


def given(args: argparse.Namespace) -> dict:
    """The settings the command line gave (their flags' defaults are suppressed; the script's other flags, such
    as the evaluate scripts' --episodes, are not settings)."""
    return {name: value for name, value in vars(args).items() if name in args.setting_flags}


def defaults(kind: str, overrides: dict | None = None) -> dict:
    """Every setting's default for a policy ``kind`` (a script's own defaults laid over)."""
    values = {item.name: item.default for settings in SECTIONS.values() for item in options(settings)}
    return {**values, "kind": kind, **(overrides or {})}


def flag_table(parser: argparse.ArgumentParser) -> list[tuple[str, str, str]]:
    """(flags, default, help) for each flag of a parser, in --help's order: the docs' flag tables."""
    rows = []
    for action in parser._actions:
        if not action.option_strings or action.help == argparse.SUPPRESS:
            continue
        plain = "" if action.default in (None, False, argparse.SUPPRESS) else str(action.default)
        default = getattr(action, "shown_default", plain)
        rows.append((", ".join(action.option_strings), default, action.help or ""))
    return rows


# --- value types of the flags that are not settings ----------------------------------------------------


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text}")
    return value


def positive_float(text: str) -> float:
    value = float(text)
    if not value > 0 or not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def _whole_number_in(text: str, low: int, high: int) -> int:
    value = int(text)
    if not low <= value <= high:
        raise argparse.ArgumentTypeError(f"must be a whole number from {low} to {high}, got {text}")
    return value


def seed_value(text: str) -> int:
    """A run's seed (``SEED_RANGE``)."""
    return _whole_number_in(text, *SEED_RANGE)


def episode_seed_value(text: str) -> int:
    """The first seed of evaluated episodes (``EPISODE_SEED_RANGE``)."""
    return _whole_number_in(text, *EPISODE_SEED_RANGE)


def non_empty(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("is empty; give a path")
    return text


def flag_value(text: str | None) -> bool:
    """``--render`` alone, or the original's ``--render True`` / ``--render False``."""
    if text is None:
        return True
    lowered = text.strip().lower()
    if lowered in ("1", "true", "yes", "on"):
        return True
    if lowered in ("0", "false", "no", "off", ""):
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


__all__ = ["add_settings", "defaults", "flag_table", "flag_value", "given", "non_empty", "positive_float",
           "positive_int", "script_options", "seed_value", "episode_seed_value", "threads_value"]
