#!/usr/bin/env python
"""The experiments of Najarro & Risi (2020): train with the paper's settings, evaluate over 100 episodes.

    python experiments/paper.py carracing static      # CarRacing, evolved static weights
    python experiments/paper.py carracing hebbian     # CarRacing, evolved ABCD_lr rules, uni init
    python experiments/paper.py ant static            # ant: train on 2 bodies, evaluate on 3
    python experiments/paper.py ant hebbian
    python experiments/paper.py ant hebbian --popsize 8 --generations 2 --episodes 3   # a quick try
    python experiments/paper.py ant report            # static against Hebbian over every seed run so far
    python experiments/paper.py carracing hebbian --budget 120   # train for at most 2 hours, then stop, saved
    python experiments/paper.py carracing hebbian --reproduce 3  # its first 3 generations again: the run's numbers?

Each experiment is a data file, experiments/paper/<experiment>_<kind>.toml, that the training
scripts read with --config (the same loader as a run's config.json); its [evaluation] section says
where and how long to evaluate. Flags given here override the file.

Runs take hours to days on 2 cores (experiments/README.md). Each experiment has its own folder
(default results/paper/<experiment>_<kind>_seed<seed>, in the repository: the campaign's runs, which
are committed as they progress); running the same command again resumes the newest run there from its
checkpoint (--resume RUN_DIR, --generations being the total), and once training is complete it only
evaluates. The evaluation is the final centre's (evaluation.json, the run's result), then the best
centre's, the one with the best training return (evaluation_best.json), on the same episodes; a centre
evaluated already is not evaluated again (an output never replaces a run's file: remove it first).
--dry-run prints the commands instead.

--budget MINUTES trains one chunk (experiments/campaign.py): it stops at a generation boundary before
the budget is spent, everything saved, and leaves in the run folder only what continuing and evaluating
need; it prints how far the run got and the command that continues it. While it runs, campaign.pid
beside the experiment's folder (results/paper/campaign.pid) holds its process id; SIGINT saves and
stops it within a minute.

Every value is checked before anything runs, --dry-run included, by the training script's own parser
and checks (``check_training``); a folder whose run has other settings than the ones asked for
(--seed, --popsize, ...) is refused, naming them, instead of being resumed with its own.

``report`` compares the two kinds over the seeds run so far (the newest run of each folder
runs/<experiment>_<kind>_seed<seed>, or under --runs) with rliable's statistics (report/stats.py:
IQM and mean with 95 % bootstrap intervals, performance profiles, probability of improvement), scored
by each run's evaluation.json, one report per evaluation environment (the ant: two seen bodies and
the unseen one), in runs/<experiment>_report/<environment>/. ``report --centre best`` scores each run
by its best centre's evaluation (evaluation_best.json) instead, in runs/<experiment>_report_best/.
It needs pip install -r requirements-stats.txt.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the project's modules, when run as a script

from experiments import campaign, paper_campaign, paper_curves, paper_report, paper_reproduce  # noqa: E402
from experiments.paper_args import parse  # noqa: E402
from experiments.paper_runs import train_and_evaluate  # noqa: E402
from experiments.paper_status import status  # noqa: E402

# one module per subcommand: experiments/paper_args.py reads the command line; paper_runs.py trains and evaluates
# an experiment; paper_campaign.py runs it in chunks (--budget), and the campaign's queue; paper_status.py says how
# far the campaign got (campaign --status, progress.md); paper_report.py, paper_curves.py and paper_reproduce.py
# are report, curves and --reproduce


def main(argv: list[str] | None = None) -> int:
    args = parse(argv, doc=__doc__)
    if args.experiment == "campaign":
        try:
            return status() if args.status else paper_campaign.run_queue(args)
        except campaign.CampaignError as error:  # its file: not a list of runs
            print(f"paper.py: error: {error}", file=sys.stderr)
            return 2
    if args.kind == "report":
        return paper_report.report(args)
    if args.kind == "curves":
        return paper_curves.training_curves(args)
    if args.reproduce is not None:
        return paper_reproduce.reproduce(args)
    if args.budget is not None and not args.dry_run:
        return paper_campaign.run_chunk(args, time.monotonic() + 60 * args.budget)
    return train_and_evaluate(args)


if __name__ == "__main__":
    sys.exit(main())
