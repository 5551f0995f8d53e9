"""The environment settings of a run, as frozen data (``config`` joins them with the others)."""

from __future__ import annotations

import re
from dataclasses import dataclass

NOT_PORTABLE = re.compile(r"[^A-Za-z0-9._+-]")  # POSIX portable file name characters, and '+'


@dataclass(frozen=True)
class EnvSettings:
    environment: str = "CarRacing-v0"  # as given on the command line: one id, or several separated by commas
    env_ids: tuple[str, ...] = ()  # the registered ids made (resolved when a run starts); fitness: their mean
    recipe_modules: tuple[str, ...] = ()  # modules that register custom recipes (``envs.recipes``)
    max_episode_steps: int | None = None  # cap on the policy steps of an episode (``envs.wrappers.MaxEpisodeSteps``)

    def __post_init__(self) -> None:
        if self.max_episode_steps is not None and self.max_episode_steps < 1:
            raise ValueError(f"--max_episode_steps must be a whole number >= 1, got {self.max_episode_steps}")

    @property
    def label(self) -> str:
        """The environment part of the original file names: the ids as given, joined by '+', without
        the ``module:`` part of custom ids, and every character that is not portable in a file name
        replaced by '-' (``ALE/Pong-v5`` -> ``ALE-Pong-v5``); other ids keep the original's names."""
        ids = (part.strip().rpartition(":")[2] for part in self.environment.split(",") if part.strip())
        return "+".join(NOT_PORTABLE.sub("-", env_id) for env_id in ids)
