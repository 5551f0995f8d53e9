"""Initial weight distributions (docs/original.md, "Initial weights"), drawn with numpy from an explicit rng.

``default_bound`` is PyTorch's default initialisation of Linear and Conv2d weights,
U(-1/sqrt(fan_in), 1/sqrt(fan_in)), which the static networks start from. ``INIT_WEIGHTS`` maps
each ``--init_weights`` value of the Hebbian scripts to a sampler of one (n_out, n_in) weight
matrix; the Hebbian networks draw fresh weights from it at every episode.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

Sampler = Callable[[np.random.Generator, tuple[int, int]], np.ndarray]


def default_bound(fan_in: int) -> float:
    return 1.0 / math.sqrt(fan_in)


def default_init(layout, rng: np.random.Generator, fan_in: dict[str, int]) -> np.ndarray:
    """PyTorch's default initialisation of a whole parameter vector: every part of ``layout``
    U(+-1/sqrt(fan_in)), with ``fan_in`` per part (Linear and Conv2d: the layer's inputs, biases alike;
    LSTMCell: its hidden size)."""
    blocks = [rng.uniform(-default_bound(fan_in[name]), default_bound(fan_in[name]), part.size)
              for name, part in layout.parts.items()]
    return np.concatenate(blocks).astype(np.float32)


def _uniform(bound_of: Callable[[int, int], float]) -> Sampler:
    def sample(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
        n_out, n_in = shape
        bound = bound_of(n_in, n_out)
        return rng.uniform(-bound, bound, shape)

    return sample


def _xavier(gain: float) -> Sampler:
    return _uniform(lambda fan_in, fan_out: gain * math.sqrt(6.0 / (fan_in + fan_out)))


def _sparse(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    # torch.nn.init.sparse_(w, 0.8): N(0, 0.01), then in every column ceil(0.8 * rows) entries zeroed.
    n_out, n_in = shape
    weights = rng.normal(0.0, 0.01, shape)
    n_zeros = math.ceil(0.8 * n_out)
    for column in range(n_in):
        weights[rng.permutation(n_out)[:n_zeros], column] = 0.0
    return weights


def _constant(value: float) -> Sampler:
    return lambda rng, shape: np.full(shape, value)


INIT_WEIGHTS: dict[str, Sampler] = {
    "uni": _uniform(lambda fan_in, fan_out: 0.1),
    "normal": lambda rng, shape: rng.normal(0.0, 0.024, shape),
    "default": _uniform(lambda fan_in, fan_out: default_bound(fan_in)),
    "xa_uni": _xavier(0.3),
    "sparse": _sparse,
    # kaiming_uniform_(w, 3) passes 3 as the negative slope a: gain sqrt(2 / (1 + 9)).
    "ka_uni": _uniform(lambda fan_in, fan_out: math.sqrt(0.6 / fan_in)),
    "uni_big": _uniform(lambda fan_in, fan_out: 1.0),
    "xa_uni_big": _xavier(1.0),
    "ones": _constant(1.0),
    "zeros": _constant(0.0),
}
COEVOLVE = "coevolve"
INIT_CHOICES = (*INIT_WEIGHTS, COEVOLVE)


def sample_weights(name: str, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    return INIT_WEIGHTS[name](rng, shape).astype(np.float32)
