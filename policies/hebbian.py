"""Hebbian networks (Najarro & Risi 2020): evolved plasticity rules, random weights every episode.

The flat parameter vector has up to three named parts:

- ``coefficients`` (n_synapses, k): one row of k rule coefficients per synapse. Row
  ``layer_offset + i * n_out + j`` belongs to the synapse from pre-synaptic unit i to post-synaptic
  unit j, as in the original code (docs/original.md, "Networks"), so original coefficient files load.
- ``cnn`` (1362 for RGB, 1416 for a stack of 4 frames): the conv weights of a pixel network.
  Evolved, never plastic.
- ``initial_weights``: with ``--init_weights coevolve``, the weights each episode starts from
  (all module weights in PyTorch order: conv1, conv2 for pixels, then the three dense layers).

Otherwise every episode draws its initial dense weights from the ``--init_weights`` distribution
with the episode's own rng. At each step the network acts with its current weights and then
updates them with the activities it just produced (``act``), so the rollout never needs to know
that the network is plastic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from policies.base import Policy
from policies.conv import ConvFeatures
from policies.init import COEVOLVE, INIT_CHOICES, sample_weights
from policies.kernels import head_state, hebbian_step
from policies.network import Layout, NetworkSpec, from_kernel_layout, to_kernel_layout
from policies.plugin import EVALUATED, FileFlag, Kind
from policies.rules import RULES, get_rule
from policies.static import check_length
from settings import setting

DISTRIBUTIONS = ("normal", "uniform")
ROLES = {"initial_weights": "coevolved_initial_weights", "cnn": "CNN_parameters"}  # layout part -> file role


@dataclass
class HebbianState:
    weights: np.ndarray  # (n_synapses,) float32, the dense layers in the kernels' layout (W^T each)
    folded: np.ndarray  # (4 * n_synapses,) float32, per layer the planes (a, b, c, d) of the rule
    scale: np.ndarray  # (3,) pending normalisation factor per layer
    work: np.ndarray
    out: np.ndarray
    features: ConvFeatures | None
    buffer: np.ndarray  # the head's state array (policies.kernels.head_state): the arrays above are views of it

    def layer_weights(self, net: NetworkSpec) -> list[np.ndarray]:
        """The current true weights of each dense layer, (n_out, n_in) each."""
        layers = from_kernel_layout(self.weights, net.layer_shapes)
        return [layer * self.scale[index] for index, layer in enumerate(layers)]


class HebbianPolicy(Policy):
    penalised_name = "coeffs"

    def __init__(self, net: NetworkSpec, rule: str = "ABCD_lr", init_weights: str = "uni",
                 normalise: bool = True, distribution: str = "normal"):
        if init_weights not in INIT_CHOICES:
            raise ValueError(f"unknown --init_weights {init_weights!r}; valid values: "
                             f"{', '.join(INIT_CHOICES)}")
        if distribution not in DISTRIBUTIONS:
            raise ValueError(f"unknown --distribution {distribution!r}; valid values: {', '.join(DISTRIBUTIONS)}")
        net.check_cnn_input()
        self.net = net
        self._sizes = net.head_sizes  # the kernel's layer sizes, once, not per step
        self.distribution = distribution
        self.rule = get_rule(rule)
        self.init_weights = init_weights
        self.normalise = normalise
        n_syn, k = net.n_synapses, self.rule.n_coeffs
        parts: list[tuple[str, tuple[int, ...]]] = [("coefficients", (n_syn, k))]
        if init_weights == COEVOLVE:
            parts.append(("initial_weights", (n_syn + net.conv_size,)))
        elif net.pixels:
            parts.append(("cnn", (net.conv_size,)))
        self.layout = Layout(parts)
        self.num_params = self.layout.size
        self.penalised = self.layout["coefficients"].slice  # the original's L2 term: coefficients only
        self.roles = ("coeffs",) + tuple(ROLES[name] for name, _ in parts[1:])

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        """Generation-0 vector: N(0, 1) or U(-1, 1) for every part, as the original (docs/original.md,
        "Initial weights")."""
        if self.distribution == "normal":
            return rng.standard_normal(self.num_params, dtype=np.float32)
        return rng.uniform(-1.0, 1.0, self.num_params).astype(np.float32)

    def fold(self, params: np.ndarray) -> np.ndarray:
        """Per layer, the rule's planes (a, b, c, d) over (n_in, n_out), flat: what the kernel reads.

        Coefficient row ``offset + i*n_out + j`` already is position (i, j) of the layer's W^T.
        """
        coeffs = self.layout.view(params, "coefficients")
        blocks, offset = [], 0
        for n_out, n_in in self.net.layer_shapes:
            blocks.append(self.rule.fold(coeffs[offset:offset + n_in * n_out]).ravel())
            offset += n_in * n_out
        return np.concatenate(blocks)

    def initial_weights(self, params: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray | None]:
        """The episode's starting dense weights (kernels' layout) and the conv weights, if any."""
        if self.init_weights == COEVOLVE:
            initial = params[self.layout["initial_weights"].slice]
            conv = initial[:self.net.conv_size] if self.net.pixels else None
            dense = initial[self.net.conv_size:]
            return to_kernel_layout(dense, self.net.layer_shapes), conv
        dense = np.concatenate([sample_weights(self.init_weights, rng, shape).ravel()
                                for shape in self.net.layer_shapes])
        conv = params[self.layout["cnn"].slice] if self.net.pixels else None
        return to_kernel_layout(dense, self.net.layer_shapes), conv

    def reset(self, params: np.ndarray, rng: np.random.Generator) -> HebbianState:
        weights, conv = self.initial_weights(params, rng)
        buffer, views = head_state(self._sizes, self.net.squash_out, self.normalise, plastic=True)
        views["weights"][:] = weights
        views["folded"][:] = self.fold(params)
        features = ConvFeatures(conv, self.net.conv_shapes) if conv is not None else None
        return HebbianState(views["weights"], views["folded"], views["scale"], views["work"], views["out"], features,
                            buffer)

    def act(self, params: np.ndarray, state: HebbianState, obs: np.ndarray):
        if state.features is not None:
            obs = state.features(obs)
        hebbian_step(state.buffer, obs)
        return state.out, state

    def layer_weights(self, state: HebbianState) -> list[np.ndarray]:
        """The weights the episode has grown so far (the adaptation plot's)."""
        return state.layer_weights(self.net)

    # --- files in the original shapes --------------------------------------------------------

    def export(self, params: np.ndarray) -> dict[str, np.ndarray]:
        """The arrays the original wrote: coefficients (n_syn, k), or (n_syn,) for rule A."""
        coeffs = self.layout.view(params, "coefficients").copy()
        arrays = {"coeffs": coeffs[:, 0] if self.rule.n_coeffs == 1 else coeffs}
        for name, role in ROLES.items():
            if name in self.layout:
                arrays[role] = self.layout.view(params, name).copy()
        return arrays

    def load(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        n_syn, k = self.layout["coefficients"].shape
        coeffs = np.asarray(arrays["coeffs"])
        accepted = {(n_syn, k)} | ({(n_syn,)} if k == 1 else set())
        if coeffs.shape not in accepted:
            raise ValueError(f"the coefficient file holds shape {coeffs.shape}, but rule "
                             f"{self.rule.name} on this network needs shape ({n_syn}, {k})"
                             + (f" or ({n_syn},)" if k == 1 else ""))
        blocks = [coeffs.reshape(-1).astype(np.float32)]
        for name, role in ROLES.items():
            if name in self.layout:
                if arrays.get(role) is None:
                    raise ValueError(f"this network also needs {role.replace('_', ' ')} "
                                     f"({self.layout[name].size} values): pass --path_coev")
                blocks.append(check_length("the --path_coev file", arrays[role], self.layout[name].size,
                                           f"{role.replace('_', ' ')} of this network"))
        return np.concatenate(blocks)

    def file_name(self, role: str, env: str, reward: int | str, population: int, generation: int) -> str:
        """The original Hebbian code's name (docs/original.md, "Files")."""
        return (f"HEBcoeffs__{env}__rew_{reward}__{self.rule.name}__init_{self.init_weights}__pop_{population}"
                f"__{role}__{generation}.dat")


# --- the kind (policies.registry.KINDS) ----------------------------------------------------------------


@dataclass(frozen=True)
class HebbianSettings:
    """The Hebbian kind's own settings: flags of train_hebb.py and evaluate_hebb.py, recorded for its runs only."""

    hebb_rule: str = setting("ABCD_lr", choices=RULES, metavar="RULE", scripts=EVALUATED, evaluation=True,
                             help="Hebbian rule (the one the coefficients were evolved for)")
    init_weights: str = setting("uni", choices=INIT_CHOICES, metavar="INIT", scripts=EVALUATED, evaluation=True,
                                help="initial weights of every episode (coevolve: evolved with the rules)")
    distribution: str = setting("normal", choices=DISTRIBUTIONS,
                                help="generation-0 coefficients (and CNN / co-evolved weights): normal N(0,1) or "
                                     "uniform U(-1,1)")


KIND = Kind("hebbian", about="evolved plasticity rules (Najarro & Risi 2020)", settings=HebbianSettings,
            build=lambda settings, net, normalise: HebbianPolicy(net, settings.hebb_rule, settings.init_weights,
                                                                 normalise, settings.distribution),
            plastic=True, scripts=("train_hebb.py", "evaluate_hebb.py"),
            files=(FileFlag("--path_hebb", ("coeffs",), "Hebbian coefficients"),
                   FileFlag("--path_coev", ("CNN_parameters", "coevolved_initial_weights"),
                            "CNN weights (pixel environments) or of co-evolved initial weights")))
