"""Network shapes shared by the static and the Hebbian policies (docs/original.md, "Networks").

State vectors go through an MLP  obs -> 128 -> 64 -> actions; pixels (C x 84 x 84: 3 for the
original's RGB frames, 4 for an Atari frame stack) first through two conv layers whose 648 features
feed the same head; the first conv layer takes the observation's C channels. No layer has a bias; hidden
layers use tanh;
the output is raw unless the environment's recipe asks for tanh (pyBullet).

A ``Layout`` names the parts of a flat parameter vector, so that it can be split into weights,
Hebbian coefficients, CNN weights or co-evolved initial weights, and saved in the original shapes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HIDDEN = (128, 64)
CONV_FEATURES = 648
PIXEL_SIZE = 84  # the CNN's input is C x 84 x 84


def conv_shapes(channels: int) -> tuple[tuple[int, int, int, int], ...]:
    """The two conv weights (out, in, k, k) for ``channels`` input channels (RGB: 3)."""
    return (6, channels, 3, 3), (8, 6, 5, 5)




@dataclass(frozen=True)
class NetworkSpec:
    """What a network needs to know about its environment."""

    obs_shape: tuple[int, ...]
    n_actions: int
    squash_out: bool = False  # tanh on the output layer, seen by the Hebbian rule too

    def __post_init__(self) -> None:
        if len(self.obs_shape) not in (1, 3):
            raise ValueError(f"observations must be vectors or images, got shape {self.obs_shape}")

    @property
    def pixels(self) -> bool:
        return len(self.obs_shape) == 3

    def check_cnn_input(self) -> None:
        """The conv front end of the static and Hebbian networks needs C x 84 x 84 images."""
        if self.pixels and (self.obs_shape[0] < 1 or tuple(self.obs_shape[1:]) != (PIXEL_SIZE, PIXEL_SIZE)):
            raise ValueError(f"pixel observations must be C x {PIXEL_SIZE} x {PIXEL_SIZE}, got {self.obs_shape}")

    @property
    def conv_shapes(self) -> tuple[tuple[int, int, int, int], ...]:
        """The conv weights for this observation's channels (pixel networks only)."""
        return conv_shapes(self.obs_shape[0])

    @property
    def conv_size(self) -> int:
        """How many conv weights a pixel network has (0 for state vectors)."""
        return sum(int(np.prod(shape)) for shape in self.conv_shapes) if self.pixels else 0

    @property
    def head_sizes(self) -> tuple[int, int, int, int]:
        n_in = CONV_FEATURES if self.pixels else self.obs_shape[0]
        return (n_in, *HIDDEN, self.n_actions)

    @property
    def layer_shapes(self) -> list[tuple[int, int]]:
        """(n_out, n_in) of the three dense layers, PyTorch's orientation."""
        sizes = self.head_sizes
        return [(sizes[i + 1], sizes[i]) for i in range(3)]

    @property
    def n_synapses(self) -> int:
        return sum(n_out * n_in for n_out, n_in in self.layer_shapes)


def to_kernel_layout(weights: np.ndarray, layer_shapes: list[tuple[int, int]]) -> np.ndarray:
    """Dense layers flat in PyTorch order (each (n_out, n_in), C-order) -> the kernels' layout
    (each transposed to (n_in, n_out), C-order), as a new float32 array."""
    blocks, offset = [], 0
    for n_out, n_in in layer_shapes:
        blocks.append(weights[offset:offset + n_out * n_in].reshape(n_out, n_in).T.ravel())
        offset += n_out * n_in
    return np.concatenate(blocks).astype(np.float32)


def from_kernel_layout(weights: np.ndarray, layer_shapes: list[tuple[int, int]]) -> list[np.ndarray]:
    """The kernels' flat layout -> one (n_out, n_in) matrix per layer (PyTorch's orientation)."""
    layers, offset = [], 0
    for n_out, n_in in layer_shapes:
        layers.append(weights[offset:offset + n_out * n_in].reshape(n_in, n_out).T)
        offset += n_out * n_in
    return layers


@dataclass(frozen=True)
class Part:
    name: str
    shape: tuple[int, ...]
    offset: int

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def slice(self) -> slice:
        return slice(self.offset, self.offset + self.size)


class Layout:
    """Named, contiguous parts of a flat parameter vector, in order."""

    def __init__(self, parts: list[tuple[str, tuple[int, ...]]]):
        self.parts: dict[str, Part] = {}
        offset = 0
        for name, shape in parts:
            part = Part(name, tuple(shape), offset)
            self.parts[name] = part
            offset += part.size
        self.size = offset

    def __getitem__(self, name: str) -> Part:
        return self.parts[name]

    def __contains__(self, name: str) -> bool:
        return name in self.parts

    def view(self, params: np.ndarray, name: str) -> np.ndarray:
        part = self.parts[name]
        return params[part.slice].reshape(part.shape)

    def describe(self) -> dict[str, list[int]]:
        return {name: list(part.shape) for name, part in self.parts.items()}
