"""The settings of the ES and of a run, as frozen data (the other concerns: ``policies.settings``,
``envs.settings``; ``config`` joins the four into ``config.json``).

Every constant the original hard-coded is a field here, with the original's value as its default
(upstream spec §2.1, §9.1 item 7): the learning-rate floor, the sigma decay and floor, and the L2
coefficient of the fitness penalty.
"""

from __future__ import annotations

import os
from dataclasses import dataclass


@dataclass(frozen=True)
class ESSettings:
    """What defines the search: two runs with equal ESSettings (and seed) step alike."""

    popsize: int = 200  # even: mirrored pairs
    lr: float = 0.2
    decay: float = 0.995  # lr *= decay per generation while lr > lr_floor
    sigma: float = 0.1
    lr_floor: float = 0.001
    sigma_decay: float = 0.999  # sigma *= sigma_decay per generation while sigma > sigma_floor
    sigma_floor: float = 0.01
    fitness_l2: float = 0.01  # fitness = return - fitness_l2 * mean(theta_m^2) over the penalised part
    episodes: int = 1  # episodes per fitness evaluation (the fitness is their mean)
    noise_size: int | None = None  # floats in the noise table; None: sized to the parameter count


@dataclass(frozen=True)
class RunSettings:
    """How and where a run executes; ``seed`` and ``generations`` aside, none of it changes a result."""

    generations: int = 300
    print_every: int = 1  # save the files every this many generations
    folder: str = "weights"
    threads: int = -1  # -1: one worker per core
    seed: int = 0
    backend: str = "process"  # "process" or "ray"
    ray_address: str | None = None  # --backend ray: None starts a local Ray

    @property
    def workers(self) -> int:
        return (os.cpu_count() or 1) if self.threads == -1 else self.threads

    @property
    def in_process(self) -> bool:
        """Everything in this process: ``--threads 1``, or a one-core machine's pool."""
        return self.threads == 1 or (self.backend == "process" and self.workers == 1)


RESUMABLE = ("generations", "threads", "backend", "ray_address", "print_every")  # what a resume may change
