"""What the four scripts share: their flags, input checks, and one-line errors with exit code 2.

The flags keep the original names and defaults (upstream spec §1); new ones use the same
snake_case style. Every error a user can cause ends in one line naming the problem and what would
be valid, exit code 2, and nothing created or overwritten.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import secrets
import sys
from pathlib import Path

import numpy as np

import envs
from envs import ProblemSpec
from es.files import FileFormatError
from es.progress import display_for
from es.run import Run, SaveError, TrainConfig, UserError, new_run_dir
from policies import DISTRIBUTIONS, INIT_CHOICES, RULES

USER_ERRORS = (UserError, FileFormatError, envs.EnvironmentError_)


class Parser(argparse.ArgumentParser):
    """argparse whose errors are one line and exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text}")
    return value


def positive_float(text: str) -> float:
    value = float(text)
    if not value > 0 or not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def threads_value(text: str) -> int:
    value = int(text)
    if value == 0 or value < -1:
        raise argparse.ArgumentTypeError(f"must be -1 (all cores) or a number of workers >= 1, got {text}")
    return value


def flag_value(text: str | None) -> bool:
    """``--render`` alone, or the original's ``--render True`` / ``--render False``."""
    if text is None:
        return True
    lowered = text.strip().lower()
    if lowered in ("1", "true", "yes", "on"):
        return True
    if lowered in ("0", "false", "no", "off", ""):
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


@contextlib.contextmanager
def explained(what: str):
    """Turn a setup failure into a UserError: a ValueError already says what is wrong (incompatible
    environments, a wrong-sized file); anything else (a custom environment whose constructor
    raises, a worker that cannot start) is named with ``what`` and its type."""
    try:
        yield
    except USER_ERRORS:
        raise
    except ValueError as error:
        raise UserError(str(error)) from None
    except Exception as error:
        raise UserError(f"{what}: {type(error).__name__}: {error}") from None


# --- training -----------------------------------------------------------------------------------


def training_parser(prog: str, description: str, folder: str) -> Parser:
    parser = Parser(prog=prog, description=description,
                    formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add = parser.add_argument
    add("--environment", default="CarRacing-v0", metavar="ID",
        help="Gymnasium, pyBullet or MuJoCo id, or module:Id for a custom environment; several ids "
             "separated by commas are trained together (fitness = mean over them)")
    add("--popsize", type=int, default=200, metavar="N", help="population size (even: mirrored pairs)")
    add("--print_every", type=positive_int, default=1, metavar="K", help="save files every K generations")
    add("--lr", type=positive_float, default=0.2, help="ES learning rate")
    add("--decay", type=positive_float, default=0.995, help="learning-rate decay per generation")
    add("--sigma", type=positive_float, default=0.1, help="initial noise standard deviation")
    add("--generations", type=positive_int, default=300, metavar="G",
        help="number of generations (with --resume: the total, counting those already run)")
    add("--folder", default=folder, metavar="DIR", help="where run folders are created")
    add("--threads", type=threads_value, default=-1, metavar="W",
        help="worker processes; -1 = all cores, 1 = run in this process")
    add("--seed", type=int, default=None, help="seed of the run (default: a random one, printed and saved)")
    add("--episodes", type=positive_int, default=1, metavar="E",
        help="episodes per fitness evaluation (the fitness is their mean)")
    add("--resume", default=None, metavar="RUN_DIR", help="continue the run saved in RUN_DIR")
    add("--backend", choices=("process", "ray"), default="process",
        help="parallel backend for --threads > 1: a process pool on this machine, or Ray (one machine "
             "or a cluster; pip install -r requirements-ray.txt)")
    add("--ray_address", default=None, metavar="ADDRESS",
        help="with --backend ray: 'auto' joins the cluster `ray start` runs on this machine, HOST:PORT "
             "another one; default: start a local Ray with --threads CPUs")
    return parser


def resolve_environments(text: str) -> list[str]:
    ids = [part.strip() for part in text.split(",") if part.strip()]
    if not ids:
        raise UserError("--environment is empty; give an id such as CartPole-v1")
    return [envs.resolve_env_id(env_id) for env_id in ids]


def population_size(requested: int) -> int:
    if requested < 2:
        raise UserError(f"--popsize must be at least 2 (one mirrored pair), got {requested}")
    if requested % 2:
        print(f"note: --popsize {requested} is odd; mirrored sampling needs pairs, using {requested + 1}")
        return requested + 1
    return requested


def config_from_args(kind: str, args: argparse.Namespace) -> TrainConfig:
    seed = args.seed if args.seed is not None else secrets.randbelow(2**31)
    if args.ray_address is not None and args.backend != "ray":
        raise UserError(f"--ray_address {args.ray_address} needs --backend ray")
    hebbian = {key: getattr(args, key) for key in ("hebb_rule", "init_weights", "distribution") if hasattr(args, key)}
    return TrainConfig(kind=kind, environment=args.environment, env_ids=resolve_environments(args.environment),
                       popsize=population_size(args.popsize), lr=args.lr, decay=args.decay, sigma=args.sigma,
                       generations=args.generations, print_every=args.print_every, folder=args.folder,
                       threads=args.threads, seed=seed, episodes=args.episodes, backend=args.backend,
                       ray_address=args.ray_address, **hebbian)


def config_for_resume(kind: str, args: argparse.Namespace, argv: list[str]) -> tuple[TrainConfig, Path]:
    from es.files import read_json

    run_dir = Path(args.resume)
    if not (run_dir / "config.json").is_file() or not (run_dir / "checkpoint.npz").is_file():
        raise UserError(f"--resume {run_dir}: not a run folder (needs config.json and checkpoint.npz)")
    try:
        config = TrainConfig.from_dict(read_json(run_dir / "config.json"))
    except (ValueError, TypeError) as error:
        raise UserError(f"--resume {run_dir}: unreadable config.json ({error})") from None
    if config.kind != kind:
        script = "train_hebb.py" if config.kind == "hebbian" else "train_static.py"
        raise UserError(f"--resume {run_dir}: this is a {config.kind} run; resume it with {script}")
    given = {item.split("=")[0] for item in argv if item.startswith("--")}
    for name in ("generations", "threads", "backend", "ray_address", "print_every"):  # what a resume may change
        if f"--{name}" in given:
            setattr(config, name, getattr(args, name))
    return config, run_dir


def check_writable(folder: str) -> None:
    """Refuse, before anything is built or created, a --folder that could not hold a run folder."""
    path = Path(folder)
    existing = next((parent for parent in (path, *path.parents) if parent.exists()), Path("."))
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"--folder {folder}: {existing} is not a writable folder")


def train_main(kind: str, parser: Parser, argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    run = None
    try:
        if args.resume:
            config, run_dir = config_for_resume(kind, args, argv)
        else:
            config, run_dir = config_from_args(kind, args), None
            check_writable(config.folder)
        spec = ProblemSpec(tuple(config.env_ids), kind, config.hebb_rule, config.init_weights)
        with explained("cannot start the run"):
            run = Run(config, spec, run_dir or Path("."), log=_log, display=display_for(sys.stdout))
        if run_dir is None:
            try:
                run.run_dir = new_run_dir(config.folder, config.env_label, config.seed)
            except OSError as error:
                raise UserError(f"--folder {config.folder}: {error.strerror or error}") from None
            run.write_config([parser.prog, *argv])
            run.save_checkpoint()  # resumable from the start, even if the first generation fails
        else:
            run.load_checkpoint()
            if run.state.generation >= config.generations:
                _log(f"{run_dir} has already run {run.state.generation} generations; nothing to do "
                     f"(--generations is the total: pass more than {run.state.generation} to continue)")
                return 0
            _log(f"resuming {run_dir} at generation {run.state.generation} of {config.generations}")
            run.write_config([parser.prog, *argv])  # records the new settings and the resume command
        _log(f"run folder: {run.run_dir} | environment: {', '.join(config.env_ids)} | parameters: {run.dim} "
             f"| workers: {run.evaluator.workers} | seed: {config.seed}")
        code = run.train()
        if code == 0:
            _log(f"done; evaluate with: {run.evaluate_hint()}")
        return code
    except (*USER_ERRORS, SaveError) as error:  # SaveError here: before training started
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = f" (resume with: {run.resume_hint()})" if run is not None and run.checkpoint_generation is not None else ""
        print(f"{parser.prog}: stopped at once; saved files are intact{resume}", file=sys.stderr)
        return 130
    finally:
        if run is not None:
            run.close()


# --- evaluation ---------------------------------------------------------------------------------


def evaluation_parser(prog: str, description: str) -> Parser:
    parser = Parser(prog=prog, description=description,
                    formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add = parser.add_argument
    add("--environment", default="CarRacing-v0", metavar="ID",
        help="environment id; several ids separated by commas give one row each")
    add("--episodes", type=positive_int, default=1, metavar="N", help="episodes per environment")
    add("--seed", type=int, default=0, help="seed of the first episode; episode i uses seed + i")
    add("--render", type=flag_value, nargs="?", const=True, default=False, metavar="BOOL",
        help="show the episodes in a window (needs a display)")
    add("--video", default=None, metavar="PATH", help="write the first episode to this mp4 file")
    add("--json", default=None, metavar="PATH",
        help="also write the statistics (per environment: returns, mean, std, steps, seeds; for ants "
             "the distances and forward displacements walked) to this JSON file")
    add("--plot", default=None, metavar="PATH",
        help="PNG of one episode (first environment, first seed): reward per step, or for ants the "
             "distance walked, and for Hebbian networks the norm of each layer's weights over time")
    return parser


def check_output_file(path: str | None, flag: str) -> None:
    """Refuse, before any episode runs, an output file that could not be written."""
    if path is None:
        return
    target = Path(path)
    if target.exists() and not target.is_file():
        raise UserError(f"{flag} {path}: exists and is not a regular file (a folder or a device); give a file name")
    parent = target.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise UserError(f"{flag} {path}: {parent} is not an existing writable folder")


def write_evaluation_outputs(args: argparse.Namespace, command: list[str], kind: str, reports, problem,
                             params) -> None:
    """The table, then the --json, --plot and --video files the user asked for."""
    from envs.evaluation import format_table, plot_adaptation, trace_episode, write_video
    from es.files import write_json

    print(format_table(reports), flush=True)
    if args.json:
        write_json(Path(args.json), {"kind": kind, "command": command, "episodes": args.episodes, "seed": args.seed,
                                     "distance": "ants only: metres between the torso's (x, y) at the start "
                                                 "and the end of the policy steps; forward: its x component",
                                     "environments": [report.to_dict() for report in reports]})
        print(f"statistics: {args.json}")
    if args.plot:
        trace = trace_episode(problem, params, args.seed)
        plot_adaptation(trace, args.plot)
        print(f"adaptation plot ({trace.env_id}, seed {args.seed}, {len(trace.rewards)} steps): {args.plot}")
    if args.video:
        fps = int(problem.envs[0].metadata.get("render_fps") or 30)
        write_video(args.video, problem.envs[0].frames, fps)
        print(f"video of the first episode: {args.video}")


def evaluate_main(kind: str, parser: Parser, argv: list[str] | None, load_arrays) -> int:
    """Shared body of the evaluate scripts; ``load_arrays(args)`` reads the weight files."""
    from envs.evaluation import evaluate, record_first_episode

    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    problem = None
    try:
        env_ids = resolve_environments(args.environment)
        for path, flag in ((args.json, "--json"), (args.plot, "--plot"), (args.video, "--video")):
            check_output_file(path, flag)
        if args.render and args.video:
            raise UserError("--video records frames off screen; it cannot be combined with --render")
        arrays = load_arrays(args)
        spec = ProblemSpec(tuple(env_ids), kind, getattr(args, "hebb_rule", "ABCD_lr"),
                           getattr(args, "init_weights", "uni"))
        render_mode = "human" if args.render else ("rgb_array" if args.video else None)
        with explained("cannot make the environments"):
            problem = spec.build(render_mode)
        with explained("cannot load the weights"):
            params = problem.policy.load(arrays)
        if args.video:
            record_first_episode(problem)

        def show(report):
            distance = (f" | distance {report.distances[-1]:.2f} m, forward {report.forward[-1]:.2f} m"
                        if report.distances else "")
            print(f"{report.env_id} | episode {len(report.returns)} | seed {report.seeds[-1]} | return "
                  f"{report.returns[-1]:.2f} | steps {report.steps[-1]}{distance}", flush=True)

        reports = evaluate(problem, params, args.episodes, args.seed, on_episode=show)
        try:
            write_evaluation_outputs(args, [parser.prog, *argv], kind, reports, problem, params)
        except (OSError, ValueError) as error:  # a full disk, an environment that renders no frames
            raise UserError(f"{type(error).__name__}: {error}") from None
        return 0
    except USER_ERRORS as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    finally:
        if problem is not None:
            problem.close()


def _log(line: str) -> None:
    print(line, flush=True)


__all__ = ["DISTRIBUTIONS", "INIT_CHOICES", "RULES", "Parser", "flag_value", "train_main", "training_parser"]
