"""``evaluate_static.py`` and ``evaluate_hebb.py``: their flags, the outputs, and the shared body.

One evaluation function (``envs.evaluation.evaluate``) runs the episodes through the training's own
rollout; the outputs the user asks for (``--json``, ``--plot``, ``--video``) are checked before any
episode runs.

A weight file in a run folder (or the folder itself: its ``last`` files) is evaluated as the run
recorded it: every setting that shapes the policy (declared ``evaluation``: rule, init, network,
normalisation, reservoir) and the environment come from its config.json (``TrainConfig.overlay``, as a
resume does); a flag that contradicts the recording is refused naming both values, and ``--environment``
may name others (a body the run did not train on). The run's other files of the same ``best``/``last``
prefix (the CNN, co-evolved initial weights, evolved reservoir hyperparameters) are found beside the
file; observation statistics (``<name>.obs_norm.npz``, ``es.observations``) too. The original program's
``.dat`` files, outside a run folder, are evaluated with the flags given, as the original did.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from cli.config import Contradiction, TrainConfig, declared
from cli.errors import USER_ERRORS, Parser, UserError, explained, say
from cli.flags import add_settings, defaults, episode_seed_value, flag_value, given, positive_int
from cli.hints import EVALUATE_SCRIPTS, RESERVOIR_FILE
from cli.train import resolve_environments
from envs import ProblemSpec
from envs.headless import RenderingUnavailable, check_can_render, check_display, choose_mujoco_gl
from es.files import read_json
from es.interrupts import honour_sigint
from es.observations import SavedStatistics, load_statistics, statistics_path
from es.outputs import JSON_SUFFIXES
from es.outputs import check_outputs as check_paths
from es.runfolder import named_file, read_checkpoint
from policies import KINDS
from report.plots import FIGURE_SUFFIXES
from report.video import STRIP_EVERY, VIDEO_SUFFIXES
from settings import EPISODE_SEED_RANGE, SEED_RANGE, unmet_requirement

FROM_RUN = "the run's, from the config.json beside the weights; else"


def evaluation_parser(prog: str, description: str, kind: str) -> Parser:
    """The flags of an evaluate script: its files, its episodes and outputs, and the settings declared
    for evaluating a ``kind`` (``cli.flags``)."""
    parser = Parser(prog=prog, description=description)
    add = parser.add_argument
    main, *others = KINDS[kind].files
    add(main.flag, required=True, metavar="FILE",
        help=f"the .dat file of {main.holds}, or a run folder (its {named_file('last', main.roles[0])}), or a "
             "folder of run folders (the newest run's)")
    for file in others:
        add(file.flag, default=None, metavar="FILE",
            help=f"the .dat file of {file.holds} (default: in a run folder, the one beside the {main.holds})")
    add(RESERVOIR_FILE.flag, default=None, metavar="FILE",
        help=f"{RESERVOIR_FILE.holds} (default: in a run folder, best_reservoir.dat or last_reservoir.dat beside the "
             f"{main.holds})")
    add("--episodes", type=positive_int, default=1, metavar="N", help="episodes per environment (default: 1)")
    add("--seed", type=episode_seed_value, default=0,
        help="seed of the first episode; episode i uses seed + i; a whole number from {} to {}, the seeds from "
             "{} on being those of the training's centre evaluation (default: 0)".format(*EPISODE_SEED_RANGE,
                                                                                       SEED_RANGE[1] + 1))
    add("--render", type=flag_value, nargs="?", const=True, default=False, metavar="BOOL",
        help="show the episodes in a window (needs a display)")
    add("--video", default=None, metavar="PATH",
        help=f"write the first episode to this video file ({', '.join(VIDEO_SUFFIXES)}), frame by frame; a "
             f".png: a strip of every {STRIP_EVERY}th frame")
    add("--json", default=None, metavar="PATH",
        help="also write the statistics (per environment: returns, mean, std, steps, seeds; for ants "
             "the distances and forward displacements walked) to this JSON file")
    add("--plot", default=None, metavar="PATH",
        help=f"a figure ({', '.join(FIGURE_SUFFIXES)}) of one episode (first environment, first seed): the return "
             "so far, or for ants the distance walked, and for Hebbian networks the norm of each layer's weights over "
             "time")
    parser.set_defaults(kind=kind)
    add_settings(parser, "evaluate", kind, evaluation_note=FROM_RUN)
    return parser


def file_flags(kind: str) -> tuple:
    """The evaluate script's file flags for a ``kind`` (``policies.registry.FileFlag``), its main file's first."""
    return (*KINDS[kind].files, RESERVOIR_FILE)


def path_flags(args: argparse.Namespace) -> dict[str, str]:
    """flag -> path of the weight files given."""
    flags = [file.flag for file in file_flags(args.kind)]
    return {flag: getattr(args, flag[2:]) for flag in flags if getattr(args, flag[2:], None) is not None}


def check_outputs(args: argparse.Namespace, inputs: list[str]) -> None:
    """Refuse, before any episode runs, outputs that could not be written or that would replace an
    input (the weight files), a run's file or each other (``es.outputs``, the guard of every output)."""
    check_paths([(flag, path, suffixes) for flag, path, suffixes in (("--json", args.json, JSON_SUFFIXES), (
        "--plot", args.plot, FIGURE_SUFFIXES), ("--video", args.video, VIDEO_SUFFIXES)) if path is not None], inputs)


def write_outputs(args: argparse.Namespace, command: list[str], kind: str, reports, problem, params) -> None:
    """The --json and --plot files the user asked for (the video is written during its episode)."""
    from envs.evaluation import trace_episode
    from es.files import write_json
    from report.adaptation import plot_adaptation, steps_text

    if args.json:
        write_json(Path(args.json), {"kind": kind, "command": command, "episodes": args.episodes, "seed": args.seed,
                                     "distance": "ants only: metres between the torso's (x, y) at the start "
                                                 "and the end of the policy steps; forward: its x component",
                                     "environments": [report.to_dict() for report in reports]})
        say(f"statistics: {args.json}")
    if args.plot:
        trace = trace_episode(problem, params, args.seed)
        plot_adaptation(trace, args.plot)
        say(f"adaptation plot ({trace.env_id}, seed {args.seed}, {steps_text(trace)}): {args.plot}")


def show(report) -> None:
    """One line per episode, as it ends."""
    distance = (f" | distance {report.distances[-1]:.2f} m, forward {report.forward[-1]:.2f} m"
                if report.distances else "")
    say(f"{report.env_id} | episode {len(report.returns)} | seed {report.seeds[-1]} | return "
          f"{report.returns[-1]:.2f} | steps {report.steps[-1]}{distance}")


def build_problem(spec: ProblemSpec, render_mode: str | None):
    """The environments and policy; rendering needs a GL backend that loads (``envs.headless``)."""
    if render_mode is not None:
        check_display(render_mode)
        choose_mujoco_gl()
    with explained("cannot make the environments"):
        problem = spec.build(render_mode)
    try:
        check_can_render(problem.envs, render_mode)
    except RenderingUnavailable:
        problem.close()
        raise
    return problem


def saved_statistics(weight_file: Path) -> SavedStatistics | None:
    """The observation statistics beside ``weight_file``, if there are any (said in one line)."""
    path = statistics_path(weight_file)
    if not path.is_file():
        return None
    statistics = load_statistics(path)
    say(f"observation normalisation: statistics from {path} ({statistics.observations} observations)")
    return statistics


def main_file(kind: str, given: str) -> Path:
    """The file the script reads first: the one given; in a run folder given as such, its ``last`` file; in a
    folder of run folders (training's --folder, such as results/paper/carracing_hebbian_seed1), the newest run's
    (run folders are named by the time they started)."""
    path = Path(given)
    if path.is_dir() and not (path / "config.json").is_file():
        runs = sorted(run for run in path.iterdir() if (run / "config.json").is_file())
        if runs:
            path = runs[-1]
            say(f"run: {path}" + (f" (the newest of {len(runs)} in {given})" if len(runs) > 1 else ""))
    if not (path / "config.json").is_file():
        return path
    last = path / named_file("last", KINDS[kind].files[0].roles[0])
    if not last.exists() and (path / "checkpoint.npz").is_file():  # a campaign's run keeps only its checkpoint
        done = read_checkpoint(path / "checkpoint.npz").generation
        total = read_json(path / "config.json").get("run", {}).get("generations", "?")
        raise UserError(f"{path} has no {last.name}: the run is at generation {done} of {total}, and a campaign "
                        "keeps only its checkpoint until training is complete; continue it (python experiments/"
                        "paper.py campaign --budget MINUTES) or evaluate another run")
    return last


def recorded_config(kind: str, weight_file: Path) -> TrainConfig | None:
    """The settings of the run folder ``weight_file`` lies in (its config.json); None outside a run folder."""
    path = weight_file.parent / "config.json"
    if not path.is_file():
        return None
    try:
        config = TrainConfig.from_dict(read_json(path), str(path))
    except (ValueError, TypeError) as error:
        raise UserError(f"{path}: unreadable ({error})") from None
    if config.policy.kind != kind:
        raise UserError(f"{weight_file} is from a {config.policy.kind} run ({path}); evaluate it with "
                        f"{EVALUATE_SCRIPTS[config.policy.kind]}")
    return config


def evaluation_config(kind: str, args: argparse.Namespace, weight_file: Path,
                      statistics: SavedStatistics | None) -> TrainConfig:
    """What to evaluate with: the run's recorded settings (or outside a run, the defaults), then the flags given;
    a flag that contradicts the recording is refused, naming both values. --environment may differ."""
    flags = given(args)
    recorded = recorded_config(kind, weight_file)
    base = recorded or TrainConfig.from_values(defaults(kind), "flags")
    values = {**{item.name: base.value(item.name) for item in declared()}, **flags}
    if recorded is None and args.path_reservoir is not None:  # the original's files: evolved if given
        flags["reservoir_evolve"] = values["reservoir_evolve"] = True
    unmet = unmet_requirement(declared(), values, flags)
    if unmet is not None:
        raise UserError(unmet)
    try:
        config = base.overlay(flags, {"environment"} if recorded else set(flags))
    except Contradiction as error:
        raise UserError(f"{error}: {weight_file} is a file of the run {weight_file.parent}, whose config.json records "
                        "these; leave the flags out, or give the run's values") from None
    except ValueError as error:
        raise UserError(str(error)) from None
    obs_norm = statistics is not None or config.policy.obs_norm
    clip = statistics.clip if statistics is not None else config.policy.obs_clip
    return replace(config, policy=replace(config.policy, obs_norm=obs_norm, obs_clip=clip if obs_norm else None))


def weight_arrays(args: argparse.Namespace, weight_file: Path, first: np.ndarray, policy) -> dict:
    """role -> array: the files given, each refused if this policy has no such file, and the run's others
    of the same prefix beside ``weight_file`` (``best_reservoir.dat`` beside ``best.dat``)."""
    from es.files import load_dat

    flags = {file.flag: file for file in file_flags(args.kind)}
    paths = {}
    for flag, path in path_flags(args).items():
        role = next((role for role in flags[flag].roles if role in policy.roles), None)
        if role is None:
            mine = [file.flag for file in flags.values() if set(file.roles) & set(policy.roles)]
            raise UserError(f"{flag} {path}: this policy has no such file (its files: {', '.join(mine)}); leave "
                            f"{flag} out")
        paths[role] = Path(path)
    prefix = next((prefix for prefix in ("best", "last") if weight_file.name == named_file(prefix, policy.roles[0])),
                  None)
    for role in policy.roles:
        beside = weight_file.parent / named_file(prefix, role) if prefix else None
        if role not in paths and beside is not None and beside.is_file():
            paths[role] = beside
    return {role: first if role == policy.roles[0] else load_dat(path) for role, path in paths.items()}


def describe_reservoir(problem, params) -> None:
    """One line for each front end the weights are evaluated with (a reservoir's evolved hyperparameters decoded)."""
    for line in problem.policy.describe_front_ends(params):
        say(line)


def normalise_observations(problem, weight_file: Path, statistics: SavedStatistics | None) -> None:
    """Give a normalising policy its statistics; refuse where they are missing."""
    if not problem.policy.normalised_inputs:
        return
    if statistics is None:
        raise UserError(f"{weight_file} was trained with --obs_norm, but its observation statistics "
                        f"{statistics_path(weight_file)} are missing; put that file of the run beside it")
    with explained(f"cannot use the statistics {statistics_path(weight_file)}"):
        problem.policy.observe((statistics.mean, statistics.std))


def evaluate_main(kind: str, parser: Parser, argv: list[str] | None = None) -> int:
    """Shared body of the evaluate scripts."""
    from envs.evaluation import EpisodeError, evaluate, format_table
    from es.files import load_dat
    from report.video import record_first_episode

    honour_sigint()  # a background job's SIGINT too
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    problem = recorder = None
    done: dict[str, object] = {}  # env id -> its report so far

    def finished_episode(report) -> None:
        done[report.env_id] = report
        show(report)

    try:
        main_flag = KINDS[kind].files[0].flag
        weight_file = main_file(kind, getattr(args, main_flag[2:]))
        check_outputs(args, [str(weight_file), *(path for flag, path in path_flags(args).items() if flag != main_flag)])
        if args.seed + args.episodes - 1 > EPISODE_SEED_RANGE[1]:
            raise UserError(f"--seed {args.seed} with --episodes {args.episodes} runs past the largest episode seed "
                            f"{EPISODE_SEED_RANGE[1]}")
        if args.render and args.video:
            raise UserError("--video records frames off screen; it cannot be combined with --render")
        first = load_dat(weight_file)
        with explained("cannot load the observation statistics"):
            statistics = saved_statistics(weight_file)
        config = evaluation_config(kind, args, weight_file, statistics)
        env_ids = resolve_environments(config.env.environment)
        render_mode = "human" if args.render else ("rgb_array" if args.video else None)
        with explained("bad reservoir settings"):
            problem = build_problem(ProblemSpec(env_ids, config.policy), render_mode)
        normalise_observations(problem, weight_file, statistics)
        arrays = weight_arrays(args, weight_file, first, problem.policy)
        with explained("cannot load the weights"):
            params = problem.policy.load(arrays)
        if (weight_file.parent / "config.json").is_file():
            say(f"settings: as {weight_file.parent / 'config.json'} records them")
        describe_reservoir(problem, params)
        if args.video:
            recorder = record_first_episode(problem, args.video)
        reports = evaluate(problem, params, args.episodes, args.seed, on_episode=finished_episode)
        if recorder is not None:
            recorder.finish()
            if recorder.frames_written == 0:
                raise UserError(f"--video {args.video}: the environment rendered no frames")
            say(f"video of the first episode: {args.video}")
        say(format_table(reports))
        try:
            write_outputs(args, [parser.prog, *argv], kind, reports, problem, params)
        except (OSError, ValueError) as error:  # a full disk
            raise UserError(f"{type(error).__name__}: {error}") from None
        return 0
    except (*USER_ERRORS, RenderingUnavailable) as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2
    except EpisodeError as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if done:
            say(f"\ninterrupted; the episodes done:\n{format_table(list(done.values()))}")
        return 130
    finally:
        if recorder is not None:
            recorder.finish()
        if problem is not None:
            problem.close()
