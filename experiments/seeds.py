#!/usr/bin/env python
"""Run one training configuration over several seeds, in parallel here or on a Ray cluster.

    python experiments/seeds.py --seeds 5 --jobs 2 -- train_static.py --environment CartPole-v1 \\
        --popsize 16 --generations 20 --folder runs/cartpole_static
    python experiments/seeds.py --seeds 5 -- train_hebb.py --config experiments/paper/ant_hebbian.toml \\
        --folder runs/ant_hebbian
    python experiments/seeds.py --seeds 8 --ray --ray_address auto -- train_static.py ...   # one run per Ray task

Everything after ``--`` is the training command, as you would type it, without --seed, --threads and
--resume, which the launcher sets. Seed k (k = --first_seed, ..., --first_seed + --seeds - 1) trains in
``<folder>/seed<k>/``, where the training script makes its usual run folder ``<time>_<env>_seed<k>``.
Whole runs go to a pool of --jobs at a time (default: one per core, at most one per seed), each with
``--threads`` = cores // jobs, so the cores are never oversubscribed; each run's output goes to
``<folder>/seed<k>/launch.log``.

``<folder>/launch.json`` records the command. Running the same launch again resumes every unfinished
seed from its checkpoint (a finished one has nothing to do) and adds seeds that are new; a different
configuration in the same folder is refused, naming the settings that differ (only the settings a
resume may change, such as --generations, may differ). Compare launches with ``report_runs.py``.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the project's modules, when run as a script

from cli import Parser, UserError  # noqa: E402
from cli.config import declared  # noqa: E402
from cli.flags import defaults, given, positive_int, seed_value  # noqa: E402
from cli.hints import TRAIN_SCRIPTS  # noqa: E402
from cli.train import check_writable, config_from_args  # noqa: E402
from es import files  # noqa: E402
from experiments.paper_runs import latest_run  # noqa: E402
from settings import SEED_RANGE  # noqa: E402

SET_BY_LAUNCHER = ("seed", "threads", "resume")
RESUMABLE = tuple(item.name for item in declared() if item.spec.resumable)  # what a resume may change
RECORD = "launch.json"
SEED_BYTES = 4096  # memory per seed of a launch: its command, its log's path, its task in the pool


def parse(argv: list[str]) -> tuple[argparse.Namespace, list[str]]:
    if "--" not in argv:
        argv = [*argv, "--"]
    mine, training = argv[:argv.index("--")], argv[argv.index("--") + 1:]
    parser = Parser(prog="seeds.py", description=__doc__.splitlines()[0],
                    formatter_class=argparse.RawDescriptionHelpFormatter, epilog="\n".join(__doc__.splitlines()[2:]))
    parser.add_argument("--seeds", type=positive_int, default=5, metavar="N", help="how many seeds")
    parser.add_argument("--first_seed", type=seed_value, default=1, metavar="S", help="the first seed")
    parser.add_argument("--jobs", type=positive_int, default=None, metavar="J",
                        help="runs at a time (default: one per core, at most --seeds)")
    parser.add_argument("--ray", action="store_true",
                        help="run each seed as a Ray task (pip install -r requirements-ray.txt); the folder must be "
                             "shared by the cluster's machines")
    parser.add_argument("--ray_address", default=None, metavar="ADDRESS",
                        help="with --ray: 'auto' or HOST:PORT of a running cluster (default: a local Ray)")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    args = parser.parse_args(mine)
    last = args.first_seed + args.seeds - 1
    if last > SEED_RANGE[1]:  # before any list of seeds is made: --seeds 3000000000 is refused, not allocated
        parser.error(f"--first_seed {args.first_seed} with --seeds {args.seeds} runs past the largest seed "
                     f"{SEED_RANGE[1]} (the last would be {last}); give --seeds {SEED_RANGE[1] - args.first_seed + 1} "
                     "or fewer, or a smaller --first_seed")
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    if args.seeds * SEED_BYTES > memory // 2:
        parser.error(f"--seeds {args.seeds} needs about {args.seeds * SEED_BYTES / 2**30:.0f} GiB to hold the launch's "
                     f"commands, more than half of this machine's {memory / 2**30:.1f} GiB; give --seeds "
                     f"{memory // 2 // SEED_BYTES} or fewer")
    if args.ray_address is not None and not args.ray:
        parser.error("--ray_address has an effect only with --ray; add --ray or leave --ray_address out")
    if not training:
        parser.error("give the training command after --, e.g. -- train_static.py --environment CartPole-v1 "
                     "--folder runs/cartpole")
    return args, training


def training_script(name: str) -> tuple[str, object]:
    """The training script's file name and its argument parser."""
    scripts = {Path(script).name: kind for kind, script in TRAIN_SCRIPTS.items()}
    if Path(name).name not in scripts:
        raise UserError(f"the command after -- must start with one of {', '.join(scripts)}, got {name}")
    import importlib

    module = importlib.import_module(Path(name).stem)
    return Path(name).name, module.build_parser()


def given_names(values: argparse.Namespace) -> set[str]:
    """The settings a parsed training command gives, and --resume if it does."""
    return set(given(values)) | ({"resume"} if values.resume is not None else set())


def check_flags(script: str, parser, flags: list[str]) -> argparse.Namespace:
    """The training flags, parsed by the script's own parser (its one-line errors), without the launcher's."""
    parser.prog = script
    values = parser.parse_args(flags)
    owned = sorted(given_names(values) & set(SET_BY_LAUNCHER))
    if owned:
        raise UserError(f"{', '.join('--' + name for name in owned)}: set by the launcher for each seed; "
                        "give --seeds, --first_seed and --jobs to seeds.py instead")
    if "folder" not in given_names(values):
        raise UserError(f"give {script} a --folder for the launch (its seeds go to <folder>/seed<k>)")
    config_from_args(values.kind, values)  # every value checked as the script will, before any run starts
    check_writable(values.folder)
    return values


def settings_of(parser, flags: list[str]) -> dict:
    """Every setting of a training command: the script's defaults, then the flags given."""
    values = parser.parse_args(flags)
    return {**defaults(values.kind, {"folder": values.default_folder}), **given(values)}


def differences(parser, recorded: list[str], flags: list[str]) -> list[str]:
    """The settings (other than those a resume may change) where ``flags`` differ from ``recorded``."""
    before, now = settings_of(parser, recorded), settings_of(parser, flags)
    return [f"--{name} {now[name]} (the launch has {before[name]})" for name in sorted(now)
            if name not in RESUMABLE and name != "folder" and now[name] != before.get(name)]


def check_record(folder: Path, script: str, parser, flags: list[str]) -> None:
    """Refuse a folder launched with another configuration, before anything runs."""
    path = folder / RECORD
    if not path.exists():
        return
    try:
        record = files.read_json(path)
        recorded_script, recorded_flags = record["script"], list(record["flags"])
    except (OSError, ValueError, KeyError, TypeError):
        raise UserError(f"{path} is unreadable; it is not a launch record of seeds.py (use another --folder)") from None
    if recorded_script != script:
        raise UserError(f"{folder} holds a launch of {recorded_script}, not {script}; use another --folder")
    changed = differences(parser, recorded_flags, flags)
    if changed:
        raise UserError(f"{folder} holds a launch with other settings: {', '.join(changed)}; give the same settings "
                        f"to resume it (only {', '.join('--' + name for name in RESUMABLE)} may change) or use "
                        "another --folder")


def seed_command(script: str, flags: list[str], seed: int, seed_folder: Path, threads: int) -> list[str]:
    """A new run of the seed, or the resume of its newest run. On resume the flags are given again (but
    --config, which cannot be): the training script refuses any that differ from the run's config.json."""
    command = [sys.executable, str(ROOT / script)]
    own = ["--seed", str(seed), "--threads", str(threads), "--folder", str(seed_folder)]
    previous = latest_run(seed_folder)
    if previous is None:
        return command + [*without(flags, "folder"), *own]
    return command + ["--resume", str(previous), *without(flags, "folder", "config"), *own]


def without(flags: list[str], *names: str) -> list[str]:
    """``flags`` less ``--name VALUE`` and ``--name=VALUE`` for each of ``names``."""
    kept, skip = [], False
    for word in flags:
        if skip:
            skip = False
        elif word in {f"--{name}" for name in names}:
            skip = True
        elif not any(word.startswith(f"--{name}=") for name in names):
            kept.append(word)
    return kept


def cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_logged(command: list[str], log: Path, cwd: str) -> int:
    """One whole run, its output appended to ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "a") as handle:
        handle.write(f"$ {' '.join(command)}\n")
        handle.flush()
        return subprocess.run(command, check=False, cwd=cwd, stdout=handle, stderr=subprocess.STDOUT,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"}).returncode


def run_local(jobs: dict[int, tuple[list[str], Path]], parallel: int) -> dict[int, int]:
    """A pool of ``parallel`` whole runs at a time. Ctrl-C reaches the runs too (same process group):
    they save and stop, and no further seed starts."""
    codes: dict[int, int] = {}
    stopping = threading.Event()

    def one(seed: int) -> int:
        if stopping.is_set():
            return 130
        command, log = jobs[seed]
        started = time.perf_counter()
        print(f"seed {seed}: started (output: {log})", flush=True)
        code = run_logged(command, log, os.getcwd())
        print(f"seed {seed}: exit {code} after {time.perf_counter() - started:.0f} s", flush=True)
        return code
    with concurrent.futures.ThreadPoolExecutor(max_workers=parallel) as pool:
        futures = {pool.submit(one, seed): seed for seed in jobs}
        try:
            for future in concurrent.futures.as_completed(futures):
                codes[futures[future]] = future.result()
        except KeyboardInterrupt:
            stopping.set()
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return codes


def run_ray(jobs: dict[int, tuple[list[str], Path]], threads: int, address: str | None) -> dict[int, int]:
    """Each seed's run as a Ray task asking for ``threads`` CPUs; Ray places them on the cluster."""
    try:
        import ray
    except ImportError:
        raise UserError("--ray needs Ray, which is not installed; pip install -r requirements-ray.txt") from None
    ray.init(address=address, include_dashboard=False, log_to_driver=False)
    task = ray.remote(num_cpus=threads)(run_logged)
    futures = {seed: task.remote(command, log, os.getcwd()) for seed, (command, log) in jobs.items()}
    codes = {seed: ray.get(future) for seed, future in futures.items()}
    ray.shutdown()
    return codes


def launch(args: argparse.Namespace, training: list[str]) -> int:
    script, parser = training_script(training[0])
    flags = training[1:]
    folder = Path(check_flags(script, parser, flags).folder)
    check_record(folder, script, parser, flags)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    for seed in seeds:  # a file where a seed's folder goes
        check_writable(str(folder / f"seed{seed}"))
    parallel = min(args.jobs or cores(), len(seeds))
    threads = max(1, cores() // parallel)
    jobs = {seed: (seed_command(script, flags, seed, folder / f"seed{seed}", threads),
                   folder / f"seed{seed}" / "launch.log") for seed in seeds}
    if args.dry_run:
        for command, _ in jobs.values():
            print("$ " + " ".join(command))
        return 0
    folder.mkdir(parents=True, exist_ok=True)
    files.write_json(folder / RECORD, {"script": script, "flags": flags, "command": sys.argv})
    print(f"{len(seeds)} seeds of {script} in {folder}: {parallel} at a time, --threads {threads} each", flush=True)
    codes = run_ray(jobs, threads, args.ray_address) if args.ray else run_local(jobs, parallel)
    failed = {seed: code for seed, code in sorted(codes.items()) if code != 0}
    if failed:
        listed = ", ".join(f"seed {seed} (exit {code}, see {jobs[seed][1]})" for seed, code in failed.items())
        print(f"seeds.py: {len(failed)} of {len(seeds)} runs did not finish: {listed}; run the same command again "
              "to resume them", file=sys.stderr)
        return 130 if 130 in failed.values() else 1
    print(f"all {len(seeds)} seeds done; compare with: python report_runs.py --group NAME={folder}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    args, training = parse(sys.argv[1:] if argv is None else argv)
    try:
        return launch(args, training)
    except UserError as error:
        print(f"seeds.py: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("seeds.py: stopped; the runs saved their checkpoints: run the same command again to resume",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
