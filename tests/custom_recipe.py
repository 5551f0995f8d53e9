"""A custom recipe, registered on import the way a user's module would: the corridor of
``tests.custom_env_module`` ends after more than two steps to the left in a row."""

from __future__ import annotations

from envs import Recipe, register_recipe
from tests.custom_env_module import Corridor


def is_corridor(env) -> bool:
    return isinstance(env, Corridor)


SHORT_CORRIDOR = Recipe("short corridor", is_corridor, stop_patience=2)
register_recipe(SHORT_CORRIDOR)
