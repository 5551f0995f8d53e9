"""The reservoir front end (``--reservoir``): an evolved head reads an echo state network's state.

One step beyond ER-MRL (Léger et al. 2024, docs/original.md, "ER-MRL"): there a PPO agent learns on a
reservoir's state; here the head this tool evolves, static (Salimans et al. 2017) or Hebbian
(Najarro & Risi 2020), reads it instead of the observation, so the three kinds of evolved prior
(weights, plasticity rules, reservoirs) run on the same environments and the same protocol.

- **The reservoir** is ER-MRL's: the leaky integrator
  x[t+1] = (1 - lr) x[t] + lr tanh(W_in u[t+1] + W x[t] + b), W, W_in and b drawn as reservoirpy 0.3
  drew them (``policies.reservoir_matrices``), so a given (units, lr, sr, iss, seed) is the very
  reservoir ER-MRL's scripts build. The state starts at zero at every episode (``reset``); the draws
  are fixed for the run, from ``PolicySettings.reservoir_seed`` (the run's seed unless given), so every
  worker, and a resumed run, regenerates the same matrices from one integer: nothing but the seed
  travels. reservoirpy is needed to draw them (ER-MRL's matrices come from its ``mat_gen``); the
  steps run here, one compiled call on the sparse matrices, without reservoirpy's node API.
- **Its input is the observation only**, not ER-MRL's (observation, previous action, reward). The
  three priors are compared on the same information: static and Hebbian networks see observations,
  never rewards (``act`` does not receive them), so a reward input would add information, and change
  two things at once. And the previous action adds none: an ES policy is deterministic, so its actions
  are a function of the observations it has seen, whereas PPO's are sampled, which is why ER-MRL feeds
  them. The reservoir brings memory (velocities from positions, a trace of the past) and a random
  nonlinear expansion. With ``--obs_norm`` it reads the normalised observation.
- **Evolved hyperparameters** (``--reservoir_evolve``): θ ends with three genes z = (z_lr, z_sr, z_iss),
  one per hyperparameter, mapped log-uniformly into ER-MRL's search bounds (its ``--min_*`` /
  ``--max_*`` defaults, ``BOUNDS``) through a logistic function:
      value = low * (high / low) ** sigmoid(z)
  smooth, always inside the bounds, never flat as a clip would be; z = 0 is the geometric middle of
  the range (where ER-MRL's CMA-ES starts), and θ starts at the values of ``--reservoir_lr/_sr/_iss``.
  With σ = 0.1, a gene's perturbation near z = 0 moves sr by a factor of about 1.4, lr by 1.12, iss
  by 1.12. The genes are not in the fitness's L2 penalty (``penalised`` is the head's). Each episode
  rescales the drawn matrices by the member's sr and iss (``ReservoirMatrices``: bit for bit the
  matrices a fresh build would make), a multiplication of the non-zero entries: about a microsecond
  for 100 units, where a rebuild costs an eigenvalue solve (10 ms).
- **Files**: the head's, plus with evolved hyperparameters the role ``reservoir``: the three genes as
  θ holds them (float32, so that evaluation runs exactly the trained reservoir; ``hyperparameters``
  decodes them), in ``best_reservoir.dat`` / ``last_reservoir.dat`` and the per-generation file the
  head names for that role.

Pixel observations are refused: ER-MRL's reservoirs read vectors, and a reservoir behind the CNN
would change what the CNN's weights are evolved for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit

from policies.base import FrontEnd, Policy
from policies.network import Layout, NetworkSpec
from policies.static import check_length
from reservoir_extra import SEARCH_BOUNDS

ROLE = "reservoir"  # the file role (and layout part) of the evolved hyperparameters
# ER-MRL's default search bounds, in the order of the genes
BOUNDS: dict[str, tuple[float, float]] = {name: SEARCH_BOUNDS[name] for name in ("lr", "sr", "iss")}
EVOLVED_COLUMNS = ("reservoir_lr", "reservoir_sr", "reservoir_iss")  # their metrics columns, in the genes' order
MAX_UNITS = 10_000  # each worker holds its own matrices, and their eigenvalue solve grows with units^2


@dataclass(frozen=True)
class Hyperparameters:
    leak_rate: float
    spectral_radius: float
    input_scaling: float

    def describe(self) -> str:
        return f"leak rate {self.leak_rate:.4g}, spectral radius {self.spectral_radius:.4g}, " \
               f"input scaling {self.input_scaling:.4g}"


def _sigmoid(gene: float) -> float:
    if gene >= 0:
        return 1.0 / (1.0 + math.exp(-gene))
    tail = math.exp(gene)  # no overflow for a very negative gene
    return tail / (1.0 + tail)


def hyperparameters(genes: np.ndarray) -> Hyperparameters:
    """The hyperparameters three genes encode: low * (high / low) ** sigmoid(z), each within BOUNDS."""
    values = []
    for gene, (low, high) in zip(np.asarray(genes, dtype=np.float64), BOUNDS.values()):
        value = math.exp(math.log(low) + _sigmoid(float(gene)) * (math.log(high) - math.log(low)))
        values.append(min(max(value, low), high))  # rounding never leaves the bounds
    return Hyperparameters(*values)


def genes(values: Hyperparameters) -> np.ndarray:
    """The genes that encode ``values`` (each strictly inside its bounds): generation 0's."""
    encoded = []
    for value, (low, high) in zip((values.leak_rate, values.spectral_radius, values.input_scaling),
                                  BOUNDS.values()):
        fraction = (math.log(value) - math.log(low)) / (math.log(high) - math.log(low))
        encoded.append(math.log(fraction / (1.0 - fraction)))
    return np.array(encoded, dtype=np.float32)


def check_evolve_start(values: Hyperparameters) -> None:
    """Refuse, naming the flag, a --reservoir_evolve start outside ER-MRL's bounds (the flags' own ranges are
    declared with them, in ``policies.registry.PolicySettings``)."""
    for (flag, (low, high)), value in zip(BOUNDS.items(), (values.leak_rate, values.spectral_radius,
                                                            values.input_scaling)):
        if not low < value < high:
            raise ValueError(f"--reservoir_{flag} {value} is where --reservoir_evolve starts; it must lie "
                             f"strictly between ER-MRL's bounds {low:g} and {high:g}")


@njit(cache=True, nogil=True)
def reservoir_step(w_data, w_indices, w_indptr, in_data, in_indices, in_indptr, bias, leak_rate,
                   inputs, state, pre, features):
    """state <- (1 - lr) state + lr tanh(W_in inputs + W state + b) on CSR matrices; features = float32(state)."""
    for unit in range(state.shape[0]):
        total = bias[unit]
        for k in range(in_indptr[unit], in_indptr[unit + 1]):
            total += in_data[k] * inputs[in_indices[k]]
        for k in range(w_indptr[unit], w_indptr[unit + 1]):
            total += w_data[k] * state[w_indices[k]]
        pre[unit] = total
    for unit in range(state.shape[0]):
        state[unit] = (1.0 - leak_rate) * state[unit] + leak_rate * np.tanh(pre[unit])
        features[unit] = state[unit]


@dataclass
class ReservoirState:
    inner: Any  # the head's own episode state
    leak_rate: float
    recurrent: np.ndarray  # W's non-zero entries, scaled for this episode's spectral radius
    inputs: np.ndarray  # W_in's non-zero entries, scaled for this episode's input scaling
    state: np.ndarray  # x, float64 (units,): zero at the start of every episode
    pre: np.ndarray
    features: np.ndarray  # float32 copy of x: what the head reads


class ReservoirFrontEnd(FrontEnd):
    """``head`` (built for ``units`` inputs) reading a reservoir that reads the observation; the head
    is the front end's ``inner`` policy."""

    def __init__(self, head: Policy, input_dim: int, units: int, values: Hyperparameters, seed: int,
                 evolve: bool = False):
        from policies.reservoir_matrices import ReservoirMatrices  # reservoirpy: the caller has checked it is there

        super().__init__(head)
        self.units, self.values, self.seed, self.evolve = units, values, seed, evolve  # checked by PolicySettings
        self.matrices = ReservoirMatrices.generate(units, input_dim, seed)
        self._bias = self.matrices.bias.toarray().ravel()
        if evolve:
            parts = [(name, part.shape) for name, part in head.layout.parts.items()]
            self.layout = Layout(parts + [(ROLE, (len(BOUNDS),))])
            self.num_params = self.layout.size
            self.roles = head.roles + (ROLE,)
            self.metrics_columns = head.metrics_columns + EVOLVED_COLUMNS

    def hyperparameters(self, params: np.ndarray) -> Hyperparameters:
        """The reservoir's hyperparameters for ``params``: decoded from its genes, or the fixed ones."""
        return hyperparameters(self.layout.view(params, ROLE)) if self.evolve else self.values

    def evolved_values(self, params: np.ndarray) -> dict[str, float]:
        """The evolved hyperparameters ``params`` encode, as metrics columns (``EVOLVED_COLUMNS``)."""
        values = super().evolved_values(params)
        if self.evolve:
            decoded = self.hyperparameters(params)
            values |= dict(zip(EVOLVED_COLUMNS, (decoded.leak_rate, decoded.spectral_radius, decoded.input_scaling)))
        return values

    def describe_front_ends(self, params: np.ndarray) -> list[str]:
        evolved = " (evolved)" if self.evolve else ""
        return [f"reservoir: {self.units} units, seed {self.seed}, {self.hyperparameters(params).describe()}{evolved}",
                *super().describe_front_ends(params)]

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        head = self.inner.initial_params(rng)
        return np.concatenate([head, genes(self.values)]) if self.evolve else head

    def reset(self, params: np.ndarray, rng: np.random.Generator) -> ReservoirState:
        values = self.hyperparameters(params)
        recurrent = self.matrices.recurrent.data * self.matrices.recurrent_factor(values.spectral_radius)
        inputs = self.matrices.input_signs.data * values.input_scaling
        return ReservoirState(self.inner.reset(params[self._inner], rng), values.leak_rate, recurrent, inputs,
                              np.zeros(self.units), np.zeros(self.units), np.zeros(self.units, dtype=np.float32))

    def act(self, params: np.ndarray, state: ReservoirState, obs: np.ndarray):
        matrices = self.matrices
        reservoir_step(state.recurrent, matrices.recurrent.indices, matrices.recurrent.indptr, state.inputs,
                       matrices.input_signs.indices, matrices.input_signs.indptr, self._bias, state.leak_rate, obs,
                       state.state, state.pre, state.features)
        output, state.inner = self.inner.act(params[self._inner], state.inner, state.features)
        return output, state

    def export(self, params: np.ndarray) -> dict[str, np.ndarray]:
        arrays = super().export(params)
        if self.evolve:
            arrays[ROLE] = np.array(self.layout.view(params, ROLE), dtype=np.float32)
        return arrays

    def load(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        head = self.inner.load(arrays)
        if not self.evolve:
            return head
        if arrays.get(ROLE) is None:
            raise ValueError(f"these weights were trained with --reservoir_evolve: pass the run's evolved reservoir "
                             f"hyperparameters too, --path_reservoir (best_{ROLE}.dat or last_{ROLE}.dat)")
        return np.concatenate([head, check_length("the --path_reservoir file", arrays[ROLE], len(BOUNDS),
                                                  "the reservoir's genes (lr, sr, iss)")])


def head_network(net: NetworkSpec, units: int) -> NetworkSpec:
    """The head's network: the environment's, reading ``units`` reservoir states instead of observations."""
    if net.pixels:
        raise ValueError(f"--reservoir reads observation vectors, but these observations are images {net.obs_shape}; "
                         "leave --reservoir out for pixel environments")
    return replace(net, obs_shape=(units,))
