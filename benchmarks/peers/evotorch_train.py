#!/usr/bin/env python
"""EvoTorch's side of the comparison: a training command as an EvoTorch user would write it.

    python benchmarks/peers/evotorch_train.py --environment HalfCheetah-v5 --strategy pgpe --popsize 32 \
        --generations 5 --workers 2 --seed 1 --json times.json

It imports EvoTorch, Gymnasium and torch only (nothing of this tool), so that timing it as a whole command
(``benchmarks/vs_evotorch_speed.py``) times what an EvoTorch user pays. ``benchmarks/vs_evotorch.py`` imports
its pieces to run EvoTorch in its own process, generation by generation:

- ``network``: the network both tools evolve, obs -> 128 -> 64 -> actions, no biases, tanh hidden layers, as a
  GymNE layer string. GymNE takes an argmax of the outputs for a Discrete action and clips them to a Box, as
  this tool's recipes do. Its parameters, flattened as torch flattens a module, are (out, in) per layer in
  layer order: this tool's layout (``tests/test_vs_evotorch.py`` checks it output for output).
- ``SeededEnv``: GymNE resets its environment without a seed. This maker seeds the environment's reset
  stream once, from numpy's global generator, which the run seeds (and EvoTorch seeds in each Ray actor), so
  a run's episodes follow its seed.
- ``EvoTorchSettings`` and ``searcher``: PGPE (with ClipUp) or SNES, as EvoTorch 0.6.1 takes them.
- ``seed_everything``: torch (EvoTorch's sampling), numpy and random.

With ``--workers`` W > 1 GymNE gets ``num_actors=W`` (Ray actors, each with its environment); with 1 it
evaluates in this process (``num_actors=None``, EvoTorch's default). The environments, and the actors, are
made before the first generation, outside its timing. ``--json`` writes each generation's seconds (the
searcher's step alone) and environment steps.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

HIDDEN = (128, 64)  # policies/network.py's HIDDEN: the same network on both sides


def network(hidden: tuple[int, ...] = HIDDEN) -> str:
    """GymNE's layer string for obs -> hidden... -> actions, no biases, tanh between layers."""
    sizes = ("obs_length", *map(str, hidden), "act_length")
    return " >> Tanh() >> ".join(f"Linear({a}, {b}, bias=False)" for a, b in zip(sizes, sizes[1:]))


class SeededEnv:
    """``gym.make(env_id)`` with its reset stream seeded once from numpy's global generator (GymNE itself
    resets with no seed). A class, not a closure, so Ray can send it to the actors."""

    def __init__(self, env_id: str):
        self.env_id = env_id

    def __call__(self, **kwargs) -> gym.Env:
        env = gym.make(self.env_id, **kwargs)
        env.reset(seed=int(np.random.randint(2**31 - 1)))  # below 2**31: the held-out seeds are above
        return env


def seed_everything(seed: int) -> None:
    import torch

    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


@dataclass(frozen=True)
class EvoTorchSettings:
    """A searcher's settings as EvoTorch 0.6.1 takes them; None is EvoTorch's own default."""
    strategy: str  # pgpe (ClipUp) or snes
    popsize: int | None = None  # SNES: None is EvoTorch's 4 + floor(3 ln d)
    sigma: float | None = None  # stdev_init
    radius: float | None = None  # radius_init, instead of sigma: sigma = radius / sqrt(d)
    center_lr: float | None = None  # PGPE: required; SNES: None is 1
    sigma_lr: float | None = None  # PGPE: required; SNES: None is 0.2 (3 + ln d) / sqrt(d)
    max_speed: float | None = None  # PGPE: ClipUp's maximum speed (None: twice center_lr)
    max_sigma_change: float | None = 0.2  # PGPE: stdev_max_change
    obs_norm: bool = False  # GymNE's observation_normalization
    centre: str = "evotorch"  # where the search starts: EvoTorch's (near 0), "zeros", or given (this tool's)

    def rows(self) -> dict[str, object]:
        return {key: value for key, value in asdict(self).items() if value is not None}


def searcher(problem, settings: EvoTorchSettings, center_init=None):
    """The PGPE or SNES searcher of ``settings`` on ``problem``, from ``center_init`` if given."""
    from evotorch.algorithms import PGPE, SNES

    spread = {"stdev_init": settings.sigma} if settings.sigma is not None else {"radius_init": settings.radius}
    if settings.centre == "zeros" and center_init is None:
        center_init = problem.make_zeros(num_solutions=1)[0]
    if settings.strategy == "pgpe":
        optimizer = {} if settings.max_speed is None else {"max_speed": settings.max_speed}
        return PGPE(problem, popsize=settings.popsize, center_learning_rate=settings.center_lr,
                    stdev_learning_rate=settings.sigma_lr, optimizer="clipup", optimizer_config=optimizer,
                    stdev_max_change=settings.max_sigma_change, ranking_method="centered", symmetric=True,
                    center_init=center_init, **spread)
    if settings.strategy == "snes":
        return SNES(problem, popsize=settings.popsize, center_learning_rate=settings.center_lr,
                    stdev_learning_rate=settings.sigma_lr, center_init=center_init, **spread)
    raise ValueError(f"strategy {settings.strategy!r}: choose pgpe or snes")


def problem(env_id: str, obs_norm: bool, workers: int = 1, hidden: tuple[int, ...] = HIDDEN):
    """GymNE on ``env_id``, its environments (and Ray actors) made now."""
    from evotorch.neuroevolution import GymNE

    made = GymNE(env=SeededEnv(env_id), network=network(hidden), observation_normalization=obs_norm,
                 num_actors=workers if workers > 1 else None)
    if workers > 1:
        made.all_remote_envs().reset()  # starts Ray and the actors, each making its environment
    else:
        made.get_env()
    return made


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="\n".join(__doc__.splitlines()[2:]))
    parser.add_argument("--environment", default="HalfCheetah-v5")
    parser.add_argument("--strategy", default="pgpe", choices=("pgpe", "snes"))
    parser.add_argument("--popsize", type=int, default=32)
    parser.add_argument("--generations", type=int, default=5)
    parser.add_argument("--sigma", type=float, default=0.1, help="the initial standard deviation (stdev_init)")
    parser.add_argument("--center_lr", type=float, default=None, help="PGPE: default half the maximum speed")
    parser.add_argument("--max_speed", type=float, default=None,
                        help="PGPE: ClipUp's maximum speed (default: sigma sqrt(d) / 15, ClipUp's rule)")
    parser.add_argument("--workers", type=int, default=1, help="Ray actors (num_actors); 1: this process alone")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, default=None, help="write each generation's seconds and steps here")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    seed_everything(args.seed)
    made = problem(args.environment, obs_norm=False, workers=args.workers)
    max_speed = args.max_speed or args.sigma * made.solution_length ** 0.5 / 15
    settings = EvoTorchSettings(args.strategy, args.popsize, sigma=args.sigma,
                                center_lr=(args.center_lr or max_speed / 2) if args.strategy == "pgpe" else None,
                                sigma_lr=0.1 if args.strategy == "pgpe" else None,
                                max_speed=max_speed if args.strategy == "pgpe" else None)
    search = searcher(made, settings)
    generations = []
    for number in range(1, args.generations + 1):
        before, started = made.interaction_count, time.perf_counter()
        search.step()
        seconds = time.perf_counter() - started
        generations.append({"seconds": seconds, "env_steps": made.interaction_count - before})
        print(f"generation {number}: mean return {float(search.status['mean_eval']):.1f}, {seconds:.2f} s", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps({"generations": generations}) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
