"""The settings of the ES and of a run, as frozen data (the other concerns: ``policies.registry``'s
``PolicySettings``, ``envs.settings``; ``cli.config`` joins the four into ``config.json``).

Each field is the one declaration of its option (``settings.setting``): its default, range or choices,
flag, help, and whether a resume may change it. Every constant the original hard-coded is a field here,
with the original's value as its default (docs/original.md, "The evolution strategy"): the learning-rate floor, the
sigma decay and floor, and the L2 coefficient of the fitness penalty; those have no flag (experiment files
and config.json only). The options beyond the original (the shaping, the optimiser, weight decay in the
gradient, observation statistics, centre evaluation; OpenAI's es-starter and pytorch-es, docs/original.md,
"The evolution strategy" and "pytorch-es") default to the original's behaviour. The strategy
(``--strategy``, ``es.strategies``; default openai, the original's) and each strategy's settings are one
block of fields, each requiring the strategy it belongs to; the openai-only settings require
``--strategy openai``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from es.optimizers import OPTIMIZERS
from es.shaping import SHAPINGS
from es.strategies import PGPE_OPTIMIZERS, STRATEGIES
from settings import ANY, FLOAT32_MAX, SEED_RANGE, check, setting

BACKENDS = ("process", "ray")  # es.backends: a process pool on this machine, or Ray
MODERN = "beyond the original algorithm (defaults: the original)"
STRATEGY = "strategies beyond the original's OpenAI-ES (--strategy openai)"
OPENAI = ("strategy", "openai")  # what the settings of OpenAI-ES's step require


def optional_float(text: str) -> float | None:
    """A flag's number, or ``none`` for no value."""
    return None if text.strip().lower() == "none" else float(text)


@dataclass(frozen=True)
class ESSettings:
    """What defines the search: two runs with equal ESSettings (and seed) step alike."""

    popsize: int = setting(200, low=2, metavar="N", help="population size (even: mirrored pairs)")
    lr: float = setting(0.2, requires=OPENAI, low=0, low_open=True, help="ES learning rate")
    decay: float = setting(0.995, requires=OPENAI, low=0, high=1, low_open=True,
                           help="learning-rate decay per generation (while lr > lr_floor)")
    sigma: float = setting(0.1, low=0, low_open=True, high=FLOAT32_MAX,
                           help="initial noise standard deviation (the members theta + sigma * noise are float32)")
    lr_floor: float = setting(0.001, requires=OPENAI, flag=None, low=0, help="lr decays while above this")
    sigma_decay: float = setting(0.999, requires=OPENAI, flag=None, low=0, high=1, low_open=True,
                                 help="sigma *= sigma_decay per generation while sigma > sigma_floor")
    sigma_floor: float = setting(0.01, requires=OPENAI, flag=None, low=0, help="sigma decays while above this")
    fitness_l2: float = setting(0.01, low=0, high=FLOAT32_MAX, metavar="C", group=MODERN,
                                help="the original's L2 penalty in the fitness: return - C * mean(theta_m^2) "
                                     "(recorded in float32)")
    episodes: int = setting(1, low=1, metavar="E", help="episodes per fitness evaluation (the fitness is their mean)")
    noise_size: int | None = setting(None, flag=None, low=1,
                                     help="floats in the noise table; default: sized to the parameter count")
    shaping: str = setting("rank_std", requires=OPENAI, choices=SHAPINGS, group=MODERN,
                           help="fitness shaping: rank_std (the original: centered ranks, standardised), rank "
                                "(OpenAI's centered ranks), none (the fitness, standardised), nes (pytorch-es's NES "
                                "utilities)")
    optimizer: str = setting("sgd", choices=OPTIMIZERS, aliases={"useAdam": "adam"}, requires=OPENAI, group=MODERN,
                             help="sgd (the original), adam or momentum (OpenAI's; gradient sum F*eps / N); --lr is "
                                  "the step size")
    beta1: float = setting(0.9, low=0, high=1, high_open=True, requires=("optimizer", "adam"), group=MODERN,
                           help="Adam's first-moment decay")
    beta2: float = setting(0.999, low=0, high=1, high_open=True, requires=("optimizer", "adam"), group=MODERN,
                           help="Adam's second-moment decay")
    momentum: float = setting(0.9, low=0, high=1, high_open=True, requires=("optimizer", "momentum"), group=MODERN,
                              help="the momentum of --optimizer momentum")
    l2coeff: float = setting(0.0, requires=OPENAI, low=0, metavar="C", group=MODERN,
                             help="weight decay in the gradient, g <- g - C * theta (OpenAI's l2coeff)")
    obs_norm_prob: float = setting(0.01, low=0, high=1, low_open=True, requires=("obs_norm", True), metavar="P",
                                   group=MODERN, help="the fraction of mirrored pairs whose observations update the "
                                                      "statistics of --obs_norm")
    eval_every: int | None = setting(None, low=1, metavar="G", group=MODERN,
                                     help="every G generations the centre also runs --eval_episodes episodes on seeds "
                                          "of their own; their mean picks best.dat")
    eval_episodes: int = setting(10, low=1, metavar="K", requires=("eval_every", ANY), group=MODERN,
                                 help="the centre's evaluation episodes of --eval_every")
    variable_ep_len: bool = setting(False, group=MODERN,
                                    help="pytorch-es's adaptive episode length: each generation's episodes end after "
                                         "twice the mean length of the last generation's perturbed episodes")

    # --- the strategy (es.strategies) and the settings of each
    strategy: str = setting("openai", choices=STRATEGIES, group=STRATEGY,
                            help="openai (Salimans et al. 2017, the original), pgpe (Sehnke et al. 2010, with ClipUp), "
                                 "snes (separable NES), cma_es and sep_cma_es (the cmaes library: pip install -r "
                                 "requirements-strategies.txt), ars (Mania et al. 2018; V2 with --obs_norm "
                                 "--obs_norm_prob 1); docs/strategies.md")
    pgpe_optimizer: str = setting("clipup", choices=PGPE_OPTIMIZERS, requires=("strategy", "pgpe"), group=STRATEGY,
                                  help="how PGPE steps its centre (ClipUp, Toklu et al. 2020; Adam; plain gradient "
                                       "ascent)")
    pgpe_lr: float | None = setting(None, low=0, low_open=True, requires=("strategy", "pgpe"), group=STRATEGY,
                                    shown_default="--clipup_max_speed / 2", help="PGPE's centre step size")
    clipup_max_speed: float | None = setting(None, low=0, low_open=True, requires=("strategy", "pgpe"),
                                             group=STRATEGY, shown_default="--sigma * sqrt(d) / 15, d the parameters",
                                             help="ClipUp's maximum speed (the velocity's largest norm); by default "
                                                  "the ClipUp paper's rule: initial radius sigma sqrt(d) = 15 x it")
    clipup_momentum: float = setting(0.9, low=0, high=1, high_open=True, group=STRATEGY,
                                     requires=(("strategy", "pgpe"), ("pgpe_optimizer", "clipup")),
                                     help="ClipUp's momentum (the velocity's decay)")
    pgpe_sigma_lr: float = setting(0.1, low=0, low_open=True, requires=("strategy", "pgpe"), group=STRATEGY,
                                   help="PGPE: sigma += pgpe_sigma_lr * its gradient")
    pgpe_max_sigma_change: float | None = setting(0.2, low=0, high=1, low_open=True, parse=optional_float,
                                                  requires=("strategy", "pgpe"), metavar="C", group=STRATEGY,
                                                  help="PGPE: each sigma changes by at most this fraction per "
                                                       "generation; none: no limit")
    snes_lr: float = setting(1.0, low=0, low_open=True, requires=("strategy", "snes"), group=STRATEGY,
                             help="SNES: the centre's learning rate (the paper's 1)")
    snes_sigma_lr: float | None = setting(None, low=0, low_open=True, requires=("strategy", "snes"), group=STRATEGY,
                                          shown_default="(3 + ln d) / (5 sqrt d), d the parameters",
                                          help="SNES: sigma's learning rate")
    ars_lr: float = setting(0.02, low=0, low_open=True, requires=("strategy", "ars"), group=STRATEGY,
                            help="ARS: the step size alpha")
    ars_top: int | None = setting(None, low=1, requires=("strategy", "ars"), metavar="B", group=STRATEGY,
                                  shown_default="all --popsize / 2",
                                  help="ARS: the b best directions make the step (V1-t, V2-t)")

    def __post_init__(self) -> None:
        check(self)
        directions = self.popsize // 2
        if self.ars_top is not None and self.ars_top > directions:
            raise ValueError(f"--ars_top must be a whole number from 1 to {directions} (the directions: --popsize / 2)"
                             ", "
                             f"got {self.ars_top}")

    def evaluates_centre(self, generation: int) -> bool:
        """Whether the centre runs its evaluation episodes in generation ``generation`` (0-based):
        generations G, 2G, ... counted from 1."""
        return self.eval_every is not None and (generation + 1) % self.eval_every == 0


def _threads(value: int) -> bool:
    return value == -1 or value >= 1


def original_threads(text: str) -> int:
    """--threads as the original took it: any value <= 1 but -1 (0, -2) ran serially, so it means 1."""
    value = int(text)
    if value == 0 or value < -1:
        try:
            print(f"note: --threads {value} runs everything in this process, as the original did; that is "
                  "--threads 1", flush=True)
        except BrokenPipeError:  # nobody reads the output: the run goes on (cli.errors.say)
            pass
        return 1
    return value


@dataclass(frozen=True)
class RunSettings:
    """How and where a run executes; ``seed`` and ``generations`` aside, none of it changes a result."""

    generations: int = setting(300, low=1, metavar="G", resumable=True,
                               help="number of generations (with --resume: the total, counting those already run)")
    print_every: int = setting(1, low=1, metavar="K", resumable=True, help="save files every K generations")
    folder: str = setting("weights", nonempty=True, metavar="DIR", help="where run folders are created")
    threads: int = setting(-1, rule=(_threads, "-1 (all cores) or a whole number >= 1"), metavar="W", resumable=True,
                           parse=original_threads,
                           help="worker processes; -1 = all cores, 1 = run in this process (0 and other negative "
                                "values too, as the original)")
    seed: int = setting(0, low=SEED_RANGE[0], high=SEED_RANGE[1], shown_default="a random one, printed and saved",
                        help="seed of the run")
    backend: str = setting("process", choices=BACKENDS, resumable=True,
                           help="parallel backend for --threads > 1: a process pool on this machine, or Ray (one "
                                "machine or a cluster; pip install -r requirements-ray.txt)")
    ray_address: str | None = setting(None, requires=("backend", "ray"), metavar="ADDRESS", resumable=True,
                                      shown_default="start a local Ray with --threads CPUs",
                                      help="'auto' joins the cluster `ray start` runs on this machine, HOST:PORT "
                                           "another one")
    tensorboard: bool = setting(False, resumable=True, group=MODERN,
                                help="also write every metrics column as TensorBoard scalars in <run>/tensorboard "
                                     "(pip install -r requirements-tensorboard.txt)")

    def __post_init__(self) -> None:
        check(self)

    @property
    def workers(self) -> int:
        return (os.cpu_count() or 1) if self.threads == -1 else self.threads

    @property
    def in_process(self) -> bool:
        """Everything in this process: ``--threads 1``, or a one-core machine's pool."""
        return self.threads == 1 or (self.backend == "process" and self.workers == 1)
