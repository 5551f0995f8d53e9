"""PGPE: policy gradients with parameter-based exploration (Sehnke et al. 2010, "Parameter-exploring
policy gradients", Neural Networks 23), with symmetric sampling, a learned per-parameter sigma and
the ClipUp optimiser (Toklu et al. 2020, "ClipUp: a simple and powerful optimizer for
distribution-based policy evolution", PPSN XVI), as EvoTorch's and EvoJAX's PGPE (both after
nnaisense/pgpelib).

Direction p is a slice eps_p of the shared noise table; members 2p and 2p+1 are
mu + sigma * eps_p and mu - sigma * eps_p, with sigma a per-parameter vector that the workers
receive once per generation beside theta (``Population.scale``): only noise indices travel. With the
fitness shaped into centered ranks F in [-0.5, 0.5], over the N = popsize / 2 directions
(F+_p, F-_p) and delta_p = sigma * eps_p:

    grad_mu    = sum_p (F+_p - F-_p) / 2 * delta_p / N
    grad_sigma = sum_p ((F+_p + F-_p) / 2 - b) * (delta_p^2 - sigma^2) / sigma / N

(Sehnke et al. 2010, the symmetric-sampling gradients, with the baseline b the ranks' mean, 0; the
division by N as EvoTorch's ``divide_*_grad_by="num_directions"``). Then

    mu    <- mu + the optimiser's step along grad_mu
    sigma <- sigma + pgpe_sigma_lr * grad_sigma, each component kept within
             [(1 - c) sigma, (1 + c) sigma], c = pgpe_max_sigma_change (EvoTorch's stdev_max_change)

The centre's optimisers (``PGPE_OPTIMIZERS``, ``--pgpe_optimizer``): ClipUp, the default, with step
size alpha (``--pgpe_lr``, by default max_speed / 2, the paper's rule), momentum m and max_speed:

    v <- clip(m v + alpha g / ||g||, max_speed);  mu <- mu + v,   clip(x, c) = x c / ||x|| if ||x|| > c

max_speed (``--clipup_max_speed``) is by default the ClipUp paper's rule of thumb, the initial search
radius over 15: sigma sqrt(d) / 15 for d parameters (EvoTorch's examples write max_speed = radius_init / 15,
or radius_init = 15 max_speed). A fixed 0.15, the paper's value for its small linear policies, is a step
of a sixtieth of the radius on the project's 8 832-weight CartPole network (sigma 0.1): PGPE solved
CartPole in 1 of 5 seeds within 30 generations of 16 with it, in 5 of 5 with the rule (docs/strategies.md).

Adam (Kingma & Ba 2015, ``es.optimizers.Adam`` with its default betas) and plain gradient ascent
(mu += alpha g) on request. Without pgpe_max_sigma_change nothing keeps sigma positive: as in
EvoTorch, that is the user's to choose.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from es import exact
from es.noise import NoiseTable
from es.optimizers import Adam, OptimizerState
from es.shaping import rank
from es.strategy import STRATEGY_GROUP, ESState, Population, StrategyPlugin, check_fitness, mirrored_population
from settings import optional_float, setting


def clipup_velocity(velocity: np.ndarray, gradient: np.ndarray, step_size: float, max_speed: float,
                    momentum: float) -> np.ndarray:
    """ClipUp's new velocity: the normalised gradient times the step size, added to the decayed
    velocity, clipped to norm max_speed."""
    norm = exact.norm(gradient)
    ascent = gradient * (step_size / norm) if norm > 0 else np.zeros_like(gradient)
    velocity = momentum * velocity + ascent
    speed = exact.norm(velocity)
    return velocity * (max_speed / speed) if speed > max_speed else velocity


CenterStep = Callable[["PGPE", np.ndarray, np.ndarray, OptimizerState], tuple[np.ndarray, OptimizerState]]


def _clipup(pgpe: PGPE, theta: np.ndarray, gradient: np.ndarray, state: OptimizerState):
    velocity = clipup_velocity(state.get("velocity", np.zeros_like(gradient)), gradient, pgpe.lr, pgpe.max_speed,
                               pgpe.momentum)
    return (theta + velocity).astype(np.float32), {"velocity": velocity}


def _adam(pgpe: PGPE, theta: np.ndarray, gradient: np.ndarray, state: OptimizerState):
    return Adam().step(theta, gradient, 1, 1.0, pgpe.lr, state)  # Adam's g = weighted_sum / 1


def _sgd(pgpe: PGPE, theta: np.ndarray, gradient: np.ndarray, state: OptimizerState):
    return (theta + pgpe.lr * gradient).astype(np.float32), state


PGPE_OPTIMIZERS: dict[str, CenterStep] = {"clipup": _clipup, "adam": _adam, "sgd": _sgd}


@dataclass(frozen=True)
class PGPESettings:
    pgpe_optimizer: str = setting("clipup", choices=PGPE_OPTIMIZERS, group=STRATEGY_GROUP,
                                  help="how PGPE steps its centre (ClipUp, Toklu et al. 2020; Adam; plain gradient "
                                       "ascent)")
    pgpe_lr: float | None = setting(None, low=0, low_open=True, group=STRATEGY_GROUP,
                                    shown_default="--clipup_max_speed / 2", help="PGPE's centre step size")
    clipup_max_speed: float | None = setting(None, low=0, low_open=True, group=STRATEGY_GROUP,
                                             shown_default="--sigma * sqrt(d) / 15, d the parameters",
                                             help="ClipUp's maximum speed (the velocity's largest norm); by default "
                                                  "the ClipUp paper's rule: initial radius sigma sqrt(d) = 15 x it")
    clipup_momentum: float = setting(0.9, low=0, high=1, high_open=True, group=STRATEGY_GROUP,
                                     requires=("pgpe_optimizer", "clipup"),
                                     help="ClipUp's momentum (the velocity's decay)")
    pgpe_sigma_lr: float = setting(0.1, low=0, low_open=True, group=STRATEGY_GROUP,
                                   help="PGPE: sigma += pgpe_sigma_lr * its gradient")
    pgpe_max_sigma_change: float | None = setting(0.2, low=0, high=1, low_open=True, parse=optional_float,
                                                  metavar="C", group=STRATEGY_GROUP,
                                                  help="PGPE: each sigma changes by at most this fraction per "
                                                       "generation; none: no limit")


@dataclass(frozen=True)
class PGPE:
    population_size: int  # even (the plug-in's population rule): N = population_size / 2 directions
    sigma_init: float
    lr: float  # the centre's step size
    sigma_lr: float
    max_sigma_change: float | None = 0.2
    optimizer: str = "clipup"
    max_speed: float = 0.15  # ClipUp
    momentum: float = 0.9  # ClipUp

    def initial_state(self, theta: np.ndarray) -> ESState:
        sigma = np.full(theta.size, self.sigma_init, dtype=np.float64)
        return ESState(np.asarray(theta, dtype=np.float32), self.lr, float(sigma.mean()), strategy={"sigma": sigma})

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        population = mirrored_population(rng, noise, state.theta.size, self.population_size // 2)
        with np.errstate(over="ignore"):  # a sigma beyond float32's range: the workers refuse the parameters
            return replace(population, scale=state.strategy["sigma"].astype(np.float32))

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        check_fitness(fitness, self.population_size)
        ranks = rank(fitness)  # None: every member equal, no direction to step in
        theta, optimizer_state, sigma = state.theta, state.optimizer, state.strategy["sigma"]
        if ranks is not None:
            grad_mu, grad_sigma = self.gradients(ranks, population.indices[0::2], noise, sigma)
            with np.errstate(over="ignore", invalid="ignore"):  # a non-finite step is the loop's to refuse
                theta, optimizer_state = PGPE_OPTIMIZERS[self.optimizer](self, theta, grad_mu, optimizer_state)
            sigma = self.new_sigma(sigma, grad_sigma)
        new_state = replace(state, theta=theta, sigma=float(sigma.mean()), generation=state.generation + 1,
                            optimizer=optimizer_state, strategy={"sigma": sigma})
        return new_state, {"update_factor": self.lr, "skipped": ranks is None}

    @staticmethod
    def gradients(ranks: np.ndarray, indices: np.ndarray, noise: NoiseTable,
                  sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """grad_mu and grad_sigma of the symmetric pairs, one direction at a time (no N x d matrix)."""
        grad_mu, grad_sigma = np.zeros_like(sigma), np.zeros_like(sigma)
        for plus, minus, index in zip(ranks[0::2], ranks[1::2], indices):
            delta = sigma * noise.slice(index, sigma.size)
            grad_mu += (plus - minus) / 2 * delta
            grad_sigma += (plus + minus) / 2 * ((delta * delta - sigma * sigma) / sigma)
        return grad_mu / indices.size, grad_sigma / indices.size

    def new_sigma(self, sigma: np.ndarray, grad_sigma: np.ndarray) -> np.ndarray:
        updated = sigma + self.sigma_lr * grad_sigma
        if self.max_sigma_change is None:
            return updated
        return np.clip(updated, sigma * (1 - self.max_sigma_change), sigma * (1 + self.max_sigma_change))


def default_max_speed(sigma: float, dim: int) -> float:
    """ClipUp's rule of thumb (Toklu et al. 2020; EvoTorch's examples: max_speed = radius_init / 15): the
    largest step is a fifteenth of the initial search radius, the norm sigma sqrt(d) of the sigma vector."""
    return sigma * math.sqrt(dim) / 15


def make(settings, dim: int) -> PGPE:
    max_speed = settings.clipup_max_speed
    max_speed = max_speed if max_speed is not None else default_max_speed(settings.sigma, dim)
    lr = settings.pgpe_lr if settings.pgpe_lr is not None else max_speed / 2
    return PGPE(settings.popsize, settings.sigma, lr, settings.pgpe_sigma_lr, settings.pgpe_max_sigma_change,
                settings.pgpe_optimizer, max_speed, settings.clipup_momentum)


PLUGIN = StrategyPlugin("pgpe", about="Sehnke et al. 2010, with ClipUp", settings=PGPESettings, make=make, pairs=True)
