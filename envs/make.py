"""Environment construction: id resolution, aliases of retired ids, the fast CarRacing's ids, the
family recipe, warm-up.

``make_env`` is the only place an environment is created, for training, evaluation, benchmarks
and tests alike.
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import difflib
import importlib
import os
import sys

import gymnasium as gym
from gymnasium.envs.registration import parse_env_id

from envs import atari
from envs.recipes import Recipe, recipe_for
from envs.wrappers import MaxEpisodeSteps

STOCK_CAR_RACING_ID = "CarRacingStock-v3"


class EnvironmentError_(ValueError):
    """An environment id that cannot be made; the message names close matches."""


def register_fast_car_racing() -> None:
    """``CarRacing-v3`` (so the retired ``CarRacing-v0`` too) makes ``envs.car_racing.FastCarRacing``,
    Gymnasium's class drawn faster with the same frames; ``CarRacingStock-v3`` makes
    Gymnasium's own class with the same spec, to check any result against it.

    Idempotent. Nothing is imported here: the fast class's module (Box2D, pygame, numba kernels)
    loads when a CarRacing is made.
    """
    spec = gym.registry.get("CarRacing-v3")
    if spec is None or STOCK_CAR_RACING_ID in gym.registry:
        return
    gym.registry[STOCK_CAR_RACING_ID] = dataclasses.replace(spec, id=STOCK_CAR_RACING_ID)
    gym.registry["CarRacing-v3"] = dataclasses.replace(spec, entry_point="envs.car_racing:FastCarRacing")


def _usable(spec) -> bool:
    # Gymnasium keeps the mujoco-py based v2/v3 ids registered, with an entry point that raises.
    entry = spec.entry_point
    return not (callable(entry) and getattr(entry, "__name__", "").startswith("_raise"))


def resolve_env_id(env_id: str, notify=print) -> str:
    """The registered id to make for ``env_id``; retired versions map to the newest one.

    ``module:EnvId`` imports ``module`` first (Gymnasium's form for custom environments); the
    returned id keeps the ``module:`` part, so worker processes and resumed runs import it too.
    """
    prefix = ""
    if ":" in env_id:
        module, _, rest = env_id.partition(":")
        try:
            importlib.import_module(module)
        except Exception as error:  # not found, or its own code raised while it was imported
            first = (str(error).strip().splitlines() or [""])[0]
            reason = first if isinstance(error, ImportError) else f"{type(error).__name__}: {first}"
            raise EnvironmentError_(f"cannot import {module!r} for environment {env_id!r}: {reason}") from None
        env_id, prefix = rest, f"{module}:"
    registry = gym.registry
    if env_id in registry and _usable(registry[env_id]):
        return prefix + env_id
    try:
        namespace, name, version = parse_env_id(env_id)
    except gym.error.Error:
        namespace, name, version = None, None, None
    versions = [spec for spec in registry.values()
                if spec.namespace == namespace and spec.name == name and _usable(spec)]
    newest = max(versions, key=lambda spec: spec.version or 0) if versions else None
    if newest is not None and (version is None or version < (newest.version or 0)):
        why = "names no version" if version is None else f"is retired in Gymnasium {gym.__version__}"
        notify(f"note: {env_id} {why}; using {newest.id}")
        return prefix + newest.id
    if not atari.AVAILABLE and atari.looks_like_atari(env_id):
        raise EnvironmentError_(f"unknown environment {env_id!r}: {atari.INSTALL_HINT}")
    known = [spec_id for spec_id, spec in registry.items() if _usable(spec)]
    close = difflib.get_close_matches(env_id, known, n=5, cutoff=0.5)
    hint = (f"; did you mean {', '.join(close)}?" if close else
            "; list them with: python -c 'import envs, gymnasium; gymnasium.pprint_registry()'")
    raise EnvironmentError_(f"unknown environment {env_id!r}{hint}")


@contextlib.contextmanager
def quiet_output():
    """Silence C-level prints to fds 1 and 2 (pyBullet's build banner and 'argv[0]=' lines).

    Python exceptions still propagate; only text written by C code meanwhile is dropped.
    """
    streams = [sys.stdout, sys.stderr]
    try:
        fds = [stream.fileno() for stream in streams]
    except (AttributeError, OSError, ValueError):  # captured streams (pytest): nothing to silence
        yield
        return
    for stream in streams:
        stream.flush()
    saved = [os.dup(fd) for fd in fds]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(devnull, fd)
        yield
    finally:
        ctypes.CDLL(None).fflush(None)
        for fd, copy in zip(fds, saved):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)


def make_env(env_id: str, render_mode: str | None = None, preprocessing: str = "default",
             max_episode_steps: int | None = None) -> tuple[gym.Env, Recipe]:
    """Make a registered (already resolved) id, wrapped by its family's recipe (images preprocessed
    for the network, ``envs.recipes.PREPROCESSING``; and, outermost, ``MaxEpisodeSteps`` if a cap is
    given), warmed up.

    The warm-up reset matters for pyBullet: its first reset loads the model and later ones restore
    a saved state, which gives slightly different trajectories. After the warm-up every episode,
    on whichever worker, starts the same way.
    """
    with quiet_output():
        env = gym.make(env_id, render_mode=render_mode)
        recipe = recipe_for(env)
        env = recipe.wrap(env, preprocessing)
        if max_episode_steps is not None:
            env = MaxEpisodeSteps(env, max_episode_steps)
        env.reset(seed=0)
    return env, recipe
