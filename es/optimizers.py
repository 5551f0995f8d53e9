"""How the ES step turns the fitness-weighted noise into a new theta: the original's SGD, and
OpenAI's Adam and momentum (openai/evolution-strategies-starter, ``es_distributed/optimizers.py``).

Every optimiser gets ``weighted_sum = sum_m F_m eps_m`` (shaped fitness F, noise eps, in float64),
the population size N, sigma, the learning rate and its own state (a dict of arrays, saved in the
checkpoint so that a resumed run steps exactly as one that never stopped). How the gradient
estimate is normalised follows each optimiser's source:

- ``sgd``, the original (Najarro & Risi 2020; docs/original.md, "The evolution strategy"): the estimate of
  Salimans et al. (2017) of the gradient of the smoothed objective, g = sum_m F_m eps_m / (N sigma),
  and theta += lr * g, computed as ``theta + (lr / (N sigma)) * weighted_sum`` so that its results
  are bit-identical to the original formula.
- ``adam`` and ``momentum``, OpenAI's (docs/original.md, "The evolution strategy"): g = sum_m F_m eps_m
  / N, i.e. divided by the number of returns and *not* by sigma, as es-starter does. Adam is invariant to the scale of g
  (up to its epsilon), so this matters only for the balance with ``l2coeff``, which then means
  what it means in es-starter's configurations (e.g. humanoid.json's 0.005).

Weight decay in the gradient (es-starter's ``l2coeff``): g <- g - l2coeff * theta, for every
optimiser. It is distinct from the original's L2 penalty in the fitness (``es.shaping``).

The learning rate is every optimiser's step size, and the schedule of ``es.strategy`` (lr *= decay
while lr > lr_floor) applies to it whatever the optimiser: one rule, stated once. es-starter has
no schedule and pytorch-es skipped its decay under Adam; ``--decay 1`` gives their constant step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from es import exact

OptimizerState = dict[str, np.ndarray]


class Optimizer(Protocol):
    def step(self, theta: np.ndarray, weighted_sum: np.ndarray, population_size: int, sigma: float, lr: float,
             state: OptimizerState) -> tuple[np.ndarray, OptimizerState]:
        """The new theta (float32) and the new state; neither input is modified."""


def openai_gradient(theta: np.ndarray, weighted_sum: np.ndarray, population_size: int,
                    l2coeff: float) -> np.ndarray:
    """es-starter's ascent direction: sum_m F_m eps_m / N - l2coeff * theta, in float64."""
    return weighted_sum / population_size - l2coeff * theta.astype(np.float64)


@dataclass(frozen=True)
class SGD:
    """The original step: theta += lr / (N sigma) * sum_m F_m eps_m  (- lr * l2coeff * theta)."""

    l2coeff: float = 0.0

    def step(self, theta, weighted_sum, population_size, sigma, lr, state):
        step = (lr / (population_size * sigma)) * weighted_sum
        if self.l2coeff:  # skipped at 0: the original's arithmetic, bit for bit
            step = step - (lr * self.l2coeff) * theta.astype(np.float64)
        return (theta + step).astype(np.float32), state


@dataclass(frozen=True)
class Momentum:
    """es-starter's SGD: v = momentum * v + (1 - momentum) * g; theta += lr * v."""

    momentum: float = 0.9
    l2coeff: float = 0.0

    def step(self, theta, weighted_sum, population_size, sigma, lr, state):
        gradient = openai_gradient(theta, weighted_sum, population_size, self.l2coeff)
        velocity = self.momentum * state.get("velocity", np.zeros_like(gradient)) + (1 - self.momentum) * gradient
        return (theta + lr * velocity).astype(np.float32), {"velocity": velocity}


@dataclass(frozen=True)
class Adam:
    """es-starter's Adam (Kingma & Ba 2015 with the bias corrections folded into the step size):

        t += 1;  a = lr * sqrt(1 - beta2^t) / (1 - beta1^t)
        m = beta1 * m + (1 - beta1) * g;  v = beta2 * v + (1 - beta2) * g^2
        theta += a * m / (sqrt(v) + epsilon)

    beta^t is ``es.exact.power``'s (correctly rounded), not the C library's ``pow``, whose last bit follows
    the CPU.
    """

    beta1: float = 0.9
    beta2: float = 0.999
    l2coeff: float = 0.0
    epsilon: float = 1e-8

    def step(self, theta, weighted_sum, population_size, sigma, lr, state):
        gradient = openai_gradient(theta, weighted_sum, population_size, self.l2coeff)
        t = int(state.get("t", 0)) + 1
        first = self.beta1 * state.get("m", np.zeros_like(gradient)) + (1 - self.beta1) * gradient
        second = self.beta2 * state.get("v", np.zeros_like(gradient)) + (1 - self.beta2) * gradient * gradient
        size = lr * np.sqrt(1 - exact.power(self.beta2, t)) / (1 - exact.power(self.beta1, t))
        new_theta = theta + size * first / (np.sqrt(second) + self.epsilon)
        return new_theta.astype(np.float32), {"m": first, "v": second, "t": np.array(t)}


OPTIMIZERS = {
    "sgd": lambda settings: SGD(settings.l2coeff),
    "adam": lambda settings: Adam(settings.beta1, settings.beta2, settings.l2coeff),
    "momentum": lambda settings: Momentum(settings.momentum, settings.l2coeff),
}


class OptimizerSettings(Protocol):
    """What an optimiser is made from (``es.settings.ESSettings``, which imports this module for the names)."""

    optimizer: str
    beta1: float
    beta2: float
    momentum: float
    l2coeff: float


def make_optimizer(settings: OptimizerSettings) -> Optimizer:
    """The optimiser ``settings`` name (ESSettings has checked the name)."""
    return OPTIMIZERS[settings.optimizer](settings)
