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
file; observation statistics (``<name>.obs_norm.npz``, ``es.observations``) too. ``--centre`` picks a run
folder's ``last`` or ``best`` centre; where the folder keeps only its checkpoint (a campaign's run, before
training is complete or after the pruning of ``best*``), the centre is read from ``checkpoint.npz``
(``SavedCentre``). The original program's ``.dat`` files, outside a run folder, are evaluated with the
flags given, as the original did.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from cli.config import Contradiction, TrainConfig, declared
from cli.errors import USER_ERRORS, Parser, UserError, explained, say
from cli.flags import add_settings, defaults, episode_seed_value, flag_value, given, positive_int
from cli.hints import EVALUATE_SCRIPTS, RESERVOIR_FILE
from cli.train import resolve_environments
from envs import ProblemSpec
from envs.headless import RenderingUnavailable, check_can_render, check_display, choose_mujoco_gl
from es.files import read_json, read_metrics
from es.interrupts import honour_sigint
from es.observations import RunningStat, SavedStatistics, load_statistics, statistics_path
from es.outputs import JSON_SUFFIXES
from es.outputs import check_outputs as check_paths
from es.runfolder import RunFolderError, named_file, read_checkpoint
from policies import KINDS
from report.plots import FIGURE_SUFFIXES
from report.video import STRIP_EVERY, VIDEO_SUFFIXES
from settings import EPISODE_SEED_RANGE, SEED_RANGE, unmet_requirement

FROM_RUN = "the run's, from the config.json beside the weights; else"
CENTRES = ("last", "best")  # a run folder's centres: the final one, the one with the best training return


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
    add("--centre", choices=CENTRES, default=None,
        help="with a run folder: which of its centres to evaluate, last (the final centre, the default) or best (the "
             "centre with the best training return); where the folder keeps only checkpoint.npz (a campaign's run), "
             "read from there")
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
             "the distances and forward displacements walked; for a run folder's centre, which one, the generation "
             "and its training return) to this JSON file")
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


def write_outputs(args: argparse.Namespace, command: list[str], kind: str, reports, problem, params,
                  centre: SavedCentre | None = None) -> None:
    """The --json and --plot files the user asked for (the video is written during its episode); the JSON says
    which of a run's centres was evaluated (``SavedCentre.record``)."""
    from envs.evaluation import trace_episode
    from es.files import write_json
    from report.adaptation import plot_adaptation, steps_text

    if args.json:
        write_json(Path(args.json), {"kind": kind, "command": command, "episodes": args.episodes, "seed": args.seed,
                                     **({"weights": centre.record()} if centre is not None else {}),
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


@dataclass(frozen=True)
class SavedCentre:
    """A centre read from a run's checkpoint.npz, for a run folder without that centre's files (a campaign keeps
    only its checkpoint until training is complete, and never the ``best*`` files)."""

    file: Path  # the run's file of that centre, absent: last.dat, best_coeffs.dat, ...
    centre: str  # "last" or "best"
    theta: np.ndarray
    statistics: SavedStatistics | None  # --obs_norm: those the centre was evaluated with
    generation: int | None  # last: the generations done; best: the generation it scored in (None: not found)
    total: int | None  # the generations config.json asks for
    score: float | None  # best: its training return (its evaluation mean with --eval_every)

    @property
    def checkpoint(self) -> Path:
        return self.file.parent / "checkpoint.npz"

    def describe(self) -> str:
        if self.centre == "best":
            where = f" at generation {self.generation}" if self.generation is not None else ""
            return f"the best centre (training return {self.score:.2f}{where})"
        if self.total is not None and self.generation < self.total:
            return (f"the centre at generation {self.generation} of {self.total}: training is not complete, and a "
                    "campaign keeps only its checkpoint until it is")
        return f"the final centre (generation {self.generation})"

    def record(self) -> dict:
        """What ``--json`` says about the weights evaluated."""
        return {"centre": self.centre, "generation": self.generation, "training_return": self.score}


def main_file(kind: str, given: str, centre: str | None = None) -> Path | SavedCentre:
    """The file the script reads first: the one given; in a run folder given as such, its ``last`` file (or
    ``centre``'s); in a folder of run folders (training's --folder, such as results/paper/carracing_hebbian_seed1),
    the newest run's (run folders are named by the time they started). A run folder without that file but with
    its checkpoint gives the centre saved there."""
    path = Path(given)
    if centre is not None and not path.is_dir():
        raise UserError(f"--centre {centre} picks a centre of a run folder, and {given} is not a folder; give the run "
                        "folder, or leave --centre out")
    if path.is_dir() and not (path / "config.json").is_file():
        runs = sorted(run for run in path.iterdir() if (run / "config.json").is_file())
        if runs:
            path = runs[-1]
            say(f"run: {path}" + (f" (the newest of {len(runs)} in {given})" if len(runs) > 1 else ""))
    if not (path / "config.json").is_file():
        return path
    chosen = path / named_file(centre or "last", KINDS[kind].files[0].roles[0])
    if chosen.exists() or not (path / "checkpoint.npz").is_file():
        return chosen
    return saved_centre(kind, chosen, centre or "last")


def saved_centre(kind: str, file: Path, centre: str) -> SavedCentre:
    """``centre`` of the run folder ``file`` lies in (``file``: that centre's main file, present or not), from its
    checkpoint.npz, with the observation statistics it was evaluated with, and where it stands: the generation and,
    for the best centre, its training return."""
    run = file.parent
    try:
        checkpoint = read_checkpoint(run / "checkpoint.npz")
    except RunFolderError:
        raise UserError(f"cannot evaluate {run}: {run / 'checkpoint.npz'} is not a readable checkpoint; evaluate a "
                        "weight file of the run instead") from None
    config = recorded_config(kind, file)
    if centre == "best":
        if not checkpoint.best_theta.size:
            raise UserError(f"{run}: no centre has scored yet (its checkpoint.npz holds no best centre); evaluate "
                            "its last centre (--centre last)")
        theta, statistics = checkpoint.best_theta, checkpoint.best_observations
        column = "center_eval_mean" if config.es.eval_every is not None else "center_return"  # what picked it
        generation, score = scored_in(run, column, checkpoint.best_center), checkpoint.best_center
    else:
        theta, statistics, generation, score = checkpoint.theta, checkpoint.observations, checkpoint.generation, None
    stat = RunningStat.from_arrays(statistics)
    saved = None if stat is None else SavedStatistics(stat.mean, stat.std, config.policy.obs_clip, stat.observations)
    return SavedCentre(file, centre, theta, saved, generation, config.run.generations, score)


def centre_of(kind: str, weight_file: Path) -> SavedCentre | None:
    """Where a run folder's ``last``/``best`` file stands, from the checkpoint beside it (for ``--json``); None
    for another file, or where there is no checkpoint it can read (the file itself is what is evaluated)."""
    run, role = weight_file.parent, KINDS[kind].files[0].roles[0]
    centre = next((centre for centre in CENTRES if weight_file.name == named_file(centre, role)), None)
    if centre is None or not (run / "checkpoint.npz").is_file() or not (run / "config.json").is_file():
        return None
    try:
        return saved_centre(kind, weight_file, centre)
    except (*USER_ERRORS, ValueError, OSError):
        return None


def scored_in(run: Path, column: str, score: float) -> int | None:
    """The first generation of the run's metrics.csv whose ``column`` (the centre's return, or its evaluation mean)
    is ``score``; None where metrics.csv is missing or holds no such row."""
    try:
        rows = read_metrics(run / "metrics.csv")
        return next((int(row["generation"]) for row in rows if row.get(column) not in (None, "")
                     and math.isclose(float(row[column]), score, rel_tol=1e-12, abs_tol=1e-12)), None)
    except (OSError, ValueError, KeyError, *USER_ERRORS):
        return None


def recorded_config(kind: str, weight_file: Path) -> TrainConfig | None:
    """The settings of the run folder ``weight_file`` lies in (its config.json); None outside a run folder."""
    path = weight_file.parent / "config.json"
    if not path.is_file():
        return None
    try:
        config = TrainConfig.from_dict(read_json(path), path.name)
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


def saved_arrays(args: argparse.Namespace, saved: SavedCentre, policy) -> dict:
    """role -> array of a centre read from a checkpoint, as the run's files would hold them; the checkpoint holds
    every part of the centre, so no other file is taken."""
    given = [flag for flag in path_flags(args) if flag != KINDS[args.kind].files[0].flag]
    if given:
        raise UserError(f"{given[0]}: the centre comes from {saved.checkpoint}, which holds all of its weights; leave "
                        f"{given[0]} out")
    if saved.theta.size != policy.num_params:
        raise UserError(f"{saved.checkpoint} holds {saved.theta.size} parameters, and the network its config.json "
                        f"records has {policy.num_params}")
    return policy.export(saved.theta)


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
        source = main_file(kind, getattr(args, main_flag[2:]), args.centre)
        saved = source if isinstance(source, SavedCentre) else None
        # a saved centre: its checkpoint is read, and the settings and messages name the file it stands for
        weight_file = saved.file if saved else source
        check_outputs(args, [str(saved.checkpoint if saved else weight_file),
                             *(path for flag, path in path_flags(args).items() if flag != main_flag)])
        if args.seed + args.episodes - 1 > EPISODE_SEED_RANGE[1]:
            raise UserError(f"--seed {args.seed} with --episodes {args.episodes} runs past the largest episode seed "
                            f"{EPISODE_SEED_RANGE[1]}")
        if args.render and args.video:
            raise UserError("--video records frames off screen; it cannot be combined with --render")
        if saved is not None:
            say(f"weights: {saved.describe()}, from {saved.checkpoint}")
            statistics = saved.statistics
        else:
            first = load_dat(weight_file)
            with explained("cannot load the observation statistics"):
                statistics = saved_statistics(weight_file)
        centre = saved or (centre_of(kind, weight_file) if args.json else None)  # for the JSON
        config = evaluation_config(kind, args, weight_file, statistics)
        env_ids = resolve_environments(config.env.environment)
        render_mode = "human" if args.render else ("rgb_array" if args.video else None)
        with explained("bad reservoir settings"):
            problem = build_problem(ProblemSpec(env_ids, config.policy), render_mode)
        normalise_observations(problem, weight_file, statistics)
        arrays = saved_arrays(args, saved, problem.policy) if saved else weight_arrays(args, weight_file, first,
                                                                                        problem.policy)
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
            write_outputs(args, [parser.prog, *argv], kind, reports, problem, params, centre)
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
