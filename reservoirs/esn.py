"""The echo state network of ER-MRL: reservoirpy 0.4's ``Reservoir`` with reservoirpy 0.3's semantics.

ER-MRL (Léger et al. 2024) built ``reservoirpy.nodes.Reservoir(units, lr, sr, input_scaling, seed)``
with reservoirpy 0.3.9 (docs/original.md, "ER-MRL"). With all other arguments at 0.3's defaults that is the
leaky integrator (0.3's "internal" equation, without noise)

    x[t+1] = (1 - lr) * x[t] + lr * tanh(W_in u[t+1] + W x[t] + b)

- W: normal entries, 10 % of them non-zero, then rescaled to spectral radius ``sr``;
- W_in: Bernoulli entries ±1, 10 % non-zero, times the input scaling ``iss``;
- b: Bernoulli entries ±1, 10 % non-zero (0.3's ``input_bias=True``, ``bias_scaling=1``);
- all three generated from the same integer ``seed``; the state starts, and is reset, at zero.

reservoirpy 0.4 rewrote the node API and changed the defaults (no bias, spectral radius 1, one random
stream split three ways), so the matrices are made with 0.4's own ``mat_gen`` initialisers, called as
0.3 called them (``policies.reservoir_matrices``), and handed to a 0.4 ``Reservoir``. With scipy 1.17
they are the matrices
0.3.9.post1 makes, bit for bit, and so are the states (tests/test_reservoirs.py holds 0.3's output).

The random draws themselves, ``ReservoirMatrices``, live in ``policies.reservoir_matrices``: the ES
networks' reservoir front end (``policies.reservoir``) draws the same matrices, and this package is a
client of ``policies``, not the other way round.

``EchoStateNetwork`` is one reservoir behind a small interface, one input vector in, the state out: the
Gymnasium wrappers use it, on reservoirpy's node (bit-identical to reservoirpy 0.3). The ES networks'
front end (``policies.reservoir``) takes only ``ReservoirMatrices`` and steps them in one compiled call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from reservoirpy.nodes import Reservoir

from policies.reservoir_matrices import ReservoirMatrices


@dataclass(frozen=True)
class ReservoirSettings:
    """The hyperparameters ER-MRL evolves (lr, sr, iss), and the size it keeps fixed (units)."""

    units: int
    leak_rate: float
    spectral_radius: float
    input_scaling: float = 1.0

    def __post_init__(self):
        if self.units < 1:
            raise ValueError(f"a reservoir needs at least 1 unit, got {self.units}")
        if not 0 < self.leak_rate <= 1:
            raise ValueError(f"the leak rate must be in (0, 1], got {self.leak_rate}")
        for name in ("spectral_radius", "input_scaling"):
            value = getattr(self, name)
            if not (value > 0 and np.isfinite(value)):
                raise ValueError(f"the {name.replace('_', ' ')} must be a number > 0, got {value}")


class EchoStateNetwork:
    """One reservoir: ``reset()`` zeroes the state, ``step(u)`` feeds one input vector and returns the state.

    Building one costs an eigenvalue solve for the spectral radius (about 10 ms of CPU for 100 units),
    so build it once per worker, not per episode; a step costs 20-30 µs. It pickles. The returned
    state is a copy the caller may keep.
    """

    def __init__(self, input_dim: int, settings: ReservoirSettings, seed: int):
        if input_dim < 1:
            raise ValueError(f"a reservoir needs at least one input, got input_dim {input_dim}")
        self.input_dim = input_dim
        self.settings = settings
        self.seed = int(seed)
        units = settings.units
        weights, input_weights, bias = ReservoirMatrices.generate(units, input_dim, self.seed).scaled(
            settings.spectral_radius, settings.input_scaling)
        self._node = Reservoir(units=units, lr=settings.leak_rate, W=weights, Win=input_weights,
                               bias=_dense(bias).ravel(), input_dim=input_dim)
        self._node.initialize(np.zeros(input_dim))  # 0.4 cannot reset a node before it has state

    @property
    def state(self) -> np.ndarray:
        return self._node.state["out"].copy()

    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(W, W_in, b) as dense arrays of shapes (units, units), (units, input_dim), (units,)."""
        return _dense(self._node.W), _dense(self._node.Win), np.array(self._node.bias, dtype=np.float64)

    def reset(self) -> None:
        self._node.reset()

    def step(self, inputs: np.ndarray) -> np.ndarray:
        inputs = np.asarray(inputs, dtype=np.float64)
        if inputs.shape != (self.input_dim,):
            raise ValueError(f"reservoir input must have shape ({self.input_dim},), got {inputs.shape}")
        return self._node.step(inputs).copy()


def _dense(matrix) -> np.ndarray:
    return np.asarray(matrix.toarray() if hasattr(matrix, "toarray") else matrix, dtype=np.float64)
