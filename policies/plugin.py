"""What a policy kind and a static network declare as plug-ins (``plugins``), in their own modules; the
registries that list them are ``policies.registry.KINDS`` and ``policies.networks.NETWORKS``.

A kind (``Kind``): its name (the policy kind of config.json), its settings (a frozen dataclass of its own
fields: flags of its scripts only, recorded for its runs only), how to build its policy, whether its weights
are plastic, its training and evaluate scripts, and the evaluate script's flags of its files. A static
network (``Network``): its name (``--network``), how to build it, and the image preprocessing it is fed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from plugins import Plugin

EVALUATED = ("train", "evaluate")  # flags of the evaluate scripts too, which take them from a run's config.json


@dataclass(frozen=True)
class FileFlag:
    """The evaluate script's flag for one of the files a kind's policies save (``Policy.roles``)."""

    flag: str  # "--path_hebb"
    roles: tuple[str, ...]  # the roles it can give; a policy has one of them (CNN weights or co-evolved ones)
    holds: str  # what the file holds, for --help


@dataclass(frozen=True, kw_only=True)
class Kind(Plugin):
    """A kind of policy: how to build one, and what the scripts need to know of it."""

    build: Callable[[Any, Any, bool], Any]  # (the run's PolicySettings, its NetworkSpec, normalise) -> the Policy
    plastic: bool  # its weights change within an episode, so the environments' normalisation matters
    scripts: tuple[str, str]  # its training script and its evaluate script
    files: tuple[FileFlag, ...]  # the evaluate script's flags of its files; the first its main file (roles[0])


@dataclass(frozen=True, kw_only=True)
class Network(Plugin):
    """A static network's shape (``--network``)."""

    build: Callable[[Any], Any]  # NetworkSpec -> the Policy
    preprocessing: str = "default"  # the images it is fed: envs.recipes.PREPROCESSING
