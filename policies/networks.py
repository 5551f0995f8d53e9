"""The static kind (the baseline of Najarro & Risi 2020: a network whose weights are evolved directly) and the
networks it takes (``--network``, ``NETWORKS``): the original's MLP / CNN (``default``, ``policies.static``) and
pytorch-es's small net and conv-LSTM (``policies.pytorch_es``). A network also names the image preprocessing
it expects (``envs.recipes.PREPROCESSING``), which the environments are made with.

Adding a network: its module, which declares its plug-in (``policies.plugin.Network``), and one line in
``NETWORKS``.
"""

from __future__ import annotations

from dataclasses import dataclass

from plugins import Registry
from policies import pytorch_es, static
from policies.plugin import EVALUATED, FileFlag, Kind, Network
from settings import setting

NETWORKS: Registry[Network] = Registry("network", [
    static.NETWORK,
    pytorch_es.SMALL,
    pytorch_es.LSTM,
])


@dataclass(frozen=True)
class StaticSettings:
    """The static kind's own settings: flags of train_static.py and evaluate_static.py, recorded for its runs
    only."""

    network: str = setting("default", choices=NETWORKS, scripts=EVALUATED, evaluation=True,
                           help="; ".join(f"{name}: {network.about}" for name, network in NETWORKS.items()))


KIND = Kind("static", about="evolved weights", settings=StaticSettings,
            build=lambda settings, net, normalise: NETWORKS[settings.network].build(net),
            plastic=False, scripts=("train_static.py", "evaluate_static.py"),
            files=(FileFlag("--path_weights", ("weights",), "evolved weights"),))
