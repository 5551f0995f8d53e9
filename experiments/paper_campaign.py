"""``experiments/paper.py ... --budget MINUTES``: the campaign, one chunk at a time.

``run_chunk`` trains one experiment's run until the deadline (``campaign.Chunk``: stopped at a generation boundary,
everything saved), evaluates it once training is complete, leaves in its folder only what continuing and
evaluating need (``campaign.prune``) and writes the pages beside the runs (``write_pages``: the progress page, the
curves, the report). ``run_queue`` (``campaign --budget``) takes the runs of ``experiments/paper/campaign.toml`` in
order, each continued until it is complete and evaluated, as far as the budget goes.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from pathlib import Path

from cli.errors import USER_ERRORS, say
from cli.hints import TRAIN_SCRIPTS
from experiments import campaign, paper_runs
from experiments.paper_args import campaign_entries
from experiments.paper_curves import curves_figure
from experiments.paper_report import evaluated_runs, report_folder, write_report
from experiments.paper_runs import (
    CENTRES,
    ROOT,
    continue_words,
    evaluate_command,
    evaluated,
    experiment_folder,
    generations_done,
    latest_run,
    load_experiment,
    prepared,
    run_name,
    shown,
)
from experiments.paper_status import progress_page


def run_chunk(args: argparse.Namespace, deadline: float) -> int:
    """One chunk of the campaign (experiments/campaign.py): train until ``deadline`` (``time.monotonic()``),
    evaluate once training is complete, leave only what continuing and evaluating need, say how far the run got.
    The training command is checked first (``paper_runs.prepared``)."""
    checked = prepared(args)
    if checked is None:
        return 2
    experiment, folder, command = checked
    folder = ROOT / folder
    total = args.generations if args.generations is not None else experiment["run"]["generations"]

    def metrics() -> Path | None:
        run_dir = latest_run(folder)
        return run_dir / "metrics.csv" if run_dir is not None else None

    try:
        with campaign.pid_file(folder.parent / campaign.PID_FILE):  # results/paper/campaign.pid by default
            chunk = None
            if generations_done(latest_run(folder)) < total:
                minutes = (deadline - time.monotonic()) / 60
                say(f"campaign: training, for at most {minutes:.1f} min: $ {shlex.join(command)}")
                chunk = campaign.Chunk(command, deadline, metrics, ROOT, say)
                code = chunk.run()
                if code != 0 and code not in campaign.STOPPED:
                    return code if code > 0 else 1
            run_dir = latest_run(folder)
            if run_dir is None:  # stopped before the run folder was made
                say("campaign: stopped before the run started; nothing was saved")
                return 130 if chunk is not None and chunk.signals else 1
            done = generations_done(run_dir)
            interrupted = chunk is not None and chunk.signals > 0
            for centre, name, what in CENTRES:
                if done < total or (run_dir / name).exists() or interrupted:
                    continue
                evaluation = evaluate_command(args, experiment, run_dir, centre)
                say(f"campaign: training complete; evaluating {what}: $ {shlex.join(evaluation)}")
                chunk = campaign.Chunk(evaluation, deadline, lambda: None, ROOT, say)
                code = chunk.run()
                interrupted = interrupted or chunk.signals > 0
                if code != 0 and code not in campaign.STOPPED:
                    return code if code > 0 else 1
            campaign.prune(run_dir, complete=done >= total)
            write_pages(folder.parent, args.experiment)  # before the pid file goes: a stop hook commits them
    except campaign.CampaignError as error:
        print(f"paper.py: error: {error}", file=sys.stderr)
        return 2
    state = ("complete and evaluated" if evaluated(run_dir) else "complete, not yet evaluated" if done >= total
             else "saved")
    say(f"campaign: {shown(run_dir)}: generation {done} "
        f"of {total}, {state}")
    if not evaluated(run_dir):
        say(f"continue with: python experiments/paper.py {continue_words(args)} --budget MINUTES "
            "(or the whole campaign: python experiments/paper.py campaign --budget MINUTES)")
    return 130 if interrupted else 0


def write_pages(runs: Path, experiment: str) -> None:
    """At a chunk's end, beside the runs: ``progress.md`` (``progress_page``), the experiment's curves
    (``curves_figure``), for the ant the static ant's study (experiments/stand.py) and, once both kinds have an
    evaluated run, its report (``write_report``), so that
    what a session commits says how far the campaign got. A file that cannot be written is named; the
    chunk's run stays as it was saved."""
    from es import files
    from report import stats

    try:
        files.atomic_write_text(runs / campaign.PROGRESS, progress_page(runs))
        written = curves_figure(runs, experiment)
    except (OSError, KeyError, TypeError, *USER_ERRORS, ValueError) as error:  # a run's file unreadable, no room
        say(f"campaign: the progress page or the curves in {shown(runs)} could not be written: "
            f"{type(error).__name__}: {error}")
        return
    say(f"campaign: wrote {shown(runs / campaign.PROGRESS)}" + (f" and {shown(written[0])}" if written else ""))
    if experiment == "ant":  # the static ant's study reads the ant's runs: rewritten with them (its own line says)
        subprocess.run([sys.executable, str(ROOT / "experiments" / "stand.py"), "--runs", str(runs)], cwd=ROOT,
                       check=False)
    if not all(evaluated_runs(runs, experiment, kind) for kind in TRAIN_SCRIPTS):
        return
    try:
        reported = write_report(runs, experiment)
    except (stats.StatsError, OSError) as error:
        say(f"campaign: the report of {experiment} was not written: {error}")
        return
    say(f"campaign: wrote the report of {experiment}'s evaluated runs in {shown(report_folder(runs, experiment))} "
        f"({', '.join(environment for environment, _, _ in reported)})")
    # the replication report reads every experiment's report: rewritten with them (in a process of its own,
    # as its command runs; its own line says what it wrote, or why not)
    subprocess.run([sys.executable, str(ROOT / "experiments" / "replication.py"), "--runs", str(runs)], cwd=ROOT,
                   check=False)


def entry_folder(args: argparse.Namespace) -> Path:
    return ROOT / experiment_folder(args, load_experiment(args)[1])


def run_queue(args: argparse.Namespace) -> int:
    """``campaign --budget``: the runs of experiments/paper/campaign.toml in order, each continued until it is
    complete and evaluated, as far as the budget goes."""
    deadline = time.monotonic() + 60 * args.budget
    for entry in campaign_entries(args.threads):
        run_dir = latest_run(entry_folder(entry))
        if run_dir is not None and evaluated(run_dir):
            continue
        if deadline - time.monotonic() < 60 * campaign.MIN_BUDGET:
            say("campaign: less than a minute of the budget left; stopping before the next run")
            return 0
        name = run_name(entry, load_experiment(entry)[1])
        say(f"campaign: next run: {name.replace('_seed', ' seed ').replace('_', ' ')}")
        code = run_chunk(entry, deadline)
        latest = latest_run(entry_folder(entry))
        if code != 0 or latest is None or not evaluated(latest):
            return code
    say(f"campaign: every run of {shown(paper_runs.CAMPAIGN)} is complete and evaluated")
    return 0
