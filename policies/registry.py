"""Policy kinds by name, and the settings that choose one.

A new kind of network is one module that implements ``policies.base.Policy`` plus one line in
``KINDS``: a function from (settings, network spec, whether the environment normalises plastic
weights) to the policy. Nothing else in the project branches on the kind.

Static networks come in three shapes (``--network``, ``NETWORKS``): the original's MLP / CNN
(``default``), and pytorch-es's small net and conv-LSTM (``policies.pytorch_es``). A network also
names the image preprocessing it expects (``envs.recipes.PREPROCESSING``), which the environments
are made with.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from policies.base import Policy
from policies.hebbian import HebbianPolicy
from policies.network import NetworkSpec
from policies.pytorch_es import ConvLSTMPolicy, SmallNetPolicy
from policies.normalised import NormalisedInputs
from policies.static import StaticPolicy


@dataclass(frozen=True)
class Network:
    build: Callable[[NetworkSpec], Policy]
    preprocessing: str = "default"  # the images it is fed: envs.recipes.PREPROCESSING


NETWORKS: dict[str, Network] = {
    "default": Network(StaticPolicy),
    "small": Network(SmallNetPolicy),
    "lstm": Network(ConvLSTMPolicy, preprocessing="pytorch-es"),
}


@dataclass(frozen=True)
class PolicySettings:
    kind: str = "static"
    hebb_rule: str = "ABCD_lr"  # Hebbian kinds: the rule family
    init_weights: str = "uni"  # Hebbian kinds: each episode's initial weights
    distribution: str = "normal"  # Hebbian kinds: generation 0's coefficients (and CNN / co-evolved weights)
    network: str = "default"  # static kinds: the network's shape, NETWORKS
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
    "static": Kind(lambda settings, net, normalise: network_of(settings).build(net), plastic=False),
    "hebbian": Kind(lambda settings, net, normalise: HebbianPolicy(net, settings.hebb_rule, settings.init_weights,
                                                                   normalise, settings.distribution), plastic=True),
}


def kind_of(settings: PolicySettings) -> Kind:
    if settings.kind not in KINDS:
        raise ValueError(f"unknown policy kind {settings.kind!r}; valid kinds: {', '.join(KINDS)}")
    if settings.kind != "static" and settings.network != "default":
        raise ValueError(f"network {settings.network!r} is a static network (pytorch-es's); {settings.kind} "
                         "networks have the default shape only")
    return KINDS[settings.kind]


def network_of(settings: PolicySettings) -> Network:
    if settings.network not in NETWORKS:
        raise ValueError(f"unknown network {settings.network!r}; valid networks: {', '.join(NETWORKS)}")
    return NETWORKS[settings.network]


def preprocessing(settings: PolicySettings) -> str:
    """The image preprocessing the environments are made with for this policy."""
    return network_of(settings).preprocessing


def make_policy(settings: PolicySettings, net: NetworkSpec, normalise: bool = True) -> Policy:
    """The policy ``settings`` name, for a network ``net``; ``normalise``: the environment's Hebbian
    weight normalisation (upstream spec §4.3), used by plastic kinds only. With ``obs_norm`` a
    vector-input network sees normalised observations; a pixel network is left as it is."""
    policy = kind_of(settings).build(settings, net, normalise)
    if settings.obs_norm and not net.pixels:
        return NormalisedInputs(policy, net.obs_shape[0], settings.obs_clip)
    return policy
