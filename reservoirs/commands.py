"""The six ER-MRL scripts of ``scripts/``, with the original's names, flags, study names and output
folders (docs/original.md, "ER-MRL"), and what this tool adds: one-line errors with exit code 2, seeds,
recorded settings, and the fixes of docs/original.md, "ER-MRL".

- evolve_res.py, evolve_multi_res.py, evolve_generalization.py: run ``--nb_trials`` more trials of the
  study ``optuna-journal_<name>.log`` in the current folder (created, or continued).
- test.py, test_multi_res.py, test_generalization.py: train PPO without a reservoir and with the
  study's best reservoirs; TensorBoard logs in ``logs/<env_id>_<h_test>/``, SB3 models in
  ``models/<env_id>_<h_test>/``.
- get_random_scores.py: the random agent's returns behind ``reservoirs.experiments``.

Each process trains on one core (torch is set to one thread): to use more cores, start more processes
on the same study.
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import optuna
import torch

import envs
from cli.errors import USER_ERRORS, Parser, UserError, explained
from cli.errors import say as log
from cli.flags import flag_value, positive_float, positive_int, seed_value
from cli.hints import command  # hints by the interpreter and the script's absolute path: they work from any folder
from es.files import atomic_write_bytes, atomic_write_text, write_json
from es.outputs import check_output
from reservoir_extra import SEARCH_BOUNDS
from reservoirs import experiments
from reservoirs.esn import ReservoirSettings
from reservoirs.experiments import ENV_TYPES, TARGET_RETURN, SearchSpace, env_ids_for, reservoirs_from_params
from reservoirs.study import (
    SAMPLERS,
    journal_path,
    load_evolved,
    open_study,
    recorded_settings,
    safe_file_name,
    study_name,
)
from reservoirs.training import InnerLoop, NoFinishedEpisode, PPOFrontEnd, make_base_env, train_ppo
from reservoirs.wrappers import RewardsSavingWrapper

DEFAULT_BOUNDS = SEARCH_BOUNDS
SLURM_SEED = "SLURM_ARRAY_TASK_ID"
# test scripts: model name -> PPO learning rate (the original's get_models and lists)
MODELS_TEST = {"PPO": 3e-4, "RES_PPO_0.0003": 3e-4, "RES_PPO_0.0001": 1e-4}
MODELS_DEL_OBS = {**MODELS_TEST, "RES_PPO_0.00005": 5e-5}
MODELS_GENERALIZATION = {"PPO": 3e-4, "RES_PPO_0.0003": 3e-4}


def new_parser(prog: str, description: str) -> Parser:
    return Parser(prog=prog, description=description, formatter_class=argparse.ArgumentDefaultsHelpFormatter)


def add_bool(parser: Parser, name: str, default: bool | None, help: str) -> None:
    """The original's 'True' / 'False' strings; the flag alone means True."""
    parser.add_argument(f"--{name}", type=flag_value, nargs="?", const=True, default=default, metavar="BOOL", help=help)


def study_part(text: str) -> str:
    """A part of a study's name (--h_test): not empty, since it names the journal and the output folders."""
    if not text.strip():
        raise argparse.ArgumentTypeError("is empty; give the experiment a name")
    return text


def add_training_steps(parser: Parser, **options) -> None:
    parser.add_argument("--training_steps", "--training_timesteps", dest="training_steps", type=positive_int,
                        metavar="N", **options)


# --- evolve ---------------------------------------------------------------------------------------


def add_search_flags(parser: Parser, sampler_default: str | None, fixed_iss_default: bool) -> None:
    add = parser.add_argument
    add("--nb_trials", type=positive_int, required=True, help="trials this process runs, added to the study's")
    add_training_steps(parser, required=True, help="PPO training steps of each lifetime")
    add("--sampler", choices=SAMPLERS, required=sampler_default is None, default=sampler_default,
        help="Cmaes: CMA-ES with IPOP restarts; Tpe; Random")
    add("--sampler_seed", type=seed_value, default=None,
        help="seed of the sampler (None: a random one); processes sharing a study need different seeds")
    add("--nb_seeds", type=positive_int, default=3, help="training seeds 0 .. nb_seeds-1 per environment")
    add("--ep_eval", type=positive_int, default=10, help="fitness: mean return of the last ep_eval episodes")
    add("--units", type=positive_int, default=100, help="neurons per reservoir")
    add_bool(parser, "skip_c", False, "the agent also sees the reservoir's input (obs, action, reward)")
    add_bool(parser, "fixed_iss", fixed_iss_default, "input scaling fixed at 1.0 instead of evolved")
    add_bool(parser, "zero_action", False, "feed the reservoir a zero action, as the published code did")
    for name, (low, high) in DEFAULT_BOUNDS.items():
        add(f"--min_{name}", type=positive_float, default=low, help=f"lower bound of {name} (log-uniform)")
        add(f"--max_{name}", type=positive_float, default=high, help=f"upper bound of {name}")


def search_space(args: argparse.Namespace, nb_res: int, suffixed: bool) -> SearchSpace:
    bounds = {name: (getattr(args, f"min_{name}"), getattr(args, f"max_{name}")) for name in DEFAULT_BOUNDS}
    with explained("bounds"):
        return SearchSpace(bounds, args.units, nb_res, args.fixed_iss, suffixed)


def search_settings(args: argparse.Namespace, space: SearchSpace, **extra) -> dict:
    """What a study records, and what a later process must not change."""
    return {"units": args.units, "training_steps": args.training_steps, "nb_res": space.nb_res,
            "skip_c": args.skip_c, "fixed_iss": args.fixed_iss, "zero_action": args.zero_action,
            "nb_seeds": args.nb_seeds, "ep_eval": args.ep_eval,
            "bounds": {name: list(bounds) for name, bounds in space.bounds.items()}, **extra}


def evolve_res_parser(prog: str) -> Parser:
    parser = new_parser(prog, "Evolve the hyperparameters of one reservoir whose state a PPO agent learns from.")
    parser.add_argument("--h_test", type=study_part, required=True,
                        help="name of the experiment (part of the study's name)")
    parser.add_argument("--env_id", required=True, help="Gymnasium id, or module:Id for a custom environment")
    add_bool(parser, "del_obs", False, "remove the velocities from the observation (DeletedVelocityWrapper)")
    add_search_flags(parser, None, True)
    return parser


def evolve_multi_res_parser(prog: str) -> Parser:
    parser = new_parser(prog, "Evolve the hyperparameters of several reservoirs read by one PPO agent.")
    parser.add_argument("--h_test", type=study_part, default="Multi_RES",
                        help="name of the experiment (part of the study's name)")
    parser.add_argument("--env_id", required=True, help="Gymnasium id, or module:Id for a custom environment")
    parser.add_argument("--nb_res", type=positive_int, default=3, help="number of reservoirs")
    add_bool(parser, "del_obs", False, "remove the velocities from the observation (DeletedVelocityWrapper)")
    add_search_flags(parser, "Random", False)
    return parser


def evolve_generalization_parser(prog: str) -> Parser:
    parser = new_parser(prog, "Evolve reservoirs on several environments (mean normalised score), to test them "
                              "on an unseen one with test_generalization.py.")
    parser.add_argument("--h_test", type=study_part, required=True,
                        help="name of the experiment (part of the study's name)")
    parser.add_argument("--env_type", required=True,
                        help=f"preset ({', '.join(ENV_TYPES)}) or ids separated by commas among "
                             f"{', '.join(TARGET_RETURN)}")
    parser.add_argument("--nb_res", type=positive_int, required=True, help="number of reservoirs")
    parser.add_argument("--random_baseline", choices=tuple(experiments.RANDOM_BASELINES), default="episodic",
                        help="R_random: a random agent's episodic return, or the original's per-step reward")
    add_search_flags(parser, None, False)
    return parser


def resolve_env(env_id: str) -> str:
    return envs.resolve_env_id(env_id, notify=log)


def check_front_end(loop: InnerLoop, env_ids: tuple[str, ...], space: SearchSpace) -> None:
    """Build each environment with a reservoir once, so that bad input fails before any trial."""
    probe = [ReservoirSettings(space.units, 1.0, 1.0)] * space.nb_res
    for env_id in env_ids:
        loop.front_end.wrap(make_base_env(env_id, loop.del_obs), probe, 0).close()


def evolve(prog: str, args: argparse.Namespace, name: str, env_ids: tuple[str, ...], space: SearchSpace,
           loop: InnerLoop, baseline: str | None, settings: dict, test_command: str) -> int:
    """Run ``--nb_trials`` trials of study ``name``; the shared body of the three evolve scripts."""
    with explained("cannot make the environment"):
        check_front_end(loop, env_ids, space)
        study = open_study(name, settings, args.sampler, args.sampler_seed)
    log(f"study {name} | journal {journal_path(name)} | {len(study.trials)} trials so far | sampler {args.sampler} "
        f"| {', '.join(env_ids)}")

    def objective(trial: optuna.Trial) -> float:
        start = time.perf_counter()
        reservoirs = space.sample(trial)
        log(f"trial {trial.number} | " + " ".join(f"{key} {value:.4g}" for key, value in trial.params.items()))
        try:
            fitness = loop.fitness(env_ids, reservoirs, baseline, log)
        except NoFinishedEpisode as error:
            log(f"trial {trial.number} pruned: {error}")
            raise optuna.TrialPruned(str(error)) from None
        log(f"trial {trial.number} | fitness {fitness:.4f} | {time.perf_counter() - start:.1f} s")
        return fitness

    try:
        study.optimize(objective, n_trials=args.nb_trials)
    except KeyboardInterrupt:
        print(f"{prog}: stopped; the finished trials are in {journal_path(name)}, and the same command continues "
              "the study", file=sys.stderr)
        return 130
    finished = [trial for trial in study.trials if trial.state == optuna.trial.TrialState.COMPLETE]
    if finished:
        best = study.best_trial
        log(f"best of {len(finished)} finished trials: trial {best.number}, fitness {best.value:.4f}, "
            + " ".join(f"{key} {value:.4g}" for key, value in best.params.items()))
        log(f"test it with: {test_command}")
    return 0


def evolve_one_env(prog: str, args: argparse.Namespace, several: bool) -> int:
    """evolve_res.py (one reservoir) and evolve_multi_res.py (``--nb_res``, parameters lr_1, sr_1, ...)."""
    env_id = resolve_env(args.env_id)
    nb_res = args.nb_res if several else 1
    space = search_space(args, nb_res, suffixed=several)
    loop = InnerLoop(PPOFrontEnd(args.skip_c, args.zero_action), args.training_steps, args.nb_seeds, args.ep_eval,
                     args.del_obs)
    if several:
        name = study_name(args.env_id, nb_res, args.h_test, training_steps=args.training_steps)
        test = command("scripts/test_multi_res.py", "--env_id", args.env_id, "--h_test", args.h_test, "--nb_res",
                       nb_res, "--HP_training_steps", args.training_steps)
    else:
        name = study_name(args.env_id, args.h_test, training_steps=args.training_steps)
        test = command("scripts/test.py", "--env_id", args.env_id, "--h_test", args.h_test, "--HP_training_steps",
                       args.training_steps)
    return evolve(prog, args, name, (env_id,), space, loop, None,
                  search_settings(args, space, env=args.env_id, del_obs=args.del_obs), test)


def evolve_res(prog: str, args: argparse.Namespace) -> int:
    return evolve_one_env(prog, args, several=False)


def evolve_multi_res(prog: str, args: argparse.Namespace) -> int:
    return evolve_one_env(prog, args, several=True)


def evolve_generalization(prog: str, args: argparse.Namespace) -> int:
    with explained("--env_type"):
        env_ids = tuple(resolve_env(env_id) for env_id in env_ids_for(args.env_type))
        experiments.check_normalisable(env_ids, args.random_baseline)
    space = search_space(args, args.nb_res, suffixed=True)
    loop = InnerLoop(PPOFrontEnd(args.skip_c, args.zero_action), args.training_steps, args.nb_seeds, args.ep_eval)
    name = study_name(args.env_type, args.nb_res, args.h_test, training_steps=args.training_steps)
    test = command("scripts/test_generalization.py", "--env_id", "<an unseen id>", "--HP_env_type", args.env_type,
                   "--h_test", args.h_test, "--nb_res", args.nb_res, "--HP_training_steps", args.training_steps)
    settings = search_settings(args, space, env=args.env_type, random_baseline=args.random_baseline)
    return evolve(prog, args, name, env_ids, space, loop, args.random_baseline, settings, test)


# --- test -----------------------------------------------------------------------------------------


def slurm_seed() -> int:
    """The original's seed for a test run: the SLURM array task id, or 0."""
    text = os.environ.get(SLURM_SEED) or "0"
    try:
        return seed_value(text)
    except (ValueError, argparse.ArgumentTypeError) as error:
        raise UserError(f"{SLURM_SEED}={text!r}: {error}; unset it or give --seed") from None


def add_test_flags(parser: Parser) -> None:
    """Flags of all three test scripts; None defaults are taken from the study, else the original's."""
    add = parser.add_argument
    add("--env_id", required=True, help="environment to train on (Gymnasium id, or module:Id)")
    add("--h_test", type=study_part, required=True, help="the --h_test of the evolution")
    add("--HP_training_steps", type=positive_int, default=300000, help="the --training_steps of the evolution")
    add_training_steps(parser, default=10000000, help="PPO training steps of each model")
    add("--seed", type=seed_value, default=None,
        help=f"seed of the reservoirs and PPO (default: ${SLURM_SEED}, else 0)")
    add("--units", type=positive_int, default=None, help="neurons per reservoir (default: the study's, else 100)")
    add_bool(parser, "skip_c", None, "as in the evolution (default: the study's, else False)")
    add_bool(parser, "zero_action", None, "as in the evolution (default: the study's, else False)")
    add("--overwrite", action="store_true",
        help="replace the models and summary of an earlier test with the same name (default: refuse)")


def test_parser(prog: str) -> Parser:
    parser = new_parser(prog, "Train PPO with and without the best evolved reservoir (study of evolve_res.py).")
    add_test_flags(parser)
    add_bool(parser, "del_obs", None, "as in the evolution (default: the study's, else False)")
    add_bool(parser, "fixed_iss", None, "as in the evolution (default: the study's, else True)")
    return parser


def test_multi_res_parser(prog: str) -> Parser:
    parser = new_parser(prog, "Train PPO with and without the best evolved reservoirs (evolve_multi_res.py).")
    add_test_flags(parser)
    parser.add_argument("--nb_res", type=positive_int, required=True, help="the --nb_res of the evolution")
    add_bool(parser, "del_obs", None, "as in the evolution (default: the study's, else False)")
    add_bool(parser, "fixed_iss", None, "as in the evolution (default: the study's, else False)")
    return parser


def test_generalization_parser(prog: str) -> Parser:
    parser = new_parser(prog, "Train PPO with and without the reservoirs evolved on other environments "
                              "(evolve_generalization.py) on --env_id.")
    add_test_flags(parser)
    parser.add_argument("--HP_env_type", required=True, help="the --env_type of the evolution")
    parser.add_argument("--nb_res", type=positive_int, required=True, help="the --nb_res of the evolution")
    add_bool(parser, "fixed_iss", None, "as in the evolution (default: the study's, else False)")
    return parser


def chosen(args: argparse.Namespace, recorded: dict, key: str, default):
    """A flag given on the command line, else the study's recorded value, else the original's default."""
    value = getattr(args, key, None)
    return value if value is not None else recorded.get(key, default)


@dataclass(frozen=True)
class TestSetup:
    """What a test script rebuilds from the study: its best reservoirs and how the agent sees them."""

    study: optuna.Study
    reservoirs: list[ReservoirSettings]
    front_end: PPOFrontEnd
    del_obs: bool
    ep_eval: int


def load_test_setup(args: argparse.Namespace, name: str, evolve_hint: str, env_id: str, several: bool, nb_res: int,
                    fixed_iss_default: bool, seed: int) -> TestSetup:
    with explained(f"cannot load study {name}"):
        study = load_evolved(name, evolve_hint)
        recorded = recorded_settings(study)
        units, fixed_iss = chosen(args, recorded, "units", 100), chosen(args, recorded, "fixed_iss", fixed_iss_default)
        del_obs = chosen(args, recorded, "del_obs", False)
        front_end = PPOFrontEnd(chosen(args, recorded, "skip_c", False),
                                      chosen(args, recorded, "zero_action", False))
        reservoirs = reservoirs_from_params(study.best_params, units, nb_res, fixed_iss, suffixed=several)
        front_end.wrap(make_base_env(env_id, del_obs), reservoirs, seed).close()
    best = study.best_trial
    log(f"study {name}: best trial {best.number}, fitness {best.value:.4f} | reservoirs "
        + "; ".join(f"units {one.units} lr {one.leak_rate:.4g} sr {one.spectral_radius:.4g} iss {one.input_scaling:.4g}"
                    for one in reservoirs) + f" | skip_c {front_end.skip_c} | zero_action {front_end.zero_action}")
    return TestSetup(study, reservoirs, front_end, del_obs, recorded.get("ep_eval", 10))


def train_test_model(setup: TestSetup, env_id: str, seed: int, training_steps: int, model_name: str,
                     learning_rate: float, logdir: Path, model_path: Path) -> dict:
    """One model of a test script: PPO, with the study's reservoirs if its name starts with RES; saved."""
    start = time.perf_counter()
    env = make_base_env(env_id, setup.del_obs)
    if model_name.startswith("RES"):
        env = setup.front_end.wrap(env, setup.reservoirs, seed)
    env = RewardsSavingWrapper(env)
    buffer = io.BytesIO()  # SB3 writes its zip to the buffer; the file is replaced atomically
    train_ppo(env, seed, training_steps, learning_rate, str(logdir), model_path.stem).save(buffer)
    atomic_write_bytes(model_path, buffer.getvalue())
    env.close()
    episodes = len(env.episode_returns)
    mean_return = env.mean_reward(setup.ep_eval) if episodes else None
    score = (f"mean return of the last {min(setup.ep_eval, episodes)} of {episodes} episodes {mean_return:.2f}"
             if episodes else "no episode finished")
    log(f"{model_name}: {score} ({time.perf_counter() - start:.1f} s) | {model_path}")
    return {"learning_rate": learning_rate, "episodes": episodes, f"mean_return_last_{setup.ep_eval}": mean_return,
            "file": model_path.name}


def test_models(args: argparse.Namespace, name: str, evolve_hint: str, several: bool, nb_res: int,
                fixed_iss_default: bool, models: dict[str, float]) -> int:
    """Train each of ``models`` on ``--env_id``; the shared body of the three test scripts."""
    seed = args.seed if args.seed is not None else slurm_seed()
    env_id = resolve_env(args.env_id)
    setup = load_test_setup(args, name, evolve_hint, env_id, several, nb_res, fixed_iss_default, seed)
    folder = safe_file_name(f"{args.env_id}_{args.h_test}")
    logdir, models_dir = Path("logs") / folder, Path("models") / folder
    steps_label = f"{args.training_steps // 1000}k_steps_seed_{seed}"
    chosen_models = MODELS_DEL_OBS if setup.del_obs else models
    summary_path = models_dir / f"test_{steps_label}.json"
    check_test_outputs([models_dir / f"{name}_{steps_label}.zip" for name in chosen_models] + [summary_path],
                       args.overwrite)
    with explained("cannot create the output folders"):
        logdir.mkdir(parents=True, exist_ok=True)
        models_dir.mkdir(parents=True, exist_ok=True)
    results = {}
    for model_name, learning_rate in chosen_models.items():
        run_name = f"{model_name}_{steps_label}"
        results[model_name] = train_test_model(setup, env_id, seed, args.training_steps, model_name, learning_rate,
                                               logdir, models_dir / f"{run_name}.zip")
    best = setup.study.best_trial
    write_json(summary_path, {
        "study": name, "journal": str(journal_path(name)), "trial": best.number, "fitness": best.value,
        "params": best.params, "env_id": env_id, "seed": seed, "training_steps": args.training_steps,
        "del_obs": setup.del_obs, "skip_c": setup.front_end.skip_c, "zero_action": setup.front_end.zero_action,
        "reservoirs": [asdict(one) for one in setup.reservoirs], "models": results})
    log(f"TensorBoard logs: {logdir} | summary: {summary_path}")
    return 0


def check_test_outputs(paths: list[Path], overwrite: bool) -> None:
    """Refuse, before any training, to replace an earlier test's models or summary unless --overwrite."""
    earlier = [path for path in paths if path.exists()]
    if earlier and not overwrite:
        raise UserError(f"{earlier[0]} is from an earlier test ({len(earlier)} of its {len(paths)} files exist); give "
                        "--overwrite to replace them, or another --seed, --training_steps or --h_test")
    for path in earlier:
        if not path.is_file():
            raise UserError(f"{path} exists and is not a file; move it away")


def test(prog: str, args: argparse.Namespace) -> int:
    name = study_name(args.env_id, args.h_test, training_steps=args.HP_training_steps)
    hint = command("scripts/evolve_res.py", "--env_id", args.env_id, "--h_test", args.h_test, "--training_steps",
                   args.HP_training_steps, "--nb_trials", "N", "--sampler", "Cmaes")
    return test_models(args, name, hint, False, 1, True, MODELS_TEST)


def test_multi_res(prog: str, args: argparse.Namespace) -> int:
    name = study_name(args.env_id, args.nb_res, args.h_test, training_steps=args.HP_training_steps)
    hint = command("scripts/evolve_multi_res.py", "--env_id", args.env_id, "--h_test", args.h_test, "--nb_res",
                   args.nb_res, "--training_steps", args.HP_training_steps, "--nb_trials", "N")
    return test_models(args, name, hint, True, args.nb_res, False, MODELS_DEL_OBS)  # always the four models


def test_generalization(prog: str, args: argparse.Namespace) -> int:
    name = study_name(args.HP_env_type, args.nb_res, args.h_test, training_steps=args.HP_training_steps)
    hint = command("scripts/evolve_generalization.py", "--env_type", args.HP_env_type, "--h_test", args.h_test,
                   "--nb_res", args.nb_res, "--training_steps", args.HP_training_steps, "--nb_trials", "N",
                   "--sampler", "Cmaes")
    return test_models(args, name, hint, True, args.nb_res, False, MODELS_GENERALIZATION)


# --- the random agent -----------------------------------------------------------------------------


def random_scores_parser(prog: str) -> Parser:
    parser = new_parser(prog, "Mean return of a uniformly random agent (the R_random of the normalised score).")
    parser.add_argument("--env_ids", default=",".join(experiments.RANDOM_SCORE_ENV_IDS),
                        help="ids separated by commas (the original's list but Pusher-v4, which needs mujoco < 3)")
    parser.add_argument("--episodes", type=positive_int, default=100, help="episodes per environment (seeds 0, 1, ...)")
    add_bool(parser, "per_step", False, "the mean reward per step, as the original measured it")
    parser.add_argument("--output", default="logs_random_agents.txt", help="also write the scores to this file")
    return parser


def get_random_scores(prog: str, args: argparse.Namespace) -> int:
    with explained("--env_ids"):
        env_ids = [resolve_env(env_id.strip()) for env_id in args.env_ids.split(",") if env_id.strip()]
    if not env_ids:
        raise UserError(f"--env_ids {args.env_ids!r} names no environment; give ids separated by commas")
    output = check_output("--output", args.output, (".txt",))  # never a file of a run, a journal or a folder
    lines = []
    for env_id in env_ids:
        with explained(f"cannot make {env_id}"):
            score = experiments.random_agent_return(env_id, args.episodes, args.per_step)
        lines.append(f"env: {env_id} score: {score}")
        log(lines[-1])
    with explained(f"cannot write {args.output}"):
        atomic_write_text(output, "\n".join(lines) + "\n")
    return 0


# --- entry points ---------------------------------------------------------------------------------

COMMANDS = {
    "evolve_res": (evolve_res_parser, evolve_res),
    "evolve_multi_res": (evolve_multi_res_parser, evolve_multi_res),
    "evolve_generalization": (evolve_generalization_parser, evolve_generalization),
    "test": (test_parser, test),
    "test_multi_res": (test_multi_res_parser, test_multi_res),
    "test_generalization": (test_generalization_parser, test_generalization),
    "get_random_scores": (random_scores_parser, get_random_scores),
}


def main(script: str, argv: list[str] | None = None) -> int:
    """Parse, run, and turn every error a user can cause into one line and exit code 2."""
    build_parser, body = COMMANDS[script]
    prog = f"{script}.py"
    args = build_parser(prog).parse_args(sys.argv[1:] if argv is None else argv)
    optuna.logging.set_verbosity(optuna.logging.ERROR)
    torch.set_num_threads(1)  # one core per process: PPO's small MLP gains nothing from more; share a study instead
    try:
        return body(prog, args)
    except USER_ERRORS as error:
        print(f"{prog}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C, or SIGTERM (reservoirs.launch.run_script), outside a study's trials
        print(f"{prog}: stopped", file=sys.stderr)
        return 130
