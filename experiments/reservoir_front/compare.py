#!/usr/bin/env python
"""Three evolved priors side by side: evolved weights, evolved Hebbian rules, and either one reading a reservoir.

    python experiments/reservoir_front/compare.py                       # CartPole without velocities, 3 seeds
    python experiments/reservoir_front/compare.py --seeds 1 --generations 5 --popsize 8 --episodes 5  # a quick try
    python experiments/reservoir_front/compare.py --environment Ant-v5,AntAsymRight-v5 \\
        --evaluate_on Ant-v5,AntAsymRight-v5,AntAsymLeft-v5 --generations 300 --popsize 200   # the damaged ants

Every arm runs the same ES with the same flags (those after ``--`` go to every training run), on the same
seeds, and is evaluated on the same episodes (seeds 0 to --episodes - 1, on every --evaluate_on
environment), from the run's last*.dat files. The arms (ARMS) differ only in what is evolved:

    static              train_static.py: the weights of the MLP (Salimans et al. 2017)
    hebbian             train_hebb.py: one ABCD_lr rule per synapse, random weights every episode (Najarro & Risi 2020)
    static+reservoir    the MLP reads a reservoir with ER-MRL's best CartPole-without-velocities hyperparameters
    static+evolved      the MLP reads a reservoir whose lr, sr and iss evolve with it (--reservoir_evolve)
    hebbian+reservoir   as static+reservoir, with Hebbian rules
    hebbian+evolved     as static+evolved, with Hebbian rules

Runs go to <folder>/<arm>_seed<seed>/ (default folder: runs/reservoir_front); running the same command
again resumes unfinished runs and re-evaluates nothing already evaluated. The table (mean return over the
evaluation episodes, per seed, and the mean over seeds) is printed and written to <folder>/results.md, with
the numbers in <folder>/results.json, and with --record as a record that docs/reservoirs.md renders.
--dry-run prints the commands.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent.parent
sys.path.insert(0, str(ROOT))  # the project's modules, when run as a script

import envs  # noqa: E402
from benchmarks import record as records  # noqa: E402
from cli.errors import USER_ERRORS, Parser, explained, say  # noqa: E402
from cli.flags import positive_int, seed_value, threads_value  # noqa: E402
from cli.hints import EVALUATE_FLAGS, EVALUATE_SCRIPTS, TRAIN_SCRIPTS  # noqa: E402
from cli.reporting import check_loggers  # noqa: E402
from cli.train import config_from_args, training_parser  # noqa: E402
from envs import ProblemSpec  # noqa: E402
from es.files import atomic_write_text  # noqa: E402
from es.runfolder import named_file  # noqa: E402
from es.strategies import make_strategy  # noqa: E402
from experiments.paper_runs import latest_run, run  # noqa: E402

DEFAULT_ENV = "experiments.reservoir_front.partial:CartPoleNoVelocity-v1"
# the reservoir ER-MRL evolved for PPO on CartPole without velocities (docs/reservoirs.md:
# trial 7, sr 1.00, lr 0.34), given as it is to the ES arms
GIVEN = ("--reservoir", "--reservoir_lr", "0.34", "--reservoir_sr", "1.0")
EVOLVED = ("--reservoir", "--reservoir_evolve")
ARMS = {
    "static": ("static", ()),
    "hebbian": ("hebbian", ()),
    "static+reservoir": ("static", GIVEN),
    "static+evolved": ("static", EVOLVED),
    "hebbian+reservoir": ("hebbian", GIVEN),
    "hebbian+evolved": ("hebbian", EVOLVED),
}


def parse(argv: list[str]) -> tuple[argparse.Namespace, list[str]]:
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[:argv.index("--")] if "--" in argv else argv
    parser = Parser(prog="compare.py", description=__doc__.splitlines()[0],
                    formatter_class=argparse.RawDescriptionHelpFormatter, epilog="\n".join(__doc__.splitlines()[2:]))
    parser.add_argument("--environment", default=DEFAULT_ENV, help="training environment(s), as the scripts take them")
    parser.add_argument("--evaluate_on", default=None, help="evaluation environment(s); default: --environment")
    parser.add_argument("--arms", nargs="+", choices=list(ARMS), default=list(ARMS), metavar="ARM",
                        help=f"which arms, of {', '.join(ARMS)}")
    parser.add_argument("--seeds", nargs="+", type=seed_value, default=[1, 2, 3], metavar="SEED")
    parser.add_argument("--generations", type=positive_int, default=100)
    parser.add_argument("--popsize", type=positive_int, default=64)
    parser.add_argument("--units", type=positive_int, default=20, help="the reservoir's units (--reservoir_units)")
    parser.add_argument("--episodes", type=positive_int, default=100, help="evaluation episodes per environment")
    parser.add_argument("--threads", type=threads_value, default=-1)
    parser.add_argument("--folder", type=Path, default=ROOT / "runs" / "reservoir_front")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    parser.add_argument("--record", type=records.writable_folder, default=None, metavar="FOLDER",
                        help="also write the table as a record (benchmarks/record.py, not timed: a seeded run's "
                        "returns are the same at any load) into FOLDER: benchmarks/results for the docs' table")
    args = parser.parse_args(argv)
    args.folder = args.folder.resolve()  # the scripts run in the repository root
    resolved = []
    for flag, ids in (("--environment", args.environment), ("--evaluate_on", args.evaluate_on or "")):
        try:  # before hours of training, not at the first evaluation
            resolved += [envs.resolve_env_id(env_id.strip(), notify=lambda line: None) for env_id in ids.split(",")
                         if env_id.strip()]
        except envs.EnvironmentError_ as error:
            parser.error(f"{flag}: {error}")
    try:
        check_sizes(tuple(dict.fromkeys(resolved)))
    except ValueError as error:
        parser.error(f"--evaluate_on {args.evaluate_on}: {error}")
    for arm in args.arms:
        try:
            check_arm(args, extra, arm)
        except USER_ERRORS as error:
            parser.error(f"the {arm} arm: {error}")
    return args, extra


def check_sizes(env_ids: tuple[str, ...]) -> None:
    """The training and evaluation environments make one network (observation and action sizes): each is
    made once, as a run would, and refused here if it does not fit."""
    from policies import PolicySettings

    ProblemSpec(env_ids, PolicySettings()).build().close()


def check_arm(args: argparse.Namespace, extra: list[str], arm: str) -> None:
    """Before any arm trains: the arm's training flags checked as its script checks them, and its network and
    strategy made once, so that an extra it needs and that is missing (reservoirpy for the reservoir arms,
    cmaes for --strategy cma_es) or a flag after -- that does not fit it stops the comparison here."""
    kind = ARMS[arm][0]
    parser = training_parser(TRAIN_SCRIPTS[kind], "", kind, folder=str(args.folder))
    config = config_from_args(kind, parser.parse_args(arm_flags(args, extra, arm, args.seeds[0], args.folder)))
    check_loggers(config.log)
    spec = ProblemSpec(config.env.env_ids, config.policy, config.env.recipe_modules, config.env.max_episode_steps)
    with explained("cannot make the environments"):
        problem = spec.build()
    try:
        with explained("cannot start the run"):
            make_strategy(config.es, problem.policy.num_params)
    finally:
        problem.close()


def arm_flags(args: argparse.Namespace, extra: list[str], arm: str, seed: int, folder: Path) -> list[str]:
    """The flags of the arm's training run."""
    flags = ARMS[arm][1]
    reservoir = ["--reservoir_units", str(args.units)] if flags else []
    return ["--environment", args.environment, "--seed", str(seed), "--generations", str(args.generations),
            "--popsize", str(args.popsize), "--threads", str(args.threads), "--folder", str(folder),
            *flags, *reservoir, *extra]


def train_command(args: argparse.Namespace, extra: list[str], arm: str, seed: int, folder: Path) -> list[str]:
    """The arm's training; an unfinished run resumes (--generations the total), and the training script
    refuses any other flag that differs from the run's."""
    previous = latest_run(folder)
    return [sys.executable, str(ROOT / TRAIN_SCRIPTS[ARMS[arm][0]]), *(["--resume", str(previous)] if previous else []),
            *arm_flags(args, extra, arm, seed, folder)]


def evaluate_command(args: argparse.Namespace, arm: str, run_dir: Path) -> list[str]:
    """The run's last*.dat files; the evaluate scripts take the rule and the reservoir from its config.json."""
    kind = ARMS[arm][0]
    command = [sys.executable, str(ROOT / EVALUATE_SCRIPTS[kind]),
               "--environment", args.evaluate_on or args.environment,
               "--episodes", str(args.episodes), "--seed", "0", "--json", str(run_dir / "evaluation.json")]
    files = [(flag, run_dir / named_file("last", role)) for role, flag in EVALUATE_FLAGS.items()]
    return command + [word for flag, path in files if path.exists() for word in (flag, str(path))]


def evaluated(run_dir: Path, command: list[str]) -> bool:
    """Whether evaluation.json is this evaluation of the run's latest parameters."""
    evaluation = run_dir / "evaluation.json"
    if not evaluation.exists() or evaluation.stat().st_mtime < (run_dir / "checkpoint.npz").stat().st_mtime:
        return False
    return json.loads(evaluation.read_text())["command"][1:] == command[2:]


def succeeded(command: list[str], dry_run: bool) -> None:
    code = run(command, dry_run)
    if code:
        sys.exit(code)


def means(results: dict[str, dict[int, dict]], seeds: list[int]) -> list[tuple[str, list[float], float, list[float]]]:
    """Per arm: the mean return of each seed's run (over all evaluation environments and episodes), their mean
    over seeds, and with several environments each one's mean over seeds (else none)."""
    count = len(environment_names(results))
    found = []
    for arm, runs in results.items():
        per_seed = [sum(sum(e["returns"]) for e in runs[seed]["environments"])
                    / sum(len(e["returns"]) for e in runs[seed]["environments"]) for seed in seeds]
        per_env = [sum(sum(runs[seed]["environments"][i]["returns"]) / len(runs[seed]["environments"][i]["returns"])
                       for seed in seeds) / len(seeds) for i in range(count)]
        found.append((arm, per_seed, sum(per_seed) / len(seeds), per_env))
    return found


def environment_names(results: dict[str, dict[int, dict]]) -> list[str]:
    """The evaluation environments, where there are several (a column each)."""
    environments = next(iter(next(iter(results.values())).values()))["environments"]
    return [environment["env_id"] for environment in environments] if len(environments) > 1 else []


def table(results: dict[str, dict[int, dict]], seeds: list[int]) -> str:
    """Markdown: one row per arm, the mean return of each seed's run and the mean over seeds (``means``)."""
    names = environment_names(results)

    def row(cells: list[str]) -> str:
        return "| " + " | ".join(cells) + " |"

    lines = [row(["arm", *(f"seed {seed}" for seed in seeds), "mean", *names]),
             row(["---"] * (len(seeds) + 2 + len(names)))]
    lines += [row([arm, *(f"{value:.1f}" for value in per_seed), f"**{mean:.1f}**",
                   *(f"{value:.1f}" for value in per_env)]) for arm, per_seed, mean, per_env in means(results, seeds)]
    return "\n".join(lines)


def write_record(results: dict[str, dict[int, dict]], args: argparse.Namespace, extra: list[str]) -> None:
    """The table as a record, ``reservoir_front-<environment>`` (docs/reservoirs.md renders it): each arm's mean
    return per seed and over the seeds (``means``), one measure per arm."""
    environment = args.environment.split(":")[-1].replace(",", "+")
    record = records.Record(f"reservoir_front-{environment}", timed=False)
    rows = []
    for arm, per_seed, mean, per_env in means(results, args.seeds):
        record.add(arm, f"{arm}: each seed's mean evaluation return", "", per_seed)
        rows.append([arm, *(f"{value:.1f}" for value in (*per_seed, mean, *per_env))])  # as the printed table
    record.table("results", ["arm", *(f"seed {seed}" for seed in args.seeds), "mean", *environment_names(results)],
                 rows)
    record.note("protocol", {"environment": args.environment, "evaluate_on": args.evaluate_on, "seeds": args.seeds,
                             "episodes": args.episodes, "popsize": args.popsize, "generations": args.generations,
                             "training_flags": extra, "folder": str(args.folder)})
    record.write(args.record)


def main(argv: list[str] | None = None) -> int:
    args, extra = parse(sys.argv[1:] if argv is None else argv)
    results: dict[str, dict[int, dict]] = {}
    for arm in args.arms:
        for seed in args.seeds:
            folder = args.folder / f"{arm}_seed{seed}"
            started = time.perf_counter()
            succeeded(train_command(args, extra, arm, seed, folder), args.dry_run)
            run_dir = latest_run(folder)
            if run_dir is None:  # a dry run
                say(f"# then the evaluation of {folder}/<run folder>/last*.dat")
                continue
            command = evaluate_command(args, arm, run_dir)
            if not evaluated(run_dir, command):
                succeeded(command, args.dry_run)
            if args.dry_run:
                continue
            results.setdefault(arm, {})[seed] = json.loads((run_dir / "evaluation.json").read_text())
            say(f"# {arm}, seed {seed}: {time.perf_counter() - started:.0f} s")
    if args.dry_run:
        return 0
    text = table(results, args.seeds)
    say(text)
    args.folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.folder / "results.md", text + "\n")
    atomic_write_text(args.folder / "results.json", json.dumps(results, indent=1))
    if args.record is not None:
        write_record(results, args, extra)
    return 0


if __name__ == "__main__":
    sys.exit(main())
