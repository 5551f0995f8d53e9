"""The ask/tell interface every strategy shares, and what a strategy declares to the registry.

The interface (``Strategy``, in the style of evosax): ``initial_state(theta)``; ``ask(state, rng,
noise)`` returns the generation's ``Population`` -- a noise index and a sign per member (the wire
protocol of docs/how-it-works.md), and what the workers need beside theta: a per-parameter sigma (``scale``)
or, for a strategy that cannot draw from the noise table, the members' vectors (``rows``), both
published once per generation as theta is; ``tell(state, noise, population, fitness)`` returns the
new ``ESState`` and a dict of metrics (``update_factor``, ``skipped``). A strategy's own arrays live
in ``ESState.strategy`` and the optimiser's in ``ESState.optimizer``, both saved in the checkpoint.

A strategy's module (``es.strategies``) declares, as evosax's algorithms own their parameters:

- its settings: a frozen dataclass subclassing ``StrategySettings`` (the population size and initial
  sigma every strategy reads), each field made with ``settings.setting()`` and requiring its strategy
  (``requires=("strategy", NAME)``), so that its flags, TOML keys, config.json keys, checks and docs
  come from that one declaration (``es.settings.ESSettings`` joins every strategy's);
- its entry (``StrategyEntry``): the factory from those settings and the number of parameters, the
  settings class, and the population rule -- whether members come in mirrored pairs, which needs an
  even ``--popsize`` (refused in one line otherwise, never rounded).

The registry of strategies is ``es.strategies.STRATEGIES``, one line per strategy.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from es.noise import NoiseTable
from es.optimizers import OptimizerState
from settings import FLOAT32_MAX, setting

STRATEGY_GROUP = "strategies beyond the original's OpenAI-ES (--strategy openai)"  # their flags' --help group


@dataclass(frozen=True)
class StrategySettings:
    """What every strategy reads: the population and the initial scale of the search."""

    popsize: int = setting(200, low=2, metavar="N",
                           help="population size (even for the strategies that sample mirrored pairs: openai, pgpe, "
                                "ars)")
    sigma: float = setting(0.1, low=0, low_open=True, high=FLOAT32_MAX,
                           help="initial noise standard deviation (the members theta + sigma * noise are float32)")

    def validate(self) -> None:
        """What a strategy's settings refuse beyond each one's own range (a ValueError naming the flag);
        called for the run's strategy only. Nothing here."""


@dataclass(frozen=True)
class ESState:
    theta: np.ndarray  # float32: the centre, what the run saves and evaluates
    lr: float  # the step size (the metrics' lr column)
    sigma: float  # the search's scale (the metrics' sigma column; the mean of a per-parameter sigma)
    generation: int = 0  # generations done
    optimizer: OptimizerState = field(default_factory=dict)
    strategy: dict[str, np.ndarray] = field(default_factory=dict)  # the strategy's own arrays (PGPE's sigma, ...)


@dataclass(frozen=True)
class Population:
    """One generation's members as the workers rebuild them: member m is
    ``theta + signs[m] * sigma * noise[indices[m] : indices[m] + dim]``, with ``scale`` (a float32
    per-parameter sigma) in place of sigma where given, or ``rows[indices[m]]`` where rows are given."""

    indices: np.ndarray  # int64: noise index (or row of ``rows``) of each member
    signs: np.ndarray  # int8: +1 or -1
    mirrored: bool = True  # members 2p and 2p+1 are a mirrored pair: they share their episode seeds
    scale: np.ndarray | None = None  # float32 (dim,): per-parameter sigma, published with theta
    rows: np.ndarray | None = None  # float32 (members, dim): the members themselves, published with theta


class Strategy(Protocol):
    population_size: int

    def initial_state(self, theta: np.ndarray) -> ESState:
        """The state before the first generation, centred on ``theta``."""

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        """The generation's members; every random draw comes from ``rng``."""

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        """The next state from each member's fitness (member order, higher is better), and metrics."""


@dataclass(frozen=True)
class StrategyEntry:
    """A strategy as the registry holds it."""

    make: Callable[[Any, int], Strategy]  # (the run's settings, an instance of ``settings``; parameters) -> it
    settings: type[StrategySettings] = StrategySettings  # the dataclass declaring its own settings
    pairs: bool = False  # its members are mirrored pairs: --popsize must be even

    def check(self, name: str, settings: StrategySettings) -> None:
        """The population rule, then the strategy's own (``validate``): a ValueError in one line."""
        size = settings.popsize
        if self.pairs and size % 2:
            raise ValueError(f"--popsize {size} is odd, but --strategy {name} samples mirrored pairs; give an even "
                             f"--popsize such as {size - 1} or {size + 1}")
        self.settings.validate(settings)


def mirrored_population(rng: np.random.Generator, noise: NoiseTable, dim: int, pairs: int) -> Population:
    """``pairs`` noise slices, each taken with + then - : [+e1, -e1, +e2, -e2, ...]."""
    indices = noise.sample_indices(rng, dim, pairs)
    return Population(np.repeat(indices, 2), np.tile(np.array([1, -1], dtype=np.int8), pairs))


def check_fitness(fitness: np.ndarray, population_size: int) -> None:
    if fitness.shape != (population_size,):
        raise ValueError(f"expected {population_size} fitness values, got shape {fitness.shape}")
