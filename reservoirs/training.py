"""The inner loop of ER-MRL (docs/original.md, "ER-MRL"): a PPO agent trained from scratch on the reservoir's
state, and the fitness of a trial's reservoirs.

PPO is stable-baselines3's ``PPO('MlpPolicy')`` with SB3's defaults, as the original (learning rate
3e-4, 2048 steps per rollout, batches of 64, 10 epochs, gamma 0.99, GAE lambda 0.95, clip 0.2, a
64-64 tanh MLP); the test scripts also train with learning rates 1e-4 and 5e-5. It runs on the CPU,
where SB3 recommends running PPO with an MLP, which also keeps results independent of the machine.

The fitness of a set of reservoirs on one environment is the mean, over the training seeds 0 ..
nb_seeds - 1, of the mean return of the last ``ep_eval`` episodes of training; across environments it
is the mean of the normalised scores (``reservoirs.experiments.normalised_score``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO

from reservoirs.esn import ReservoirSettings
from reservoirs.experiments import normalised_score
from reservoirs.wrappers import DeletedVelocityWrapper, MultiReservoirWrapper, RewardsSavingWrapper


class NoFinishedEpisode(Exception):
    """Training ended before any episode did: there is no return to score (the original scored NaN)."""


def make_base_env(env_id: str, del_obs: bool) -> gym.Env:
    env = gym.make(env_id)
    return DeletedVelocityWrapper(env) if del_obs else env


def train_ppo(env: gym.Env, seed: int, training_steps: int, learning_rate: float | None = None,
              tensorboard_log: str | None = None, tb_log_name: str = "PPO") -> PPO:
    """``PPO('MlpPolicy', env, seed=seed)`` trained for ``training_steps`` (at least one 2048-step rollout)."""
    options = {} if learning_rate is None else {"learning_rate": learning_rate}
    model = PPO("MlpPolicy", env, verbose=0, seed=seed, device="cpu", tensorboard_log=tensorboard_log, **options)
    model.learn(total_timesteps=training_steps, tb_log_name=tb_log_name)
    return model


@dataclass(frozen=True)
class PPOFrontEnd:
    """How the PPO agent sees its environment: the reservoirs a script puts around it (one or several,
    ``MultiReservoirWrapper``; ``policies.reservoir`` is the ES networks' front end)."""

    skip_c: bool = False
    zero_action: bool = False

    def wrap(self, env: gym.Env, reservoirs: list[ReservoirSettings], seed: int) -> gym.Env:
        return MultiReservoirWrapper(env, reservoirs, seed, skip_c=self.skip_c, zero_action=self.zero_action)


@dataclass(frozen=True)
class InnerLoop:
    """One trial's lifetimes: for each environment and training seed, a PPO agent trained from scratch."""

    front_end: PPOFrontEnd
    training_steps: int
    nb_seeds: int = 3
    ep_eval: int = 10
    del_obs: bool = False

    def lifetime_return(self, env_id: str, reservoirs: list[ReservoirSettings], seed: int,
                        log: Callable[[str], None]) -> float:
        """Mean return of the last ``ep_eval`` episodes of one training run (reservoir and PPO seed ``seed``)."""
        start = time.perf_counter()
        env = RewardsSavingWrapper(self.front_end.wrap(make_base_env(env_id, self.del_obs), reservoirs, seed))
        train_ppo(env, seed, self.training_steps)
        env.close()
        returns = env.episode_returns
        if not returns:
            raise NoFinishedEpisode(f"no episode of {env_id} finished within {self.training_steps} training steps "
                                    f"(seed {seed}); give more --training_steps")
        value = env.mean_reward(self.ep_eval)
        log(f"  {env_id} seed {seed}: mean return of the last {min(self.ep_eval, len(returns))} of {len(returns)} "
            f"episodes {value:.2f} ({time.perf_counter() - start:.1f} s)")
        return value

    def env_return(self, env_id: str, reservoirs: list[ReservoirSettings], log: Callable[[str], None]) -> float:
        return float(np.mean([self.lifetime_return(env_id, reservoirs, seed, log) for seed in range(self.nb_seeds)]))

    def fitness(self, env_ids: tuple[str, ...], reservoirs: list[ReservoirSettings], baseline: str | None,
                log: Callable[[str], None]) -> float:
        """One environment: its mean return. Several (``baseline`` names R_random): the mean normalised score."""
        if baseline is None:
            (env_id,) = env_ids
            return self.env_return(env_id, reservoirs, log)
        scores = []
        for env_id in env_ids:
            scores.append(normalised_score(self.env_return(env_id, reservoirs, log), env_id, baseline))
            log(f"  {env_id}: normalised score {scores[-1]:.4f}")
        return float(np.mean(scores))
