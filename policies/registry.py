"""Policy kinds by name (``KINDS``), and the settings that choose one.

A new kind of network is one module that implements ``policies.base.Policy`` and declares its plug-in
(``policies.plugin.Kind``: its settings, a function from (settings, network spec, whether the environment
normalises plastic weights) to the policy, whether its weights are plastic, the scripts that train and evaluate
it, and the evaluate script's flags of its files), plus one line in ``KINDS``. Nothing else in the project
branches on the kind: the scripts, the printed commands and config.json take what they need of a kind from its
plug-in, and a kind's settings are flags of its scripts only (``policies.networks``: only the static kind takes
``--network``).

A front end changes what any kind reads: ``--reservoir`` puts an echo state network between the
observation and the network (``policies.reservoir``); ``--obs_norm`` normalises what comes first.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from plugins import Registry, joined
from policies import hebbian, networks
from policies.base import Policy
from policies.network import NetworkSpec
from policies.networks import NETWORKS
from policies.normalised import NormalisedInputs
from policies.plugin import EVALUATED, Kind, Network
from policies.reservoir import BOUNDS, MAX_UNITS, Hyperparameters, ReservoirFrontEnd, check_evolve_start, head_network
from settings import MODERN, SEED_RANGE, check, setting

KINDS: Registry[Kind] = Registry("kind", [
    hebbian.KIND,
    networks.KIND,
])

RESERVOIR = "reservoir front end (ER-MRL's echo state network before the network)"


@dataclass(frozen=True)
class CommonPolicySettings:
    """The policy of a run: its kind, and the front ends every kind takes; then (``PolicySettings``) each kind's
    and each network's own settings. Each field is its option's one declaration (``settings.setting``)."""

    kind: str = setting("static", flag=None, choices=KINDS, evaluation=True,
                        help="the policy kind: the script's (" + ", ".join(kind.scripts[0] for kind in KINDS.values())
                             + ")")
    obs_norm: bool = setting(False, evaluation=True, group=MODERN,
                             help="normalise observations by running statistics (OpenAI's RunningStat); not for pixels")
    obs_clip: float | None = setting(None, low=0, low_open=True, requires=("obs_norm", True), metavar="C",
                                     evaluation=True, group=MODERN, shown_default="no clip",
                                     help="clip normalised observations to +-C (OpenAI: 5)")
    reservoir: bool = setting(False, scripts=EVALUATED, evaluation=True, group=RESERVOIR,
                              help="the network reads the state of a random reservoir (ER-MRL's leaky echo state "
                                   "network, reset every episode) that reads the observation; not for pixels; needs "
                                   "reservoirpy (pip install -r requirements-reservoirs.txt)")
    reservoir_units: int = setting(100, low=1, high=MAX_UNITS, requires=("reservoir", True), scripts=EVALUATED,
                                   evaluation=True, metavar="N", group=RESERVOIR, help="its neurons (ER-MRL's --units)")
    # the reservoir's hyperparameters, or with reservoir_evolve where their evolution starts; default: those
    # ER-MRL's CMA-ES found for PPO on CartPole without velocities (docs/reservoirs.md: lr 0.34, sr 1.00), a classic
    # echo state network (memory of a few steps, at the edge of stability), and ER-MRL's input scaling 1
    reservoir_lr: float = setting(0.3, low=0, high=1, low_open=True, requires=("reservoir", True), scripts=EVALUATED,
                                  evaluation=True, metavar="LR", group=RESERVOIR,
                                  help="its leak rate; with --reservoir_evolve where evolution starts")
    reservoir_sr: float = setting(1.0, low=0, low_open=True, requires=("reservoir", True), scripts=EVALUATED,
                                  evaluation=True, metavar="SR", group=RESERVOIR,
                                  help="the spectral radius of its recurrent weights")
    reservoir_iss: float = setting(1.0, low=0, low_open=True, requires=("reservoir", True), scripts=EVALUATED,
                                   evaluation=True, metavar="ISS", group=RESERVOIR,
                                   help="the scaling of its input weights")
    reservoir_evolve: bool = setting(False, requires=("reservoir", True), evaluation=True, group=RESERVOIR,
                                     help="evolve its leak rate, spectral radius and input scaling with the network: "
                                          "three more parameters, log-scale within ER-MRL's bounds "
                                          + ", ".join(f"{name} [{low:g}, {high:g}]" for name, (low, high) in
                                                      BOUNDS.items()))
    reservoir_seed: int | None = setting(None, low=SEED_RANGE[0], high=SEED_RANGE[1], requires=("reservoir", True),
                                         scripts=EVALUATED, evaluation=True, group=RESERVOIR, metavar="SEED",
                                         shown_default="the run's --seed",
                                         help="the seed of its random matrices")

    def __post_init__(self) -> None:
        check(self)
        if self.reservoir_evolve:
            check_evolve_start(self.reservoir_hyperparameters)

    @property
    def reservoir_hyperparameters(self) -> Hyperparameters:
        return Hyperparameters(self.reservoir_lr, self.reservoir_sr, self.reservoir_iss)

    def seeded(self, run_seed: int) -> CommonPolicySettings:
        """These settings with the reservoir's seed filled in: the run's, unless one was given."""
        if not self.reservoir or self.reservoir_seed is not None:
            return self
        return replace(self, reservoir_seed=run_seed)


PolicySettings = joined(CommonPolicySettings, KINDS, NETWORKS, name="PolicySettings", module=__name__)


def kind_of(settings: PolicySettings) -> Kind:
    if settings.kind not in KINDS:
        raise ValueError(f"unknown policy kind {settings.kind!r}; valid kinds: {', '.join(KINDS)}")
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
    weight normalisation (docs/original.md, "Hebbian rules"), used by plastic kinds only. With ``reservoir`` the
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
