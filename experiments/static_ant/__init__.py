"""What makes a static ant stand: the paper's static ant with one of its settings changed at a time.

Each ``*.toml`` here is a variant file of ``experiments/paper/ant_static.toml`` (``paper.py ant static --variant
FILE``): the settings it changes, a short run (20 generations) and a short evaluation (20 episodes per body). The
campaign trains each over three seeds; ``experiments/stand.py`` compares them with the paper's own runs'
first 20 generations, from the runs' files (``results/paper/STATIC_ANT.md``).

Two of the changes are to the episode, not to a setting. Each is a module that registers the paper's bodies again
under ids of its own (``register_bodies``: ``NoGraceAntBulletEnv-v0``, the same environment, marked as the
module's) and a recipe that takes only the ants so marked (``envs.register_recipe``): every other ant, in that
process too, keeps the built-in recipe. A variant names the module in its environment ids
(``experiments.static_ant.no_grace:NoGraceAntBulletEnv-v0``), so every worker and a resumed run import it, and
the run's config.json records it as the module of its recipe.
"""

from __future__ import annotations

BODIES = ("AntBulletEnv-v0", "AntAsymRightBulletEnv-v0", "AntAsymLeftBulletEnv-v0")  # the paper's three
MARK = "static_ant_change"  # the attribute of an unwrapped environment that names the module it was made for


def register_bodies(prefix: str, module: str) -> None:
    """Register ``<prefix><body>`` for each of the paper's bodies: the body's own environment (its entry point, its
    arguments, its time limit), marked as ``module``'s (``made_for``). Idempotent."""
    import gymnasium as gym
    from gymnasium.envs.registration import load_env_creator

    import envs  # noqa: F401  (registers the damaged bodies)

    for body in BODIES:
        if prefix + body in gym.registry:
            continue
        spec = gym.spec(body)

        def make(spec=spec, **kwargs):
            creator = spec.entry_point if callable(spec.entry_point) else load_env_creator(spec.entry_point)
            env = creator(**{**spec.kwargs, **kwargs})
            setattr(env, MARK, module)
            return env

        gym.register(prefix + body, entry_point=make, max_episode_steps=spec.max_episode_steps)


def made_for(env, module: str) -> bool:
    """Whether an (unwrapped) environment was made by ``register_bodies`` for ``module``."""
    return getattr(env, MARK, None) == module
