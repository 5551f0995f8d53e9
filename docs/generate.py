#!/usr/bin/env python
"""Write the generated parts of the docs: flag tables from the scripts' own parsers, measured figures from the
benchmarks' records, and the campaign's results from its runs' files.

A generated part sits between two markers, ``<!-- KIND:WORDS -->`` and ``<!-- end KIND -->``; ``MARKERS`` is the
one table of the kinds, saying what each holds and which function renders it: ``generate_flags.py`` (the
parsers), ``generate_records.py`` (benchmarks/results/), ``generate_evaluations.py`` (a campaign run's evaluation)
and ``generate_campaign.py`` (the rest of results/paper/). A marker
quoted as inline code, in backticks, is an example, not a marker.

``python docs/generate.py`` rewrites the generated parts of every page (README.md, experiments/README.md and
``docs/``); ``--check`` rewrites nothing and exits 1 naming the pages that differ (tests/test_docs.py runs the same
check). A figure that cannot be published (no record, a loaded one, too few rounds; a run this tool did not
evaluate) is refused, the page left as it is. The campaign's parts move on as it trains: a run evaluated (or a
report completed) since its page was written, and the campaign's remaining runs, are reported by ``--check`` as
behind, not refused, so the figures a page shows are always its files'.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent.parent
for folder in (ROOT, ROOT / "benchmarks", ROOT / "docs"):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

import generate_campaign as runs_files  # noqa: E402
import generate_evaluations as evaluations  # noqa: E402
import generate_flags as parsers  # noqa: E402
import generate_records as records_files  # noqa: E402
from generate_records import FigureError  # noqa: E402


class Where(NamedTuple):
    """What a marker is rendered for: its page (links are relative to it), and the folders it reads."""

    page: Path
    results: Path = records_files.records.RESULTS  # the benchmarks' records
    runs: Path = evaluations.RUNS  # the campaign's run folders


class Marker(NamedTuple):
    """A kind of marker: what its WORDS are, what it holds, and the function that renders it."""

    words: str  # as a page writes them, for the reader and the message naming a marker written wrong
    counts: tuple[int, ...]  # how many words it takes
    holds: str
    render: Callable[[list[str], Where], str]
    block: bool = False  # what it holds begins on the line after the marker and spans lines (a table)
    pending: str | None = None  # what it holds until its run is evaluated: a check leaves it, naming it behind
    moving: bool = False  # it follows every chunk of the campaign: a check leaves any other text, naming it behind


def flag_table(words: list[str], where: Where) -> str:
    """A flags marker's table: SCRIPT, or SCRIPT except OTHER."""
    if len(words) == 3 and words[1] != "except":
        raise FigureError(f"<!-- flags:{' '.join(words)} --> is not a marker: it takes flags:SCRIPT [except OTHER]")
    return parsers.table(words[0], words[2] if len(words) == 3 else None)


def one_run(render: Callable) -> Callable[[list[str], Where], str]:
    """A campaign run's marker, RUN [ENVIRONMENT]: ``render(run, environment or None, page, runs)``."""
    return lambda words, where: render(words[0], words[1] if len(words) > 1 else None, where.page, where.runs)


MARKERS: dict[str, Marker] = {
    "flags": Marker(
        "SCRIPT [except OTHER]", (1, 3), "the table of SCRIPT's flags as its parser declares them; with except "
        "OTHER, only the flags OTHER lacks", flag_table, block=True),
    "figure": Marker(
        "RECORD MEASURE", (2,), "one measured figure: the median of MEASURE in the newest quiet record of the "
        "benchmark command RECORD, its range and machine, linked to the record",
        lambda words, where: records_files.figure(*words, where.page, where.results)),
    "table": Marker(
        "RECORD KEY", (2,), "the table KEY a benchmark wrote into its record, estimates with their intervals, then "
        "the machine, linked", lambda words, where: records_files.record_table(*words, where.page, where.results),
        block=True),
    "intervals": Marker(
        "RECORD KEY", (2,), "for each probability P(X > Y) of the table KEY of a record: the rows whose 95 % "
        "interval lies above a half, holds a half, lies below it", lambda words, where:
        records_files.half_intervals(*words, where.page, where.results)),
    "result": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "a campaign run's evaluation: mean ± std, episodes, generation, hours of "
        "training and machines, linked to the file and the weights", one_run(evaluations.result),
        pending=evaluations.PENDING),
    "headline": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "a campaign run's evaluation in a few characters, for a table of results",
        one_run(evaluations.headline), pending=evaluations.PENDING),
    "spread": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "how a campaign run's evaluation returns spread: median, quartiles, lowest, "
        "highest, episodes far below the mean", one_run(evaluations.spread), pending=evaluations.PENDING),
    "best": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "the evaluation of a campaign run's best centre, with the generation it scored "
        "in and its training return", one_run(evaluations.best), pending=evaluations.PENDING),
    "lengths": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "how long a campaign run's evaluation episodes lasted: all of one length, or "
        "how many last the longest and what they score, and the others' lengths and median return",
        one_run(evaluations.lengths), pending=evaluations.PENDING),
    "lowest": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "a campaign run's lowest evaluation episode: its seed, its return and its "
        "length", one_run(evaluations.lowest), pending=evaluations.PENDING),
    "first": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "a campaign run's first evaluation episode, the one its frames.png shows: its "
        "length and its return", one_run(evaluations.first), pending=evaluations.PENDING),
    "forward": Marker(
        "RUN [ENVIRONMENT]", (1, 2), "how far a campaign run's ant walked toward +x in its evaluation, mean ± std",
        one_run(evaluations.forward), pending=evaluations.PENDING),
    "curve": Marker(
        "RUN THRESHOLD [THRESHOLD ...]", tuple(range(2, 10)), "how an evaluated campaign run trained: the first "
        "generation its population's mean return passed each threshold, and the range of that mean and of the "
        "centre's training episodes over the last 50 generations",
        lambda words, where: runs_files.curve(words[0], words[1:], where.page, where.runs),
        pending=evaluations.PENDING),
    "frames": Marker(
        "RUN", (1,), "a campaign run's frames.png, every 100th frame of its first evaluation episode",
        lambda words, where: runs_files.frames(words[0], where.page, where.runs), pending=runs_files.FRAMES_PENDING),
    "report": Marker(
        "EXPERIMENT ENVIRONMENT", (2,), "the campaign's report of an experiment on an environment: each kind's IQM "
        "and mean with their intervals and P(Hebbian > static), once every run it plans is in",
        lambda words, where: runs_files.report(*words, where.page, where.runs), pending=runs_files.REPORT_PENDING),
    "weight": Marker(
        "RUN", (1,), "what a campaign run adds to a clone: its checkpoint, committed by each chunk, then its final "
        "weights, evaluations and pictures, from the sizes of its files",
        lambda words, where: runs_files.weight(words[0], where.page, where.runs), pending=evaluations.PENDING),
    "remaining": Marker(
        "", (0,), "the campaign's remaining runs and what they will cost, projected from its completed runs "
        "(experiments/cost.py)", lambda words, where: runs_files.remaining(where.page, where.runs), moving=True),
}


@cache
def pattern(kind: str) -> re.Pattern:
    """The markers of ``kind`` in a page: the opening marker (group 1), its words, what it holds, its end."""
    block = MARKERS[kind].block
    return re.compile(rf"(?<!`)(<!-- {kind}(?::(?P<words>[^\n>]*?))? -->{chr(10) if block else ''})(?P<text>.*?)"
                      rf"(?P<end><!-- end {kind} -->)", re.DOTALL if block else 0)


def rewrite(kind: str, match: re.Match, where: Where, behind: list[str] | None) -> str:
    """One marker with what it holds now; given ``behind`` (a check), a campaign marker whose run has moved on
    since its page was written is left as it is, and named there."""
    marker, words = MARKERS[kind], (match["words"] or "").split()
    if len(words) not in marker.counts:
        raise FigureError(f"<!-- {kind}:{match['words'] or ''} --> is not a marker: it takes {kind}:{marker.words}"
                          if marker.words else f"<!-- {kind}:{match['words']} --> is not a marker: it takes no words")
    rendered = marker.render(words, where)
    late = (marker.moving and rendered != match["text"]) or (
        marker.pending is not None and match["text"] == marker.pending and rendered != marker.pending)
    if behind is not None and late:
        behind.append(words[0] if words else f"the campaign's {kind} runs")
        rendered = match["text"]
    return match[1] + rendered + match["end"]


def render(text: str, page: Path, behind: list[str] | None = None, kinds=None, **folders: Path) -> str:
    """``text`` (the page ``page``) with every marker of ``kinds`` (default: all of ``MARKERS``) rewritten; the
    folders read (``Where``: ``results``, ``runs``) may be given. FigureError for a marker that cannot be
    published; ``behind``: ``rewrite``."""
    where = Where(page, **folders)
    for kind in kinds or MARKERS:
        text = pattern(kind).sub(lambda match, kind=kind: rewrite(kind, match, where, behind), text)
    return text


def pages() -> list[Path]:
    """The pages whose figures come from the records (and, in docs/, whose flag tables come from the parsers)."""
    return [ROOT / "README.md", ROOT / "experiments" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table differs")
    args = parser.parse_args(argv)
    stale, refused, behind = [], [], []
    for page in pages():
        text = page.read_text()
        try:
            late = []
            generated = render(text, page, late if args.check else None)
            if late:
                behind.append(f"{page.relative_to(ROOT)} ({', '.join(late)})")
        except FigureError as error:
            refused.append(f"{page.relative_to(ROOT)}: {error}")
            continue
        if generated != text:
            stale.append(page.relative_to(ROOT))
            if not args.check:
                page.write_text(generated)
    if stale:
        print(("differ from the parsers or records: " if args.check else "rewritten: ") + ", ".join(map(str, stale)))
    if behind:
        print(f"behind their evaluated campaign runs (python docs/generate.py fills them in): {', '.join(behind)}")
    for line in refused:
        print(f"refused, left as it is: {line}", file=sys.stderr)
    return 1 if refused or (stale and args.check) else 0


if __name__ == "__main__":
    sys.exit(main())
