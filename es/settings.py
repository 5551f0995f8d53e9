"""The settings of the ES and of a run, as frozen data (the other concerns: ``policies.registry``'s
``PolicySettings``, ``envs.settings``, ``report.loggers``' ``LogSettings``; ``cli.config`` joins them into
``config.json``).

Each field is the one declaration of its option (``settings.setting``): its default, range or choices,
flag, help, and whether a resume may change it. ``ESSettings`` is the search's settings (``SearchSettings``:
the population, the fitness, the episodes, the centre's evaluation, the strategy) joined with each
strategy's own, which its plug-in declares (``es.strategies``: OpenAI-ES's learning rate, schedules,
shaping and optimiser; PGPE's, SNES's and ARS's; ``plugins.joined``), so that a run's ES settings stay one
flat section of config.json and of an experiment file, which holds the chosen strategy's. Every constant the
original hard-coded is a field, with the original's value as its default (docs/original.md, "The evolution
strategy"); the options beyond the original default to the original's behaviour.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from es.strategies import STRATEGIES
from es.strategy import STRATEGY_GROUP
from plugins import joined
from settings import ANY, FLOAT32_MAX, MODERN, SEED_RANGE, check, setting

BACKENDS = ("process", "ray")  # es.backends: a process pool on this machine, or Ray


@dataclass(frozen=True)
class SearchSettings:
    """What defines the search: two runs with equal ESSettings (and seed) step alike. The loop's settings and
    which strategy it runs, then (``ESSettings``) each strategy's own, in the registry's order."""

    popsize: int = setting(200, low=2, metavar="N",
                           help="population size (even for the strategies that sample mirrored pairs: "
                                f"{', '.join(name for name, plugin in STRATEGIES.items() if plugin.pairs)})")
    sigma: float = setting(0.1, low=0, low_open=True, high=FLOAT32_MAX,
                           help="initial noise standard deviation (the members theta + sigma * noise are float32)")
    fitness_l2: float = setting(0.01, low=0, high=FLOAT32_MAX, metavar="C", group=MODERN,
                                help="the original's L2 penalty in the fitness: return - C * mean(theta_m^2) "
                                     "(recorded in float32)")
    episodes: int = setting(1, low=1, metavar="E", help="episodes per fitness evaluation (the fitness is their mean)")
    noise_size: int | None = setting(None, flag=None, low=1,
                                     help="floats in the noise table; default: sized to the parameter count")
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
    strategy: str = setting("openai", choices=STRATEGIES, group=STRATEGY_GROUP,
                            help=f"{STRATEGIES.described()}; docs/strategies.md")

    def __post_init__(self) -> None:
        check(self)
        STRATEGIES[self.strategy].check(self)  # the population rule, the strategy's own checks

    def evaluates_centre(self, generation: int) -> bool:
        """Whether the centre runs its evaluation episodes in generation ``generation`` (0-based):
        generations G, 2G, ... counted from 1."""
        return self.eval_every is not None and (generation + 1) % self.eval_every == 0


ESSettings = joined(SearchSettings, STRATEGIES, name="ESSettings", module=__name__)


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
    def __post_init__(self) -> None:
        check(self)

    @property
    def workers(self) -> int:
        return (os.cpu_count() or 1) if self.threads == -1 else self.threads

    @property
    def in_process(self) -> bool:
        """Everything in this process: ``--threads 1``, or a one-core machine's pool."""
        return self.threads == 1 or (self.backend == "process" and self.workers == 1)
