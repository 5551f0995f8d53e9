"""The registry of strategies: ``--strategy`` name -> factory ``(ESSettings, number of parameters) ->
Strategy`` (the ask/tell interface of ``es.strategy``). The loop (``es.loop.Trainer``) knows a
strategy only through that interface.

    openai      OpenAI-ES, the original's (Salimans et al. 2017; ``es.strategy``)
    pgpe        PGPE with symmetric sampling and ClipUp (Sehnke et al. 2010; Toklu et al. 2020)
    snes        separable NES (Schaul et al. 2011; Wierstra et al. 2014)
    cma_es      CMA-ES (Hansen 2016), through the ``cmaes`` library (optional extra)
    sep_cma_es  separable CMA-ES (Ros & Hansen 2008), through the ``cmaes`` library (optional extra)
    ars         augmented random search, V1-t and V2-t (Mania et al. 2018)

Adding a strategy: one module with a factory, one entry here, and its settings as fields of
``es.settings.ESSettings`` (each ``setting()`` requiring its strategy). ``tests/test_strategies.py``
runs every entry. Nothing here imports ``es.settings`` (it imports this registry for its choices).
"""

from __future__ import annotations

from collections.abc import Callable

from es.strategies import ars, cma, pgpe, snes
from es.strategies.pgpe import PGPE_OPTIMIZERS
from es.strategy import ESSettings, OpenES, Strategy


def _openai(settings: ESSettings, dim: int) -> Strategy:
    return OpenES(settings)


STRATEGIES: dict[str, Callable[[ESSettings, int], Strategy]] = {
    "openai": _openai,
    "pgpe": pgpe.make,
    "snes": snes.make,
    "cma_es": cma.make_full,
    "sep_cma_es": cma.make_separable,
    "ars": ars.make,
}


def make_strategy(settings: ESSettings, dim: int) -> Strategy:
    """The strategy ``settings.strategy`` names, for ``dim`` parameters (ESSettings has checked the name)."""
    return STRATEGIES[settings.strategy](settings, dim)


__all__ = ["PGPE_OPTIMIZERS", "STRATEGIES", "make_strategy"]
