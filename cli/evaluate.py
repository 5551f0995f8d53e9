"""``evaluate_static.py`` and ``evaluate_hebb.py``: their flags, the outputs, and the shared body.

One evaluation function (``envs.evaluation.evaluate``) runs the episodes through the training's own
rollout; the outputs the user asks for (``--json``, ``--plot``, ``--video``) are checked before any
episode runs. Weights trained with ``--obs_norm`` are evaluated with the observation statistics
saved beside them (``<name>.obs_norm.npz``, ``es.observations``), found automatically; weights in
a run folder whose config.json says ``obs_norm`` but without that file are refused. Weights trained with
``--reservoir`` are evaluated with the reservoir the flags describe, or, without ``--reservoir``, the one
the run folder's config.json records (``policies.reservoir``); evolved reservoir hyperparameters come
from ``--path_reservoir``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from cli.errors import USER_ERRORS, Parser, UserError, explained, say
from cli.flags import RESERVOIR_FLAGS, SEED_RANGE, add_reservoir_flags, flag_value, positive_int, seed_value
from cli.train import given_flags, resolve_environments
from envs import ProblemSpec
from envs.headless import RenderingUnavailable, check_can_render, check_display, choose_mujoco_gl
from es.interrupts import honour_sigint
from es.observations import SavedStatistics, load_statistics, statistics_path
from policies import PolicySettings
from report.video import check_video_path


def evaluation_parser(prog: str, description: str) -> Parser:
    parser = Parser(prog=prog, description=description,
                    formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add = parser.add_argument
    add("--environment", default="CarRacing-v0", metavar="ID",
        help="environment id; several ids separated by commas give one row each")
    add("--episodes", type=positive_int, default=1, metavar="N", help="episodes per environment")
    add("--seed", type=seed_value, default=0, help="seed of the first episode; episode i uses seed + i")
    add("--render", type=flag_value, nargs="?", const=True, default=False, metavar="BOOL",
        help="show the episodes in a window (needs a display)")
    add("--video", default=None, metavar="PATH",
        help="write the first episode to this video file (.mp4, .mkv, .mov or .avi), frame by frame")
    add("--json", default=None, metavar="PATH",
        help="also write the statistics (per environment: returns, mean, std, steps, seeds; for ants "
             "the distances and forward displacements walked) to this JSON file")
    add("--plot", default=None, metavar="PATH",
        help="PNG of one episode (first environment, first seed): reward per step, or for ants the "
             "distance walked, and for Hebbian networks the norm of each layer's weights over time")
    add_reservoir_flags(parser, evaluation=True)
    return parser


def check_outputs(args: argparse.Namespace, inputs: list[str]) -> None:
    """Refuse, before any episode runs, outputs that could not be written or that would replace an
    input (the weight files) or each other."""
    from es.outputs import JSON_SUFFIXES, check_outputs as check_paths  # [trust] the guard of every output
    from report.plots import FIGURE_SUFFIXES
    from report.video import VIDEO_SUFFIXES

    check_paths([(flag, path, suffixes) for flag, path, suffixes in (("--json", args.json, JSON_SUFFIXES), (
        "--plot", args.plot, FIGURE_SUFFIXES), ("--video", args.video, VIDEO_SUFFIXES)) if path is not None], inputs)
    outputs = [(flag, path) for flag, path in (("--json", args.json), ("--plot", args.plot), ("--video", args.video))
               if path is not None]
    for flag, path in outputs:
        target = Path(path)
        if target.exists() and not target.is_file():
            raise UserError(f"{flag} {path}: exists and is not a regular file (a folder or a device); give a file name")
        parent = target.parent
        if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
            raise UserError(f"{flag} {path}: {parent} is not an existing writable folder")
        for other in inputs:
            if same_file(path, other):
                raise UserError(f"{flag} {path} is the weight file {other}; writing it would destroy the input: "
                                "give another file name")
    for index, (flag, path) in enumerate(outputs):
        for other_flag, other in outputs[index + 1:]:
            if same_file(path, other):
                raise UserError(f"{flag} and {other_flag} are the same file {path}; give each its own name")
    if args.video is not None and (problem := check_video_path(args.video)) is not None:
        raise UserError(f"--video {args.video}: {problem}")


def same_file(first: str | Path, second: str | Path) -> bool:
    """The same file once links are resolved (or the same path for files not there yet)."""
    first, second = Path(first), Path(second)
    if first.exists() and second.exists():
        return os.path.samefile(first, second)
    return first.resolve() == second.resolve()


def write_outputs(args: argparse.Namespace, command: list[str], kind: str, reports, problem, params) -> None:
    """The --json and --plot files the user asked for (the video is written during its episode)."""
    from envs.evaluation import trace_episode
    from es.files import write_json
    from report.adaptation import plot_adaptation

    if args.json:
        write_json(Path(args.json), {"kind": kind, "command": command, "episodes": args.episodes, "seed": args.seed,
                                     "distance": "ants only: metres between the torso's (x, y) at the start "
                                                 "and the end of the policy steps; forward: its x component",
                                     "environments": [report.to_dict() for report in reports]})
        say(f"statistics: {args.json}")
    if args.plot:
        trace = trace_episode(problem, params, args.seed)
        plot_adaptation(trace, args.plot)
        say(f"adaptation plot ({trace.env_id}, seed {args.seed}, {len(trace.rewards)} steps): {args.plot}")


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


def trained_policy(weight_file: Path) -> dict:
    """The policy settings of the run folder ``weight_file`` lies in (its config.json); {} elsewhere."""
    try:
        policy = json.loads((weight_file.parent / "config.json").read_text())["policy"]
    except (OSError, ValueError, KeyError, TypeError):  # not in a run folder, or one from before sections
        return {}
    return policy if isinstance(policy, dict) else {}


def trained_with_obs_norm(weight_file: Path) -> bool:
    """Whether the run folder ``weight_file`` lies in (its config.json) normalised observations."""
    return bool(trained_policy(weight_file).get("obs_norm", False))


def reservoir_options(args: argparse.Namespace, argv: list[str], weight_file: Path) -> dict:
    """The reservoir settings to evaluate with: with ``--reservoir``, the flags given, and for the others the
    run folder's config.json (if it records a reservoir), else the flags' defaults; without it, the run
    folder's reservoir, if any; else none."""
    given = sorted(given_flags(argv) & {*RESERVOIR_FLAGS, "path_reservoir"})
    trained = trained_policy(weight_file)
    stored = trained if trained.get("reservoir") else {}
    if args.reservoir:
        options = {name: getattr(args, name) if name in given else stored.get(name, getattr(args, name))
                   for name in RESERVOIR_FLAGS}
        evolved = args.path_reservoir is not None or bool(stored.get("reservoir_evolve"))
        return dict(reservoir=True, reservoir_evolve=evolved, **options)
    extra = [name for name in given if name != "path_reservoir" or not stored.get("reservoir_evolve")]
    if extra:
        raise UserError(f"--{extra[0]} has an effect only with --reservoir (or, for --path_reservoir, weights of a "
                        f"--reservoir_evolve run); add --reservoir or leave --{extra[0]} out")
    if not stored:
        return {}
    say(f"reservoir: as {weight_file.parent / 'config.json'} records it")
    return {name: stored[name] for name in ("reservoir", "reservoir_evolve", *RESERVOIR_FLAGS) if name in stored}


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


def evaluate_main(kind: str, parser: Parser, argv: list[str] | None, load_arrays, input_paths) -> int:
    """Shared body of the evaluate scripts; ``load_arrays(args)`` reads the weight files, whose paths
    ``input_paths(args)`` lists (the first is the one observation statistics are looked for beside)."""
    from envs.evaluation import EpisodeError, evaluate, format_table
    from es.files import load_dat
    from report.video import record_first_episode

    honour_sigint()  # [trust] a background job's SIGINT too
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    problem = recorder = None
    done: dict[str, object] = {}  # env id -> its report so far

    def finished_episode(report) -> None:
        done[report.env_id] = report
        show(report)

    try:
        env_ids = resolve_environments(args.environment)
        check_outputs(args, input_paths(args) + ([args.path_reservoir] if args.path_reservoir else []))
        if args.seed + args.episodes - 1 > SEED_RANGE[1]:
            raise UserError(f"--seed {args.seed} with --episodes {args.episodes} runs past the largest episode seed "
                            f"{SEED_RANGE[1]}")
        if args.render and args.video:
            raise UserError("--video records frames off screen; it cannot be combined with --render")
        arrays = load_arrays(args)
        if args.path_reservoir is not None:
            arrays["reservoir"] = load_dat(args.path_reservoir)
        weight_file = Path(input_paths(args)[0])
        with explained("cannot load the observation statistics"):
            statistics = saved_statistics(weight_file)
        options = {name: getattr(args, name) for name in ("hebb_rule", "init_weights", "network") if hasattr(args, name)}
        with explained("bad reservoir settings"):
            policy = PolicySettings(kind, **options, obs_clip=statistics.clip if statistics else None,
                                    obs_norm=statistics is not None or trained_with_obs_norm(weight_file),
                                    **reservoir_options(args, argv, weight_file))
        render_mode = "human" if args.render else ("rgb_array" if args.video else None)
        problem = build_problem(ProblemSpec(env_ids, policy), render_mode)
        normalise_observations(problem, weight_file, statistics)
        with explained("cannot load the weights"):
            params = problem.policy.load(arrays)
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
