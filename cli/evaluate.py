"""``evaluate_static.py`` and ``evaluate_hebb.py``: their flags, the outputs, and the shared body.

One evaluation function (``envs.evaluation.evaluate``) runs the episodes through the training's own
rollout; the outputs the user asks for (``--json``, ``--plot``, ``--video``) are checked before any
episode runs. Weights trained with ``--obs_norm`` are evaluated with the observation statistics
saved beside them (``<name>.obs_norm.npz``, ``es.observations``), found automatically; weights in
a run folder whose config.json says ``obs_norm`` but without that file are refused.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from cli.errors import USER_ERRORS, Parser, UserError, explained
from cli.flags import flag_value, positive_int
from cli.train import resolve_environments
from envs import ProblemSpec
from es.observations import SavedStatistics, load_statistics, statistics_path
from policies import PolicySettings


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
    from envs.evaluation import format_table, trace_episode
    from es.files import write_json
    from report.adaptation import plot_adaptation
    from report.video import write_video

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


def saved_statistics(weight_file: Path) -> SavedStatistics | None:
    """The observation statistics beside ``weight_file``, if there are any (said in one line)."""
    path = statistics_path(weight_file)
    if not path.is_file():
        return None
    statistics = load_statistics(path)
    print(f"observation normalisation: statistics from {path} ({statistics.observations} observations)")
    return statistics


def trained_with_obs_norm(weight_file: Path) -> bool:
    """Whether the run folder ``weight_file`` lies in (its config.json) normalised observations."""
    try:
        return bool(json.loads((weight_file.parent / "config.json").read_text())["policy"]["obs_norm"])
    except (OSError, ValueError, KeyError, TypeError):  # not in a run folder, or one from before --obs_norm
        return False


def normalise_observations(problem, weight_file: Path, statistics: SavedStatistics | None) -> None:
    """Give a normalising policy its statistics; refuse where they are missing."""
    if not problem.policy.normalised_inputs:
        return
    if statistics is None:
        raise UserError(f"{weight_file} was trained with --obs_norm, but its observation statistics "
                        f"{statistics_path(weight_file)} are missing; put that file of the run beside it")
    with explained(f"cannot use the statistics {statistics_path(weight_file)}"):
        problem.policy.observe((statistics.mean, statistics.std))


def evaluate_main(kind: str, parser: Parser, argv: list[str] | None, load_arrays, weight_flag: str) -> int:
    """Shared body of the evaluate scripts; ``load_arrays(args)`` reads the weight files, the file of
    ``weight_flag`` is the one observation statistics are looked for beside."""
    from envs.evaluation import evaluate
    from report.video import record_first_episode

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
        weight_file = Path(getattr(args, weight_flag))
        with explained("cannot load the observation statistics"):
            statistics = saved_statistics(weight_file)
        options = {name: getattr(args, name) for name in ("hebb_rule", "init_weights") if hasattr(args, name)}
        spec = ProblemSpec(env_ids, PolicySettings(kind, **options, obs_clip=statistics.clip if statistics else None,
                                                   obs_norm=statistics is not None or trained_with_obs_norm(weight_file)))
        render_mode = "human" if args.render else ("rgb_array" if args.video else None)
        with explained("cannot make the environments"):
            problem = spec.build(render_mode)
        normalise_observations(problem, weight_file, statistics)
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
