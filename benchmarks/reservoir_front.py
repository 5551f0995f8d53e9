#!/usr/bin/env python
"""Evolved weights and Hebbian rules, with and without a reservoir before the network: the table of
docs/reservoirs.md, from ``experiments/reservoir_front/compare.py``.

    python benchmarks/reservoir_front.py --popsize 32 --generations 100 --threads 2 -- \\
        --optimizer adam --lr 0.01 --sigma 0.02 --obs_norm

Every flag but ``--results`` goes to ``compare.py`` as it is (its arms, seeds, budget, evaluation episodes, and
after ``--`` the training flags of every arm); its runs go to its ``--folder`` (default runs/reservoir_front),
and the same command again resumes what a stop left unfinished and evaluates nothing twice. The record
(``reservoir_front-<environment>``, not timed: a seeded run's returns are the same at any load) holds each arm's
mean evaluation return per seed and over the seeds (``compare.means``), one measure per arm.
"""

from __future__ import annotations

import json
import subprocess
import sys

from record import ROOT, Record, add_results_flag

from experiments.reservoir_front import compare

SCRIPT = ROOT / "experiments" / "reservoir_front" / "compare.py"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = compare.build_parser(prog="reservoir_front.py", doc=__doc__)
    add_results_flag(parser)
    settings, _ = compare.parse(argv, parser)  # compare.py's refusals, in one line, before any run
    if settings.dry_run:
        parser.error("--dry-run: a dry run measures nothing; give it to experiments/reservoir_front/compare.py")
    cut = argv.index("--") if "--" in argv else len(argv)
    at = next((i for i, word in enumerate(argv[:cut]) if word == "--results" or word.startswith("--results=")), None)
    passed = argv if at is None else [*argv[:at], *argv[at + (1 if "=" in argv[at] else 2):]]
    code = subprocess.run([sys.executable, str(SCRIPT), *passed]).returncode
    if code != 0:
        print(f"reservoir_front.py: error: compare.py stopped (exit code {code}); the same command resumes it",
              file=sys.stderr)
        return 2 if code == 2 else 1
    results = {arm: {int(seed): run for seed, run in runs.items()}
               for arm, runs in json.loads((settings.folder / "results.json").read_text()).items()}
    environment = settings.environment.split(":")[-1].replace(",", "+")
    record = Record(f"reservoir_front-{environment}", timed=False)
    names = compare.environment_names(results)
    rows = []
    for arm, per_seed, mean, per_env in compare.means(results, settings.seeds):
        record.add(arm, f"{arm}: each seed's mean evaluation return", "", per_seed)
        rows.append([arm, *(f"{value:.1f}" for value in (*per_seed, mean, *per_env))])  # as compare.py's table
    record.table("results", ["arm", *(f"seed {seed}" for seed in settings.seeds), "mean", *names], rows)
    record.note("protocol", {"command": ["compare.py", *passed], "folder": str(settings.folder),
                             "environment": settings.environment, "seeds": settings.seeds,
                             "episodes": settings.episodes})
    record.write(settings.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
