"""OpenAI-ES with mirrored sampling, the original code's strategy (``--strategy openai``, the default).

Salimans et al. 2017 ("Evolution Strategies as a Scalable Alternative to Reinforcement Learning"),
Algorithm 2, as adapted by Najarro & Risi 2020 (docs/original.md, "The evolution strategy"):

- mirrored sampling: members 2p and 2p+1 are theta + sigma*eps_p and theta - sigma*eps_p;
- fitness shaping (``es.shaping``), injected: by default centered ranks, then standardised;
- the step (``es.optimizers``), injected: by default theta += lr / (N * sigma) * sum_m F_m * eps_m;
  OpenAI's Adam or momentum on request, each with optional weight decay in the gradient;
- schedules: lr *= decay while lr > lr_floor; sigma *= sigma_decay while sigma > sigma_floor,
  whatever the optimiser (lr is its step size).

Its settings (``OpenAISettings``) are the original's constants, with the original's values as their
defaults (docs/original.md, "The evolution strategy": the learning-rate floor, the sigma decay and floor have no
flag, experiment files and config.json only), and the options of OpenAI's es-starter and pytorch-es
(docs/original.md, "The evolution strategy" and "pytorch-es": the shaping, the optimiser, weight decay in
the gradient), defaulting to the
original's behaviour. ``OpenES(settings)`` picks the shaping and the optimiser they name from their
registries.

The perturbations eps_p are slices of a shared noise table (``es.noise``), so a member is only a
noise index and a sign.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from es.noise import NoiseTable
from es.optimizers import OPTIMIZERS, Optimizer, make_optimizer
from es.shaping import SHAPINGS, Shaping
from es.strategy import ESState, Population, StrategyPlugin, check_fitness, mirrored_population
from settings import MODERN, setting


@dataclass(frozen=True)
class OpenAISettings:
    """Its own settings (``popsize`` and ``sigma`` are the search's: ``es.settings``)."""

    lr: float = setting(0.2, low=0, low_open=True, help="ES learning rate")
    decay: float = setting(0.995, low=0, high=1, low_open=True,
                           help="learning-rate decay per generation (while lr > lr_floor)")
    lr_floor: float = setting(0.001, flag=None, low=0, help="lr decays while above this")
    sigma_decay: float = setting(0.999, flag=None, low=0, high=1, low_open=True,
                                 help="sigma *= sigma_decay per generation while sigma > sigma_floor")
    sigma_floor: float = setting(0.01, flag=None, low=0, help="sigma decays while above this")
    shaping: str = setting("rank_std", choices=SHAPINGS, group=MODERN,
                           help="fitness shaping: rank_std (the original: centered ranks, standardised), rank "
                                "(OpenAI's centered ranks), none (the fitness, standardised), nes (pytorch-es's NES "
                                "utilities)")
    optimizer: str = setting("sgd", choices=OPTIMIZERS, aliases={"useAdam": "adam"}, group=MODERN,
                             help="sgd (the original), adam or momentum (OpenAI's; gradient sum F*eps / N); --lr is "
                                  "the step size")
    beta1: float = setting(0.9, low=0, high=1, high_open=True, requires=("optimizer", "adam"), group=MODERN,
                           help="Adam's first-moment decay")
    beta2: float = setting(0.999, low=0, high=1, high_open=True, requires=("optimizer", "adam"), group=MODERN,
                           help="Adam's second-moment decay")
    momentum: float = setting(0.9, low=0, high=1, high_open=True, requires=("optimizer", "momentum"), group=MODERN,
                              help="the momentum of --optimizer momentum")
    l2coeff: float = setting(0.0, low=0, metavar="C", group=MODERN,
                             help="weight decay in the gradient, g <- g - C * theta (OpenAI's l2coeff)")


def decay_lr(lr: float, settings) -> float:
    return lr * settings.decay if lr > settings.lr_floor else lr


def decay_sigma(sigma: float, settings) -> float:
    return sigma * settings.sigma_decay if sigma > settings.sigma_floor else sigma


@dataclass(frozen=True)
class OpenES:
    settings: object  # the run's es.settings.ESSettings: its population size is even (the plug-in's population rule)
    shaping: Shaping | None = None  # default: the one settings.shaping names
    optimizer: Optimizer | None = None  # default: the one settings.optimizer names

    def __post_init__(self) -> None:
        if self.shaping is None:
            object.__setattr__(self, "shaping", SHAPINGS[self.settings.shaping])
        if self.optimizer is None:
            object.__setattr__(self, "optimizer", make_optimizer(self.settings))

    @property
    def population_size(self) -> int:
        return self.settings.popsize

    @property
    def pairs(self) -> int:
        return self.population_size // 2

    def initial_state(self, theta: np.ndarray) -> ESState:
        return ESState(np.asarray(theta, dtype=np.float32), self.settings.lr, self.settings.sigma)

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        """Noise index and sign of every member, in member order [+e1, -e1, +e2, -e2, ...]."""
        return mirrored_population(rng, noise, state.theta.size, self.pairs)

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        """One step from the fitness of each member (member order, higher is better)."""
        check_fitness(fitness, self.population_size)
        shaped = self.shaping(fitness)
        normaliser = self.population_size * state.sigma
        theta, optimizer_state = state.theta, state.optimizer
        if shaped is not None:
            weighted_sum = self.weighted_noise(shaped, population.indices, noise, theta.size)
            with np.errstate(over="ignore", invalid="ignore"):  # a non-finite step is the caller's to refuse
                theta, optimizer_state = self.optimizer.step(theta, weighted_sum, self.population_size, state.sigma,
                                                             state.lr, optimizer_state)
        new_state = replace(state, theta=theta, lr=decay_lr(state.lr, self.settings),
                            sigma=decay_sigma(state.sigma, self.settings), generation=state.generation + 1,
                            optimizer=optimizer_state)
        return new_state, {"update_factor": state.lr / normaliser, "skipped": shaped is None}

    @staticmethod
    def weighted_noise(shaped: np.ndarray, indices: np.ndarray, noise: NoiseTable, dim: int) -> np.ndarray:
        """sum_m F_m eps_m over mirrored pairs: F+ eps + F- (-eps) = (F+ - F-) eps, in float64."""
        total = np.zeros(dim, dtype=np.float64)
        for weight, index in zip(shaped[0::2] - shaped[1::2], indices[0::2]):
            total += weight * noise.slice(index, dim)
        return total


def make(settings, dim: int) -> OpenES:
    return OpenES(settings)


PLUGIN = StrategyPlugin("openai", about="Salimans et al. 2017, the original", settings=OpenAISettings, make=make,
                        pairs=True)
