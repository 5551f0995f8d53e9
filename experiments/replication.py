#!/usr/bin/env python
"""The replication report of Najarro & Risi (2020): one page, ``results/paper/REPLICATION.md``, generated.

    python experiments/replication.py            # writes the page from the runs' files
    python experiments/replication.py --check    # writes nothing; exit 1 if the page differs from what they give

One row per claim of the paper: CarRacing, Hebbian against static; the quadruped on each body it trained on; on the
body it never saw; and the Hebbian network's adaptation within an episode. Each row holds the figure cited for the
paper (from secondary sources, unverified: docs/original.md), this tool's evidence, and a verdict decided by the rules
of ``experiments/verdicts.py`` (``verdict_of``), with its reason in one sentence. Everything comes from files:

- the campaign's reports (``experiments/paper.py EXPERIMENT report``, written by the campaign in
  ``results/paper/<experiment>_report/<environment>/``): the runs, the IQM and the mean of each kind with their 95 %
  bootstrap intervals, and P(X > Y) with its interval (summary.csv, improvement.csv, scores.csv);
- each evaluated run's files (config.json, metrics.csv, evaluation.json, made_with.json): the runs table and the
  compute each took;
- the adaptation row: episodes of each Hebbian ant run's final weights (``last_coeffs.dat``) at the first seeds of
  its evaluation, traced step by step (where the torso is, the norm of each layer's weights); the same numbers on
  every CPU (docs/reproducibility.md);
- the comparison with the environment the original ran (``experiments/original_ant.py``'s records in
  ``results/original_ant/``).

A run evaluated since the page was written makes ``--check`` say the page is behind (exit 0), as docs/generate.py
does with the docs' campaign results: the campaign writes its files as it goes; ``python experiments/replication.py``
catches the page up.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script
    sys.path.insert(0, str(ROOT))
from experiments import stand  # noqa: E402  (after the repository's root is on the path)
from experiments.original_ant import paired_interval  # noqa: E402
from experiments.pages import covered, runs_line, settle  # noqa: E402
from experiments.replication_files import (  # noqa: E402
    ReplicationError,
    Report,
    Run,
    evaluated_runs,
    hours,
    read_json,
    read_report,
)
from experiments.verdicts import (  # noqa: E402
    ADAPTATION,
    ALIVE_HEIGHT,
    ANT_BODIES,
    BODY_NAMES,
    CLAIMS,
    KIND_NAMES,
    MIN_RUNS,
    TRACE_EPISODES,
    WALK_DISTANCE,
    WALK_FROM,
    WALK_UNTIL,
    Claim,
    Trace,
    adaptation_verdict,
    trace_run,
    verdict_of,
)

RUNS = ROOT / "results" / "paper"
PAGE_NAME = "REPLICATION.md"
ORIGINAL_RECORDS = ROOT / "results" / "original_ant"


# --- the page ------------------------------------------------------------------------------------------------


def estimate(values: tuple[float, float, float], runs: int) -> str:
    value, low, high = values
    return f"{value:.1f}" if runs == 1 else f"{value:.1f} [{low:.1f}, {high:.1f}]"


def evidence(claim: Claim, report: Report | None, page: Path) -> str:
    if report is None:
        return "no evaluated run yet"
    cells = []
    for kind in ("hebbian", "static"):
        group = report.groups.get(kind)
        if group is not None:
            cells.append(f"{KIND_NAMES[kind]}: {group.runs} run{'s' * (group.runs != 1)}, IQM "
                         f"{estimate(group.iqm, group.runs)}, mean {estimate(group.mean, group.runs)}")
    if claim.higher and claim.higher in report.better:
        x, y = claim.higher
        probability, low, high = report.better[x, y]
        cells.append(f"P({KIND_NAMES[x]} > {KIND_NAMES[y]}) {probability:.2f} [{low:.2f}, {high:.2f}]")
    link = (report.folder / "summary.md").relative_to(page.parent).as_posix()
    return "; ".join(cells) + f" ([report]({link}))"


def adaptation_evidence(traces: dict[str, dict[str, list[Trace]]]) -> str:
    if not traces:
        return "no evaluated Hebbian run of the quadruped yet"
    cells = []
    for body in ANT_BODIES:
        episodes = [trace for runs in traces.values() for trace in runs[body]]
        walking = sum(trace.walks for trace in episodes)
        turned = float(np.median([trace.turned for trace in episodes]))
        cells.append(f"{BODY_NAMES[body]}: {walking} of {len(episodes)} episodes walk from step {WALK_FROM}, the "
                     f"weights at step {WALK_FROM} at cosine {turned:.2f} with their last (median)")
    runs = len(traces)
    return (f"{runs} run{'s' * (runs != 1)}, {TRACE_EPISODES} episodes per body: " + "; ".join(cells))


def runs_table(runs: list[Run], page: Path) -> list[str]:
    from report.machine import machines_text

    lines = ["| run | generations | evaluation: mean ± std (episodes) | training | environment steps | machine |",
             "|---|---|---|---|---|---|"]
    notes = []
    for run in runs:
        wall, steps, generations = hours(run)
        scores = "; ".join(f"{BODY_NAMES.get(entry['environment'], entry['environment'])} {entry['mean']:.1f} ± "
                           f"{entry['std']:.1f} ({entry['episodes']})" for entry in run.evaluation["environments"])
        workers = {entry.get("workers") for entry in run.config.get("machines", [])} - {None}
        worker_text = f" × {workers.pop()} workers" if len(workers) == 1 else ""
        name = f"[{run.name}]({run.folder.relative_to(page.parent).as_posix()})"
        if run.made_with is not None:
            notes.append(run)
            name += f" [^{run.name}]"
        lines.append(f"| {name} | {generations} of {run.config['run']['generations']} | {scores} | {wall:.2f} h"
                     f"{worker_text} | {steps:,} | {machines_text(run.config.get('machines', []))} |")
    lines.append("")
    for run in notes:
        lines.append(f"[^{run.name}]: Made with commit {run.made_with.get('commit', '?')[:12]}; its generations "
                     f"come again on {run.made_with.get('reproduces_on', '?')}: {run.made_with.get('why', '')}.")
    return lines


def compute_lines(runs: list[Run]) -> list[str]:
    totals: dict[tuple[str, str], list[float]] = {}
    for run in runs:
        wall, steps, _ = hours(run)
        workers = max([entry.get("workers", 1) for entry in run.config.get("machines", [])] or [1])
        totals.setdefault((run.experiment, run.kind), []).append(wall * workers)
    return [f"- {experiment}, {KIND_NAMES[kind]}: {len(values)} run{'s' * (len(values) != 1)}, "
            f"{sum(values):.1f} core-hours in all ({min(values):.1f} to {max(values):.1f} each)"
            for (experiment, kind), values in totals.items()]


def original_lines(records: Path, page: Path) -> list[str]:
    """The comparison with the environment the original ran, from experiments/original_ant.py's records: what the
    same actions gave, step by step, and the shipped agents' scores on both (a list, then a table)."""
    files = sorted(records.glob("*.json")) if records.is_dir() else []
    if not files:
        return ["- No record of `experiments/original_ant.py` yet.", ""]
    lines, scored = [], {}
    for file in files:
        record = read_json(file)
        code = {key: value for key, value in record.get("cpu_code", {}).items() if value}
        how = (f"the code numpy and OpenBLAS take on an AVX2 CPU ({', '.join(f'{k}={v}' for k, v in code.items())})"
               if code else "numpy's and OpenBLAS's own choice of code for this CPU")
        link = Path(os.path.relpath(file, page.parent)).as_posix()
        lockstep = record.get("lockstep", [])
        port = [entry for entry in lockstep if entry["against"] == "port"]
        batched = [entry for entry in lockstep if entry["against"] == "batched"]
        parted = sorted({entry["first_difference"] for entry in batched if entry["first_difference"] is not None})
        agree = "at every step" if all(entry["first_difference"] is None for entry in port) else "not at every step"
        batched_text = ("so does the batched class" if not parted else
                        f"the batched class parts from it, in last bits, at step {parted[0]}"
                        + (f" to {parted[-1]}" if len(parted) > 1 else ""))
        lines.append(f"- [{file.stem}]({link}), on {record.get('cpu', '?')} with {how}, gym "
                     f"{record.get('versions', {}).get('gym', '?')}: the same actions from the same reset "
                     f"({len(port)} episodes, random, static and Hebbian actions on the three bodies, "
                     f"{sum(entry['steps'] for entry in port):,} policy steps): pyBullet's port gives the original's "
                     f"observations, progress rewards and ends {agree}; {batched_text}; the first observation differs "
                     f"in the sine of the angle to the target alone, by at most "
                     f"{max(entry['reset_difference'] for entry in lockstep):.1e}.")
        for scores in record.get("scores", []):
            scored.setdefault((scores["kind"], scores["run"], scores["environment"]), []).append((file.stem, scores))
    if not scored:
        return [*lines, ""]
    spread = max(float(np.max(np.abs(np.array(a["original"]) - np.array(b["original"]))))
                 for entries in scored.values() for _, a in entries for _, b in entries)
    episodes = len(next(iter(scored.values()))[0][1]["seeds"])
    lines += ["", f"Each shipped agent on both, from the same resets ({episodes} episodes); the original's returns in "
                  f"the records differ by at most {spread:.1e}:", "",
              "| agent | body | the original's environment | this tool | this tool − original (95 %) | equal returns |",
              "|---|---|---|---|---|---|"]
    for (kind, run, environment), entries in scored.items():
        scores = entries[0][1]
        original, tool = np.array(scores["original"]), np.array(scores["tool"])
        difference = tool - original
        low, high = paired_interval(difference)
        equal = ", ".join(f"{int(np.sum(np.array(s['original']) == np.array(s['tool'])))} ({name})"
                          for name, s in entries)
        body = BODY_NAMES.get(environment, environment)
        lines.append(f"| {KIND_NAMES.get(kind, kind)}, seed {seed_of(run)} | {body} | {original.mean():.1f} ± "
                     f"{original.std():.1f} | {tool.mean():.1f} ± {tool.std():.1f} | {difference.mean():+.1f} "
                     f"[{low:+.1f}, {high:+.1f}] | {equal} |")
    return [*lines, ""]


def seed_of(run: str) -> str:
    match = re.search(r"_seed(\d+)", run)
    return match[1] if match else "?"


def render(runs_root: Path = RUNS, records: Path = ORIGINAL_RECORDS) -> str:
    page = runs_root / PAGE_NAME
    runs = evaluated_runs(runs_root)
    rows = []
    for claim in CLAIMS:
        report = read_report(runs_root, claim.experiment, claim.environment)
        verdict = verdict_of(claim, report)
        rows.append(f"| {claim.what} | {claim.paper} | {evidence(claim, report, page)} | **{verdict.status}**: "
                    f"{verdict.reason}. |")
    hebbian_ants = [run for run in runs if run.experiment == "ant" and run.kind == "hebbian"]
    traces = {run.name: trace_run(run) for run in hebbian_ants}
    verdict = adaptation_verdict(traces)
    rows.append(f"| {ADAPTATION[0]} | {ADAPTATION[1]} | {adaptation_evidence(traces)} | **{verdict.status}**: "
                f"{verdict.reason}. |")
    lines = [
        "# Replicating Najarro & Risi (2020)", "",
        "[← README](../../README.md) · generated by `python experiments/replication.py` from the campaign's files "
        "(do not edit: `python experiments/replication.py --check` compares)", "",
        "The figures cited for the paper come from secondary sources and are **unverified**: the paper's tables could "
        "not be read here ([docs/original.md](../../docs/original.md#the-papers-settings-and-figures)). This tool's "
        "evidence is the campaign's runs, at the paper's settings, each evaluated on the same 100 held-out episodes "
        "per environment; the intervals are 95 % stratified bootstrap intervals over the runs "
        "([report/stats.py](../../report/stats.py)).", "",
        "## The claims", "",
        "| claim | cited for the paper (unverified) | this tool's evidence | verdict |", "|---|---|---|---|",
        *rows, "",
        "How a verdict is decided: a claim that one kind scores higher is reproduced where the lower end of "
        "P(X > Y)'s interval is above 0.5, not reproduced where its upper end is below 0.5; a cited figure m ± s is "
        "reproduced where m lies within the interval of that kind's mean over runs, not reproduced where the interval "
        "misses [m − s, m + s]; anything else, and any claim with fewer than "
        f"{MIN_RUNS} runs of a kind it needs, is not yet decided. The adaptation row traces {TRACE_EPISODES} episodes "
        "per body of each Hebbian run's final weights (the first seeds of its evaluation): an episode walks from step "
        f"{WALK_FROM} where over steps {WALK_FROM + 1} to {WALK_UNTIL} the torso stays above {ALIVE_HEIGHT} m and "
        f"moves at least {WALK_DISTANCE} m forward; a run walks on a body where most of its episodes do, and the claim "
        "is reproduced where most runs walk on every body. The rules are code: "
        "[experiments/verdicts.py](../../experiments/verdicts.py).", "",
        "## The runs", "",
        *runs_table(runs, page), "",
        runs_line(run.name for run in runs), "",
        "## The checks behind it", "",
        "- **Gymnasium's and pyBullet's own classes give the same episodes.** The CarRacing this tool steps is a "
        "faster class that returns Gymnasium's `CarRacing-v3` observations, rewards and ends bit for bit "
        "(tests/test_car_racing.py steps both side by side; `CarRacingStock-v3` makes Gymnasium's own); the "
        "quadruped's batched class returns pyBullet's (tests/test_bullet_locomotion.py, with an AVX2 CPU's code, "
        "which the batched class computes as on every CPU).",
        "- **What makes a static ant stand**: the paper's static ant with one setting changed at a time, each "
        "change over three seeds, against the paper's runs over the same generations ([STATIC_ANT.md](STATIC_ANT.md)): "
        + stand.answer(stand.runs_in(runs_root)),
        "- **The compute each run took**, from its metrics.csv (wall-clock hours times the workers):",
        *("  " + line for line in compute_lines(runs)), "",
        "### The environment the original ran", "",
        "pyBullet's gym-based `pybullet_envs`, stepped as the original's fitness function stepped it, beside this "
        "tool's bodies ([docs/original.md](../../docs/original.md#the-originals-quadruped-side-by-side); "
        "`experiments/original_ant.py`, tests/test_original_ant.py):", "",
        *original_lines(records, page),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="experiments/replication.py", description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if the page differs from what the files give")
    parser.add_argument("--runs", type=Path, default=RUNS, metavar="DIR",
                        help=f"the campaign's folder; the page is DIR/{PAGE_NAME} (default: results/paper)")
    parser.add_argument("--records", type=Path, default=ORIGINAL_RECORDS, metavar="DIR",
                        help="experiments/original_ant.py's records (default: results/original_ant)")
    args = parser.parse_args(argv)
    page = args.runs / PAGE_NAME
    try:
        if not args.runs.is_dir():
            raise ReplicationError(f"--runs {args.runs}: not a folder")
        generated = render(args.runs, args.records)
    except ReplicationError as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2
    def behind(current: str) -> str | None:
        newer = covered(generated) - covered(current)
        return (f"the runs evaluated since it was written ({', '.join(sorted(newer))})"
                if newer and covered(current) <= covered(generated) else None)

    def write() -> None:
        page.write_text(generated)
        print(f"wrote {page}")

    return settle(page, generated, args.check, "python experiments/replication.py", write, behind)


if __name__ == "__main__":
    sys.exit(main())
