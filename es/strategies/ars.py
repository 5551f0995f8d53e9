"""ARS: augmented random search (Mania, Guy & Recht 2018, "Simple random search of static linear
policies is competitive for reinforcement learning", NeurIPS, Algorithm 2), V1-t and V2-t.

Direction k is a slice delta_k of the shared noise table; members 2k and 2k+1 are theta + nu delta_k
and theta - nu delta_k (nu = ``--sigma``, constant), on the same episode seeds. The directions are
sorted by max(r+_k, r-_k), and the b best (``--ars_top``; all popsize / 2 by default, which is V1 and
V2 without the "-t") make the step

    theta <- theta + alpha / (b sigma_R) * sum_{k in the b best} (r+_k - r-_k) delta_k

with alpha = ``--ars_lr`` and sigma_R the standard deviation of the 2b rewards used (ddof 0, as the
authors' code). r is the run's fitness, the return minus the original's L2 penalty (``--fitness_l2
0`` gives the return alone); a non-finite one counts as the lowest finite one. Directions with equal
max(r+, r-) are ranked in member order (the authors' code keeps every direction at or above the
b-th's value, so ties may add directions there).

V2-t is V1-t on normalised states: ``--strategy ars --obs_norm --obs_norm_prob 1``. The project's
observation statistics (``es.observations``, OpenAI's RunningStat) are ARS's: a running mean and
diagonal standard deviation of the states the members' episodes visited, frozen during a generation
and updated after it, the centre's episodes not counted. Where they differ: ARS counts every state
of every rollout (here the fraction ``--obs_norm_prob``, 1 for ARS's), and the project's standard
deviation has a floor of 0.1 and a prior count of 0.01 (ARS's has neither). The authors'
survival-bonus shift for Humanoid is not applied.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from es.noise import NoiseTable
from es.strategy import STRATEGY_GROUP, ESState, Population, StrategyPlugin, check_fitness, mirrored_population
from settings import setting


def finite_rewards(fitness: np.ndarray) -> np.ndarray | None:
    """The fitness, non-finite values replaced by the lowest finite one; None if none is finite."""
    fitness = np.asarray(fitness, dtype=np.float64)
    finite = np.isfinite(fitness)
    if not finite.any():
        return None
    return np.where(finite, fitness, fitness[finite].min())


@dataclass(frozen=True)
class ARSSettings:
    ars_lr: float = setting(0.02, low=0, low_open=True, group=STRATEGY_GROUP, help="ARS: the step size alpha")
    ars_top: int | None = setting(None, low=1, metavar="B", group=STRATEGY_GROUP, shown_default="all --popsize / 2",
                                  help="ARS: the b best directions make the step (V1-t, V2-t)")


def check_top(settings) -> None:
    """--ars_top is at most the number of directions."""
    directions = settings.popsize // 2
    if settings.ars_top is not None and settings.ars_top > directions:
        raise ValueError(f"--ars_top must be a whole number from 1 to {directions} (the directions: --popsize / 2), "
                         f"got {settings.ars_top}")


@dataclass(frozen=True)
class ARS:
    population_size: int  # even (the plug-in's population rule): popsize / 2 directions
    sigma: float  # nu
    lr: float  # alpha
    top: int | None = None  # b; None: every direction

    @property
    def directions(self) -> int:
        return self.population_size // 2

    @property
    def used(self) -> int:
        return self.directions if self.top is None else self.top

    def initial_state(self, theta: np.ndarray) -> ESState:
        return ESState(np.asarray(theta, dtype=np.float32), self.lr, self.sigma)

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        return mirrored_population(rng, noise, state.theta.size, self.directions)

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        check_fitness(fitness, self.population_size)
        rewards, theta, factor = finite_rewards(fitness), state.theta, 0.0
        if rewards is not None:
            plus, minus = rewards[0::2], rewards[1::2]
            best = np.argsort(-np.maximum(plus, minus), kind="stable")[:self.used]
            spread = float(np.concatenate([plus[best], minus[best]]).std())
            if spread > 0:
                factor = self.lr / (self.used * spread)
                step = np.zeros(theta.size, dtype=np.float64)
                for k in best:
                    step += (plus[k] - minus[k]) * noise.slice(population.indices[2 * k], theta.size)
                with np.errstate(over="ignore", invalid="ignore"):  # a non-finite step is the loop's to refuse
                    theta = (theta + factor * step).astype(np.float32)
        new_state = replace(state, theta=theta, generation=state.generation + 1)
        return new_state, {"update_factor": factor, "skipped": factor == 0.0}


def make(settings, dim: int) -> ARS:
    return ARS(settings.popsize, settings.sigma, settings.ars_lr, settings.ars_top)


PLUGIN = StrategyPlugin("ars", about="Mania et al. 2018; V2 with --obs_norm --obs_norm_prob 1", settings=ARSSettings,
                        make=make, pairs=True, validate=check_top)
