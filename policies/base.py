"""The policy protocol (EvoJAX style): what the ES, the rollout and the files need of a network, and
what a policy may optionally do, declared once with its defaults.

A policy is a pure function of a flat float32 parameter vector. ``reset`` makes the per-episode
state (nothing for a static network; the episode's initial weights for a Hebbian one) and ``act``
maps an observation to the network's output, updating the state (the Hebbian update happens inside
``act``), so one rollout runs every kind. A policy also names its parameters: a ``layout`` of named
parts, the slice the ES's L2 term ``penalised``, and the arrays and file names it saves and loads
in the original code's shapes.

The optional hooks have defaults here, those of a policy that does none of it; a kind overrides
what it does, and nothing outside asks a policy anything else (no ``getattr`` probing):

- **carry plastic state**: ``layer_weights(state)``, the dense weights an episode's state holds now
  (a Hebbian network's change as it acts; the adaptation plot draws them);
- **keep observation statistics** (``--obs_norm``, ``policies.normalised``): ``normalised_inputs``,
  ``obs_clip``, ``observe`` (the runner's published mean and std) and ``observation_sums`` (what an
  episode's state added up);
- **own a front end** (``FrontEnd``: ``policies.normalised``, ``policies.reservoir``): a policy that
  feeds another, ``inner``, spells out every member of the protocol, and says what it is in
  ``describe_front_ends``;
- **add metrics columns**: ``metrics_columns`` names them, ``evolved_values`` gives their values for
  a parameter vector (the reservoir's evolved hyperparameters); ``es.files`` writes them;
- **import heavy modules in its episodes**: ``worker_modules`` names them, for the process pool to
  load once before its workers start (no built-in policy needs it: the CNN does not use torch).

Concrete policies subclass ``Policy`` to inherit the defaults (PEP 544 allows a protocol with default
members to be subclassed explicitly).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from policies.network import Layout, NetworkSpec

Statistics = tuple[np.ndarray, np.ndarray]  # (mean, std) of the observations
Sums = tuple[np.ndarray, np.ndarray, int]  # (sum, sum of squares, count) of an episode's observations


class Policy(Protocol):
    net: NetworkSpec  # the network the evolved weights define (behind a front end, the inner one's)
    num_params: int
    layout: Layout
    penalised: slice  # the parameters the ES's fitness penalty covers
    penalised_name: str  # what those are called in the generation line ("w", "coeffs")
    roles: tuple[str, ...]  # the arrays ``export`` writes and ``load`` reads, one file each

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        """Generation 0's parameter vector."""
        raise NotImplementedError

    def reset(self, params: np.ndarray, rng: np.random.Generator) -> Any:
        """The state an episode starts from; ``rng`` is the episode's own random stream."""
        raise NotImplementedError

    def act(self, params: np.ndarray, state: Any, obs: np.ndarray) -> tuple[np.ndarray, Any]:
        """The network's output for ``obs``, and the next state."""
        raise NotImplementedError

    def export(self, params: np.ndarray) -> dict[str, np.ndarray]:
        """role -> array, in the original files' shapes."""
        raise NotImplementedError

    def load(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        """The parameter vector from arrays as ``export`` gives them (or the original code wrote them)."""
        raise NotImplementedError

    def file_name(self, role: str, env: str, reward: int | str, population: int, generation: int) -> str:
        """The original code's name for the file of ``role`` saved after ``generation`` (0-based)."""
        raise NotImplementedError

    # --- optional hooks, with the defaults of a policy that does none of it ----------------------

    def layer_weights(self, state: Any) -> list[np.ndarray] | None:
        """The weights of each dense layer, (n_out, n_in), as ``state`` holds them now; None: the
        network's weights are its parameters and never change within an episode."""
        return None

    normalised_inputs: int = 0  # how many observations it normalises (``policies.normalised``); 0: none
    obs_clip: float | None = None  # with normalised inputs: the clip of the normalised observations

    def observe(self, statistics: Statistics) -> None:
        """Normalise observations with (mean, std) from now on (the runner's, once per generation)."""
        raise TypeError(f"{type(self).__name__} normalises no observations")

    def observation_sums(self, state: Any) -> Sums | None:
        """What the episode that ended in ``state`` added up of the observations it normalised."""
        return None

    metrics_columns: tuple[str, ...] = ()  # the metrics.csv columns ``evolved_values`` fills

    # modules its episodes import that a process pool's fork server loads once, for the workers to
    # share their pages (``es.backends.process``): torch's libraries alone are ~120 MiB per process
    worker_modules: tuple[str, ...] = ()

    def evolved_values(self, params: np.ndarray) -> dict[str, float]:
        """column -> value for ``params``: settings it evolves beside its weights; {} for most policies."""
        return {}

    def describe_front_ends(self, params: np.ndarray) -> list[str]:
        """One line for each front end between the observation and the network (the evaluate scripts')."""
        return []


class FrontEnd(Policy):
    """A policy that owns another, ``inner``, and changes what it reads. Every member of the protocol is
    the inner policy's unless the front end overrides it, spelled out here (no ``__getattr__``: a front
    end offers the protocol and nothing else). A front end's episode state keeps the inner policy's
    as its ``inner`` field; its parameters start with the inner policy's."""

    def __init__(self, inner: Policy):
        self.inner = inner
        self.net = inner.net
        self.layout, self.num_params = inner.layout, inner.num_params
        self.penalised, self.penalised_name, self.roles = inner.penalised, inner.penalised_name, inner.roles
        self.normalised_inputs, self.obs_clip = inner.normalised_inputs, inner.obs_clip
        self.metrics_columns, self.worker_modules = inner.metrics_columns, inner.worker_modules
        self._inner = slice(0, inner.num_params)

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        return self.inner.initial_params(rng)

    def export(self, params: np.ndarray) -> dict[str, np.ndarray]:
        return self.inner.export(params[self._inner])

    def load(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        return self.inner.load(arrays)

    def file_name(self, role: str, env: str, reward: int | str, population: int, generation: int) -> str:
        return self.inner.file_name(role, env, reward, population, generation)

    def layer_weights(self, state: Any) -> list[np.ndarray] | None:
        return self.inner.layer_weights(state.inner)

    def observe(self, statistics: Statistics) -> None:
        self.inner.observe(statistics)

    def observation_sums(self, state: Any) -> Sums | None:
        return self.inner.observation_sums(state.inner)

    def evolved_values(self, params: np.ndarray) -> dict[str, float]:
        return self.inner.evolved_values(params[self._inner])

    def describe_front_ends(self, params: np.ndarray) -> list[str]:
        return self.inner.describe_front_ends(params[self._inner])
