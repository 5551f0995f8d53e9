"""Policy kinds by name, and the settings that choose one.

A new kind of network is one module that implements ``policies.base.Policy`` plus one line in
``KINDS``: a function from (settings, network spec, whether the environment normalises plastic
weights) to the policy. Nothing else in the project branches on the kind.

A front end changes what any kind reads: ``--reservoir`` puts an echo state network between the
observation and the network (``policies.reservoir``); ``--obs_norm`` normalises what comes first.

Static networks come in three shapes (``--network``, ``NETWORKS``): the original's MLP / CNN
(``default``), and pytorch-es's small net and conv-LSTM (``policies.pytorch_es``). A network also
names the image preprocessing it expects (``envs.recipes.PREPROCESSING``), which the environments
are made with.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

from policies.base import Policy
from policies.hebbian import HebbianPolicy
from policies.network import NetworkSpec
from policies.pytorch_es import ConvLSTMPolicy, SmallNetPolicy
from policies.normalised import NormalisedInputs
from policies.reservoir import Hyperparameters, ReservoirFrontEnd, check_settings, head_network
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
    reservoir: bool = False  # the network reads an echo state network's state (``policies.reservoir``); not pixels
    reservoir_units: int = 100  # ER-MRL's --units
    # the reservoir's hyperparameters, or with reservoir_evolve where their evolution starts; default: those
    # ER-MRL's CMA-ES found for PPO on CartPole without velocities (README: lr 0.34, sr 1.00), a classic
    # echo state network (memory of a few steps, at the edge of stability), and ER-MRL's input scaling 1
    reservoir_lr: float = 0.3
    reservoir_sr: float = 1.0
    reservoir_iss: float = 1.0
    reservoir_evolve: bool = False  # lr, sr and iss evolved as three more parameters of theta
    reservoir_seed: int | None = None  # the seed of its matrices; a new run fills in its own --seed

    def __post_init__(self) -> None:
        if self.obs_clip is not None and not 0 < self.obs_clip < float("inf"):
            raise ValueError(f"--obs_clip must be a number > 0, got {self.obs_clip}")
        if self.reservoir_evolve and not self.reservoir:
            raise ValueError("--reservoir_evolve evolves the hyperparameters of --reservoir; add --reservoir")
        check_settings(self.reservoir_units, self.reservoir_hyperparameters, self.reservoir_evolve,
                       self.reservoir_seed)

    @property
    def reservoir_hyperparameters(self) -> Hyperparameters:
        return Hyperparameters(self.reservoir_lr, self.reservoir_sr, self.reservoir_iss)

    def seeded(self, run_seed: int) -> "PolicySettings":
        """These settings with the reservoir's seed filled in: the run's, unless one was given."""
        if not self.reservoir or self.reservoir_seed is not None:
            return self
        return replace(self, reservoir_seed=run_seed)


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
    weight normalisation (upstream spec §4.3), used by plastic kinds only. With ``reservoir`` the
    network reads a reservoir's state (a ValueError for pixels, or without reservoirpy). With
    ``obs_norm`` a vector-input network sees normalised observations (through the reservoir, if any);
    a pixel network is left as it is."""
    if settings.reservoir:
        policy = reservoir_front_end(settings, net, normalise)
    else:
        policy = kind_of(settings).build(settings, net, normalise)
    if settings.obs_norm and not net.pixels:
        return NormalisedInputs(policy, net.obs_shape[0], settings.obs_clip)
    return policy


def reservoir_front_end(settings: PolicySettings, net: NetworkSpec, normalise: bool) -> ReservoirFrontEnd:
    from reservoir_extra import INSTALL_HINT, missing_packages

    head = kind_of(settings).build(settings, head_network(net, settings.reservoir_units), normalise)
    if missing_packages({"reservoirpy": "reservoirpy"}):
        raise ValueError(f"--reservoir draws ER-MRL's reservoirs with reservoirpy, which is not installed here; "
                         f"{INSTALL_HINT}")
    if settings.reservoir_seed is None:
        raise ValueError("--reservoir needs --reservoir_seed, the seed its matrices were drawn with (a training "
                         "run's own --seed unless it was given; see its config.json)")
    return ReservoirFrontEnd(head, net.obs_shape[0], settings.reservoir_units, settings.reservoir_hyperparameters,
                             settings.reservoir_seed, settings.reservoir_evolve)
