#!/usr/bin/env python
"""Write the flag tables of the docs from the scripts' own argparse parsers.

Between ``<!-- flags:SCRIPT -->`` and ``<!-- end flags -->`` a page holds the table of SCRIPT's flags, as
its parser declares them (option strings, default, help, choices). ``<!-- flags:SCRIPT except OTHER -->``
lists only the flags OTHER lacks. ``python docs/generate.py`` rewrites the tables of every page of
``docs/``; ``--check`` rewrites nothing and exits 1 naming the pages whose tables differ (tests/test_docs.py
runs the same check). The parsers are imported, never read from ``--help``.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

MARKER = re.compile(r"(<!-- flags:(?P<script>\S+)(?: except (?P<other>\S+))? -->\n)(?P<table>.*?)(<!-- end flags -->)",
                    re.DOTALL)
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
    text = (action.help or "").replace("%(default)s", str(action.default)).replace("%%", "%")
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


def render(text: str) -> str:
    """``text`` with every flag table rewritten from the parsers."""
    return MARKER.sub(lambda match: match[1] + table(match["script"], match["other"]) + match[5], text)


def pages() -> list[Path]:
    return sorted((ROOT / "docs").glob("*.md"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table differs")
    args = parser.parse_args(argv)
    stale = []
    for page in pages():
        text = page.read_text()
        generated = render(text)
        if generated != text:
            stale.append(page.relative_to(ROOT))
            if not args.check:
                page.write_text(generated)
    if stale:
        print(("differ from the parsers: " if args.check else "rewritten: ") + ", ".join(map(str, stale)))
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
