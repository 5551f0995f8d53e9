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

import argparse
import shlex
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the project's modules, when run as a script

import envs  # noqa: E402
from cli.errors import USER_ERRORS, Parser, say  # noqa: E402
from cli.flags import non_empty, positive_float, positive_int, seed_value, threads_value  # noqa: E402
from cli.hints import EVALUATE_SCRIPTS, TRAIN_SCRIPTS  # noqa: E402
from es.runfolder import named_file  # noqa: E402
from experiments import campaign, cost  # noqa: E402
from policies import KINDS  # noqa: E402
from report.stats import DEFAULT_REPS  # noqa: E402

FILES = ROOT / "experiments" / "paper"
CAMPAIGN = FILES / "campaign.toml"  # the campaign's runs, in order
RESULTS = Path("results") / "paper"  # the campaign's run folders, relative to the repository's root
FRAMES = "frames.png"  # the first evaluation episode, every 100th frame (--video PATH.png)
HELD_OUT_SEED = 2**31  # the evaluation's first episode seed: training draws its seeds below 2**31 - 1, never these
EXPERIMENTS = sorted({path.stem.split("_")[0] for path in FILES.glob("*_*.toml")})


def parse(argv: list[str] | None, entry_of: str | None = None) -> argparse.Namespace:
    """paper.py's arguments; ``entry_of``: they are a run of that campaign file, and a problem with them raises a
    CampaignError naming it (the file is data, and its errors are not the command line's)."""
    parser = Parser(prog="paper.py", description=__doc__.splitlines()[0],
                    formatter_class=argparse.RawDescriptionHelpFormatter, epilog="\n".join(__doc__.splitlines()[2:]))
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
    parser.add_argument("--popsize", type=positive_int, default=None, help="default: the file's")
    parser.add_argument("--generations", type=positive_int, default=None,
                        help="total generations (default: the file's)")
    parser.add_argument("--episodes", type=positive_int, default=None,
                        help="evaluation episodes per body (default: the file's)")
    parser.add_argument("--threads", type=threads_value, default=None,
                        help="workers; -1 = all cores (default: the file's)")
    parser.add_argument("--folder", type=non_empty, default=None,
                        help=f"default: {RESULTS}/<experiment>_<kind>_seed<seed> in the repository")
    parser.add_argument("--budget", type=positive_float, default=None, metavar="MINUTES",
                        help="train one chunk of at most MINUTES, stop at a generation boundary, saved (the campaign)")
    parser.add_argument("--runs", type=Path, default=ROOT / RESULTS,
                        help=f"with report: the folder holding the <experiment>_<kind>_seed<seed> folders (default: "
                             f"{RESULTS})")
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
    if args.budget is not None and args.budget < campaign.MIN_BUDGET:
        parser.error(f"--budget {args.budget:g} leaves no time for a chunk: the training takes seconds to start and "
                     f"a generation to save; give --budget {campaign.MIN_BUDGET} or more (minutes)")
    if args.experiment == "campaign":
        others = [f"--{name.replace('_', '-')}" for name in ("kind", "seed", "popsize", "generations", "episodes",
                                                             "folder", "dry_run", "reproduce")
                  if getattr(args, name) not in (None, False)]
        if (args.budget is None) == (not args.status) or others:
            parser.error("campaign takes --budget MINUTES (and --threads) or --status, and its runs from "
                         f"{shown(CAMPAIGN)}" + (f", not {' '.join(others)}" if others else ""))
    elif args.status:
        parser.error("--status goes with campaign: python experiments/paper.py campaign --status")
    elif args.reproduce is not None and (args.kind not in TRAIN_SCRIPTS or args.budget is not None or args.dry_run
                                         or args.generations is not None or args.episodes is not None):
        parser.error("--reproduce N goes with an experiment and a kind (static or hebbian), without --budget, "
                     "--dry-run, --generations and --episodes: python experiments/paper.py carracing hebbian "
                     "--reproduce 10")
    elif args.kind is None:
        parser.error(f"{args.experiment} needs a kind: static, hebbian or report")
    elif args.centre is not None and args.kind != "report":
        parser.error(f"--centre goes with report: python experiments/paper.py {args.experiment} report --centre "
                     f"{args.centre}")
    return args


def shown(path: Path) -> Path:
    """A path as the messages show it: relative to the repository's root where it lies inside."""
    return path.relative_to(ROOT) if path.is_relative_to(ROOT) else path


def load_experiment(args: argparse.Namespace) -> tuple[Path, dict]:
    """The experiment file of ``args`` (experiments/paper/<experiment>_<kind>.toml) and its content."""
    file = FILES / f"{args.experiment}_{args.kind}.toml"
    with open(file, "rb") as handle:
        return file, tomllib.load(handle)


def experiment_folder(args: argparse.Namespace, experiment: dict) -> Path:
    """Where the experiment's runs go: by default results/paper/<experiment>_<kind>_seed<seed>, relative to the
    repository's root, where the training runs (config.json stays portable); a --folder given, resolved from
    where this command runs. ``ROOT / folder`` is the folder in both cases."""
    return Path(args.folder).resolve() if args.folder else RESULTS / run_name(args, experiment)


def run_name(args: argparse.Namespace, experiment: dict) -> str:
    """The folder name of an experiment's runs with its seed (the file's, where none is given):
    ``carracing_hebbian_seed1``."""
    seed = args.seed if args.seed is not None else experiment["run"]["seed"]
    return f"{args.experiment}_{args.kind}_seed{seed}"


def latest_run(folder: Path) -> Path | None:
    runs = sorted(path.parent for path in folder.glob("*/checkpoint.npz"))  # names start with the time
    return runs[-1] if runs else None


def overrides(args: argparse.Namespace, *names: str) -> list[str]:
    return [word for name in names if getattr(args, name) is not None
            for word in (f"--{name}", str(getattr(args, name)))]


def train_command(args: argparse.Namespace, file: Path, folder: Path) -> list[str]:
    """A new run from the experiment file, or the resume of the folder's run; on resume, the settings asked
    for are given again, so the training script refuses them where the run has others."""
    command = [sys.executable, TRAIN_SCRIPTS[args.kind]]
    previous = latest_run(ROOT / folder)  # ``folder``: relative to the repository's root, where the child runs
    if previous is not None:
        return command + ["--resume", str(shown(previous)), *overrides(args, "seed", "popsize", "generations",
                                                                         "threads")]
    return command + ["--config", str(shown(file)), "--folder", str(shown(folder)),
                      *overrides(args, "seed", "popsize", "generations", "threads")]


def check_training(kind: str, command: list[str]):
    """Check the training command as its script will (flags, experiment file, a resumed run's settings),
    without running it, and return the settings it would train with (a ``TrainConfig``): a UserError names the
    first problem; argparse's own errors exit with code 2. ``kind`` is one of ``TRAIN_SCRIPTS`` (the parser's
    choices), whose script is imported for its parser. Its paths are read from the repository's root, where the
    script runs."""
    import contextlib
    import importlib

    from cli.train import checked_resume, config_from_args
    from es.backends.process import check_workers

    script = importlib.import_module(Path(TRAIN_SCRIPTS[kind]).stem)
    args = script.build_parser().parse_args(command[2:])
    with contextlib.chdir(ROOT):
        if args.resume is not None:
            return checked_resume(kind, args)[0]
        config = config_from_args(kind, args)
    if config.run.backend == "process" and not config.run.in_process:
        check_workers(config.run.workers)
    return config


def evaluate_command(args: argparse.Namespace, experiment: dict, run_dir: Path, centre: str = "last") -> list[str]:
    """The final weights (last*.dat) on every body; statistics to JSON, one episode to a PNG, and where the
    experiment file asks for ``frames``, that episode's every 100th frame to a strip. With ``centre`` "best",
    the best centre (from the run's best*.dat, or its checkpoint once pruned) on the same episodes, statistics
    only."""
    evaluation = experiment["evaluation"]
    run_dir = shown(run_dir)
    command = [sys.executable, EVALUATE_SCRIPTS[args.kind], "--environment", evaluation["environment"],
               "--episodes", str(args.episodes if args.episodes is not None else evaluation["episodes"]),
               "--seed", str(HELD_OUT_SEED)]
    main = KINDS[args.kind].files[0]
    if centre == "best":
        return command + ["--json", str(run_dir / campaign.BEST_EVALUATION), main.flag, str(run_dir), "--centre",
                          "best"]
    command += ["--json", str(run_dir / campaign.EVALUATION)]
    # the pictures of an evaluation whose statistics were not written (stopped between them) are there already: an
    # output never replaces a run's file, and the same episode draws the same pictures
    if not (ROOT / run_dir / "adaptation.png").exists():
        command += ["--plot", str(run_dir / "adaptation.png")]
    if evaluation.get("frames") and not (ROOT / run_dir / FRAMES).exists():
        command += ["--video", str(run_dir / FRAMES)]
    # the run's main file: the evaluate script takes the rule, the network and the files beside it (a CNN,
    # co-evolved initial weights) from the run folder
    return command + [main.flag, str(run_dir / named_file("last", main.roles[0]))]


CENTRES = (("last", campaign.EVALUATION, "the final centre"), ("best", campaign.BEST_EVALUATION, "the best centre"))


def evaluated(run_dir: Path) -> bool:
    """Whether both centres of a run have been evaluated (the queue's test of a run done)."""
    return all((run_dir / name).exists() for _, name, _ in CENTRES)


def run(command: list[str], dry_run: bool) -> int:
    say("$ " + shlex.join(command))
    return 0 if dry_run else subprocess.run(command, cwd=ROOT).returncode



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
            progress = campaign.measure(run)
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


def report_folder(runs: Path, experiment: str, centre: str = "last") -> Path:
    """Where the report of ``experiment``'s runs in ``runs`` goes: one folder per evaluation environment in it."""
    return runs / (f"{experiment}_report" + ("" if centre == "last" else f"_{centre}"))


def evaluated_runs(runs: Path, experiment: str, kind: str, file: str = campaign.EVALUATION) -> list[Path]:
    """Each seed's newest run of ``kind`` in ``runs`` that has the evaluation ``file``."""
    return [run for folder in sorted(runs.glob(f"{experiment}_{kind}_seed*"))
            if (run := latest_run(folder)) is not None and (run / file).exists()]


def write_report(runs: Path, experiment: str, centre: str = "last", reps: int = DEFAULT_REPS) -> list[tuple]:
    """Static against Hebbian: each seed's newest run in ``runs``, scored by the evaluation of its ``centre``,
    one report per evaluation environment in ``report_folder``, its runs named relative to ``runs``. Returns
    (environment, folder, stats.Report) for each; stats.StatsError says what is missing."""
    from report import stats

    if not stats.available():
        raise stats.StatsError(f"the report needs rliable, which is not installed; install it with: "
                               f"{stats.INSTALL_HINT}")
    with open(FILES / f"{experiment}_static.toml", "rb") as handle:
        named = tomllib.load(handle)["evaluation"]["environment"].split(",")
    # as evaluation.json names them: the ids they resolve to (CarRacing-v0 -> CarRacing-v3)
    environments = [envs.resolve_env_id(env_id, notify=lambda *_: None) for env_id in named]
    score = "evaluation" if centre == "last" else "evaluation_best"  # report/stats.py's score of that centre's file
    file = stats.EVALUATIONS[score]
    groups = []
    for kind in TRAIN_SCRIPTS:
        found = evaluated_runs(runs, experiment, kind, file)
        if not found:
            raise stats.StatsError(f"no {kind} run in {runs}/{experiment}_{kind}_seed* has {file}; run python "
                                   f"experiments/paper.py {experiment} {kind} --seed N first")
        groups.append(f"{kind}={','.join(map(str, found))}")
    written = []
    for environment in environments:
        out = report_folder(runs, experiment, centre) / environment
        written.append((environment, out, stats.report(groups, out, score, environment, reps=reps, root=runs)))
    return written


def report(args: argparse.Namespace) -> int:
    """``EXPERIMENT report``: ``write_report`` of the runs in --runs, printed."""
    from report import stats

    try:
        written = write_report(args.runs, args.experiment, args.centre or "last", args.reps)
    except stats.StatsError as error:
        print(f"paper.py: error: {error}", file=sys.stderr)
        return 2
    for environment, out, result in written:
        print(f"## {environment} (written to {out})\n\n{result.markdown}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.experiment == "campaign":
        try:
            return status() if args.status else run_queue(args)
        except campaign.CampaignError as error:  # its file: not a list of runs
            print(f"paper.py: error: {error}", file=sys.stderr)
            return 2
    if args.kind == "report":
        return report(args)
    if args.kind == "curves":
        return training_curves(args)
    if args.reproduce is not None:
        return reproduce(args)
    deadline = time.monotonic() + 60 * args.budget if args.budget is not None else None
    return experiment_main(args, deadline)


TIMINGS = ("seconds", "total_seconds")  # the columns of metrics.csv that no two runs share


def reproduce(args: argparse.Namespace) -> int:
    """``--reproduce N``: the experiment's command trained again for N generations in a temporary folder, its
    metrics.csv compared with the run's, row by row, every column but the timings. Exit 0 when every row is
    the run's, 1 at the first that is not (named, with its columns), 2 when there is nothing to compare."""
    import tempfile

    from cli.config import TrainConfig, declared
    from es import files
    from settings import contradictions

    file, experiment = load_experiment(args)
    run_dir = latest_run(ROOT / experiment_folder(args, experiment))
    if run_dir is None:
        print(f"paper.py: error: no run in {shown(ROOT / experiment_folder(args, experiment))} to reproduce; train "
              "one first", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="reproduce-") as scratch:
        command = [sys.executable, TRAIN_SCRIPTS[args.kind], "--config", str(shown(file)), "--folder", scratch,
                   *overrides(args, "seed", "popsize", "threads"), "--generations", str(args.reproduce)]
        try:
            recorded = files.read_metrics(run_dir / "metrics.csv")[:generations_done(run_dir)]
            if len(recorded) < args.reproduce:
                raise ValueError(f"{shown(run_dir)} has " + (
                    f"{len(recorded)} generations saved; give --reproduce {len(recorded)} or less" if recorded
                    else "no generation saved yet"))
            # the fixed settings (not the workers nor the generations, which change no number of those run), but
            # the folder and the noise table's size, derived when the training starts
            asked = {name: value for name, value in check_training(args.kind, command).fixed().items()
                     if name not in ("folder", "noise_size")}
            differing = contradictions(TrainConfig.from_dict(files.read_json(run_dir / "config.json")).fixed(), asked,
                                       declared())
        except (*USER_ERRORS, OSError, ValueError, TypeError) as error:
            print(f"paper.py: error: {error}", file=sys.stderr)
            return 2
        if differing:
            print(f"paper.py: error: {shown(run_dir)} was made with other settings than "
                  f"{shown(file)} and the flags given: {', '.join(differing)}", file=sys.stderr)
            return 2
        code = run(command, dry_run=False)
        if code != 0:
            return code
        again = files.read_metrics(next(Path(scratch).glob("*/metrics.csv")))
    for row, theirs in zip(again, recorded[:args.reproduce]):
        columns = [f"{column} {row.get(column)} here, {value} in the run" for column, value in theirs.items()
                   if column not in TIMINGS and row.get(column) != value]
        if columns:
            say(f"generation {theirs['generation']} differs from {shown(run_dir)}: {'; '.join(columns)}"
                + made_with_note(run_dir))
            return 1
    say(f"generations 1-{args.reproduce}: every column but the timings is {shown(run_dir)}'s")
    return 0


def made_with_note(run_dir: Path) -> str:
    """For a run made by older code (its ``made_with.json``): where its generations come again."""
    from es import files

    try:
        label = files.read_json(run_dir / campaign.MADE_WITH)
        return (f" (the run was made by the code at commit {label['commit'][:12]}, and reproduces with it on "
                f"{label['reproduces_on']}: see its {campaign.MADE_WITH})")
    except (OSError, ValueError, TypeError, KeyError):
        return ""


def experiment_main(args: argparse.Namespace, deadline: float | None) -> int:
    """One experiment: training and evaluation, or with a ``deadline`` one chunk of the campaign."""
    file, experiment = load_experiment(args)
    folder = experiment_folder(args, experiment)
    command = train_command(args, file, folder)
    try:
        check_training(args.kind, command)
    except (*USER_ERRORS, ValueError) as error:
        print(f"paper.py: error: {error}", file=sys.stderr)
        return 2
    if deadline is not None and not args.dry_run:
        return run_campaign(args, experiment, command, ROOT / folder, deadline)
    code = run(command, args.dry_run)
    if code != 0:
        return code
    run_dir = latest_run(ROOT / folder)
    if run_dir is None:  # a dry run before any training
        say("# then, once the run exists, the evaluation of its final centre (last*.dat) and its best")
        run_dir = folder / "<run folder>"
    for centre, name, what in CENTRES:
        if (ROOT / run_dir / name).exists():  # evaluated by an earlier command: an output never replaces it
            say(f"# {what} is evaluated already: {shown(ROOT / run_dir / name)} (remove it to evaluate again)")
            continue
        code = run(evaluate_command(args, experiment, run_dir, centre), args.dry_run)
        if code != 0:
            return code
    return 0


def generations_done(run_dir: Path | None) -> int:
    from es.runfolder import read_checkpoint

    return 0 if run_dir is None else read_checkpoint(run_dir / "checkpoint.npz").generation


def run_campaign(args: argparse.Namespace, experiment: dict, command: list[str], folder: Path,
                 deadline: float) -> int:
    """One chunk of the campaign (experiments/campaign.py): train until ``deadline``, evaluate once training is
    complete, leave only what continuing and evaluating need, say how far the run got."""
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
    (``curves_figure``) and, once both kinds have an evaluated run, its report (``write_report``), so that
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
    if not all(evaluated_runs(runs, experiment, kind) for kind in TRAIN_SCRIPTS):
        return
    try:
        reported = write_report(runs, experiment)
    except (stats.StatsError, OSError) as error:
        say(f"campaign: the report of {experiment} was not written: {error}")
        return
    say(f"campaign: wrote the report of {experiment}'s evaluated runs in {shown(report_folder(runs, experiment))} "
        f"({', '.join(environment for environment, _, _ in reported)})")


def continue_words(args: argparse.Namespace) -> str:
    words = [args.experiment, args.kind, *overrides(args, "seed", "popsize", "generations", "episodes")]
    if args.folder:
        words += ["--folder", args.folder]
    return shlex.join(words)


def campaign_entries(threads: int | None = None) -> list[argparse.Namespace]:
    """The campaign's runs (experiments/paper/campaign.toml), each as paper.py's arguments; a file that is not
    such a list raises a CampaignError naming it and what it must hold."""
    source = shown(CAMPAIGN)
    holds = 'a campaign file holds runs = ["EXPERIMENT KIND FLAGS...", ...], e.g. runs = ["carracing hebbian --seed 2"]'
    try:
        with open(CAMPAIGN, "rb") as handle:
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


def entry_folder(args: argparse.Namespace) -> Path:
    return ROOT / experiment_folder(args, load_experiment(args)[1])


@dataclass(frozen=True)
class CampaignRun:
    """A run of the campaign: its name ("carracing hebbian seed 1"), its experiment's folder and what it asks for."""

    name: str
    folder: Path
    args: argparse.Namespace
    experiment: dict

    def planned(self, progress: campaign.Progress | None) -> cost.Planned:
        """The run as the projection of its cost sees it, ``progress`` its newest run's (None: not started)."""
        run = self.experiment["run"]
        return cost.Planned(
            name=self.name, experiment=self.args.experiment, kind=self.args.kind,
            group=shlex.join([self.args.experiment, self.args.kind, *overrides(self.args, "popsize", "generations")]),
            seed=self.args.seed if self.args.seed is not None else run["seed"],
            total=self.args.generations if self.args.generations is not None else run["generations"],
            progress=progress)


def campaign_runs(runs: Path) -> list[CampaignRun]:
    """The campaign's runs, in its order, each with its experiment's folder in ``runs``."""
    named = []
    for args in campaign_entries():
        experiment = load_experiment(args)[1]
        name = run_name(args, experiment)
        named.append(CampaignRun(name.replace("_seed", " seed ").replace("_", " "), runs / name, args, experiment))
    return named


def campaign_plan(runs: Path) -> list[tuple[CampaignRun, cost.Planned]]:
    """Each run of the campaign with its newest run's progress (``campaign.measure``, whose errors it raises)."""
    return [(entry, entry.planned(None if (run_dir := latest_run(entry.folder)) is None else campaign.measure(run_dir)))
            for entry in campaign_runs(runs)]


def status() -> int:
    """Each campaign run: generations done of the total, the training time metrics.csv records, the mean time
    and environment steps of the last ten generations, the last population mean and centre, for a run not
    yet complete the time its remaining generations would take at the last ten's pace, and the machines it ran
    on (config.json's record); for every run not yet complete, started or not, its projection from the completed
    runs of its group (``cost.project``); then the campaign's remaining time in all (``cost.summary``)."""
    code, lines, plan = 0, {}, []
    for entry in campaign_runs(ROOT / RESULTS):
        run_dir = latest_run(entry.folder)
        if run_dir is None:
            lines[entry.name] = f"{entry.name}: not started"
            plan.append(entry.planned(None))
            continue
        try:
            progress = campaign.measure(run_dir)
        except (OSError, KeyError, TypeError, *USER_ERRORS, ValueError) as error:  # a hand-edited or damaged file
            print(f"paper.py: error: {entry.name}: {shown(run_dir)} cannot be read ({type(error).__name__}: {error})",
                  file=sys.stderr)
            code = 2
            continue
        plan.append(entry.planned(progress))
        line = (f"{entry.name}: {shown(run_dir)}: generation {progress.done} of {progress.total}"
                + (" (evaluated)" if progress.evaluated else ""))
        if progress.pace is not None:
            line += (f"; {progress.hours:.2f} h of training; the last {progress.paced} generations "
                     f"{progress.pace:.1f} s and {progress.steps:,.0f} env steps each; "
                     f"population mean {progress.mean:.1f}, centre {progress.centre:.1f}")
            if not progress.complete:
                line += f"; at that pace about {progress.hours_left:.1f} h more"
                if progress.hours_at_most is not None:
                    line += f", at most {progress.hours_at_most:.1f} h if every episode ran to its time limit"
        if progress.machines:
            line += f"; on {progress.machines}"
        lines[entry.name] = line
    projections = cost.project(plan)
    for projection in projections:
        lines[projection.planned.name] += f"; {projection.line()}"
    for line in lines.values():
        say(line)
    say(f"remaining: {cost.summary(projections)}")
    return code


def progress_page(runs: Path) -> str:
    """The campaign's runs in ``runs`` as a Markdown table (``runs/progress.md``, written at every chunk's end),
    and what its remaining runs will cost (``cost.summary``)."""
    lines = ["# The campaign's runs", "",
             "How far each run of `experiments/paper/campaign.toml` got, written by `experiments/paper.py` at the "
             "end of every chunk from the run's own files: the generation its `checkpoint.npz` holds, the "
             f"`seconds` and `env_steps` of its `metrics.csv` (the mean of the last {campaign.PACE} generations is "
             "the pace), the machines its `config.json` records. A run not yet complete is **partial**: its "
             "figures are those of the generations done so far, and its remaining time is the last generations' "
             "pace times the generations left. Generations grow longer as a run learns to stay in its episodes, so "
             "early in a run that says too little; the bound beside it is every remaining episode run to its "
             "environment's time limit at the last generations' cost per environment step. Every run not yet "
             "complete, started or not, is also projected from the completed runs of its experiment and kind (the "
             "seeds named): the mean of the time they took for the generations it has left, the fastest and the "
             "slowest of them in brackets.", "",
             "| run | generation | training so far | last generations, each | remaining, at that pace; at most "
             "| remaining, from the completed runs of its kind | population mean, centre | machines |",
             "|---|---|---|---|---|---|---|---|"]
    plan = campaign_plan(runs)
    projections = {projection.planned.name: projection for projection in cost.project([p for _, p in plan])}
    for entry, planned in plan:
        projection = projections.get(entry.name)
        projected = ("" if projection is None else "no completed run of its kind" if projection.estimate is None
                     else f"{projection.estimate.text()}, from {projection.sources_text()}")
        progress = planned.progress
        if progress is None:
            lines.append(f"| {entry.name} | not started | | | | {projected} | | |")
            continue
        state = ("complete, evaluated" if progress.evaluated else "complete, not yet evaluated" if progress.complete
                 else "**partial**")
        pace = (f"{progress.pace:.1f} s, {progress.steps:,.0f} env steps" if progress.pace is not None else "")
        left = ("" if progress.hours_left is None
                else f"about {progress.hours_left:.1f} h ({progress.hours + progress.hours_left:.1f} h in all)"
                + ("" if progress.hours_at_most is None else
                   f"; at most {progress.hours_at_most:.1f} h ({progress.hours + progress.hours_at_most:.1f} h)"))
        fitness = f"{progress.mean:.1f}, {progress.centre:.1f}" if progress.mean is not None else ""
        run_dir = latest_run(entry.folder)
        lines.append(f"| [{entry.name}]({run_dir.relative_to(runs).as_posix()}) | {progress.done} of {progress.total}, "
                     f"{state} | {progress.hours:.2f} h | {pace} | {left} | {projected} | {fitness} | "
                     f"{progress.machines} |")
    lines += ["", f"**Remaining.** {cost.summary(list(projections.values()), runs / campaign.PROGRESS)}"]
    return "\n".join(lines) + "\n"


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
        say(f"campaign: next run: {entry.experiment} {entry.kind} seed {entry.seed if entry.seed is not None else 1}")
        code = experiment_main(entry, deadline)
        latest = latest_run(entry_folder(entry))
        if code != 0 or latest is None or not evaluated(latest):
            return code
    say(f"campaign: every run of {shown(CAMPAIGN)} is complete and evaluated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
