"""``experiments/paper.py EXPERIMENT curves``: both kinds' training curves, every seed's, in one figure.

Each seed's newest run in the folder of the runs is drawn as its population mean, centre and best so far, the x
axis to the runs' total generations; a run not yet complete is labelled partial, with how far it got. A chunk of
the campaign redraws the figure of the experiment it trained at its end.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cli.errors import say
from cli.hints import TRAIN_SCRIPTS
from experiments.paper_runs import latest_run, shown
from experiments.progress import measure


def curves_figure(runs: Path, experiment: str) -> tuple[Path, list[str]] | None:
    """Every seed's newest run of both kinds in ``runs``, each as population mean, centre and best so far, in
    one figure, ``runs/<experiment>_curves.png``, the x axis to the runs' total generations: a run not yet
    complete is labelled partial, with how far it got. Returns the file and the labels; None for no run."""
    from es import files
    from report import plots

    curves, total = [], 0
    for kind in TRAIN_SCRIPTS:
        for folder in sorted(runs.glob(f"{experiment}_{kind}_seed*")):
            run = latest_run(folder)
            if run is None or not (run / "metrics.csv").exists():
                continue
            progress = measure(run)
            label = f"{kind} seed {folder.name.rsplit('seed', 1)[1]}"
            if not progress.complete:
                label += f", partial: generation {progress.done} of {progress.total}"
            rows = [row for row in files.read_metrics(run / "metrics.csv") if int(row["generation"]) <= progress.done]
            curves.append((label, rows))
            total = max(total, progress.total)
    if not curves:
        return None
    out = runs / f"{experiment}_curves.png"
    plots.save_comparison(out, curves, generations=total)
    return out, [label for label, _ in curves]


def training_curves(args: argparse.Namespace) -> int:
    """``EXPERIMENT curves``: ``curves_figure`` of the runs in --runs."""
    written = curves_figure(args.runs, args.experiment)
    if written is None:
        print(f"paper.py: error: no {args.experiment} run in {args.runs}; train one first", file=sys.stderr)
        return 2
    out, labels = written
    say(f"wrote {shown(out)} ({'; '.join(labels)})")
    return 0
