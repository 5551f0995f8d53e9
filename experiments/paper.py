#!/usr/bin/env python
"""The experiments of Najarro & Risi (2020), "Meta-Learning through Hebbian Plasticity in Random
Networks", as commands: train with the paper's settings, then evaluate over 100 episodes.

    python experiments/paper.py carracing static      # CarRacing, evolved static weights
    python experiments/paper.py carracing hebbian     # CarRacing, evolved ABCD_lr rules, uni init
    python experiments/paper.py ant static            # ant: train on 2 bodies, evaluate on 3
    python experiments/paper.py ant hebbian
    python experiments/paper.py ant hebbian --popsize 8 --generations 2 --episodes 3   # a quick try

Settings (HML README and defaults, upstream spec §10): popsize 200, 300 generations, lr 0.2,
decay 0.995, sigma 0.1; Hebbian: ABCD_lr, --init_weights uni, --distribution normal. The paper's
population and generation counts for the ant could not be verified; these are the code's defaults.
The ant protocol (spec §5.4): fitness = mean over the standard ant and the ant with a damaged right
front leg; the left-damaged ant is held out and only seen in evaluation.

Runs take hours to days on 2 cores (experiments/README.md). Each experiment has its own folder
(default ``runs/<experiment>_<kind>_seed<seed>``); running the same command again resumes the
newest run there from its checkpoint (``--resume RUN_DIR``, ``--generations`` being the total), and
once training is complete it only evaluates. ``--dry-run`` prints the commands instead.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Experiment:
    train_on: str
    evaluate_on: str


EXPERIMENTS = {
    "carracing": Experiment("CarRacing-v0", "CarRacing-v0"),
    "ant": Experiment("AntBulletEnv-v0,AntAsymRightBulletEnv-v0",
                      "AntBulletEnv-v0,AntAsymRightBulletEnv-v0,AntAsymLeftBulletEnv-v0"),
}
HEBBIAN = ["--hebb_rule", "ABCD_lr", "--init_weights", "uni"]


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("experiment", choices=list(EXPERIMENTS))
    parser.add_argument("kind", choices=("static", "hebbian"))
    parser.add_argument("--seed", type=int, default=1, help="seed of the training run")
    parser.add_argument("--popsize", type=int, default=200)
    parser.add_argument("--generations", type=int, default=300, help="total generations")
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per body")
    parser.add_argument("--threads", type=int, default=-1, help="workers; -1 = all cores")
    parser.add_argument("--folder", default=None, help="default: runs/<experiment>_<kind>_seed<seed>")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    return parser.parse_args(argv)


def latest_run(folder: Path) -> Path | None:
    runs = sorted(path.parent for path in folder.glob("*/checkpoint.npz"))  # names start with the time
    return runs[-1] if runs else None


def train_command(args: argparse.Namespace, experiment: Experiment, folder: Path) -> list[str]:
    script = "train_hebb.py" if args.kind == "hebbian" else "train_static.py"
    command = [sys.executable, str(ROOT / script)]
    previous = latest_run(folder)
    if previous is not None:
        return command + ["--resume", str(previous), "--generations", str(args.generations),
                          "--threads", str(args.threads)]
    command += ["--environment", experiment.train_on, "--popsize", str(args.popsize),
                "--generations", str(args.generations), "--lr", "0.2", "--decay", "0.995", "--sigma", "0.1",
                "--threads", str(args.threads), "--seed", str(args.seed), "--folder", str(folder)]
    return command + (HEBBIAN + ["--distribution", "normal"] if args.kind == "hebbian" else [])


def evaluate_command(args: argparse.Namespace, experiment: Experiment, run_dir: Path) -> list[str]:
    """The final weights (last*.dat) on every body; statistics to JSON, one episode to a PNG."""
    common = ["--environment", experiment.evaluate_on, "--episodes", str(args.episodes), "--seed", "0",
              "--json", str(run_dir / "evaluation.json"), "--plot", str(run_dir / "adaptation.png")]
    if args.kind == "static":
        return [sys.executable, str(ROOT / "evaluate_static.py"), "--path_weights", str(run_dir / "last.dat"),
                *common]
    coev = ["--path_coev", str(run_dir / "last_CNN_parameters.dat")] if args.experiment == "carracing" else []
    return [sys.executable, str(ROOT / "evaluate_hebb.py"), *HEBBIAN,
            "--path_hebb", str(run_dir / "last_coeffs.dat"), *coev, *common]


def run(command: list[str], dry_run: bool) -> int:
    print("$ " + shlex.join(command), flush=True)
    return 0 if dry_run else subprocess.run(command, cwd=ROOT).returncode


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    experiment = EXPERIMENTS[args.experiment]
    folder = Path(args.folder or ROOT / "runs" / f"{args.experiment}_{args.kind}_seed{args.seed}")
    code = run(train_command(args, experiment, folder), args.dry_run)
    if code != 0:
        return code
    run_dir = latest_run(folder) or folder / "<run folder>"
    return run(evaluate_command(args, experiment, run_dir), args.dry_run)


if __name__ == "__main__":
    sys.exit(main())
