"""The paper's experiments as files and folders, and the commands that train and evaluate them.

Each experiment is a data file, ``experiments/paper/<experiment>_<kind>.toml``, that the training scripts read
with ``--config``; its runs go in a folder of their own, by default ``results/paper/<experiment>_<kind>_seed<seed>``
(the campaign's, committed as they progress). ``train_command`` starts a run there or resumes the newest one,
``check_training`` checks that command as its script will before anything runs, ``evaluate_command`` evaluates a
run's final centre or its best on held-out episodes, and ``train_and_evaluate`` does both, the command
``python experiments/paper.py EXPERIMENT KIND`` (experiments/paper.py).
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

from cli.errors import USER_ERRORS, say
from cli.hints import EVALUATE_SCRIPTS, TRAIN_SCRIPTS
from es.runfolder import generations_done, latest_run, named_file  # noqa: F401 (theirs too)
from experiments import campaign
from policies import KINDS

ROOT = Path(__file__).resolve().parent.parent
FILES = ROOT / "experiments" / "paper"
CAMPAIGN = FILES / "campaign.toml"  # the campaign's runs, in order
RESULTS = Path("results") / "paper"  # the campaign's run folders, relative to the repository's root
FRAMES = "frames.png"  # the first evaluation episode, every 100th frame (--video PATH.png)
HELD_OUT_SEED = 2**31  # the evaluation's first episode seed: training draws its seeds below 2**31 - 1, never these
EXPERIMENTS = sorted({path.stem.split("_")[0] for path in FILES.glob("*_*.toml")})


def shown(path: Path) -> Path:
    """A path as the messages show it: relative to the repository's root where it lies inside."""
    return path.relative_to(ROOT) if path.is_relative_to(ROOT) else path


def load_experiment(args: argparse.Namespace) -> tuple[Path, dict]:
    """The experiment file of ``args`` (experiments/paper/<experiment>_<kind>.toml) and its content, with the
    changes of a ``--variant`` file over it, section by section."""
    file = FILES / f"{args.experiment}_{args.kind}.toml"
    with open(file, "rb") as handle:
        experiment = tomllib.load(handle)
    for section, values in read_variant(getattr(args, "variant", None)).items():
        experiment[section] = {**experiment.get(section, {}), **values}
    return file, experiment


VARIANT_SECTIONS = ("es", "policy", "env", "run", "evaluation")  # an experiment file's sections


def read_variant(path: str | None) -> dict:
    """A variant file: some of an experiment file's sections, each with the settings it changes (``{}``: none
    given). A file that cannot be read or holds something else raises a ValueError naming it."""
    if path is None:
        return {}
    try:
        with open(path, "rb") as handle:
            variant = tomllib.load(handle)
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"--variant {path}: {getattr(error, 'strerror', None) or error}; a variant file is TOML "
                         "with some of the sections [" + "], [".join(VARIANT_SECTIONS) + "]") from None
    stray = [name for name, values in variant.items() if name not in VARIANT_SECTIONS or not isinstance(values, dict)]
    if stray:
        raise ValueError(f"--variant {path}: {', '.join(stray)} is not a section of an experiment file; valid: "
                         + ", ".join(VARIANT_SECTIONS))
    return variant


def variant_flags(args: argparse.Namespace) -> list[str]:
    """The training flags of a ``--variant`` file's changes (its [evaluation] is paper.py's own): ``--sigma 0.05``.
    The training script checks them as any flag, and a resumed run refuses those it was not made with."""
    from cli.config import declared

    flags = {item.name: item.flag for item in declared()}
    words = []
    for section, values in read_variant(getattr(args, "variant", None)).items():
        for name, value in values.items() if section != "evaluation" else ():
            if not flags.get(name):
                raise ValueError(f"--variant {args.variant}: [{section}] {name} is not a setting a flag can change; "
                                 "valid: the training script's flags, without the dashes")
            if isinstance(value, bool):
                words += [f"--{flags[name]}"] if value else []
                continue
            words += [f"--{flags[name]}", *(str(item) for item in (value if isinstance(value, list) else [value]))]
    return words


def experiment_folder(args: argparse.Namespace, experiment: dict) -> Path:
    """Where the experiment's runs go: by default results/paper/<experiment>_<kind>_seed<seed>, relative to the
    repository's root, where the training runs (config.json stays portable); a --folder given, resolved from
    where this command runs. ``ROOT / folder`` is the folder in both cases."""
    return Path(args.folder).resolve() if args.folder else RESULTS / run_name(args, experiment)


def run_name(args: argparse.Namespace, experiment: dict) -> str:
    """The folder name of an experiment's runs with its seed (the file's, where none is given):
    ``carracing_hebbian_seed1``; with a --variant file, its name before the seed: ``ant_static_sigma_seed1``."""
    seed = args.seed if args.seed is not None else experiment["run"]["seed"]
    variant = getattr(args, "variant", None)
    return f"{args.experiment}_{args.kind}{'_' + Path(variant).stem if variant else ''}_seed{seed}"


def overrides(args: argparse.Namespace, *names: str) -> list[str]:
    return [word for name in names if getattr(args, name) is not None
            for word in (f"--{name}", str(getattr(args, name)))]


def continue_words(args: argparse.Namespace) -> str:
    words = [args.experiment, args.kind, *overrides(args, "variant", "seed", "popsize", "generations", "episodes")]
    if args.folder:
        words += ["--folder", args.folder]
    return shlex.join(words)


def train_command(args: argparse.Namespace, file: Path, folder: Path) -> list[str]:
    """A new run from the experiment file, or the resume of the folder's run; on resume, the settings asked
    for are given again, so the training script refuses them where the run has others."""
    command = [sys.executable, TRAIN_SCRIPTS[args.kind]]
    previous = latest_run(ROOT / folder)  # ``folder``: relative to the repository's root, where the child runs
    asked = [*variant_flags(args), *overrides(args, "seed", "popsize", "generations", "threads")]
    if previous is not None:
        return command + ["--resume", str(shown(previous)), *asked]
    return command + ["--config", str(shown(file)), "--folder", str(shown(folder)), *asked]


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


def prepared(args: argparse.Namespace) -> tuple[dict, Path, list[str]] | None:
    """The experiment of ``args``, its folder (relative to the repository's root, or a --folder given) and its
    training command, checked as the training script will check it (``check_training``); None where it is refused,
    the problem said in one line."""
    try:
        file, experiment = load_experiment(args)
        folder = experiment_folder(args, experiment)
        command = train_command(args, file, folder)
        check_training(args.kind, command)
    except (*USER_ERRORS, ValueError) as error:
        print(f"paper.py: error: {error}", file=sys.stderr)
        return None
    return experiment, folder, command


def train_and_evaluate(args: argparse.Namespace) -> int:
    """``EXPERIMENT KIND``: train (a new run, or the folder's newest continued), then evaluate the final centre and
    the best, each unless it is evaluated already; with --dry-run, the commands printed."""
    checked = prepared(args)
    if checked is None:
        return 2
    experiment, folder, command = checked
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
