"""The registry of strategies (``plugins.Registry``): ``--strategy`` name -> ``es.strategy.StrategyPlugin`` (its
settings, its factory ``(settings, number of parameters) -> Strategy``, its population rule). The loop
(``es.loop.Trainer``) knows a strategy only through the ask/tell interface.

    openai      OpenAI-ES, the original's (Salimans et al. 2017)
    pgpe        PGPE with symmetric sampling and ClipUp (Sehnke et al. 2010; Toklu et al. 2020)
    snes        separable NES (Schaul et al. 2011; Wierstra et al. 2014)
    cma_es      CMA-ES (Hansen 2016), through the ``cmaes`` library (optional extra)
    sep_cma_es  separable CMA-ES (Ros & Hansen 2008), through the ``cmaes`` library (optional extra)
    ars         augmented random search, V1-t and V2-t (Mania et al. 2018)

Adding a strategy: its module, which declares its plug-in, and one line here; ``es.settings.ESSettings``
takes its settings from the plug-in, and ``tests/test_strategies.py`` runs every plug-in.
"""

from __future__ import annotations

from es.strategies import ars, cma, openai, pgpe, snes
from es.strategy import Strategy, StrategyPlugin
from plugins import Registry

STRATEGIES: Registry[StrategyPlugin] = Registry("strategy", [
    openai.PLUGIN,
    pgpe.PLUGIN,
    snes.PLUGIN,
    cma.FULL,
    cma.SEPARABLE,
    ars.PLUGIN,
])


def make_strategy(settings, dim: int) -> Strategy:
    """The strategy ``settings.strategy`` names, for ``dim`` parameters (``es.settings.ESSettings``, which has
    checked the name and the strategy's rules)."""
    return STRATEGIES[settings.strategy].make(settings, dim)


__all__ = ["STRATEGIES", "make_strategy"]
