"""The environment settings of a run, as frozen data (``cli.config`` joins them with the others); each
field is its option's one declaration (``settings.setting``)."""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass

from settings import check, setting

NOT_PORTABLE = re.compile(r"[^A-Za-z0-9._+-]")  # POSIX portable file name characters, and '+'
# the longest label: a run folder's files hold it twice (Fitness_values_<time>_<label>_seed<seed>_<label>.npy),
# and a name has at most 255 bytes
LABEL_MAX = 96


@dataclass(frozen=True)
class EnvSettings:
    environment: str = setting("CarRacing-v0", nonempty=True, metavar="ID", scripts=("train", "evaluate"),
                               evaluation=True,  # the evaluate scripts' default, and theirs to change
                               help="Gymnasium, pyBullet or MuJoCo id, or module:Id for a custom environment; several "
                                    "ids separated by commas: trained together (fitness = mean over them), evaluated "
                                    "one row each")
    # the registered ids made (resolved when a run starts); fitness: their mean
    env_ids: tuple[str, ...] = setting((), flag=None, derived=True, help="the ids --environment resolves to")
    recipe_modules: tuple[str, ...] = setting((), flag=None, derived=True,
                                              help="modules that register custom recipes (envs.recipes)")
    max_episode_steps: int | None = setting(None, low=1, metavar="N", shown_default="the environment's own limit",
                                            group="beyond the original algorithm (defaults: the original)",
                                            help="end an episode (as truncated) after N policy steps")

    def __post_init__(self) -> None:
        check(self)

    @property
    def label(self) -> str:
        """The environment part of the original file names: the ids as given, joined by '+', without
        the ``module:`` part of custom ids, and every character that is not portable in a file name
        replaced by '-' (``ALE/Pong-v5`` -> ``ALE-Pong-v5``); other ids keep the original's names. A label
        longer than LABEL_MAX (many ids) keeps its beginning and ends in a digest of the whole."""
        ids = (part.strip().rpartition(":")[2] for part in self.environment.split(",") if part.strip())
        label = "+".join(NOT_PORTABLE.sub("-", env_id) for env_id in ids)
        if len(label) <= LABEL_MAX:
            return label
        return f"{label[:LABEL_MAX - 9]}-{hashlib.sha256(label.encode()).hexdigest()[:8]}"
