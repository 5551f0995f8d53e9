"""SNES: separable natural evolution strategies (Schaul, Glasmachers & Schmidhuber 2011, "High
dimensions and heavy tails for natural evolution strategies", GECCO, Algorithm 2; Wierstra et al.
2014, "Natural evolution strategies", JMLR 15, its SNES algorithm).

Member k is mu + sigma * s_k, s_k a slice of the shared noise table and sigma a per-parameter vector
that the workers receive once per generation beside theta (``Population.scale``). As in the paper
the members are sampled independently (not mirrored), so each has its own noise index and episode
seeds. With lambda members ranked k = 1 (best) .. lambda and the paper's utilities

    u_k = max(0, ln(lambda/2 + 1) - ln k) / sum_j max(0, ln(lambda/2 + 1) - ln j) - 1/lambda

(members with equal fitness share the mean utility of their ranks):

    grad_mu = sum_k u_k s_k;   grad_sigma = sum_k u_k (s_k^2 - 1)
    mu <- mu + lr_mu * sigma * grad_mu;   sigma <- sigma * exp(lr_sigma / 2 * grad_sigma)

with the paper's defaults lr_mu = 1 (``--snes_lr``) and lr_sigma = (3 + ln d) / (5 sqrt d)
(``--snes_sigma_lr``), d the number of parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from es import exact
from es.noise import NoiseTable
from es.strategy import STRATEGY_GROUP, ESState, Population, StrategyPlugin, check_fitness
from settings import setting


@dataclass(frozen=True)
class SNESSettings:
    snes_lr: float = setting(1.0, low=0, low_open=True, group=STRATEGY_GROUP,
                             help="SNES: the centre's learning rate (the paper's 1)")
    snes_sigma_lr: float | None = setting(None, low=0, low_open=True, group=STRATEGY_GROUP,
                                          shown_default="(3 + ln d) / (5 sqrt d), d the parameters",
                                          help="SNES: sigma's learning rate")


def default_sigma_lr(dim: int) -> float:
    """Schaul et al. 2011's learning rate of sigma: (3 + ln d) / (5 sqrt d)."""
    return (3 + float(exact.log(dim))) / (5 * math.sqrt(dim))


def utilities(fitness: np.ndarray) -> np.ndarray | None:
    """The paper's utility of each member (member order; they sum to 0); None when all are equal."""
    fitness = np.asarray(fitness, dtype=np.float64)
    population = fitness.size
    if np.all(fitness == fitness[0]):
        return None
    by_rank = np.maximum(0.0, exact.log(population / 2 + 1) - exact.log(np.arange(1, population + 1)))
    by_rank = by_rank / by_rank.sum() - 1 / population
    order = np.argsort(-fitness, kind="stable")  # best first
    values = np.empty(population)
    values[order] = by_rank
    for tied in np.unique(fitness):  # ties share their ranks' mean utility
        members = fitness == tied
        if members.sum() > 1:
            values[members] = values[members].mean()
    return values


@dataclass(frozen=True)
class SNES:
    population_size: int
    sigma_init: float
    lr: float  # lr_mu
    sigma_lr: float  # lr_sigma

    def initial_state(self, theta: np.ndarray) -> ESState:
        sigma = np.full(theta.size, self.sigma_init, dtype=np.float64)
        return ESState(np.asarray(theta, dtype=np.float32), self.lr, float(sigma.mean()), strategy={"sigma": sigma})

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        indices = noise.sample_indices(rng, state.theta.size, self.population_size)
        with np.errstate(over="ignore"):  # a sigma beyond float32's range: the workers refuse the parameters
            scale = state.strategy["sigma"].astype(np.float32)
        return Population(indices, np.ones(self.population_size, dtype=np.int8), scale=scale)

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        check_fitness(fitness, self.population_size)
        weights = utilities(fitness)
        theta, sigma = state.theta, state.strategy["sigma"]
        if weights is not None:
            grad_mu, grad_sigma = np.zeros_like(sigma), np.zeros_like(sigma)
            for weight, index in zip(weights, population.indices):
                sample = noise.slice(index, sigma.size).astype(np.float64)
                grad_mu += weight * sample
                grad_sigma += weight * (sample * sample - 1)
            with np.errstate(over="ignore", invalid="ignore"):  # a non-finite step is the loop's to refuse
                theta = (theta + self.lr * sigma * grad_mu).astype(np.float32)
                sigma = sigma * exact.exp(self.sigma_lr / 2 * grad_sigma)
        new_state = replace(state, theta=theta, sigma=float(sigma.mean()), generation=state.generation + 1,
                            strategy={"sigma": sigma})
        return new_state, {"update_factor": self.lr, "skipped": weights is None}


def make(settings, dim: int) -> SNES:
    sigma_lr = settings.snes_sigma_lr if settings.snes_sigma_lr is not None else default_sigma_lr(dim)
    return SNES(settings.popsize, settings.sigma, settings.snes_lr, sigma_lr)


PLUGIN = StrategyPlugin("snes", about="separable NES", settings=SNESSettings, make=make,
                        pairs=False)  # members sampled independently: any population
