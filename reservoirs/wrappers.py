"""The Gymnasium wrappers of ER-MRL (Léger et al. 2024; docs/original.md, "ER-MRL"), one concern each.

- ``ReservoirWrapper``: the agent sees a reservoir's state (the "context") instead of the observation;
  with ``skip_c`` the reservoir's input is appended to it.
- ``MultiReservoirWrapper``: several reservoirs read the same input; their states are concatenated.
- ``POReservoirWrapper``: the agent sees only the first ``obs_units`` neurons of the reservoir.
- ``DeletedVelocityWrapper``: removes the velocities from the observation (a partially observable MDP).
- ``RewardsSavingWrapper``: records the return of every finished episode, for the fitness.

The reservoir's input at every step is (observation, previous action, reward), the action one-hot for
a Discrete action space (``TransitionEncoder``). The original always fed a zero action, or one-hot(0),
because ``step`` overwrote its ``action`` variable before using it (docs/original.md, "ER-MRL"); here the action is
the one the environment received, and ``zero_action=True`` reproduces the published behaviour. After
a reset there is no previous action: the input holds zeros there (the original's one-hot(0) for a
Discrete space with ``zero_action``). Every reservoir is reset to zero at every episode.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from reservoirs.esn import EchoStateNetwork, ReservoirSettings


class TransitionEncoder:
    """(observation, previous action, reward) as one float64 vector: a reservoir's input."""

    def __init__(self, observation_space: gym.Space, action_space: gym.Space, zero_action: bool = False):
        if not isinstance(observation_space, spaces.Box):
            raise ValueError(f"a reservoir reads Box observations, got {observation_space}")
        if not isinstance(action_space, (spaces.Box, spaces.Discrete)):
            raise ValueError(f"a reservoir reads Box or Discrete actions, got {action_space}")
        self.discrete = isinstance(action_space, spaces.Discrete)
        self.observation_size = int(np.prod(observation_space.shape))
        self.action_size = int(action_space.n) if self.discrete else int(np.prod(action_space.shape))
        self.size = self.observation_size + self.action_size + 1
        self.zero_action = zero_action

    def action_code(self, action) -> np.ndarray:
        """One-hot for Discrete, the flat action for Box; ``None`` (no action yet) gives zeros."""
        code = np.zeros(self.action_size)
        if self.zero_action:  # the original: one-hot(0) or zeros, whatever the action was
            if self.discrete:
                code[0] = 1.0
        elif action is not None:
            if self.discrete:
                code[int(action)] = 1.0
            else:
                code[:] = np.asarray(action, dtype=np.float64).ravel()
        return code

    def encode(self, observation, action, reward: float) -> np.ndarray:
        observation = np.asarray(observation, dtype=np.float64).ravel()
        return np.concatenate((observation, self.action_code(action), [float(reward)]))


class _ReservoirContext(gym.Wrapper):
    """Feeds each transition to ``reservoirs`` and shows the agent ``context(states, inputs)``."""

    def __init__(self, env: gym.Env, settings: Sequence[ReservoirSettings], seed: int, zero_action: bool):
        super().__init__(env)
        self.encoder = TransitionEncoder(env.observation_space, env.action_space, zero_action)
        # seed + index, as the original's MultiReservoirWrapper (one reservoir: the seed itself)
        self.reservoirs = [EchoStateNetwork(self.encoder.size, one, seed + index) for index, one in enumerate(settings)]
        self.last_input: np.ndarray | None = None  # what the reservoirs read last (for tests and analysis)

    def context(self, states: list[np.ndarray], inputs: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _feed(self, inputs: np.ndarray) -> np.ndarray:
        self.last_input = inputs
        return self.context([reservoir.step(inputs) for reservoir in self.reservoirs], inputs)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        for reservoir in self.reservoirs:
            reservoir.reset()
        observation, info = self.env.reset(seed=seed, options=options)
        return self._feed(self.encoder.encode(observation, None, 0.0)), info

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return self._feed(self.encoder.encode(observation, action, reward)), reward, terminated, truncated, info


def _context_space(units: int) -> spaces.Box:
    return spaces.Box(low=-1.0, high=1.0, shape=(units,), dtype=np.float64)


def _skip_connection_space(env: gym.Env, units: int, input_size: int) -> spaces.Box:
    """The original's single [low, high] over observation and action bounds (with max, not min, for high)."""
    observation_space, action_space = env.observation_space, env.action_space
    low, high = float(np.min(observation_space.low)), float(np.max(observation_space.high))
    if isinstance(action_space, spaces.Box):
        low, high = min(low, float(np.min(action_space.low))), max(high, float(np.max(action_space.high)))
    return spaces.Box(low=low, high=high, shape=(units + input_size,), dtype=np.float64)


class MultiReservoirWrapper(_ReservoirContext):
    """Several reservoirs (seeds ``seed``, ``seed + 1``, ...) read the same input; the agent sees their states."""

    def __init__(self, env: gym.Env, settings: Sequence[ReservoirSettings], seed: int = 42, skip_c: bool = False,
                 zero_action: bool = False):
        if not settings:
            raise ValueError("MultiReservoirWrapper needs at least one reservoir")
        super().__init__(env, settings, seed, zero_action)
        self.skip_c = skip_c
        units = sum(one.units for one in settings)
        self.observation_space = (_skip_connection_space(env, units, self.encoder.size) if skip_c
                                  else _context_space(units))

    def context(self, states: list[np.ndarray], inputs: np.ndarray) -> np.ndarray:
        return np.concatenate((*states, inputs) if self.skip_c else states)


class ReservoirWrapper(MultiReservoirWrapper):
    """The agent sees one reservoir's state; with ``skip_c``, followed by (observation, action, reward)."""

    def __init__(self, env: gym.Env, settings: ReservoirSettings, seed: int = 42, skip_c: bool = False,
                 zero_action: bool = False):
        super().__init__(env, [settings], seed, skip_c, zero_action)


class POReservoirWrapper(_ReservoirContext):
    """The agent sees only the first ``obs_units`` of the reservoir's ``units`` neurons."""

    def __init__(self, env: gym.Env, settings: ReservoirSettings, obs_units: int, seed: int = 42,
                 zero_action: bool = False):
        if not 1 <= obs_units <= settings.units:
            raise ValueError(f"obs_units must be between 1 and the reservoir's {settings.units} units, got {obs_units}")
        super().__init__(env, [settings], seed, zero_action)
        self.obs_units = obs_units
        self.observation_space = _context_space(obs_units)

    def context(self, states: list[np.ndarray], inputs: np.ndarray) -> np.ndarray:
        return states[0][: self.obs_units]


class DeletedVelocityWrapper(gym.ObservationWrapper):
    """Removes velocity terms from the observation, as sb3_contrib's MaskedVelocityWrapper but deleting them.

    The indices are the original's, keyed by the environment's name without its version, so that
    ``LunarLander-v3`` (``-v2`` in the original) keeps them.
    """

    VELOCITY_INDICES = {
        "CartPole": [1, 3],
        "MountainCar": [1],
        "MountainCarContinuous": [1],
        "Pendulum": [2],
        "LunarLander": [2, 3, 5],
        "LunarLanderContinuous": [2, 3, 5],
    }

    def __init__(self, env: gym.Env):
        super().__init__(env)
        name = env.unwrapped.spec.name if env.unwrapped.spec is not None else type(env.unwrapped).__name__
        if name not in self.VELOCITY_INDICES:
            raise ValueError(f"--del_obs knows the velocities of {', '.join(self.VELOCITY_INDICES)} only, "
                             f"not {name}")
        keep = np.ones(env.observation_space.shape[0], dtype=bool)
        keep[self.VELOCITY_INDICES[name]] = False
        self.observation_mask = keep
        self.observation_space = spaces.Box(low=env.observation_space.low[keep], high=env.observation_space.high[keep],
                                            dtype=env.observation_space.dtype)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return observation[self.observation_mask]


class RewardsSavingWrapper(gym.Wrapper):
    """Keeps the return of every finished (terminated or truncated) episode."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.episode_returns: list[float] = []
        self._running_return = 0.0

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._running_return = 0.0
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._running_return += float(reward)
        if terminated or truncated:
            self.episode_returns.append(self._running_return)
            self._running_return = 0.0
        return observation, reward, terminated, truncated, info

    def mean_reward(self, last_n_ep: int) -> float:
        """Mean return of the last ``last_n_ep`` finished episodes (all of them if fewer); NaN if none."""
        if not self.episode_returns:
            return float("nan")
        return float(np.mean(self.episode_returns[-last_n_ep:]))
