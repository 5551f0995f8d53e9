#!/usr/bin/env python
"""Environment steps per second, this tool against EvoTorch 0.6.1, as a user times a training command.

    python benchmarks/vs_evotorch_speed.py --environment HalfCheetah-v5 --workers 1 --popsize 32 --generations 5
    python benchmarks/vs_evotorch_speed.py --environment HalfCheetah-v5 --workers 2 --popsize 32 --generations 5

Each round runs two commands, each in a fresh process, timed from its start to its end in wall time:

- this tool: ``train_static.py --environment E --strategy pgpe --popsize N --generations G --threads W``
  (a process pool of W workers; W = 1 runs in its process), writing its run folder as any run does;
- EvoTorch: ``benchmarks/peers/evotorch_train.py`` with the same strategy (PGPE with ClipUp), network,
  σ, maximum speed and step, population and generations, GymNE with ``num_actors=W`` (W = 1: none, its own
  process).

The two alternate (round 1: this tool first, round 2: EvoTorch first, ...), each round on its own seed. Both
build their environments (and workers or Ray actors) before the first generation. Per round this records:

- ``command``: the whole command's environment steps per second, this tool ÷ EvoTorch: every step a run
  took (this tool's include its centre's episode each generation) over the command's wall time: start-up,
  imports, Ray, the environments, every generation and the files written;
- ``generation``: the same ratio over generations 2 to G alone, each tool timing its own generations
  (``metrics.csv``'s ``seconds``; EvoTorch's ``searcher.step()``): the first generation, which pays one-time
  costs on both sides (numba's compiled code loaded, torch's first calls), is left out;
- each tool's command seconds and median seconds per generation (2 to G).

The ratios are the median over ``--rounds`` (at least 5 to publish) with their range; the record holds every
round. Needs: pip install -r requirements-bench.txt
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from record import Record, add_results_flag, documented_parser

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from es.files import read_metrics  # noqa: E402

PEER = Path(__file__).resolve().parent / "peers" / "evotorch_train.py"
INSTALL_HINT = "pip install -r requirements-bench.txt"


@dataclass(frozen=True)
class Timed:
    """One command: its wall time, and each generation's seconds and environment steps."""
    wall: float
    seconds: list[float]
    steps: list[int]

    @property
    def command_rate(self) -> float:
        return sum(self.steps) / self.wall

    @property
    def generation_rate(self) -> float:
        """Steps per second over generations 2 to G (all of them if there is only one)."""
        later = slice(1, None) if len(self.steps) > 1 else slice(None)
        return sum(self.steps[later]) / sum(self.seconds[later])

    @property
    def generation_seconds(self) -> float:
        return statistics.median(self.seconds[1:] or self.seconds)


def timed(command: list[str], log: Path) -> float:
    """Run ``command`` (output to ``log``) and return its wall time. A command that refuses its arguments (exit
    2: a user's error, such as an unknown environment) ends this one with its one line and exit 2; one that
    fails otherwise, with the end of its output (the log lies in a folder removed on exit)."""
    with log.open("w") as output:
        started = time.perf_counter()
        code = subprocess.run(command, cwd=ROOT, stdout=output, stderr=subprocess.STDOUT).returncode
        wall = time.perf_counter() - started
    if code:
        lines = log.read_text().strip().splitlines() or [f"{Path(command[1]).name} exited {code}"]
        if code == 2:
            print(lines[-1], file=sys.stderr)
            raise SystemExit(2)
        raise SystemExit(f"vs_evotorch_speed.py: error: {Path(command[1]).name} exited {code}; its output ends:\n"
                         + "\n".join(lines[-30:]))
    return wall


def run_ours(args: argparse.Namespace, seed: int, folder: Path) -> Timed:
    runs = folder / "ours"
    wall = timed([sys.executable, str(ROOT / "train_static.py"), "--environment", args.environment, "--strategy",
                  "pgpe", "--popsize", str(args.popsize), "--generations", str(args.generations), "--sigma",
                  str(args.sigma), "--threads", str(args.workers), "--seed", str(seed), "--folder", str(runs)],
                 folder / "ours.log")
    [metrics] = list(runs.glob("*/metrics.csv"))
    rows = read_metrics(metrics)
    return Timed(wall, [float(row["seconds"]) for row in rows], [int(row["env_steps"]) for row in rows])


def run_evotorch(args: argparse.Namespace, seed: int, folder: Path) -> Timed:
    times = folder / "evotorch.json"
    wall = timed([sys.executable, str(PEER), "--environment", args.environment, "--strategy", "pgpe", "--popsize",
                  str(args.popsize), "--generations", str(args.generations), "--sigma", str(args.sigma),
                  "--workers", str(args.workers), "--seed", str(seed), "--json", str(times)], folder / "evotorch.log")
    generations = json.loads(times.read_text())["generations"]
    return Timed(wall, [g["seconds"] for g in generations], [int(g["env_steps"]) for g in generations])


def round_of(args: argparse.Namespace, number: int) -> tuple[Timed, Timed]:
    """One round on seed ``number``: this tool first in odd rounds, EvoTorch first in even ones."""
    with tempfile.TemporaryDirectory() as folder:
        first, second = (run_ours, run_evotorch) if number % 2 else (run_evotorch, run_ours)
        results = {first: first(args, number, Path(folder)), second: second(args, number, Path(folder))}
    return results[run_ours], results[run_evotorch]


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        import evotorch  # noqa: F401  (only whether it is there: the commands import it themselves)
    except ImportError:
        print(f"vs_evotorch_speed.py: error: needs EvoTorch, which is not installed; {INSTALL_HINT}", file=sys.stderr)
        return 2
    record = Record(f"vs_evotorch_speed-{args.environment}-{args.workers}w", ("evotorch", "ray"))
    rounds = []
    for number in range(1, args.rounds + 1):
        ours, theirs = round_of(args, number)
        rounds.append((ours, theirs))
        print(f"round {number}: this tool {ours.wall:.1f} s ({ours.command_rate:,.0f} steps/s, generations "
              f"{ours.generation_rate:,.0f}), EvoTorch {theirs.wall:.1f} s ({theirs.command_rate:,.0f} steps/s, "
              f"generations {theirs.generation_rate:,.0f})", flush=True)
    setting = (f"{args.environment}, PGPE, popsize {args.popsize}, {args.generations} generations, "
               f"{args.workers} worker{'s' if args.workers > 1 else ''}")
    measures = {
        "command": (f"{setting}: env steps per second of the whole command (wall), this tool / EvoTorch", "x",
                    [ours.command_rate / theirs.command_rate for ours, theirs in rounds]),
        "generation": (f"{setting}: env steps per second over generations 2 to G, this tool / EvoTorch", "x",
                       [ours.generation_rate / theirs.generation_rate for ours, theirs in rounds]),
        "this_tool_command": (f"{setting}: this tool's command, wall seconds", "s", [o.wall for o, _ in rounds]),
        "evotorch_command": (f"{setting}: EvoTorch's command, wall seconds", "s", [t.wall for _, t in rounds]),
        "this_tool_generation": (f"{setting}: this tool's median seconds per generation (2 to G)", "s",
                                 [o.generation_seconds for o, _ in rounds]),
        "evotorch_generation": (f"{setting}: EvoTorch's median seconds per generation (2 to G)", "s",
                                [t.generation_seconds for _, t in rounds]),
    }
    for key, (what, unit, values) in measures.items():
        measure = record.add(key, what, unit, values)
        print(f"{key}: median {measure.median:.3g} (range {measure.min:.3g} to {measure.max:.3g})")
    record.note("steps", {"this tool": [sum(ours.steps) for ours, _ in rounds],
                          "EvoTorch": [sum(theirs.steps) for _, theirs in rounds]})
    record.write(args.results)
    return 0


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = documented_parser(__doc__)
    parser.add_argument("--environment", default="HalfCheetah-v5")
    parser.add_argument("--workers", type=int, default=1, help="this tool's --threads; EvoTorch's num_actors")
    parser.add_argument("--popsize", type=int, default=32)
    parser.add_argument("--generations", type=int, default=5)
    parser.add_argument("--sigma", type=float, default=0.1)
    parser.add_argument("--rounds", type=int, default=5)
    add_results_flag(parser)
    args = parser.parse_args(argv)
    if args.workers < 1 or args.workers > (os.cpu_count() or 1):
        parser.error(f"--workers must be 1 to the {os.cpu_count()} cores, got {args.workers}")
    if args.rounds < 1 or args.generations < 1 or args.popsize < 2 or args.popsize % 2:
        parser.error("--rounds and --generations must be at least 1, --popsize even and at least 2")
    return args


if __name__ == "__main__":
    sys.exit(main())
