"""The reservoirs' optional extra (``pip install -r requirements-reservoirs.txt``): the packages it
needs, how to install them, whether they are there; and ER-MRL's search bounds (Léger et al. 2024,
docs/original.md, "ER-MRL").

A leaf of the import graph: it imports nothing of the project and nothing heavy. The ES front end
(``policies.reservoir``, ``policies.registry``) and the ER-MRL scripts (``reservoirs.launch``,
``reservoirs.commands``) both read it, so it lives below both, and a script can say how to install the
extra before anything that needs it is imported.
"""

from __future__ import annotations

import importlib

# import name -> distribution name, for the scripts (tensorboard only for the test scripts' logs)
EXTRA_MODULES = {"reservoirpy": "reservoirpy", "stable_baselines3": "stable-baselines3", "optuna": "optuna",
                 "cmaes": "cmaes"}
TEST_MODULES = {**EXTRA_MODULES, "tensorboard": "tensorboard"}
INSTALL_HINT = "pip install -r requirements-reservoirs.txt (or pip install -e .[reservoirs])"
# ER-MRL's search bounds of each reservoir hyperparameter (its --min_* / --max_* defaults), in its scripts'
# order: the scripts' defaults, and the range policies.reservoir maps evolved genes into
SEARCH_BOUNDS: dict[str, tuple[float, float]] = {"sr": (1e-4, 1e2), "lr": (1e-2, 1.0), "iss": (1e-1, 10.0)}


def missing_packages(modules: dict[str, str]) -> list[str]:
    """The distributions of ``modules`` that cannot be imported."""
    missing = []
    for module, distribution in modules.items():
        try:
            importlib.import_module(module)
        except ImportError:
            missing.append(distribution)
    return missing
