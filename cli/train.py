"""``train_static.py`` and ``train_hebb.py``: their flags, the run's configuration, start and resume.

The flags are the settings' declarations (``settings``, ``cli.flags``): the original's names and defaults
(docs/original.md, "Command lines"), and new ones in the same snake_case style. A new run's settings
come from the flags, over an experiment file given with ``--config``, over the defaults; a resumed run's
from its config.json, where only the settings declared resumable may be given other values
(``TrainConfig.overlay``).
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import sys
from dataclasses import replace
from pathlib import Path

import envs
from cli.config import SECTIONS, TRAIN_SCRIPTS, Contradiction, TrainConfig, declared, read_toml, section_values
from cli.errors import USER_ERRORS, Parser, UserError, explained, say
from cli.flags import add_settings, defaults, given, non_empty
from cli.hints import evaluate_hint, resume_hint
from cli.reporting import RunReport
from envs import ProblemSpec
from envs.modules import resume_imports
from es.backends import NonFiniteEpisode
from es.interrupts import honour_sigint
from es.loop import NonFiniteUpdate, Status, Trainer
from es.runfolder import Checkpoint, RunFolder, RunFolderError, SaveError, release_locks, settings_record
from es.settings import ESSettings
from report.machine import machine
from report.progress import display_for
from settings import contradictions, type_problem, unmet_requirement

EXIT_CODES = {Status.DONE: 0, Status.FAILED: 1, Status.INTERRUPTED: 130}


def training_parser(prog: str, description: str, kind: str, folder: str) -> Parser:
    """The flags of a training script: every setting declared for training a ``kind`` (``cli.flags``), and
    --resume and --config; ``folder``: the script's default --folder (the original's)."""
    parser = Parser(prog=prog, description=description)
    parser.add_argument("--resume", type=non_empty, default=None, metavar="RUN_DIR",
                        help="continue the run saved in RUN_DIR")
    parser.add_argument("--config", type=non_empty, default=None, metavar="FILE",
                        help="an experiment file (TOML, as experiments/paper/*.toml) giving the settings; flags "
                             "given too override it")
    parser.set_defaults(kind=kind, default_folder=folder)
    add_settings(parser, "train", kind, defaults={"folder": folder})
    return parser


def resolve_environments(text: str) -> tuple[str, ...]:
    ids = [part.strip() for part in text.split(",") if part.strip()]
    if not ids:
        raise UserError("--environment is empty; give an id such as CartPole-v1")
    return tuple(envs.resolve_env_id(env_id) for env_id in ids)


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


def config_from_args(kind: str, args: argparse.Namespace) -> TrainConfig:
    """The flags given, over those of the experiment file ``--config`` names, if any, over the defaults."""
    flags, default = given(args), defaults(kind, {"folder": args.default_folder})
    from_file = experiment_values(args.config, kind) if args.config is not None else {}
    values = {**default, **from_file, **flags}
    unmet = unmet_requirement(declared(), values, {*from_file, *flags})
    if unmet is not None:
        raise UserError(unmet)
    seed = values["seed"] if "seed" in {*from_file, *flags} else secrets.randbelow(2**31)
    values.update(seed=seed, env_ids=(), recipe_modules=())
    try:
        config = TrainConfig.from_values(values, "--config " + args.config if args.config else "flags")
    except (ValueError, TypeError) as error:  # a value out of range or of the wrong type, from a flag or a file
        raise UserError(str(error).removeprefix("flags: ")) from None
    config = replace(config, policy=config.policy.seeded(seed))
    env = replace(config.env, env_ids=resolve_environments(config.env.environment),  # checked before resolved
                  recipe_modules=envs.custom_recipe_modules())
    check_population_fits(config.es, len(env.env_ids))
    return replace(config, env=env)


def experiment_values(path: str, kind: str) -> dict:
    """The settings an experiment file gives, flat (``{"lr": 0.2, ...}``); every key checked against the
    script: known, given to this policy kind, of its setting's type."""
    source = f"--config {path}"
    try:
        sections = read_toml(path)
    except (OSError, ValueError) as error:
        raise UserError(f"{source}: {error}") from None
    unknown = [f"[{name}]" for name in sections if name not in SECTIONS and name != "evaluation"]
    if unknown:
        raise UserError(f"{source}: unknown settings {', '.join(unknown)}")
    found = sections.get("policy", {}).get("kind", kind) if isinstance(sections.get("policy"), dict) else kind
    if found != kind:
        raise UserError(f"{source} is a {found} experiment; run it with {TRAIN_SCRIPTS.get(found, 'its script')}")
    try:
        values = section_values(sections, source, kind=kind)
    except ValueError as error:
        raise UserError(str(error)) from None
    for item in declared():  # each value of the file, also those a flag overrides
        if item.name in values and (problem := type_problem(item, values[item.name])) is not None:
            raise UserError(f"{source}: {problem}")
    return values


def configured(kind: str, args: argparse.Namespace) -> tuple[TrainConfig, RunFolder | None, dict]:
    """A new run's settings (its folder: None, made once its environments are), or a resumed run's, with its
    folder, locked for this process, and its config.json as it was."""
    if args.resume is None:
        config = config_from_args(kind, args)
        check_writable(config.run.folder)
        return config, None, {}
    resumed, folder, recorded = checked_resume(kind, args)
    folder.lock()  # held until this process exits
    return resumed, folder, recorded


def checked_resume(kind: str, args: argparse.Namespace) -> tuple[TrainConfig, RunFolder, dict]:
    """The run's recorded settings, with the flags given: only the resumable ones may differ; the
    checkpoint is checked against config.json before anything is written. Its config.json too."""
    folder = RunFolder.existing(args.resume)
    recorded = folder.read_config()
    try:
        config = TrainConfig.from_dict(recorded, "config.json")
    except (ValueError, TypeError) as error:
        raise UserError(f"--resume {folder.path}: unreadable config.json ({error})") from None
    if config.policy.kind != kind:
        raise UserError(f"--resume {folder.path}: this is a {config.policy.kind} run; resume it with "
                        f"{TRAIN_SCRIPTS[config.policy.kind]}")
    if args.config is not None:
        raise UserError("--config cannot be combined with --resume: the run's settings are in its config.json")
    flags = given(args)
    resumable = [item for item in declared() if item.spec.resumable]
    try:
        resumed = config.overlay(flags, {item.name for item in resumable})
    except Contradiction as error:
        raise UserError(f"--resume {args.resume}: {error}; a resumed run keeps its settings (only "
                        f"{', '.join(item.label for item in resumable)} may change): start a new run instead") from None
    except ValueError as error:  # a resumable value out of range
        raise UserError(str(error)) from None
    unused = unmet_requirement(declared(), {item.name: resumed.value(item.name) for item in declared()}, flags)
    if unused is not None:  # --mlflow_uri for a run that logs to no MLflow: refused as a new run refuses it
        raise UserError(f"--resume {args.resume}: {unused}")
    check_history(recorded, folder.path / "config.json")
    checkpoint = folder.check_resumable(config.es, config.policy.obs_norm)  # against config.json, before any write
    # only plain module names outside the standard library are imported
    imports = resume_imports(config.env.env_ids, config.env.recipe_modules, str(folder.path / "config.json"))
    edited = edited_settings(checkpoint, config)
    if edited:
        raise UserError(f"--resume {folder.path}: config.json differs from the settings its checkpoint was written "
                        f"under: {', '.join(edited)}; a resumed run keeps its settings (only "
                        f"{', '.join(item.label for item in resumable)} may change): put config.json back as it was, "
                        "or start a new run")
    if imports:
        say(imports)
    return resumed, folder, recorded


# what config.json records of the run's history beside its settings: (its JSON type, of entries of that type, in
# words); a resume adds its command and its machine to them
HISTORY = {"command": (str, None, "a string"), "resumed": (list, str, "a list of commands (strings)"),
           "machines": (list, dict, "a list of the machines it ran on (objects)")}
JSON_TYPES = {dict: "an object", list: "a list", str: "a string", bool: "true or false", int: "a number",
              float: "a number", type(None): "null"}


def check_history(recorded: dict, path: Path) -> None:
    """Refuse a config.json whose record of the run's history is not of its type (a hand-edited file): a resume
    would have to drop it, or fail halfway."""
    for key, (kind, entry, expected) in HISTORY.items():
        if key not in recorded:
            continue
        value = recorded[key]
        if not isinstance(value, kind):
            found = JSON_TYPES.get(type(value), "another value")
        elif entry is not None and any(not isinstance(item, entry) for item in value):
            other = next(item for item in value if not isinstance(item, entry))
            found = f"a list holding {JSON_TYPES.get(type(other), 'another value')}"
        else:
            continue
        raise UserError(f"--resume {path.parent}: {path.name}'s \"{key}\" must be {expected}, got {found}; put "
                        f"{path.name} back as it was, or start a new run")


def edited_settings(checkpoint: Checkpoint, config: TrainConfig) -> list[str]:
    """The settings of ``config`` (a run's config.json) a resume may not change that differ from those the
    checkpoint was written under: '--popsize 8 (the run has 4)', ...; none for a checkpoint written before
    checkpoints recorded them. A setting the record lacks (declared since) must hold its default."""
    if not checkpoint.settings:
        return []
    current = json.loads(settings_record(config.fixed()))  # as the record holds values: lists, not tuples
    try:
        recorded = json.loads(checkpoint.settings)
    except ValueError:
        recorded = None
    if not isinstance(recorded, dict):
        raise RunFolderError("cannot resume: the checkpoint's record of the run's settings is not a JSON object; "
                             "the checkpoint was damaged")
    defaults = json.loads(settings_record({item.name: item.default for item in declared()}))
    return contradictions({name: recorded.get(name, defaults.get(name)) for name in current}, current, declared())


def check_writable(folder: str) -> None:
    """Refuse, before anything is built or created, a --folder that could not hold a run folder."""
    path = Path(folder)
    existing = next((parent for parent in (path, *path.parents) if parent.exists()), Path("."))
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"--folder {folder}: {existing} is not a writable folder")


def versions() -> dict:
    from importlib import metadata

    found = {"python": sys.version.split()[0]}
    for package in ("numpy", "torch", "gymnasium", "mujoco", "pybullet", "pybullet-envs-gymnasium",
                    "box2d", "numba", "ray", "ale-py"):
        try:
            found[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            pass
    return found


def write_config(trainer: Trainer, config: TrainConfig, problem, command: list[str], report: RunReport,
                 earlier: dict) -> None:
    """config.json: the settings (with the noise size the run uses), then what they led to; a
    resume keeps the first command of ``earlier`` (its config.json as it was) and lists its own under "resumed",
    and each start and resume adds the machine it runs on from its generation on under "machines" (what
    metrics.csv's seconds were measured on), with the package versions it has installed; "versions" beside them
    is the latest start's or resume's. The loggers are told the settings once, and their trackers' run ids
    recorded. A new run then saves its first checkpoint: it is resumable from the start, even if the first
    generation fails."""
    folder = trainer.folder
    line = " ".join(command)
    settings = replace(config, es=trainer.es)
    data = settings.to_dict()
    installed = versions()
    here = {"from_generation": trainer.state.generation, **machine(trainer.evaluator.workers), "versions": installed}
    data.update(command=earlier.get("command", line), resumed=earlier.get("resumed", []) + ([line] if earlier else []),
                versions=installed, num_params=trainer.policy.num_params, layout=trainer.policy.layout.describe(),
                workers=trainer.evaluator.workers, wrappers=problem.wrappers(),
                machines=earlier.get("machines", []) + [here])
    with explained("cannot start the loggers"):
        data["log"].update(report.begin(folder, data, trainer.state.generation, trainer.policy.metrics_columns))
    folder.write_config(data)
    folder.settings = settings_record(settings.fixed())  # what its checkpoints record from now on
    if not earlier:
        trainer.save_checkpoint()


def start(config: TrainConfig, folder: RunFolder | None) -> tuple[Trainer, object, RunReport]:
    """The trainer of a new run (``folder`` None: created once the environments are made) or of a
    resumed one (restored from its checkpoint), its problem, and what reports on the run, which the trainer hands
    each generation's record: made first, it refuses a --logger whose packages are not installed."""
    report = RunReport(config.log, log)
    spec = ProblemSpec(config.env.env_ids, config.policy, config.env.recipe_modules, config.env.max_episode_steps)
    with explained("cannot make the environments"):
        problem = spec.build()
    if config.policy.obs_norm and not problem.policy.normalised_inputs:
        log("note: --obs_norm does nothing for pixel observations (the CNN sees pixels in [0, 1]); "
            "this run normalises nothing")
    created, trainer = folder is None, None
    try:
        if created:
            try:
                folder = RunFolder.create(config.run.folder, config.env.label, config.run.seed)
            except OSError as error:
                raise UserError(f"--folder {config.run.folder}: {error.strerror or error}") from None
        with explained("cannot start the run"):
            trainer = Trainer.start(config.es, config.run, problem, spec.build, config.env.env_ids, folder,
                                    config.env.label, log=log, display=display_for(sys.stdout), on_generation=report)
        if not created:
            with explained("cannot resume"):
                trainer.restore(folder.load_checkpoint())
    except BaseException:
        if trainer is not None:  # a checkpoint it cannot resume from: its workers stop
            trainer.close()
        problem.close()
        if created and folder is not None:
            folder.remove_if_unused()  # an empty folder but for its lock
        raise
    return trainer, problem, report


def train_main(kind: str, parser: Parser, argv: list[str] | None = None) -> int:
    honour_sigint()  # a background job's SIGINT too
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    trainer = report = None
    try:
        config, folder, recorded = configured(kind, args)
        trainer, problem, report = start(config, folder)
        done = trainer.state.generation
        if recorded and done >= config.run.generations:
            log(f"{folder.path} has already run {done} generations; nothing to do "
                f"(--generations is the total: pass more than {done} to continue)")
            return 0
        if recorded:
            log(f"resuming {folder.path} at generation {done} of {config.run.generations}")
        write_config(trainer, config, problem, [parser.prog, *argv], report, recorded)
        log(f"run folder: {trainer.folder.path} | environment: {', '.join(config.env.env_ids)} | parameters: "
            f"{trainer.policy.num_params} | workers: {trainer.evaluator.workers} | seed: {config.run.seed}")
        status = trainer.train()
        if status is Status.DONE:
            report.finished()
        return report_end(trainer, config, status, parser.prog)
    except (*USER_ERRORS, SaveError) as error:  # SaveError here: before training started
        kept = f"; {after_failed_save(config, trainer.folder)}" if isinstance(error, SaveError) and trainer else ""
        print(f"{parser.prog}: error: {error}{kept}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = (f" (resume with: {resume_hint(config, trainer.folder.path)})"
                  if trainer is not None and trainer.folder.checkpoint_generation is not None else "")
        print(f"{parser.prog}: stopped at once; saved files are intact{resume}", file=sys.stderr)
        return 130
    finally:
        if report is not None:
            report.close()
        if trainer is not None:
            trainer.close()
            if args.resume is None:  # a new run whose loggers failed to start: no folder left behind
                trainer.folder.remove_unstarted()
        release_locks()  # the run folder's lock, for the next run in this process


def report_end(trainer: Trainer, config: TrainConfig, status: Status, prog: str) -> int:
    """The run's last line, and the exit code: how to evaluate it, or how to resume it; or, where a resume
    would meet the same failure (NaN or infinity) or first needs space (a failed write), one line on
    stderr saying why and what was kept, exit code 2."""
    folder, failure = trainer.folder, trainer.failure
    if status is Status.DONE:
        # ``best`` only with --eval_every: otherwise it is the centre with the best single-episode
        # return, a noisy choice.
        prefix = "best" if config.es.eval_every is not None and trainer.history.best_theta is not None else "last"
        log(f"done; evaluate with: {evaluate_hint(config, folder.named_path(prefix, trainer.policy.roles[0]))}")
    elif status is Status.INTERRUPTED:
        log(f"interrupted after generation {trainer.state.generation}; resume with: "
            f"{resume_hint(config, folder.path)}")
    elif isinstance(failure, SaveError):
        print(f"{prog}: error: {failure}; {after_failed_save(config, folder)}", file=sys.stderr)
        return 2
    elif isinstance(failure, (NonFiniteUpdate, NonFiniteEpisode)):
        advice = NON_FINITE_ADVICE[failure.what if isinstance(failure, NonFiniteEpisode) else "update"]
        print(f"{prog}: error: {failure}; the checkpoint holds generation {folder.checkpoint_generation}; a resume "
              f"would meet it again: {advice}", file=sys.stderr)
        return 2
    else:
        log(f"error: {failure}")
        log("stopped; no checkpoint could be written" if folder.checkpoint_generation is None else
            f"stopped; the checkpoint holds generation {folder.checkpoint_generation}; "
            f"resume with: {resume_hint(config, folder.path)}")
    return EXIT_CODES[status]


NON_FINITE_ADVICE = {"update": "start a new run with a lower --lr or a larger --sigma",
                     "parameters": "start a new run with a smaller --sigma",
                     "output": "start a new run with a smaller --sigma (the network's output overflowed)",
                     "observations": "the environment returned them; fix it, then start a new run"}


def after_failed_save(config: TrainConfig, folder: RunFolder) -> str:
    """What a failed write (a full disk, a folder made read-only) kept, and what to do."""
    if folder.checkpoint_generation is None:
        return f"no checkpoint was written in {folder.path}; make space, then start the run again"
    return (f"{folder.path} keeps its checkpoint of generation {folder.checkpoint_generation} (every write is "
            f"atomic: no file is torn); make space, then resume with: {resume_hint(config, folder.path)}")


def log(line: str) -> None:
    say(line)
