"""Policy kinds by name, and the settings that choose one.

A new kind of network is one module that implements ``policies.base.Policy`` plus one line in
``KINDS``: a function from (settings, network spec, whether the environment normalises plastic
weights) to the policy. Nothing else in the project branches on the kind.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from policies.base import Policy
from policies.hebbian import HebbianPolicy
from policies.network import NetworkSpec
from policies.normalised import NormalisedInputs
from policies.static import StaticPolicy


@dataclass(frozen=True)
class PolicySettings:
    kind: str = "static"
    hebb_rule: str = "ABCD_lr"  # Hebbian kinds: the rule family
    init_weights: str = "uni"  # Hebbian kinds: each episode's initial weights
    distribution: str = "normal"  # Hebbian kinds: generation 0's coefficients (and CNN / co-evolved weights)
    obs_norm: bool = False  # the input layer sees (obs - mean) / std (``policies.normalised``); not for pixels
    obs_clip: float | None = None  # with obs_norm: clip the normalised observations to +-obs_clip

    def __post_init__(self) -> None:
        if self.obs_clip is not None and not 0 < self.obs_clip < float("inf"):
            raise ValueError(f"--obs_clip must be a number > 0, got {self.obs_clip}")


@dataclass(frozen=True)
class Kind:
    build: Callable[[PolicySettings, NetworkSpec, bool], Policy]
    plastic: bool  # its weights change within an episode, so the environments' normalisation matters


KINDS: dict[str, Kind] = {
    "static": Kind(lambda settings, net, normalise: StaticPolicy(net), plastic=False),
    "hebbian": Kind(lambda settings, net, normalise: HebbianPolicy(net, settings.hebb_rule, settings.init_weights,
                                                                   normalise, settings.distribution), plastic=True),
}


def kind_of(settings: PolicySettings) -> Kind:
    if settings.kind not in KINDS:
        raise ValueError(f"unknown policy kind {settings.kind!r}; valid kinds: {', '.join(KINDS)}")
    return KINDS[settings.kind]


def make_policy(settings: PolicySettings, net: NetworkSpec, normalise: bool = True) -> Policy:
    """The policy ``settings`` name, for a network ``net``; ``normalise``: the environment's Hebbian
    weight normalisation (upstream spec §4.3), used by plastic kinds only. With ``obs_norm`` a
    vector-input network sees normalised observations; a pixel network is left as it is."""
    policy = kind_of(settings).build(settings, net, normalise)
    if settings.obs_norm and not net.pixels:
        return NormalisedInputs(policy, net.obs_shape[0], settings.obs_clip)
    return policy
