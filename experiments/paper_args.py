"""``experiments/paper.py``'s command line, and the campaign file's runs, which are command lines of it.

``parse`` reads the arguments and checks how they go together (``campaign`` takes --budget or --status; --status,
--reproduce and --centre go with what they name); ``campaign_entries`` reads ``experiments/paper/campaign.toml``
with the same parser, a problem in the file named as the file's (``campaign.CampaignError``), not the command
line's.
"""

from __future__ import annotations

import argparse
import shlex
import tomllib
from pathlib import Path

from cli.errors import Parser
from cli.flags import non_empty, positive_float, positive_int, seed_value, threads_value
from cli.hints import TRAIN_SCRIPTS
from experiments import campaign, paper_runs
from experiments.paper_runs import CENTRES, EXPERIMENTS, ROOT, shown
from report.stats import DEFAULT_REPS


def parse(argv: list[str] | None, entry_of: str | None = None, doc: str = "") -> argparse.Namespace:
    """paper.py's arguments, its help made of ``doc`` (paper.py's docstring: a line, then the epilog); ``entry_of``:
    they are a run of that campaign file, and a problem with them raises a CampaignError naming it (the file is
    data, and its errors are not the command line's)."""
    lines = doc.splitlines() or [""]
    parser = Parser(prog="paper.py", description=lines[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                    epilog="\n".join(lines[2:]))
    if entry_of is not None:
        def refuse(message: str):
            raise campaign.CampaignError(f"{entry_of}: the run {shlex.join(argv)!r}: {message}; each run is an "
                                         "experiment, a kind and its flags, as paper.py takes them")
        parser.error = refuse
    parser.add_argument("experiment", choices=(*EXPERIMENTS, "campaign"),
                        help="an experiment, or campaign: the next runs of experiments/paper/campaign.toml (--budget)")
    parser.add_argument("kind", nargs="?", choices=(*TRAIN_SCRIPTS, "report", "curves"),
                        help="train and evaluate one kind; report: compare the kinds over their seeds; curves: "
                             "both kinds' training curves in one figure, <folder of the runs>/<experiment>_curves.png")
    parser.add_argument("--seed", type=seed_value, default=None, help="seed of the training run (default: the file's)")
    parser.add_argument("--variant", type=non_empty, default=None, metavar="FILE",
                        help="train the experiment with the changes of FILE: some of the experiment file's sections, "
                             "each with the settings it changes (experiments/static_ant/*.toml); its runs go to "
                             f"{paper_runs.RESULTS}/<experiment>_<kind>_<FILE's name>_seed<seed>. In the campaign "
                             "file, relative to the repository's root")
    parser.add_argument("--popsize", type=positive_int, default=None, help="default: the file's")
    parser.add_argument("--generations", type=positive_int, default=None,
                        help="total generations (default: the file's)")
    parser.add_argument("--episodes", type=positive_int, default=None,
                        help="evaluation episodes per body (default: the file's)")
    parser.add_argument("--threads", type=threads_value, default=None,
                        help="workers; -1 = all cores (default: the file's)")
    parser.add_argument("--folder", type=non_empty, default=None,
                        help=f"default: {paper_runs.RESULTS}/<experiment>_<kind>_seed<seed> in the repository")
    parser.add_argument("--budget", type=positive_float, default=None, metavar="MINUTES",
                        help="train one chunk of at most MINUTES, stop at a generation boundary, saved (the campaign)")
    parser.add_argument("--runs", type=Path, default=ROOT / paper_runs.RESULTS,
                        help=f"with report: the folder holding the <experiment>_<kind>_seed<seed> folders (default: "
                             f"{paper_runs.RESULTS})")
    parser.add_argument("--reps", type=positive_int, default=DEFAULT_REPS, help="with report: bootstrap replications")
    parser.add_argument("--centre", choices=[centre for centre, _, _ in CENTRES], default=None,
                        help="with report: score each run by the evaluation of its last centre (the default: "
                             f"{campaign.EVALUATION}, the run's result) or of its best ({campaign.BEST_EVALUATION})")
    parser.add_argument("--reproduce", type=positive_int, default=None, metavar="N",
                        help="train the experiment's command again for N generations, in a temporary folder, and "
                             "compare them with its run's metrics.csv row by row (every column but the timings): "
                             "does this machine and code give the run's numbers?")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    parser.add_argument("--status", action="store_true",
                        help="with campaign: how far each run got, and what its generations cost (from metrics.csv)")
    args = parser.parse_args(argv)
    if args.variant is not None:
        if entry_of is not None:  # the campaign file is data: its paths are the repository's
            args.variant = str(ROOT / args.variant)
        try:
            paper_runs.variant_flags(args)
        except ValueError as error:
            parser.error(str(error))
    if args.budget is not None and args.budget < campaign.MIN_BUDGET:
        parser.error(f"--budget {args.budget:g} leaves no time for a chunk: the training takes seconds to start and "
                     f"a generation to save; give --budget {campaign.MIN_BUDGET} or more (minutes)")
    if args.experiment == "campaign":
        others = [f"--{name.replace('_', '-')}" for name in ("kind", "variant", "seed", "popsize", "generations",
                                                             "episodes", "folder", "dry_run", "reproduce")
                  if getattr(args, name) not in (None, False)]
        if (args.budget is None) == (not args.status) or others:
            parser.error("campaign takes --budget MINUTES (and --threads) or --status, and its runs from "
                         f"{shown(paper_runs.CAMPAIGN)}" + (f", not {' '.join(others)}" if others else ""))
    elif args.status:
        parser.error("--status goes with campaign: python experiments/paper.py campaign --status")
    elif args.reproduce is not None and (args.kind not in TRAIN_SCRIPTS or args.budget is not None or args.dry_run
                                         or args.generations is not None or args.episodes is not None):
        parser.error("--reproduce N goes with an experiment and a kind (static or hebbian), without --budget, "
                     "--dry-run, --generations and --episodes: python experiments/paper.py carracing hebbian "
                     "--reproduce 10")
    elif args.kind is None:
        parser.error(f"{args.experiment} needs a kind: static, hebbian or report")
    elif args.variant is not None and args.kind not in TRAIN_SCRIPTS:
        parser.error(f"--variant goes with an experiment and a kind to train: python experiments/paper.py "
                     f"{args.experiment} static --variant FILE")
    elif args.centre is not None and args.kind != "report":
        parser.error(f"--centre goes with report: python experiments/paper.py {args.experiment} report --centre "
                     f"{args.centre}")
    return args


def campaign_entries(threads: int | None = None) -> list[argparse.Namespace]:
    """The campaign's runs (experiments/paper/campaign.toml), each as paper.py's arguments; a file that is not
    such a list raises a CampaignError naming it and what it must hold."""
    source = shown(paper_runs.CAMPAIGN)
    holds = 'a campaign file holds runs = ["EXPERIMENT KIND FLAGS...", ...], e.g. runs = ["carracing hebbian --seed 2"]'
    try:
        with open(paper_runs.CAMPAIGN, "rb") as handle:
            entries = tomllib.load(handle).get("runs")
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise campaign.CampaignError(f"{source}: {getattr(error, 'strerror', None) or error}; {holds}") from None
    if not isinstance(entries, list) or not entries or not all(isinstance(entry, str) for entry in entries):
        raise campaign.CampaignError(f"{source} has no list of runs; {holds}")
    extra = ["--threads", str(threads)] if threads is not None else []
    found = []
    for entry in entries:
        try:
            words = shlex.split(entry)
        except ValueError as error:  # an unclosed quote
            raise campaign.CampaignError(f"{source}: the run {entry!r}: {error}; {holds}") from None
        args = parse([*words, *extra], entry_of=str(source))
        if args.experiment == "campaign" or args.kind not in TRAIN_SCRIPTS or args.budget is not None \
                or args.dry_run or args.reproduce is not None:
            raise campaign.CampaignError(f"{source}: the run {entry!r} is not an experiment and a kind to train "
                                         f"({', '.join(TRAIN_SCRIPTS)}) with its flags; {holds}")
        found.append(args)
    return found
