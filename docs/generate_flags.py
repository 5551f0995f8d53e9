"""The docs' flag tables, from the scripts' own argparse parsers (``<!-- flags:SCRIPT -->``, docs/generate.py).

A table lists each flag of SCRIPT's parser as it declares it: option strings, default, help, choices;
``flags:SCRIPT except OTHER`` lists only the flags OTHER lacks. The parsers are imported, never read from
``--help``.
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

# the ER-MRL scripts' parsers live in reservoirs/commands.py (which needs the reservoirs extra)
RESERVOIR_SCRIPTS = ("evolve_res", "evolve_multi_res", "evolve_generalization", "test", "test_multi_res",
                     "test_generalization", "get_random_scores")


def parser_of(script: str) -> argparse.ArgumentParser:
    """The parser ``script`` (as the docs name it: ``train_hebb.py``, ``scripts/test.py``) runs with."""
    name = Path(script).stem
    if script.startswith("scripts/") and name in RESERVOIR_SCRIPTS:
        from reservoirs.commands import COMMANDS
        return COMMANDS[name][0](f"{name}.py")
    return importlib.import_module(name).build_parser()


def cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def default_text(action: argparse.Action) -> str:
    if hasattr(action, "shown_default"):  # a setting's flag (cli.flags): argparse's default is SUPPRESS
        return f"`{action.shown_default}`" if action.shown_default else "off"
    if action.required:
        return "required"
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreConstAction)) and not action.default:
        return "off"
    if action.default is None:
        return "–"
    if isinstance(action.default, (list, tuple)):
        return " ".join(f"`{value}`" for value in action.default)
    return f"`{action.default}`"


def meaning(action: argparse.Action) -> str:
    text = getattr(action, "plain_help", action.help) or ""  # a setting's flag: the help without its default
    text = text.replace("%(default)s", str(action.default)).replace("%%", "%")
    if action.choices is not None and not all(str(choice) in text for choice in action.choices):
        text += " (one of " + ", ".join(f"`{choice}`" for choice in action.choices) + ")"
    if isinstance(action, argparse._StoreConstAction) and action.dest != action.option_strings[0].lstrip("-"):
        text += f" (sets `--{action.dest} {action.const}`)"
    return cell(text)


def flags(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [action for action in parser._actions
            if action.option_strings and not isinstance(action, argparse._HelpAction)]


def signature(action: argparse.Action) -> tuple:
    return tuple(action.option_strings), repr(action.default), action.help, repr(action.choices), action.required


def table(script: str, other: str | None = None) -> str:
    actions = flags(parser_of(script))
    if other is not None:  # what differs: a flag of both scripts with another default or help is listed
        known = {signature(action) for action in flags(parser_of(other))}
        actions = [action for action in actions if signature(action) not in known]
    rows = ["| flag | default | meaning |", "|---|---|---|"]
    for action in actions:
        names = ", ".join(f"`{option}`" for option in action.option_strings)
        rows.append(f"| {names} | {default_text(action)} | {meaning(action)} |")
    return "\n".join(rows) + "\n"
