"""The policy protocol (EvoJAX style): what the ES, the rollout and the files need of a network.

A policy is a pure function of a flat float32 parameter vector. ``reset`` makes the per-episode
state (nothing for a static network; the episode's initial weights for a Hebbian one) and ``act``
maps an observation to the network's output, updating the state (the Hebbian update happens inside
``act``), so one rollout runs every kind. A policy also names its parameters: a ``layout`` of named
parts, the slice the ES's L2 term ``penalised``, and the arrays and file names it saves and loads
in the original code's shapes.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from policies.network import Layout


class Policy(Protocol):
    num_params: int
    layout: Layout
    penalised: slice  # the parameters the ES's fitness penalty covers
    penalised_name: str  # what those are called in the generation line ("w", "coeffs")
    roles: tuple[str, ...]  # the arrays ``export`` writes and ``load`` reads, one file each
    normalised_inputs: int  # how many observations it normalises (``policies.normalised``); 0: none

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        """Generation 0's parameter vector."""

    def reset(self, params: np.ndarray, rng: np.random.Generator) -> Any:
        """The state an episode starts from; ``rng`` is the episode's own random stream."""

    def act(self, params: np.ndarray, state: Any, obs: np.ndarray) -> tuple[np.ndarray, Any]:
        """The network's output for ``obs``, and the next state."""

    def export(self, params: np.ndarray) -> dict[str, np.ndarray]:
        """role -> array, in the original files' shapes."""

    def load(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        """The parameter vector from arrays as ``export`` gives them (or the original code wrote them)."""

    def file_name(self, role: str, env: str, reward: int, population: int, generation: int) -> str:
        """The original code's name for the file of ``role`` saved after ``generation`` (0-based)."""
