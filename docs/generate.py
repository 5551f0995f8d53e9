#!/usr/bin/env python
"""Write the docs' flag tables from the scripts' own argparse parsers, and their measured figures from the
benchmarks' records.

Between ``<!-- flags:SCRIPT -->`` and ``<!-- end flags -->`` a page holds the table of SCRIPT's flags, as
its parser declares them (option strings, default, help, choices). ``<!-- flags:SCRIPT except OTHER -->``
lists only the flags OTHER lacks. The parsers are imported, never read from ``--help``.

Between ``<!-- figure:RECORD MEASURE -->`` and ``<!-- end figure -->`` a page (README.md, experiments/README.md
or ``docs/``) holds one measured figure: the median of MEASURE in ``benchmarks/results/RECORD.json``, its
range over the rounds and the machine, linked to the record ("9.31× (8.92–9.60), AMD EPYC, 2 cores"). A
record marked loaded, or a measure of fewer than 5 rounds, is refused (docs/development.md, "Benchmark
discipline").

Between ``<!-- table:RECORD KEY -->`` and ``<!-- end table -->`` a page holds a table a benchmark wrote into
its record (``Record.table``: the settings and results of ``benchmarks/vs_evotorch.py``), each estimate with its
interval ("20,513 [15,870, 26,011]"), followed by the machine and the link to the record. A loaded record is
refused here too.

Between ``<!-- result:RUN [ENVIRONMENT] -->`` and ``<!-- end result -->`` a page holds the evaluation of a
campaign run, ``results/paper/RUN`` (``carracing_hebbian_seed1``; its newest run folder): the mean ± std of
its evaluation.json (of ENVIRONMENT, where it evaluated several), its episodes and generation, linked to the
file and to the run's weights; until the run is evaluated, ``PENDING``. ``<!-- spread:RUN [ENVIRONMENT] -->`` and
``<!-- end spread -->`` hold how its returns spread: median, quartiles, lowest and highest, and how many
episodes fell below the mean by more than a quarter of it. ``<!-- frames:RUN -->`` and
``<!-- end frames -->`` hold its frames.png the same way. ``<!-- best:RUN [ENVIRONMENT] -->`` and
``<!-- end best -->`` hold the evaluation of its best centre (evaluation_best.json): mean ± std, with the
generation it scored in and its training return. ``<!-- report:EXPERIMENT ENVIRONMENT -->`` and
``<!-- end report -->`` hold the campaign's report of an experiment (``experiments/paper.py EXPERIMENT
report``, written in results/paper/EXPERIMENT_report/ENVIRONMENT/ at every chunk's end): each kind's IQM
and mean with their intervals and P(Hebbian > static), once every run the campaign plans for it is in.
A run evaluated (or a report completed) since its page was written is reported by ``--check`` as
behind, not refused: the figures a page shows are always its files'.

``python docs/generate.py`` rewrites the tables and figures of every page; ``--check`` rewrites nothing and
exits 1 naming the pages that differ (tests/test_docs.py runs the same check).
"""

from __future__ import annotations

import argparse
import csv
import importlib
import os
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
for folder in (ROOT, ROOT / "benchmarks"):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

import record as records  # noqa: E402  (benchmarks/record.py: what a record holds)

from cli.errors import USER_ERRORS  # noqa: E402
from es.files import read_json  # noqa: E402
from experiments import campaign, cost  # noqa: E402
from experiments.paper_args import campaign_entries  # noqa: E402
from experiments.paper_report import report_folder  # noqa: E402
from experiments.paper_runs import HELD_OUT_SEED, latest_run, load_experiment, run_name  # noqa: E402
from experiments.paper_status import campaign_plan  # noqa: E402
from experiments.progress import measure  # noqa: E402

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


# (a marker quoted as inline code, `<!-- figure:... -->`, is an example, not a figure)
FIGURE = re.compile(r"(?<!`)(<!-- figure:(?P<record>[\w.-]+) (?P<measure>\w+) -->)(?P<text>.*?)(<!-- end figure -->)")
UNITS = {"x": "×", "": "", "us": " µs"}  # any other unit is written after a space as it is ("ms", "h", "steps/s")


class FigureError(ValueError):
    """A figure that cannot be published: no such record or measure, a loaded record, too few rounds."""


def number(value: float) -> str:
    """Three significant digits or so: 1,005 / 17.6 / 9.31 / 0.862."""
    size = abs(value)
    return f"{value:,.0f}" if size >= 100 else f"{value:.1f}" if size >= 10 else f"{value:.2f}" if size >= 1 \
        else f"{value:.3f}"


def published(name: str, results: Path) -> tuple[Path, dict]:
    """The newest record of the command ``name`` not taken on a loaded machine, and its path (``record.newest``);
    FigureError where there is none."""
    try:
        return records.newest(name, results)
    except ValueError as error:  # none, every one loaded, a file that is not a record
        raise FigureError(str(error)) from None


def figure(name: str, measure: str, page: Path, results: Path = records.RESULTS) -> str:
    """The text of one figure: median, range and machine, linked (from ``page``) to its record."""
    path, record = published(name, results)
    if measure not in record["measures"]:
        raise FigureError(f"{name}: no measure {measure!r} (it has {', '.join(record['measures'])})")
    values = record["measures"][measure]
    if values["rounds"] < records.MIN_ROUNDS:
        raise FigureError(f"{name} {measure}: {values['rounds']} rounds; a figure is the median of at least "
                          f"{records.MIN_ROUNDS}")
    unit = UNITS.get(values["unit"], " " + values["unit"])
    text = (f"{number(values['median'])}{unit} ({number(values['min'])}–{number(values['max'])}), {record['cpu']}, "
            f"{record['cores']} cores")
    return f"[{text}]({Path(os.path.relpath(path, page.parent)).as_posix()})"


TABLE = re.compile(r"(?<!`)(<!-- table:(?P<record>[\w.-]+) (?P<key>\w+) -->\n)(?P<text>.*?)(<!-- end table -->)",
                   re.DOTALL)


def table_cell(value) -> str:
    """Text as it is; a count (an int) as it is, with thousands separators; any other number as ``number``
    writes it; an estimate as "value [low, high]" (with ``digits`` decimals where it gives them: a
    probability)."""
    if isinstance(value, dict):
        digits = value.get("digits")
        shown = number if digits is None else (lambda x: f"{x:.{digits}f}")
        return f"{shown(value['value'])} [{shown(value['low'])}, {shown(value['high'])}]"
    if isinstance(value, int) and not isinstance(value, bool):
        return f"{value:,}"
    if isinstance(value, float):
        return number(value)
    return cell(value)


def record_table(name: str, key: str, page: Path, results: Path = records.RESULTS) -> str:
    """A record's table (``Record.table``) in markdown, then its machine and date, linked to the record."""
    path, record = published(name, results)
    table = record.get("notes", {}).get(key)
    if not isinstance(table, dict) or {"columns", "rows"} - set(table):
        raise FigureError(f"{name}: no table {key!r} in its notes")
    lines = ["| " + " | ".join(map(cell, table["columns"])) + " |", "|" + "---|" * len(table["columns"])]
    lines += ["| " + " | ".join(table_cell(value) for value in row) + " |" for row in table["rows"]]
    link = Path(os.path.relpath(path, page.parent)).as_posix()
    return "\n".join(lines) + f"\n\n[{record['cpu']}, {record['cores']} cores, {record['date'][:10]}]({link})\n"


def render_figures(text: str, page: Path, results: Path = records.RESULTS) -> str:
    """``text`` with every figure and record table rewritten from its record; FigureError for one that cannot be
    published."""
    text = TABLE.sub(lambda match: match[1] + record_table(match["record"], match["key"], page, results) + match[5],
                     text)
    return FIGURE.sub(lambda match: match[1] + figure(match["record"], match["measure"], page, results) + match[5],
                      text)


RUNS = ROOT / "results" / "paper"  # the campaign's run folders
RESULT = re.compile(r"(?<!`)(<!-- (?P<what>result|headline|spread|best):(?P<run>[\w.-]+)"
                    r"(?: (?P<environment>[\w.:-]+))? -->)(?P<text>.*?)(?P<end><!-- end (?P=what) -->)")
FRAMES = re.compile(r"(?<!`)(<!-- frames:(?P<run>[\w.-]+) -->)(?P<text>.*?)(?P<end><!-- end frames -->)")
REPORT = re.compile(r"(?<!`)(<!-- report:(?P<run>\w+) (?P<environment>[\w.:-]+) -->)(?P<text>.*?)"
                    r"(?P<end><!-- end report -->)")
REMAINING = re.compile(r"(?<!`)(<!-- remaining -->)(?P<text>.*?)(?P<end><!-- end remaining -->)")
PENDING = "not yet: training in the campaign"
FRAMES_PENDING = "(the agent's frames, once its run is evaluated)"
REPORT_PENDING = "not yet: the campaign's seeds are still training"
KIND_NAMES = {"hebbian": "Hebbian", "static": "static"}


def evaluated(name: str, runs: Path, file: str = campaign.EVALUATION) -> Path | None:
    """The newest run folder of ``runs/name`` (the one experiments/paper.py continues), if it has been evaluated
    (its ``file``: the final centre's evaluation, or the best centre's)."""
    run = latest_run(runs / name)
    return run if run is not None and (run / file).is_file() else None


def link(path: Path, page: Path) -> str:
    return Path(os.path.relpath(path, page.parent)).as_posix()


def evaluation_of(name: str, environment: str | None, runs: Path,
                  file: str = campaign.EVALUATION) -> tuple[Path, dict, dict] | None:
    """The newest run of ``runs/name``, its evaluation ``file`` and the entry of ``environment`` there (the only
    one, where None); None until the run is evaluated."""
    run = evaluated(name, runs, file)
    if run is None:
        return None
    try:
        evaluation = read_json(run / file)
        entries = evaluation["environments"]
        found = ", ".join(entry["environment"] for entry in entries)
    except (KeyError, TypeError, ValueError, OSError, *USER_ERRORS) as error:
        raise FigureError(f"{name}: {run} is not a run this tool evaluated ({type(error).__name__}: {error})") from None
    chosen = [entry for entry in entries if environment in (None, entry["environment"])]
    if len(chosen) != 1:
        raise FigureError(f"{name}: {'no' if not chosen else 'several'} environment{'' if environment else 's'} "
                          f"{environment or ''} in {run / file} ({found}); name one in the marker")
    return run, evaluation, chosen[0]


def scored(run: Path, file: str, evaluation: dict, entry: dict, page: Path) -> str:
    """"**903 ± 45.1** ([100 episodes on held-out seeds](link)": one environment's returns in an evaluation
    ``file`` of ``run``, linked; a KeyError or TypeError where the file is not one."""
    seeds = "on held-out seeds" if evaluation["seed"] >= HELD_OUT_SEED else f"from seed {evaluation['seed']}"
    return (f"**{number(entry['mean'])} ± {number(entry['std'])}** ([{entry['episodes']} episodes {seeds}]"
            f"({link(run / file, page)})")


def result(name: str, environment: str | None, page: Path, runs: Path = RUNS) -> str:
    """One campaign run's evaluation: "**903 ± 45.1** (100 episodes on held-out seeds, generation 300 after 7.31 h
    of training on AMD EPYC 7B13, 2 workers, weights)"; the hours are the sum of metrics.csv's ``seconds``, the
    machines config.json's record."""
    found = evaluation_of(name, environment, runs)
    if found is None:
        return PENDING
    run, evaluation, entry = found
    try:
        headline = scored(run, campaign.EVALUATION, evaluation, entry, page)
        progress = measure(run)
    except (KeyError, TypeError, ValueError, OSError, *USER_ERRORS) as error:
        raise FigureError(f"{name}: {run} is not a run this tool evaluated ({type(error).__name__}: {error})") from None
    return (f"{headline}, generation {progress.done} after {number(progress.hours)} h of training"
            + (f" on {progress.machines}" if progress.machines else "") + f", [weights]({link(run, page)}))")


def headline(name: str, environment: str | None, page: Path, runs: Path = RUNS) -> str:
    """One campaign run's evaluation in a few characters, for a table of results: "[**867 ± 130**](evaluation.json)"."""
    found = evaluation_of(name, environment, runs)
    if found is None:
        return PENDING
    run, _, entry = found
    try:
        return f"[**{number(entry['mean'])} ± {number(entry['std'])}**]({link(run / campaign.EVALUATION, page)})"
    except (KeyError, TypeError, ValueError) as error:
        raise FigureError(f"{name}: {run / campaign.EVALUATION} holds no mean and spread "
                          f"({type(error).__name__}: {error})") from None


def best(name: str, environment: str | None, page: Path, runs: Path = RUNS) -> str:
    """One campaign run's best centre evaluated on the final centre's episodes: "**897 ± 61.2** (100 episodes on
    held-out seeds, the best centre: training return 921.5 at generation 248)"."""
    found = evaluation_of(name, environment, runs, campaign.BEST_EVALUATION)
    if found is None:
        return PENDING
    run, evaluation, entry = found
    try:
        headline = scored(run, campaign.BEST_EVALUATION, evaluation, entry, page)
        centre = evaluation["weights"]
        where = f" at generation {centre['generation']}" if centre.get("generation") is not None else ""
        return f"{headline}, the best centre: training return {number(centre['training_return'])}{where})"
    except (KeyError, TypeError, ValueError) as error:
        raise FigureError(f"{name}: {run / campaign.BEST_EVALUATION} is not a best centre's evaluation "
                          f"({type(error).__name__}: {error})") from None


def spread(name: str, environment: str | None, page: Path, runs: Path = RUNS) -> str:
    """How one campaign run's evaluation returns spread: "median 905, quartiles 888–915, lowest 106, highest 936;
    4 of 100 episodes below three quarters of the mean (650)" (numpy's percentiles, linear)."""
    found = evaluation_of(name, environment, runs)
    if found is None:
        return PENDING
    run, _, entry = found
    try:
        returns = np.asarray(entry["returns"], dtype=np.float64)
        low, median, high = np.percentile(returns, [25, 50, 75])
        floor = 0.75 * returns.mean()
    except (KeyError, TypeError, ValueError, IndexError) as error:
        raise FigureError(f"{name}: {run / 'evaluation.json'} holds no returns ({type(error).__name__}: {error})") \
            from None
    return (f"median {number(median)}, quartiles {number(low)}–{number(high)}, lowest {number(returns.min())}, "
            f"highest {number(returns.max())}; {int((returns < floor).sum())} of {returns.size} episodes below three "
            f"quarters of the mean ({number(floor)})")


def frames(name: str, page: Path, runs: Path = RUNS) -> str:
    run = evaluated(name, runs)
    if run is None or not (run / "frames.png").is_file():
        return FRAMES_PENDING
    return f"![{name}: every 100th frame of its first evaluation episode]({link(run / 'frames.png', page)})"


def campaign_folders(experiment: str) -> dict[str, set[str]]:
    """Per kind, the folders of the runs experiments/paper/campaign.toml plans for ``experiment``."""
    planned: dict[str, set[str]] = {}
    for entry in campaign_entries():
        if entry.experiment == experiment:
            planned.setdefault(entry.kind, set()).add(run_name(entry, load_experiment(entry)[1]))
    return planned


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def report(experiment: str, environment: str, page: Path, runs: Path = RUNS,
           planned: dict[str, set[str]] | None = None) -> str:
    """The campaign's report of ``experiment`` on ``environment`` (``experiments/paper.py EXPERIMENT report``, in
    ``runs``): each kind's IQM and mean with their 95 % bootstrap intervals, and P(Hebbian > static), linked to
    the report, and how many of the runs the campaign plans for the experiment (``planned``: folder names per
    kind) are still to come. Pending until each kind has an evaluated run and the report holds every evaluated
    one, so that a page never shows a report older than the runs."""
    folder = report_folder(runs, experiment) / environment
    planned = campaign_folders(experiment) if planned is None else planned
    try:
        scores = read_rows(folder / "scores.csv")
        summaries = read_rows(folder / "summary.csv")
        pairs = read_rows(folder / "improvement.csv")
        reported = {Path(row["run"]).parts[0] for row in scores}  # the runs' folders: carracing_static_seed1, ...
    except FileNotFoundError:
        return REPORT_PENDING
    except (KeyError, IndexError):
        raise FigureError(f"{experiment}: {folder / 'scores.csv'} names no runs") from None
    done = {kind: {name for name in names if evaluated(name, runs)} for kind, names in planned.items()}
    if not planned or not all(done.values()) or not all(names <= reported for names in done.values()):
        return REPORT_PENDING
    to_come = sum(len(names) for names in planned.values()) - sum(len(names) for names in done.values())

    def interval(row: dict, low: str, high: str, single: bool, show=number) -> str:
        # a group of one run has no interval: every resample is that run (report/stats.py's markdown)
        return " (no interval: 1 run)" if single else f" [{show(float(row[low]))}, {show(float(row[high]))}]"

    try:
        counts = {row["group"]: int(row["runs"]) for row in summaries}
        sizes = set(counts.values())
        if not sizes:
            raise ValueError("no group")
        cells = [f"{KIND_NAMES.get(row['group'], row['group'])} IQM **{number(float(row['iqm']))}**"
                 f"{interval(row, 'iqm_low', 'iqm_high', counts[row['group']] == 1)}, mean "
                 f"**{number(float(row['mean']))}**{interval(row, 'mean_low', 'mean_high', counts[row['group']] == 1)}"
                 for row in summaries]
        pair = next(row for row in pairs if (row["x"], row["y"]) == ("hebbian", "static"))
        better = (f"P(Hebbian > static) **{float(pair['probability']):.2f}**"
                  f"{interval(pair, 'low', 'high', min(counts.values()) == 1, lambda value: f'{value:.2f}')}")
    except (KeyError, ValueError, StopIteration) as error:
        raise FigureError(f"{experiment}: {folder} is not a report of both kinds ({type(error).__name__}: {error})") \
            from None
    over = (f"{min(sizes)} run{'s' if min(sizes) > 1 else ''} of each kind" if len(sizes) == 1 else
            "runs of " + ", ".join(f"{group}: {count}" for group, count in counts.items()))
    over += " (95 % bootstrap intervals)" if max(sizes) > 1 else ""
    later = f"; {to_come} more run{'s' if to_come > 1 else ''} of the campaign to come" if to_come else ""
    return f"over {over}: {'; '.join(cells)}; {better} ([the report]" \
           f"({link(folder / 'summary.md', page)})){later}"


def remaining(page: Path, runs: Path = RUNS) -> str:
    """The campaign's remaining runs and what they will cost, projected from its completed runs in ``runs``
    (``experiments/cost.py``: on the workers those ran on, and on more where a benchmark's record projects it)."""
    try:
        plan = campaign_plan(runs)
    except (KeyError, TypeError, ValueError, OSError, *USER_ERRORS) as error:
        raise FigureError(f"the campaign's runs in {runs} cannot be read ({type(error).__name__}: {error})") from None
    return cost.summary(cost.project([planned for _, planned in plan]), page)


def render_results(text: str, page: Path, runs: Path = RUNS, behind: list[str] | None = None) -> str:
    """``text`` with every campaign result and frame strip rewritten from its run; given ``behind`` (a check),
    a marker that still reads as pending while its run has been evaluated is left as it is, and named there."""
    def rewrite(match: re.Match, rendered: str, pending: str) -> str:
        if behind is not None and match["text"] == pending and rendered != pending:
            behind.append(match["run"])
            rendered = pending
        return match[1] + rendered + match["end"]

    writers = {"result": result, "headline": headline, "spread": spread, "best": best}
    text = RESULT.sub(lambda match: rewrite(match, writers[match["what"]](match["run"], match["environment"], page,
                                                                          runs), PENDING), text)
    text = FRAMES.sub(lambda match: rewrite(match, frames(match["run"], page, runs), FRAMES_PENDING), text)
    text = REPORT.sub(lambda match: rewrite(match, report(match["run"], match["environment"], page, runs),
                                            REPORT_PENDING), text)

    def cost_now(match: re.Match) -> str:  # the campaign moves on at every chunk: a check names it, and goes on
        rendered = remaining(page, runs)
        if behind is not None and rendered != match["text"]:
            behind.append("the campaign's remaining runs")
            rendered = match["text"]
        return match[1] + rendered + match["end"]

    return REMAINING.sub(cost_now, text)


def render(text: str, page: Path | None = None, behind: list[str] | None = None) -> str:
    """``text`` with every flag table rewritten from the parsers, and, given its ``page``, every figure from
    its record and every campaign result from its run (``behind``: ``render_results``)."""
    text = MARKER.sub(lambda match: match[1] + table(match["script"], match["other"]) + match[5], text)
    return text if page is None else render_results(render_figures(text, page), page, behind=behind)


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
