"""CMA-ES (Hansen 2016, "The CMA evolution strategy: a tutorial", arXiv:1604.00772) and its
separable variant sep-CMA-ES (Ros & Hansen 2008, "A simple modification in CMA-ES achieving linear
time and space complexity", PPSN X), through the maintained ``cmaes`` library (Nomura & Shibata 2024,
``cmaes.CMA`` and ``cmaes.SepCMA``; an optional extra: pip install -r requirements-strategies.txt).

The library samples the members (x = m + sigma B D z), so they cannot be slices of the noise table:
``ask`` returns them as ``Population.rows``, which the backends publish once per generation through
the path theta takes (shared memory, Ray's object store), and a task's noise index is then the
member's row. The library is told the float32 vectors the workers evaluated, and minimises: it is
told -fitness. Its random draws come from a ``RandomState`` reseeded every generation from the
loop's generation stream, so a run is a function of its seed alone.

State: the library's attributes that ``tell`` changes (``STATE``: mean, sigma, C, the two evolution
paths, the generation counter and the recent best/worst values) are ``ESState.strategy``'s arrays,
saved in the checkpoint as plain arrays (no pickle); everything else the library derives from the
dimension and the population size. A resumed run rebuilds the library's object from them and steps
bit for bit as one that never stopped. The library's termination tests are not used.

Memory: full CMA-ES holds d x d matrices (C, its eigenvectors, and in ``tell`` one d x d outer
product per member), about (popsize + 3) d^2 float64 numbers; ``make_full`` refuses, before the library
allocates any, a run where that exceeds ``COVARIANCE_BUDGET`` (1 GiB) or half of the machine's memory,
and names sep_cma_es, whose covariance is diagonal (O(d)).
"""

from __future__ import annotations

import os

import numpy as np

from es.noise import NoiseTable
from es.strategy import ESState, Population, StrategyPlugin, check_fitness

INSTALL_HINT = "pip install -r requirements-strategies.txt (or pip install -e .[strategies])"
STATE = ("_mean", "_sigma", "_C", "_p_sigma", "_pc", "_g", "_funhist_values")  # what tell() changes
SEED_LIMIT = 2**32  # a RandomState seed
# full CMA-ES's d x d matrices, at most: beyond it every generation's eigendecomposition takes minutes
# (d = 8,832, CartPole's network, popsize 8: 6.4 GiB of matrices; measured, 13 GB and 218 s for one generation)
COVARIANCE_BUDGET = 2**30


def library_class(name: str, separable: bool) -> type:
    """``cmaes.SepCMA`` or ``cmaes.CMA``; a ValueError naming the extra if cmaes is not installed."""
    try:
        import cmaes
    except ModuleNotFoundError as error:
        if error.name != "cmaes":
            raise
        raise ValueError(f"--strategy {name} needs the cmaes package, which is not installed; install it with: "
                         f"{INSTALL_HINT}") from None
    return cmaes.SepCMA if separable else cmaes.CMA


def _restored(name: str, value: np.ndarray):
    """A saved attribute back in the type the library keeps it in."""
    if name == "_g":
        return int(value)
    if name == "_sigma":
        return np.float64(value)
    return np.array(value, dtype=np.float64)


class LibraryCMA:
    """CMA-ES or sep-CMA-ES behind the ask/tell of ``es.strategy``."""

    def __init__(self, name: str, population_size: int, sigma_init: float, separable: bool):
        self.name, self.population_size, self.sigma_init = name, population_size, sigma_init
        self._library = library_class(name, separable)
        self._live: tuple[ESState, object] | None = None  # the library object that state was read from

    def _fresh(self, mean: np.ndarray, sigma: float):
        optimizer = self._library(mean=np.array(mean, dtype=np.float64), sigma=sigma,
                                  population_size=self.population_size, seed=0)
        optimizer._funhist_values[:] = 0  # np.empty in the library: zeros, so that two runs' checkpoints compare
        return optimizer

    def _state(self, optimizer, generation: int) -> ESState:
        arrays = {name.lstrip("_"): np.array(getattr(optimizer, name)) for name in STATE}
        return ESState(optimizer._mean.astype(np.float32), float(optimizer._cm), float(optimizer._sigma), generation,
                       strategy=arrays)

    def _optimizer(self, state: ESState):
        """The library object in ``state``: the live one if it is, else rebuilt from the arrays."""
        if self._live is not None and self._live[0] is state:
            return self._live[1]
        saved = state.strategy
        optimizer = self._fresh(saved["mean"], float(saved["sigma"]))
        for name in STATE:
            setattr(optimizer, name, _restored(name, saved[name.lstrip("_")]))
        self._live = (state, optimizer)
        return optimizer

    def initial_state(self, theta: np.ndarray) -> ESState:
        return self._state(self._fresh(theta, self.sigma_init), 0)  # its theta: the float32 theta, exactly

    def ask(self, state: ESState, rng: np.random.Generator, noise: NoiseTable) -> Population:
        optimizer = self._optimizer(state)
        optimizer.reseed_rng(int(rng.integers(0, SEED_LIMIT)))
        with np.errstate(over="ignore"):  # members beyond float32's range: the workers refuse them, naming them
            members = np.array([optimizer.ask() for _ in range(self.population_size)], dtype=np.float32)
        return Population(np.arange(self.population_size, dtype=np.int64), np.ones(self.population_size, np.int8),
                          rows=members)

    def tell(self, state: ESState, noise: NoiseTable, population: Population,
             fitness: np.ndarray) -> tuple[ESState, dict]:
        check_fitness(fitness, self.population_size)
        optimizer = self._optimizer(state)
        members = population.rows.astype(np.float64)
        optimizer.tell([(members[m], -float(fitness[m])) for m in range(self.population_size)])  # it minimises
        new_state = self._state(optimizer, state.generation + 1)
        self._live = (new_state, optimizer)
        return new_state, {"update_factor": new_state.sigma, "skipped": False}


def physical_memory() -> int:
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_covariance_fits(popsize: int, dim: int, memory: int | None = None) -> None:
    """Refuse full CMA-ES, before anything is allocated, where its d x d matrices would take more than
    COVARIANCE_BUDGET or half of the memory."""
    memory = physical_memory() if memory is None else memory
    budget = min(COVARIANCE_BUDGET, memory // 2)
    needed = (popsize + 3) * dim * dim * 8
    if needed > budget:
        raise ValueError(f"--strategy cma_es keeps {popsize + 3} matrices of {dim} x {dim} (the covariance, its "
                         f"eigenvectors, one outer product per member): about {needed / 2**30:.1f} GiB, over its "
                         f"budget of {budget / 2**30:.1f} GiB (at most {COVARIANCE_BUDGET / 2**30:.0f} GiB, and half "
                         f"of this machine's {memory / 2**30:.1f} GiB); use --strategy sep_cma_es (a diagonal "
                         "covariance, linear in the parameters)")


def make_full(settings, dim: int) -> LibraryCMA:
    check_covariance_fits(settings.popsize, dim)
    return LibraryCMA("cma_es", settings.popsize, settings.sigma, separable=False)


def make_separable(settings, dim: int) -> LibraryCMA:
    if dim < 2:
        raise ValueError(f"--strategy sep_cma_es needs at least 2 parameters, this policy has {dim}")
    return LibraryCMA("sep_cma_es", settings.popsize, settings.sigma, separable=True)


LIBRARY = "the cmaes library: pip install -r requirements-strategies.txt"
# the library samples its members (no pairs), with no settings of their own
FULL = StrategyPlugin("cma_es", about=f"CMA-ES, {LIBRARY}", make=make_full, pairs=False)
SEPARABLE = StrategyPlugin("sep_cma_es", about=f"separable CMA-ES, {LIBRARY}", make=make_separable, pairs=False)
