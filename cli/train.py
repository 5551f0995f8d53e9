"""``train_static.py`` and ``train_hebb.py``: their flags, the run's configuration, start and resume.

The flags keep the original names and defaults (upstream spec §1); new ones use the same snake_case
style. A new run's settings come from the flags (over an experiment file given with ``--config``);
a resumed run's from its config.json, where only what changes no result may be given again.
"""

from __future__ import annotations

import argparse
import os
import secrets
import sys
import typing
from pathlib import Path

import envs
from cli.config import SECTIONS, TrainConfig, check_type, field_names, read_toml
from cli.errors import USER_ERRORS, Parser, UserError, explained, say
from cli.flags import RESERVOIR_FLAGS, fraction, non_empty, positive_float, positive_int, seed_value, threads_value
from cli.hints import TRAIN_SCRIPTS, evaluate_hint, resume_hint
from envs import EnvSettings, ProblemSpec
from es.backends import BACKENDS
from es.loop import NonFiniteUpdate, Status, Trainer
from es.optimizers import OPTIMIZERS
from es.runfolder import RunFolder, SaveError
from es.settings import RESUMABLE, STRATEGY_REQUIRES, ESSettings, RunSettings
from es.shaping import SHAPINGS
from es.strategies import PGPE_OPTIMIZERS, STRATEGIES
from policies import PolicySettings
from report import tensorboard
from report.log import FitnessPlot, GenerationLog
from report.progress import display_for

EXIT_CODES = {Status.DONE: 0, Status.FAILED: 1, Status.INTERRUPTED: 130}


def training_parser(prog: str, description: str, folder: str) -> Parser:
    parser = Parser(prog=prog, description=description, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add = parser.add_argument
    add("--environment", default="CarRacing-v0", metavar="ID",
        help="Gymnasium, pyBullet or MuJoCo id, or module:Id for a custom environment; several ids "
             "separated by commas are trained together (fitness = mean over them)")
    add("--popsize", type=int, default=200, metavar="N", help="population size (even: mirrored pairs)")
    add("--print_every", type=positive_int, default=1, metavar="K", help="save files every K generations")
    add("--lr", type=positive_float, default=0.2, help="ES learning rate")
    add("--decay", type=fraction, default=0.995, help="learning-rate decay per generation, in (0, 1]")
    add("--sigma", type=positive_float, default=0.1, help="initial noise standard deviation")
    add("--generations", type=positive_int, default=300, metavar="G",
        help="number of generations (with --resume: the total, counting those already run)")
    add("--folder", type=non_empty, default=folder, metavar="DIR", help="where run folders are created")
    add("--threads", type=threads_value, default=-1, metavar="W",
        help="worker processes; -1 = all cores, 1 = run in this process (0 and other negative values too, as "
             "the original)")
    add("--seed", type=seed_value, default=None, help="seed of the run (default: a random one, printed and saved)")
    add("--episodes", type=positive_int, default=1, metavar="E",
        help="episodes per fitness evaluation (the fitness is their mean)")
    add("--resume", type=non_empty, default=None, metavar="RUN_DIR", help="continue the run saved in RUN_DIR")
    add("--config", type=non_empty, default=None, metavar="FILE",
        help="an experiment file (TOML, as experiments/paper/*.toml) giving the settings; flags given too "
             "override it")
    add("--backend", choices=BACKENDS, default="process",
        help="parallel backend for --threads > 1: a process pool on this machine, or Ray (one machine "
             "or a cluster; pip install -r requirements-ray.txt)")
    add("--ray_address", default=None, metavar="ADDRESS",
        help="with --backend ray: 'auto' joins the cluster `ray start` runs on this machine, HOST:PORT "
             "another one; default: start a local Ray with --threads CPUs")
    add_modern_options(parser)
    add_strategy_options(parser)
    return parser


def add_modern_options(parser: Parser) -> None:
    """Options beyond the 2020 algorithm (OpenAI's es-starter, pytorch-es); their defaults are the
    original's. Values are checked by the settings (``es.settings``), in one line naming the flag."""
    group = parser.add_argument_group("beyond the original algorithm (defaults: the original)")
    add = group.add_argument
    add("--shaping", choices=list(SHAPINGS), default=ESSettings.shaping,
        help="fitness shaping: rank_std (the original: centered ranks, standardised), rank (OpenAI's centered "
             "ranks), none (the fitness, standardised), nes (pytorch-es's NES utilities)")
    add("--optimizer", choices=list(OPTIMIZERS), default=ESSettings.optimizer,
        help="sgd (the original), adam or momentum (OpenAI's; gradient sum F*eps / N); --lr is the step size")
    add("--useAdam", dest="optimizer", action="store_const", const="adam",
        help="pytorch-es's flag: the same as --optimizer adam")
    add("--beta1", type=float, default=ESSettings.beta1, help="with --optimizer adam, in [0, 1)")
    add("--beta2", type=float, default=ESSettings.beta2, help="with --optimizer adam, in [0, 1)")
    add("--momentum", type=float, default=ESSettings.momentum, help="with --optimizer momentum, in [0, 1)")
    add("--l2coeff", type=float, default=ESSettings.l2coeff, metavar="C",
        help="weight decay in the gradient, g <- g - C * theta (OpenAI's l2coeff)")
    add("--fitness_l2", type=float, default=ESSettings.fitness_l2, metavar="C",
        help="the original's L2 penalty in the fitness: return - C * mean(theta_m^2)")
    add("--obs_norm", action="store_true",
        help="normalise observations by running statistics (OpenAI's RunningStat); not for pixels")
    add("--obs_clip", type=float, default=None, metavar="C",
        help="with --obs_norm: clip normalised observations to +-C (OpenAI: 5); default no clip")
    add("--obs_norm_prob", type=float, default=ESSettings.obs_norm_prob, metavar="P",
        help="with --obs_norm: the fraction of mirrored pairs whose observations update the statistics, in (0, 1]")
    add("--eval_every", type=int, default=None, metavar="G",
        help="every G generations the centre also runs --eval_episodes episodes on seeds of their own; "
             "their mean picks best.dat")
    add("--eval_episodes", type=int, default=ESSettings.eval_episodes, metavar="K",
        help="with --eval_every: the centre's evaluation episodes")
    add("--max_episode_steps", type=int, default=None, metavar="N",
        help="end an episode (as truncated) after N policy steps; default the environment's own limit")
    add("--variable_ep_len", action="store_true",
        help="pytorch-es's adaptive episode length: each generation's episodes end after twice the mean length "
             "of the last generation's perturbed episodes")
    add("--tensorboard", action="store_true",
        help=f"also write every metrics column as TensorBoard scalars in <run>/tensorboard ({tensorboard.INSTALL_HINT})")


def optional_float(text: str) -> float | None:
    return None if text == "none" else float(text)


def add_strategy_options(parser: Parser) -> None:
    """The strategy (es.strategies) and the settings of each, with ESSettings' defaults; which flag
    applies to which strategy is es.settings.STRATEGY_REQUIRES (refused otherwise, see NEEDS)."""
    group = parser.add_argument_group("strategy (default: the original's OpenAI-ES)")
    add = group.add_argument
    add("--strategy", choices=list(STRATEGIES), default=ESSettings.strategy,
        help="openai (Salimans et al. 2017, the original), pgpe (Sehnke et al. 2010, with ClipUp), snes (separable "
             "NES), cma_es and sep_cma_es (the cmaes library: pip install -r requirements-strategies.txt), ars "
             "(Mania et al. 2018; V2 with --obs_norm --obs_norm_prob 1); docs: es/strategies/")
    add("--pgpe_optimizer", choices=list(PGPE_OPTIMIZERS), default=ESSettings.pgpe_optimizer,
        help="pgpe: how the centre steps (ClipUp, Toklu et al. 2020; Adam; plain gradient ascent)")
    add("--pgpe_lr", type=float, default=ESSettings.pgpe_lr, help="pgpe: the centre's step size; default "
        "--clipup_max_speed / 2")
    add("--clipup_max_speed", type=float, default=ESSettings.clipup_max_speed, help="pgpe: ClipUp's maximum speed")
    add("--clipup_momentum", type=float, default=ESSettings.clipup_momentum, help="pgpe: ClipUp's momentum")
    add("--pgpe_sigma_lr", type=float, default=ESSettings.pgpe_sigma_lr, help="pgpe: sigma's learning rate")
    add("--pgpe_max_sigma_change", type=optional_float, default=ESSettings.pgpe_max_sigma_change, metavar="C",
        help="pgpe: each sigma changes by at most this fraction per generation, in (0, 1]; none: no limit")
    add("--snes_lr", type=float, default=ESSettings.snes_lr, help="snes: the centre's learning rate")
    add("--snes_sigma_lr", type=float, default=ESSettings.snes_sigma_lr,
        help="snes: sigma's learning rate; default (3 + ln d) / (5 sqrt d), d the parameters")
    add("--ars_lr", type=float, default=ESSettings.ars_lr, help="ars: the step size alpha")
    add("--ars_top", type=int, default=ESSettings.ars_top, metavar="B",
        help="ars: the b best directions make the step (V1-t, V2-t); default all --popsize / 2")


def required_values(values: dict) -> tuple[str, object]:
    """NEEDS' entry for a STRATEGY_REQUIRES rule: the flags it needs and whether ``values`` has them."""
    return (" ".join(f"--{name} {value}" for name, value in values.items()),
            lambda given: all(given[name] == value for name, value in values.items()))


# flag -> (what it needs, whether the values have it): given alone, the flag would silently do nothing
NEEDS = {
    **{name: required_values(values) for name, values in STRATEGY_REQUIRES.items()},
    "beta1": ("--optimizer adam", lambda values: values["optimizer"] == "adam"),
    "beta2": ("--optimizer adam", lambda values: values["optimizer"] == "adam"),
    "momentum": ("--optimizer momentum", lambda values: values["optimizer"] == "momentum"),
    "obs_clip": ("--obs_norm", lambda values: values["obs_norm"]),
    "obs_norm_prob": ("--obs_norm", lambda values: values["obs_norm"]),
    "eval_episodes": ("--eval_every", lambda values: values["eval_every"] is not None),
    **{name: ("--reservoir", lambda values: values["reservoir"]) for name in (*RESERVOIR_FLAGS, "reservoir_evolve")},
}


def check_needs(values: dict, given: set[str]) -> None:
    for name in sorted(given & set(NEEDS)):
        needed, present = NEEDS[name]
        if not present(values):
            raise UserError(f"--{name} has an effect only with {needed}; add {needed} or leave --{name} out")


ALIASES = {"useAdam": "optimizer"}  # another program's flag -> the setting it gives


def given_flags(argv: list[str]) -> set[str]:
    """The settings the command line gives (``--lr 0.1`` and ``--lr=0.1`` alike; aliases by their setting)."""
    names = {item[2:].split("=")[0] for item in argv if item.startswith("--")}
    return {ALIASES.get(name, name) for name in names}


def resolve_environments(text: str) -> tuple[str, ...]:
    ids = [part.strip() for part in text.split(",") if part.strip()]
    if not ids:
        raise UserError("--environment is empty; give an id such as CartPole-v1")
    return tuple(envs.resolve_env_id(env_id) for env_id in ids)


def population_size(requested: int) -> int:
    if requested < 2:
        raise UserError(f"--popsize must be at least 2 (one mirrored pair), got {requested}")
    if requested % 2:
        say(f"note: --popsize {requested} is odd; mirrored sampling needs pairs, using {requested + 1}")
        return requested + 1
    return requested


TASK_BYTES = 160  # memory per episode of a generation: its task record, result, queue entry and shaping


def check_population_fits(es: ESSettings, n_envs: int) -> None:
    """Refuse, before anything is written, a population whose generation could not be held in memory."""
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    per_member = TASK_BYTES * n_envs * es.episodes
    needed = (es.popsize + 1) * per_member
    if needed > memory // 2:
        largest = max(2, (memory // 2 // per_member - 1) // 2 * 2)
        raise UserError(f"--popsize {es.popsize} needs about {needed / 2**30:.1f} GiB for one generation's "
                        f"{(es.popsize + 1) * n_envs * es.episodes} episodes, more than half of this machine's "
                        f"{memory / 2**30:.1f} GiB; give --popsize {largest} or less")


def config_from_args(kind: str, args: argparse.Namespace, argv: list[str]) -> TrainConfig:
    """The flags' values, over those of the experiment file ``--config`` names, if any."""
    values = {name: value for name, value in vars(args).items() if name not in ("resume", "config")}
    given = given_flags(argv)
    if args.config is not None:
        from_file = {name: value for name, value in experiment_values(args.config, kind).items() if name not in given}
        values.update(from_file)
        given |= set(from_file)
    if values["ray_address"] is not None and values["backend"] != "ray":
        raise UserError(f"--ray_address {values['ray_address']} needs --backend ray")
    check_needs(values, given)
    seed = values["seed"] if values["seed"] is not None else secrets.randbelow(2**31)
    try:
        es = ESSettings(**{**pick(ESSettings, values), "popsize": population_size(values["popsize"])})
        policy = PolicySettings(**{**pick(PolicySettings, values), "kind": kind}).seeded(seed)
        run = RunSettings(**{**pick(RunSettings, values), "seed": seed})
        env_values = {**pick(EnvSettings, values), "env_ids": (), "recipe_modules": ()}
        EnvSettings(**env_values)  # checked before any environment is resolved
    except (ValueError, TypeError) as error:  # a value out of range or of the wrong type, from a flag or a file
        raise UserError(str(error)) from None
    env = EnvSettings(**{**env_values, "env_ids": resolve_environments(values["environment"]),
                         "recipe_modules": envs.custom_recipe_modules()})
    check_population_fits(es, len(env.env_ids))
    return TrainConfig(es=es, policy=policy, env=env, run=run)


def experiment_values(path: str, kind: str) -> dict:
    """The settings an experiment file gives, flat (``{"lr": 0.2, ...}``); checked against the script."""
    try:
        sections = read_toml(path)
    except (OSError, ValueError) as error:
        raise UserError(f"--config {path}: {error}") from None
    tables = [f"[{name}]" for name, section in sections.items() if name in SECTIONS and not isinstance(section, dict)]
    if tables:
        raise UserError(f"--config {path}: {', '.join(tables)} must be a table of settings")
    unknown = [f"[{name}]" for name in sections if name not in SECTIONS and name != "evaluation"]
    unknown += [f"{name}.{key}" for name, section in sections.items() if name in SECTIONS
                for key in section if key not in field_names(SECTIONS[name])]
    if unknown:
        raise UserError(f"--config {path}: unknown settings {', '.join(unknown)}")
    if sections.get("policy", {}).get("kind", kind) != kind:
        found = sections["policy"]["kind"]
        raise UserError(f"--config {path} is a {found} experiment; run it with {TRAIN_SCRIPTS.get(found, 'its script')}")
    for name, settings in SECTIONS.items():
        hints = typing.get_type_hints(settings)
        for key, value in sections.get(name, {}).items():
            try:
                check_type(key, value, hints[key])
            except ValueError as error:
                raise UserError(f"--config {path}: {name}.{error}") from None
    return {key: value for name in SECTIONS for key, value in sections.get(name, {}).items() if key != "env_ids"}


def pick(settings: type, values: dict) -> dict:
    names = field_names(settings)
    return {name: value for name, value in values.items() if name in names}


def config_for_resume(kind: str, args: argparse.Namespace, argv: list[str]) -> tuple[TrainConfig, RunFolder]:
    folder = RunFolder.existing(args.resume)
    try:
        config = TrainConfig.from_dict(folder.read_config())
    except (ValueError, TypeError) as error:
        raise UserError(f"--resume {folder.path}: unreadable config.json ({error})") from None
    if config.policy.kind != kind:
        raise UserError(f"--resume {folder.path}: this is a {config.policy.kind} run; resume it with "
                        f"{TRAIN_SCRIPTS[config.policy.kind]}")
    given = given_flags(argv)
    check_resume_flags(config, args, given)
    return config.with_values(**{name: getattr(args, name) for name in RESUMABLE if name in given}), folder


def check_resume_flags(config: TrainConfig, args: argparse.Namespace, given: set[str]) -> None:
    """A flag that defines the run, given again on resume, must say what the run already uses."""
    if "config" in given:
        raise UserError("--config cannot be combined with --resume: the run's settings are in its config.json")
    differing = []
    for name in sorted(given - set(RESUMABLE) - {"resume"}):
        value, stored = getattr(args, name), config.value(name)
        if name == "popsize":
            value = value + value % 2  # as a new run would round it
        if value != stored:
            differing.append(f"--{name} {value} (the run has {stored})")
    if differing:
        raise UserError(f"--resume {args.resume}: {', '.join(differing)}; a resumed run keeps its settings (only "
                        f"{', '.join('--' + name for name in RESUMABLE)} may change): start a new run instead")


def check_tensorboard(config: TrainConfig) -> None:
    if config.run.tensorboard and not tensorboard.available():
        raise UserError(f"--tensorboard needs the tensorboard package, which is not installed; install it with: "
                        f"{tensorboard.INSTALL_HINT}")


def check_writable(folder: str) -> None:
    """Refuse, before anything is built or created, a --folder that could not hold a run folder."""
    path = Path(folder)
    existing = next((parent for parent in (path, *path.parents) if parent.exists()), Path("."))
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"--folder {folder}: {existing} is not a writable folder")


def versions() -> dict:
    import importlib.metadata as metadata

    found = {"python": sys.version.split()[0]}
    for package in ("numpy", "torch", "gymnasium", "mujoco", "pybullet", "pybullet-envs-gymnasium",
                    "box2d", "numba", "ray", "ale-py"):
        try:
            found[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            pass
    return found


def write_config(trainer: Trainer, config: TrainConfig, problem, command: list[str]) -> None:
    """config.json: the settings (with the noise size the run uses), then what they led to; a
    resume keeps the first command and lists its own under "resumed"."""
    folder = trainer.folder
    earlier = folder.read_config() if (folder.path / "config.json").exists() else {}
    line = " ".join(command)
    data = TrainConfig(trainer.es, config.policy, config.env, config.run).to_dict()
    data.update(command=earlier.get("command", line), resumed=earlier.get("resumed", []) + ([line] if earlier else []),
                versions=versions(), num_params=trainer.policy.num_params, layout=trainer.policy.layout.describe(),
                workers=trainer.evaluator.workers, wrappers=problem.wrappers())
    folder.write_config(data)


def start(config: TrainConfig, folder: RunFolder | None) -> tuple[Trainer, object]:
    """The trainer of a new run (``folder`` None: created once the environments are made) or of a
    resumed one."""
    spec = ProblemSpec(config.env.env_ids, config.policy, config.env.recipe_modules, config.env.max_episode_steps)
    with explained("cannot make the environments"):
        problem = spec.build()
    if config.policy.obs_norm and not problem.policy.normalised_inputs:
        log("note: --obs_norm does nothing for pixel observations (the CNN sees pixels in [0, 1]); "
            "this run normalises nothing")
    created = folder is None
    try:
        if created:
            try:
                folder = RunFolder.create(config.run.folder, config.env.label, config.run.seed)
            except OSError as error:
                raise UserError(f"--folder {config.run.folder}: {error.strerror or error}") from None
        with explained("cannot start the run"):
            reporters = [GenerationLog(log), FitnessPlot()]
            if config.run.tensorboard:
                reporters.append(tensorboard.TensorBoardLog(folder.path))
            trainer = Trainer.start(config.es, config.run, problem, spec.build, config.env.env_ids, folder,
                                    config.env.label, log=log, display=display_for(sys.stdout), reporters=reporters)
    except BaseException:
        problem.close()
        if created and folder is not None and not any(folder.path.iterdir()):
            folder.path.rmdir()
        raise
    return trainer, problem


def train_main(kind: str, parser: Parser, argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    trainer = None
    try:
        if args.resume is not None:
            config, folder = config_for_resume(kind, args, argv)
        else:
            config, folder = config_from_args(kind, args, argv), None
            check_writable(config.run.folder)
        check_tensorboard(config)
        trainer, problem = start(config, folder)
        if folder is None:
            write_config(trainer, config, problem, [parser.prog, *argv])
            trainer.save_checkpoint()  # resumable from the start, even if the first generation fails
        else:
            with explained("cannot resume"):
                trainer.restore(folder.load_checkpoint())
            done = trainer.state.generation
            if done >= config.run.generations:
                log(f"{folder.path} has already run {done} generations; nothing to do "
                    f"(--generations is the total: pass more than {done} to continue)")
                return 0
            log(f"resuming {folder.path} at generation {done} of {config.run.generations}")
            write_config(trainer, config, problem, [parser.prog, *argv])  # the new settings and the command
        log(f"run folder: {trainer.folder.path} | environment: {', '.join(config.env.env_ids)} | parameters: "
            f"{trainer.policy.num_params} | workers: {trainer.evaluator.workers} | seed: {config.run.seed}")
        status = trainer.train()
        report_end(trainer, config, status)
        return EXIT_CODES[status]
    except (*USER_ERRORS, SaveError) as error:  # SaveError here: before training started
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = (f" (resume with: {resume_hint(config, trainer.folder.path)})"
                  if trainer is not None and trainer.folder.checkpoint_generation is not None else "")
        print(f"{parser.prog}: stopped at once; saved files are intact{resume}", file=sys.stderr)
        return 130
    finally:
        if trainer is not None:
            trainer.close()


def report_end(trainer: Trainer, config: TrainConfig, status: Status) -> None:
    """The run's last line: how to evaluate it, or how to resume it."""
    folder = trainer.folder
    if status is Status.DONE:
        # ``best`` only with --eval_every: otherwise it is the centre with the best single-episode
        # return, a noisy choice.
        prefix = "best" if config.es.eval_every is not None and trainer.history.best_theta is not None else "last"
        paths = {role: folder.named_path(prefix, role) for role in trainer.policy.roles}
        log(f"done; evaluate with: {evaluate_hint(config, paths)}")
    elif status is Status.INTERRUPTED:
        log(f"interrupted after generation {trainer.state.generation}; resume with: "
            f"{resume_hint(config, folder.path)}")
    elif folder.checkpoint_generation is None:
        log("stopped; no checkpoint could be written")
    elif isinstance(trainer.failure, NonFiniteUpdate):  # resuming would take the same step again
        log(f"stopped; the checkpoint holds generation {folder.checkpoint_generation}; start a new run with a "
            "lower --lr or a larger --sigma")
    else:
        log(f"stopped; the checkpoint holds generation {folder.checkpoint_generation}; "
            f"resume with: {resume_hint(config, folder.path)}")


def log(line: str) -> None:
    say(line)
