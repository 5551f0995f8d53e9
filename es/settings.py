"""The settings of the ES and of a run, as frozen data (the other concerns: ``policies.settings``,
``envs.settings``; ``config`` joins the four into ``config.json``).

Every constant the original hard-coded is a field here, with the original's value as its default
(upstream spec §2.1, §9.1 item 7): the learning-rate floor, the sigma decay and floor, and the L2
coefficient of the fitness penalty. The options beyond the original (the shaping, the optimiser,
weight decay in the gradient, observation statistics, centre evaluation; OpenAI's es-starter and
pytorch-es, spec §2.5 and §7.4) default to the original's behaviour. Fields are named as their
flags, and a value out of range is refused with a message naming the flag.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from es.optimizers import OPTIMIZERS
from es.shaping import SHAPINGS
from es.strategies import PGPE_OPTIMIZERS, STRATEGIES


def check_setting(name: str, value, valid: bool, expected: str) -> None:
    """Refuse ``value`` of the setting (and flag) ``name`` unless ``valid``."""
    if not valid:
        raise ValueError(f"--{name} must be {expected}, got {value}")


def check_choice(name: str, value: str, choices) -> None:
    check_setting(name, repr(value), value in choices, f"one of {', '.join(choices)}")


def is_number(value) -> bool:
    """A finite int or float (an experiment file or config.json can hold anything: a string, a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def is_whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def check_number(name: str, value, low: float, high: float = math.inf, low_open: bool = False) -> None:
    """``value`` a finite number in [low, high] ((low, high] with ``low_open``)."""
    valid = is_number(value) and (low < value if low_open else low <= value) and value <= high
    bounds = f"{'(' if low_open else '['}{low:g}, {high:g}]" if high < math.inf else \
        f"{'>' if low_open else '>='} {low:g}"
    check_setting(name, value, valid, f"a number {'in ' if high < math.inf else ''}{bounds}")


def check_whole(name: str, value, low: int) -> None:
    check_setting(name, value, is_whole(value) and value >= low, f"a whole number >= {low}")


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
    shaping: str = "rank_std"  # es.shaping.SHAPINGS
    optimizer: str = "sgd"  # es.optimizers.OPTIMIZERS
    beta1: float = 0.9  # adam
    beta2: float = 0.999  # adam
    momentum: float = 0.9  # momentum
    l2coeff: float = 0.0  # weight decay in the gradient: g <- g - l2coeff * theta
    obs_norm_prob: float = 0.01  # with obs_norm: the fraction of mirrored pairs whose observations count
    eval_every: int | None = None  # every this many generations the centre runs eval_episodes episodes
    eval_episodes: int = 10
    variable_ep_len: bool = False  # pytorch-es: cap each generation's episodes at twice the last one's mean length
    # --- the strategy (es.strategies) and the settings of each; STRATEGY_REQUIRES says which applies to which
    strategy: str = "openai"  # es.strategies.STRATEGIES; openai: the original's OpenAI-ES
    pgpe_optimizer: str = "clipup"  # es.strategies.PGPE_OPTIMIZERS: how PGPE steps its centre
    pgpe_lr: float | None = None  # PGPE's centre step size; None: clipup_max_speed / 2 (Toklu et al. 2020)
    clipup_max_speed: float = 0.15  # ClipUp: the velocity's largest norm
    clipup_momentum: float = 0.9  # ClipUp: the velocity's decay
    pgpe_sigma_lr: float = 0.1  # PGPE: sigma += pgpe_sigma_lr * its gradient
    pgpe_max_sigma_change: float | None = 0.2  # PGPE: each sigma changes by at most this fraction per generation
    snes_lr: float = 1.0  # SNES: the centre's learning rate (the paper's 1)
    snes_sigma_lr: float | None = None  # SNES: sigma's learning rate; None: the paper's (3 + ln d) / (5 sqrt d)
    ars_lr: float = 0.02  # ARS: the step size alpha
    ars_top: int | None = None  # ARS: the b best directions the step uses; None: all popsize / 2

    def __post_init__(self) -> None:
        """Every value checked, whether it came from a flag, an experiment file or a config.json."""
        check_whole("popsize", self.popsize, 2)
        for name in ("lr", "sigma"):
            check_number(name, getattr(self, name), 0, low_open=True)
        for name in ("decay", "sigma_decay"):
            check_number(name, getattr(self, name), 0, 1, low_open=True)
        check_setting("obs_norm_prob", self.obs_norm_prob, is_number(self.obs_norm_prob) and 0 < self.obs_norm_prob <= 1,
                      "in (0, 1]")
        for name in ("lr_floor", "sigma_floor", "l2coeff", "fitness_l2"):
            check_number(name, getattr(self, name), 0)
        for name in ("beta1", "beta2", "momentum"):
            value = getattr(self, name)
            check_setting(name, value, is_number(value) and 0 <= value < 1, "in [0, 1)")
        check_whole("episodes", self.episodes, 1)
        check_whole("eval_episodes", self.eval_episodes, 1)
        if self.eval_every is not None:
            check_whole("eval_every", self.eval_every, 1)
        if self.noise_size is not None:
            check_whole("noise_size", self.noise_size, 1)
        check_choice("shaping", self.shaping, SHAPINGS)
        check_choice("optimizer", self.optimizer, OPTIMIZERS)
        self._check_strategy_settings()

    def _check_strategy_settings(self) -> None:
        check_choice("strategy", self.strategy, STRATEGIES)
        check_choice("pgpe_optimizer", self.pgpe_optimizer, PGPE_OPTIMIZERS)
        for name in ("clipup_max_speed", "pgpe_sigma_lr", "snes_lr", "ars_lr"):
            check_number(name, getattr(self, name), 0, low_open=True)
        for name in ("pgpe_lr", "snes_sigma_lr"):
            if getattr(self, name) is not None:
                check_number(name, getattr(self, name), 0, low_open=True)
        check_setting("clipup_momentum", self.clipup_momentum,
                      is_number(self.clipup_momentum) and 0 <= self.clipup_momentum < 1, "in [0, 1)")
        if self.pgpe_max_sigma_change is not None:
            check_number("pgpe_max_sigma_change", self.pgpe_max_sigma_change, 0, 1, low_open=True)
        if self.ars_top is not None:
            directions = self.popsize // 2
            check_setting("ars_top", self.ars_top, is_whole(self.ars_top) and 1 <= self.ars_top <= directions,
                          f"a whole number from 1 to {directions} (the directions: --popsize / 2)")

    def evaluates_centre(self, generation: int) -> bool:
        """Whether the centre runs its evaluation episodes in generation ``generation`` (0-based):
        generations G, 2G, ... counted from 1."""
        return self.eval_every is not None and (generation + 1) % self.eval_every == 0


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
    tensorboard: bool = False  # also write every metrics column as TensorBoard scalars

    def __post_init__(self) -> None:
        check_whole("generations", self.generations, 1)
        check_whole("print_every", self.print_every, 1)
        check_setting("threads", self.threads, is_whole(self.threads) and (self.threads == -1 or self.threads >= 1),
                      "-1 (all cores) or a whole number >= 1")
        check_setting("seed", self.seed, is_whole(self.seed) and 0 <= self.seed < 2**31,
                      f"a whole number from 0 to {2**31 - 1}")

    @property
    def workers(self) -> int:
        return (os.cpu_count() or 1) if self.threads == -1 else self.threads

    @property
    def in_process(self) -> bool:
        """Everything in this process: ``--threads 1``, or a one-core machine's pool."""
        return self.threads == 1 or (self.backend == "process" and self.workers == 1)


# setting -> the values of other settings it has an effect with; given otherwise, the scripts refuse it
STRATEGY_REQUIRES: dict[str, dict[str, str]] = {
    **{name: {"strategy": "openai"} for name in ("lr", "decay", "lr_floor", "sigma_decay", "sigma_floor", "shaping",
                                                 "optimizer", "l2coeff")},
    **{name: {"strategy": "pgpe"} for name in ("pgpe_optimizer", "pgpe_lr", "clipup_max_speed", "pgpe_sigma_lr",
                                               "pgpe_max_sigma_change")},
    "clipup_momentum": {"strategy": "pgpe", "pgpe_optimizer": "clipup"},
    **{name: {"strategy": "snes"} for name in ("snes_lr", "snes_sigma_lr")},
    **{name: {"strategy": "ars"} for name in ("ars_lr", "ars_top")},
}

RESUMABLE = ("generations", "threads", "backend", "ray_address", "print_every", "tensorboard")  # what a resume may change
