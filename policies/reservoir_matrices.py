"""The random draws of an echo state network (ER-MRL's reservoirs; Léger et al. 2024), before its
spectral radius and input scaling are applied: what both the ES networks' reservoir front end
(``policies.reservoir``) and ER-MRL's own ``reservoirs.esn.EchoStateNetwork`` are built from.

ER-MRL built ``reservoirpy.nodes.Reservoir(units, lr, sr, input_scaling, seed)`` with reservoirpy 0.3.9
(docs/original.md, "ER-MRL"); the matrices are made here with reservoirpy 0.4's own ``mat_gen`` initialisers,
called as 0.3 called them (``reservoirs.esn`` says why).

``ReservoirMatrices`` holds the draws before the hyperparameters scale them: W as drawn with its
spectral radius, and W_in with entries ±1. ``scaled(sr, iss)`` then gives exactly the matrices
``mat_gen`` gives for (sr, iss), bit for bit: ``mat_gen`` itself multiplies the drawn W by the one
factor sr / ρ(W) and the ±1 entries by iss. So a front end that changes sr and iss often (an evolved
reservoir, ``policies.reservoir``) draws and solves for ρ once and rescales, at no cost in exactness.
Rescaling a unit-radius matrix instead, (W / ρ) · sr or (W · (1 / ρ)) · sr, would not: measured on a
100-unit reservoir, 26 % to 88 % of W's non-zero entries then differ from W · (sr / ρ) by 1 or 2 in the
last bit (at most 4.4e-16 relative), enough for states, and so episodes, to drift apart eventually.

Importing this module needs reservoirpy and scipy (the reservoirs' optional extra, ``reservoir_extra``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from reservoirpy import mat_gen
from reservoirpy.observables import spectral_radius as estimated_radius
from scipy import sparse
from scipy.sparse.linalg import ArpackNoConvergence

CONNECTIVITY = 0.1  # reservoirpy 0.3's rc_connectivity and input_connectivity (the bias uses the latter)
RADIUS_FLOOR = 1e-8  # mat_gen's _epsilon: a (nilpotent) W of spectral radius ~0 is divided by this instead


@dataclass(frozen=True)
class ReservoirMatrices:
    """The random draws of one reservoir, before its spectral radius and input scaling are applied."""

    recurrent: sparse.csr_array  # W as drawn: normal entries, CONNECTIVITY of them non-zero
    radius: float  # its spectral radius, as mat_gen estimates it (ARPACK), floored at RADIUS_FLOOR
    input_signs: sparse.csr_array  # W_in / iss: entries ±1, CONNECTIVITY of them non-zero
    bias: sparse.csr_array  # (units, 1): entries ±1, CONNECTIVITY of them non-zero

    @classmethod
    def generate(cls, units: int, input_dim: int, seed: int) -> ReservoirMatrices:
        """The draws ``mat_gen.normal(..., sr=, seed=seed)`` and ``mat_gen.bernoulli(..., seed=seed)`` make,
        in the same order from the same streams (a W whose ρ ARPACK cannot find is redrawn, as mat_gen does)."""
        stream = np.random.default_rng(seed)  # what mat_gen's rand_generator makes of an integer seed
        while True:
            recurrent = mat_gen.normal(units, units, connectivity=CONNECTIVITY, seed=stream)
            try:
                radius = float(_radius(recurrent))
                break
            except ArpackNoConvergence:  # pragma: no cover (mat_gen's own retry)
                continue
        if -RADIUS_FLOOR < radius < RADIUS_FLOOR:
            radius = RADIUS_FLOOR
        input_signs = mat_gen.bernoulli(units, input_dim, connectivity=CONNECTIVITY, seed=seed)
        bias = mat_gen.bernoulli(units, 1, connectivity=CONNECTIVITY, input_scaling=1.0, seed=seed)
        return cls(sparse.csr_array(recurrent), radius, sparse.csr_array(input_signs), sparse.csr_array(bias))

    def recurrent_factor(self, spectral_radius: float) -> float:
        """What W's drawn entries are multiplied by for ``spectral_radius``: mat_gen's sr / ρ."""
        return spectral_radius / self.radius

    def scaled(self, spectral_radius: float, input_scaling: float) -> tuple[sparse.csr_array, ...]:
        """(W, W_in, b) for these hyperparameters, as mat_gen makes them."""
        recurrent = self.recurrent.copy()
        recurrent *= self.recurrent_factor(spectral_radius)
        return recurrent, sparse.csr_array(self.input_signs.multiply(input_scaling)), self.bias


def _radius(recurrent: sparse.csr_array) -> float:
    """mat_gen's spectral-radius estimate; below 3 units ARPACK cannot run, so the eigenvalues of the
    dense matrix (reservoirpy raises a TypeError there: a 1- or 2-unit reservoir could not be built)."""
    return estimated_radius(recurrent.toarray() if recurrent.shape[0] < 3 else recurrent)
