"""What ER-MRL evolves and how it scores generalisation (docs/original.md, "ER-MRL"; ER-MRL's
``er_mrl/experiments.py``): the search space, the environment presets, the target and random returns,
and the normalised score (R - R_random) / (R_target - R_random).

Parameter names in a study are the original's, so its journals and these read each other: ``lr``,
``sr``, ``iss`` for one reservoir (evolve_res.py), ``lr_1``, ``sr_1``, ``iss_1``, ... for several.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from reservoirs.esn import ReservoirSettings

# --env_type presets of evolve_generalization.py (the original's generate_env_ids); the *_4_tr_envs
# leave the named task out for testing
ENV_TYPES: dict[str, tuple[str, ...]] = {
    "Ant_Swimmer": ("Ant-v4", "Swimmer-v4"),
    "Ant_Cheetah": ("Ant-v4", "HalfCheetah-v4"),
    "Cheetah_Swimmer": ("HalfCheetah-v4", "Swimmer-v4"),
    "Ant_4_tr_envs": ("HalfCheetah-v4", "Hopper-v4", "Swimmer-v4", "Walker2d-v4"),
    "Cheetah_4_tr_envs": ("Ant-v4", "Hopper-v4", "Swimmer-v4", "Walker2d-v4"),
    "Swimmer_4_tr_envs": ("Ant-v4", "HalfCheetah-v4", "Hopper-v4", "Walker2d-v4"),
    "Hopper_4_tr_envs": ("Ant-v4", "HalfCheetah-v4", "Swimmer-v4", "Walker2d-v4"),
    "Walker_4_tr_envs": ("Ant-v4", "HalfCheetah-v4", "Swimmer-v4", "Hopper-v4"),
    "forward_mujoco": ("Ant-v4", "HalfCheetah-v4", "Hopper-v4", "Swimmer-v4", "Walker2d-v4"),
}

# the original's R_target (env_target_reward)
TARGET_RETURN: dict[str, float] = {
    "Ant-v4": 125, "HalfCheetah-v4": 750, "Swimmer-v4": 60, "Hopper-v4": 1250, "Humanoid-v4": 375,
    "HumanoidStandup-v4": 7500, "Walker2d-v4": 800,
}

# The original's R_random (env_random_reward): the mean *per-step* reward of a random agent, which it
# compared with episodic returns (docs/original.md, "ER-MRL"). Kept for --random_baseline per_step.
RANDOM_RETURN_PER_STEP: dict[str, float] = {
    "Ant-v4": -0.355, "HalfCheetah-v4": -0.292, "Hopper-v4": 0.751, "Humanoid-v4": 5.025,
    "HumanoidStandup-v4": 33.089, "InvertedDoublePendulum-v4": 9.088, "InvertedPendulum-v4": 1.0,
    "Pusher-v4": -1.493, "Reacher-v4": -0.849, "Swimmer-v4": 0.0, "Walker2d-v4": 0.075,
}

# The mean *episodic* return of a uniformly random agent, 100 episodes (seeds 0-99), measured with
#   python scripts/get_random_scores.py --episodes 100
# (Gymnasium 1.4.0, MuJoCo 3.3.7; Pusher-v4 needs mujoco < 3). The default R_random. The same script with
# --per_step gives Ant-v4 -0.329, Swimmer-v4 0.001, Walker2d-v4 0.068: the original's numbers above.
RANDOM_RETURN_EPISODIC: dict[str, float] = {
    "Ant-v4": -59.342, "HalfCheetah-v4": -285.915, "Hopper-v4": 19.892, "Humanoid-v4": 120.811,
    "HumanoidStandup-v4": 32975.100, "InvertedDoublePendulum-v4": 59.090, "InvertedPendulum-v4": 6.230,
    "Reacher-v4": -43.353, "Swimmer-v4": 0.803, "Walker2d-v4": 2.611,
}
RANDOM_SCORE_ENV_IDS = tuple(RANDOM_RETURN_EPISODIC)  # get_random_scores.py's default

RANDOM_BASELINES = {"episodic": RANDOM_RETURN_EPISODIC, "per_step": RANDOM_RETURN_PER_STEP}


def random_agent_return(env_id: str, episodes: int, per_step: bool = False) -> float:
    """Mean return of uniformly random actions over ``episodes`` episodes (seeds 0, 1, ...); with
    ``per_step``, the mean over episodes of the mean reward per step, as the original measured it."""
    env = gym.make(env_id)
    env.action_space.seed(0)
    scores = []
    for episode in range(episodes):
        env.reset(seed=episode)
        rewards, done = [], False
        while not done:
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            rewards.append(float(reward))
            done = terminated or truncated
        scores.append(np.mean(rewards) if per_step else np.sum(rewards))
    env.close()
    return float(np.mean(scores))


def env_ids_for(env_type: str) -> tuple[str, ...]:
    """A preset's environments, or a comma-separated list of ids that have a target return."""
    if env_type in ENV_TYPES:
        return ENV_TYPES[env_type]
    ids = tuple(part.strip() for part in env_type.split(",") if part.strip())
    unknown = [env_id for env_id in ids if env_id not in TARGET_RETURN]
    if "," not in env_type or not ids or unknown:
        raise ValueError(f"unknown --env_type {env_type!r}; valid: {', '.join(ENV_TYPES)}, or ids separated by "
                         f"commas among {', '.join(TARGET_RETURN)} (those with a target return)")
    return ids


def check_normalisable(env_ids: tuple[str, ...], baseline: str) -> None:
    """Every id needs R_target > R_random (HumanoidStandup-v4's target 7500 is below a random agent's return)."""
    randoms = RANDOM_BASELINES[baseline]
    bad = [env_id for env_id in env_ids if env_id not in randoms or TARGET_RETURN[env_id] <= randoms[env_id]]
    if bad:
        usable = [env_id for env_id in TARGET_RETURN if env_id in randoms and TARGET_RETURN[env_id] > randoms[env_id]]
        raise ValueError(f"no usable {baseline} random return below the target for {', '.join(bad)}; usable: "
                         f"{', '.join(usable)}")


def normalised_score(mean_return: float, env_id: str, baseline: str = "episodic") -> float:
    """(R - R_random) / (R_target - R_random): 0 for a random agent, 1 at the target."""
    random_return = RANDOM_BASELINES[baseline][env_id]
    return (mean_return - random_return) / (TARGET_RETURN[env_id] - random_return)


@dataclass(frozen=True)
class SearchSpace:
    """Log-uniform bounds of lr, sr and iss, and how many reservoirs of how many units a trial has.

    ``suffixed`` names the parameters ``lr_1``, ``sr_1``, ... (several reservoirs) instead of ``lr``,
    ``sr`` (evolve_res.py). With ``fixed_iss`` the input scaling is 1.0 and not searched.
    """

    bounds: dict[str, tuple[float, float]]  # "lr" / "sr" / "iss" -> (low, high)
    units: int
    nb_res: int = 1
    fixed_iss: bool = True
    suffixed: bool = False

    def __post_init__(self):
        for name, (low, high) in self.bounds.items():
            if not 0 < low <= high:
                raise ValueError(f"--min_{name} {low} and --max_{name} {high}: need 0 < min <= max")
        if self.bounds["lr"][1] > 1:
            raise ValueError(f"--max_lr {self.bounds['lr'][1]}: a leak rate is at most 1")

    def searched(self) -> list[str]:
        return searched_names(self.nb_res, self.fixed_iss, self.suffixed)

    def sample(self, trial) -> list[ReservoirSettings]:
        """One trial's reservoirs, suggested from an optuna trial."""
        params = {name: trial.suggest_float(name, *self.bounds[name.split("_")[0]], log=True)
                  for name in self.searched()}
        return reservoirs_from_params(params, self.units, self.nb_res, self.fixed_iss, self.suffixed)


def searched_names(nb_res: int, fixed_iss: bool, suffixed: bool) -> list[str]:
    """The parameter names a trial suggests, in the original's order (it matters to the samplers)."""
    if not suffixed:  # evolve_res.py: iss, sr, lr
        return ([] if fixed_iss else ["iss"]) + ["sr", "lr"]
    kinds = ["lr", "sr"] + ([] if fixed_iss else ["iss"])
    return [f"{kind}_{index}" for kind in kinds for index in range(1, nb_res + 1)]


def reservoirs_from_params(params: dict[str, float], units: int, nb_res: int, fixed_iss: bool,
                           suffixed: bool) -> list[ReservoirSettings]:
    """The reservoirs a trial's parameters describe (``iss`` 1.0 when fixed)."""
    missing = [name for name in searched_names(nb_res, fixed_iss, suffixed) if name not in params]
    if missing:
        hint = " (was it evolved with --fixed_iss True?)" if any(name.startswith("iss") for name in missing) else ""
        raise ValueError(f"the study's parameters ({', '.join(sorted(params))}) lack {', '.join(missing)}{hint}")

    def value(kind: str, index: int) -> float:
        if kind == "iss" and fixed_iss:
            return 1.0
        return params[f"{kind}_{index}" if suffixed else kind]

    return [ReservoirSettings(units, value("lr", index), value("sr", index), value("iss", index))
            for index in range(1, nb_res + 1)]
