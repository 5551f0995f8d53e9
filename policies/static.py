"""Static networks: the weights themselves are evolved (the baseline of Najarro & Risi 2020).

The flat vector is the original's ``parameters_to_vector`` order, each weight C-order in PyTorch's
(out, in) orientation: [conv1 (6,C,3,3), conv2 (8,6,5,5)] for pixels (C = 3 for RGB, 4 for an
Atari frame stack), then fc1, fc2, fc3. An original ``.dat`` weight file therefore loads unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from policies.base import Policy
from policies.conv import ConvFeatures
from policies.init import default_init
from policies.kernels import head_state, static_step
from policies.network import Layout, NetworkSpec, to_kernel_layout
from policies.plugin import Network


@dataclass
class StaticState:
    head: np.ndarray  # the dense layers in the kernels' layout
    work: np.ndarray
    out: np.ndarray
    features: ConvFeatures | None
    buffer: np.ndarray  # the head's state array (policies.kernels.head_state): head, work and out are views of it


def check_length(name: str, array: np.ndarray, expected: int, what: str) -> np.ndarray:
    array = np.asarray(array)
    if array.size != expected or (array.ndim == 2 and 1 not in array.shape) or array.ndim > 2:
        raise ValueError(f"{name} holds shape {array.shape}, but {what} needs {expected} values "
                         f"(shape ({expected},))")
    return array.reshape(-1).astype(np.float32)


class WeightFile(Policy):
    """One flat weight vector in one ``.dat`` file, named as the original ES code named it; every
    weight is penalised by the L2 term."""

    penalised_name = "w"
    roles = ("weights",)
    num_params: int

    def export(self, params: np.ndarray) -> dict[str, np.ndarray]:
        return {"weights": np.asarray(params, dtype=np.float32).copy()}

    def load(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        return check_length("the weight file", arrays["weights"], self.num_params, "this network")

    def file_name(self, role: str, env: str, reward: int | str, population: int, generation: int) -> str:
        """The original ES code's name (docs/original.md, "Files"); a role a front end adds (``policies.reservoir``)
        is named before the generation, as the Hebbian files name theirs."""
        if role == "weights":
            return f"{env}__rew_{reward}__pop_{population}__{generation}.dat"
        return f"{env}__rew_{reward}__pop_{population}__{role}__{generation}.dat"


class StaticPolicy(WeightFile):
    def __init__(self, net: NetworkSpec):
        net.check_cnn_input()
        self.net = net
        conv = [(f"conv{i + 1}", shape) for i, shape in enumerate(net.conv_shapes)] if net.pixels else []
        dense = [(f"fc{i + 1}", shape) for i, shape in enumerate(net.layer_shapes)]
        self.layout = Layout(conv + dense)
        self.num_params = self.layout.size
        self.penalised = slice(0, self.num_params)  # the L2 term covers every weight
        self._head = slice(net.conv_size, self.num_params)
        self._sizes = net.head_sizes

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        """PyTorch's default initialisation, U(+-1/sqrt(fan_in)) per layer, as the original."""
        fan_in = {name: int(np.prod(part.shape[1:])) for name, part in self.layout.parts.items()}
        return default_init(self.layout, rng, fan_in)

    def reset(self, params: np.ndarray, rng: np.random.Generator | None = None) -> StaticState:
        buffer, views = head_state(self._sizes, self.net.squash_out)
        views["weights"][:] = to_kernel_layout(params[self._head], self.net.layer_shapes)
        features = (ConvFeatures(params[:self.net.conv_size], self.net.conv_shapes)
                    if self.net.pixels else None)
        return StaticState(views["weights"], views["work"], views["out"], features, buffer)

    def act(self, params: np.ndarray, state: StaticState, obs: np.ndarray):
        if state.features is not None:
            obs = state.features(obs)
        static_step(state.buffer, obs)
        return state.out, state


NETWORK = Network("default", about="the original's MLP (state vectors) or CNN (images)", build=StaticPolicy)
