"""How the ES step turns the gradient estimate into a new theta.

The gradient estimate of OpenAI-ES (Salimans et al. 2017) is ``weighted_sum / normaliser`` with
``weighted_sum = sum_m F_m eps_m`` (shaped fitness F, noise eps) and ``normaliser = N * sigma``.
An optimiser gets both parts and the learning rate, and its own state (a dict of arrays, saved in
the checkpoint so a resumed run steps exactly as one that never stopped).

``sgd`` is the original's plain step, theta += lr / (N sigma) * sum_m F_m eps_m, computed in that
order so that its results are bit-identical to the original formula.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

OptimizerState = dict[str, np.ndarray]
Optimizer = Callable[[np.ndarray, np.ndarray, float, float, OptimizerState],
                     tuple[np.ndarray, OptimizerState]]


def sgd(theta: np.ndarray, weighted_sum: np.ndarray, normaliser: float, lr: float,
        state: OptimizerState) -> tuple[np.ndarray, OptimizerState]:
    """The original step (upstream spec §2.1 step 5), in float64, stored as float32."""
    return (theta + (lr / normaliser) * weighted_sum).astype(np.float32), state


OPTIMIZERS: dict[str, Optimizer] = {"sgd": sgd}
