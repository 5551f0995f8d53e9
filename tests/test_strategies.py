"""The strategies of ``es.strategies.STRATEGIES``: each update against a plain implementation written
from its paper's equations (the same samples, float tolerance), and on the one loop: 1 and 2 workers
give the same bytes, an interrupted and resumed run the same bits, every strategy learns.

Registry-driven: a strategy added to ``STRATEGIES`` is run by every parametrised test here. The plain
references are loops over members and parameters, written from:

- PGPE: Sehnke et al. 2010 (symmetric sampling), centered ranks, ClipUp (Toklu et al. 2020);
- SNES: Schaul et al. 2011, Algorithm 2, with the paper's utilities;
- ARS: Mania et al. 2018, Algorithm 2 (V1-t);
- CMA-ES: Hansen 2016, "The CMA evolution strategy: a tutorial", eqs. 39-47 with its weights (49-53);
  sep-CMA-ES: Ros & Hansen 2008, the diagonal of the same update with c_mu scaled by (n + 2) / 3.

The cmaes library is an optional extra: its cases skip without it, naming
``pip install -r requirements-strategies.txt``.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import train_hebb
import train_static
from cli.config import TrainConfig
from envs import EnvSettings, ProblemSpec
from envs.problem import Problem
from es.files import load_dat, read_metrics
from es.loop import Trainer
from es.noise import NoiseTable
from es.runfolder import Checkpoint, History, RunFolder
from es.settings import ESSettings, RunSettings
from es.strategies import STRATEGIES, make_strategy
from es.strategies.cma import check_covariance_fits
from es.strategies.pgpe import PGPE, clipup_velocity
from es.strategies.snes import default_sigma_lr
from es.worker import perturb
from policies import PolicySettings
from policies.network import Layout
from policies.static import WeightFile
from settings import options, requirement
from tests.extras import need
from tests.run_helpers import assert_same_checkpoint_and_metrics, only_run

LIBRARY = {"cma_es", "sep_cma_es"}  # the strategies of the cmaes extra
FULL_COVARIANCE = {"cma_es"}  # d x d: the project's networks (>= 4 610 parameters) are too large for a test


def needs_extra(name: str) -> None:
    if name in LIBRARY:
        need("strategies")


# --- helpers: the members as the workers rebuild them ---------------------------------------------


def members(population, state, noise: NoiseTable) -> np.ndarray:
    """Each member's parameters, by the wire protocol's rule (es.worker)."""
    if population.rows is not None:
        return population.rows[population.indices]
    sigma = state.sigma if population.scale is None else population.scale
    return np.array([perturb(state.theta, noise.slice(index, state.theta.size), sign, sigma)
                     for index, sign in zip(population.indices, population.signs)])


def sphere(params: np.ndarray) -> np.ndarray:
    """Fitness of a shifted sphere, maximal at 0.5 everywhere."""
    return -np.sum((params.astype(np.float64) - 0.5) ** 2, axis=1)


def settings_for(name: str, **values) -> ESSettings:
    return ESSettings(strategy=name, **{"popsize": 8, "sigma": 0.1, **values})


def generations(strategy, state, noise, count: int, seed: int = 0):
    for generation in range(count):
        rng = np.random.default_rng([seed, generation])
        population = strategy.ask(state, rng, noise)
        state, _ = strategy.tell(state, noise, population, sphere(members(population, state, noise)))
    return state


# --- registry-driven: the ask/tell contract, the checkpoint, learning on a sphere ---------------------


@pytest.mark.parametrize("name", list(STRATEGIES))
def test_a_population_is_what_the_wire_protocol_can_carry(name):
    needs_extra(name)
    noise = NoiseTable.create(seed=1, size=4096)
    strategy = make_strategy(settings_for(name), 12)
    state = strategy.initial_state(np.zeros(12, np.float32))
    population = strategy.ask(state, np.random.default_rng(0), noise)
    assert population.indices.shape == population.signs.shape == (8,)
    assert set(np.unique(population.signs)) <= {-1, 1}
    if population.rows is None:
        assert (population.indices >= 0).all() and (population.indices <= noise.size - 12).all()
    else:
        assert population.rows.shape == (8, 12) and population.rows.dtype == np.float32
    if population.mirrored:
        np.testing.assert_array_equal(population.indices[0::2], population.indices[1::2])
        np.testing.assert_array_equal(population.signs, np.tile([1, -1], 4))
    if population.scale is not None:
        assert population.scale.shape == (12,) and population.scale.dtype == np.float32


@pytest.mark.parametrize("name", list(STRATEGIES))
def test_a_strategy_owns_its_settings_and_its_population_rule(name):
    """Its plug-in's settings are fields of ESSettings owned by it: each has an effect only with --strategy naming
    it, and a run of another strategy neither records it nor takes another value of it. Its population rule is what
    its populations do: mirrored pairs need an even --popsize, refused when odd."""
    needs_extra(name)
    entry = STRATEGIES[name]
    own = [item.name for item in options(entry.settings)] if entry.settings is not None else []
    owned = {item.name: item for item in options(ESSettings) if item.spec.owner == ("strategy", name)}
    assert list(owned) == own
    other = next(strategy for strategy in ("openai", "snes") if strategy != name)
    for item in owned.values():
        assert requirement(item, options(ESSettings))[0].startswith(f"--strategy {name}")
        assert item.name not in TrainConfig(settings_for(other), PolicySettings(), EnvSettings(), RunSettings()
                                            ).to_dict()["es"]
    assert set(owned) <= set(TrainConfig(settings_for(name), PolicySettings(), EnvSettings(), RunSettings()
                                         ).to_dict()["es"])
    population = make_strategy(settings_for(name), 12).ask(
        make_strategy(settings_for(name), 12).initial_state(np.zeros(12, np.float32)), np.random.default_rng(0),
        NoiseTable.create(seed=1, size=4096))
    assert population.mirrored == entry.pairs
    if entry.pairs:
        with pytest.raises(ValueError, match=f"^--popsize 7 is odd, but --strategy {name} samples mirrored pairs; "
                                             "give an even --popsize such as 6 or 8$"):
            settings_for(name, popsize=7)
    else:
        assert len(make_strategy(settings_for(name, popsize=7), 12).ask(
            make_strategy(settings_for(name, popsize=7), 12).initial_state(np.zeros(12, np.float32)),
            np.random.default_rng(0), NoiseTable.create(seed=1, size=4096)).indices) == 7


@pytest.mark.parametrize("name", list(STRATEGIES))
def test_every_strategy_climbs_a_sphere(name):
    needs_extra(name)
    noise = NoiseTable.create(seed=2, size=1 << 14)
    # steps fit for an optimum 5 radii away (PGPE's default speed, a fifteenth of the radius, is for networks)
    values = {"ars": {"ars_lr": 0.05}, "openai": {"lr": 0.05}, "pgpe": {"clipup_max_speed": 0.15}}.get(name, {})
    strategy = make_strategy(settings_for(name, popsize=16, **values), 10)
    state = strategy.initial_state(np.zeros(10, np.float32))
    before = sphere(state.theta[None])[0]
    state = generations(strategy, state, noise, 40)
    assert sphere(state.theta[None])[0] > before / 4, name  # 2.5 -> less than 0.625 from the optimum


@pytest.mark.parametrize("name", list(STRATEGIES))
def test_state_through_the_checkpoint_file_continues_bit_for_bit(name, tmp_path):
    """Save after 3 generations, load into a fresh strategy (a new process), go on: the same bits as never stopping."""
    needs_extra(name)
    noise = NoiseTable.create(seed=3, size=4096)
    settings = settings_for(name)
    strategy = make_strategy(settings, 6)
    middle = generations(strategy, strategy.initial_state(np.linspace(-1, 1, 6, dtype=np.float32)), noise, 3)
    path = tmp_path / "checkpoint.npz"
    path.write_bytes(Checkpoint.of(middle, History()).to_bytes())
    with np.load(path, allow_pickle=False) as saved:  # plain arrays only
        assert all(saved[key].dtype != object for key in saved.files)
    restored = Checkpoint.from_file(path).state()
    ends = [generations(each, state, noise, 2, seed=9)
            for each, state in ((strategy, middle), (make_strategy(settings, 6), restored))]
    assert ends[0].theta.tobytes() == ends[1].theta.tobytes()
    assert sorted(ends[0].strategy) == sorted(ends[1].strategy)
    for key in ends[0].strategy:
        assert np.asarray(ends[0].strategy[key]).tobytes() == np.asarray(ends[1].strategy[key]).tobytes(), key
    for key in ends[0].optimizer:
        assert np.asarray(ends[0].optimizer[key]).tobytes() == np.asarray(ends[1].optimizer[key]).tobytes(), key


# --- PGPE against Sehnke et al. 2010 + ClipUp, written out ---------------------------------------------


def plain_centered_ranks(fitness):
    order = sorted(range(len(fitness)), key=lambda member: fitness[member])
    ranks = [0.0] * len(fitness)
    for position, member in enumerate(order):
        ranks[member] = position / (len(fitness) - 1) - 0.5
    return ranks


def plain_pgpe(theta, sigma, epsilons, fitness, lr, sigma_lr, max_change, max_speed, momentum, velocity):
    ranks, directions, dim = plain_centered_ranks(fitness), len(epsilons), len(theta)
    grad_mu, grad_sigma = [0.0] * dim, [0.0] * dim
    for p, eps in enumerate(epsilons):
        plus, minus = ranks[2 * p], ranks[2 * p + 1]
        for i in range(dim):
            delta = sigma[i] * eps[i]
            grad_mu[i] += (plus - minus) / 2 * delta / directions
            grad_sigma[i] += (plus + minus) / 2 * (delta ** 2 - sigma[i] ** 2) / sigma[i] / directions
    norm = math.sqrt(sum(g * g for g in grad_mu))
    velocity = [momentum * v + lr * g / norm for v, g in zip(velocity, grad_mu)]
    speed = math.sqrt(sum(v * v for v in velocity))
    if speed > max_speed:
        velocity = [v * max_speed / speed for v in velocity]
    new_theta = [t + v for t, v in zip(theta, velocity)]
    new_sigma = [min(max(s + sigma_lr * g, s * (1 - max_change)), s * (1 + max_change))
                 for s, g in zip(sigma, grad_sigma)]
    return new_theta, new_sigma, velocity


def test_pgpe_step_is_sehnke_et_al_with_clipup():
    rng = np.random.default_rng(4)
    noise = NoiseTable(rng.standard_normal(64).astype(np.float32))
    dim = 5
    strategy = make_strategy(settings_for("pgpe", popsize=6, sigma=0.3, pgpe_sigma_lr=0.5, clipup_max_speed=0.4), dim)
    sigma = rng.uniform(0.1, 0.5, dim)
    velocity = rng.normal(scale=0.2, size=dim)
    state = replace(strategy.initial_state(rng.normal(size=dim).astype(np.float32)), optimizer={"velocity": velocity},
                    strategy={"sigma": sigma})
    population = strategy.ask(state, np.random.default_rng(5), noise)
    fitness = np.array([3.0, -1.0, 7.0, 2.5, 0.5, 4.0])
    epsilons = [noise.slice(index, dim).astype(np.float64) for index in population.indices[0::2]]
    theta, new_sigma, new_velocity = plain_pgpe(state.theta.astype(np.float64), sigma, epsilons, fitness, 0.2, 0.5,
                                                0.2, 0.4, 0.9, velocity)
    new_state, info = strategy.tell(state, noise, population, fitness)
    np.testing.assert_allclose(new_state.theta, theta, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(new_state.strategy["sigma"], new_sigma, rtol=1e-12)
    np.testing.assert_allclose(new_state.optimizer["velocity"], new_velocity, rtol=1e-12)
    np.testing.assert_allclose(population.scale, sigma.astype(np.float32))
    assert info["update_factor"] == 0.2 and new_state.sigma == pytest.approx(np.mean(new_sigma))


def test_clipup_speed_never_exceeds_its_maximum_and_its_step_is_half_of_it_by_default():
    pgpe = make_strategy(settings_for("pgpe", clipup_max_speed=0.3), 4)
    assert isinstance(pgpe, PGPE) and pgpe.lr == 0.15
    velocity, speeds = np.zeros(4), []
    for gradient in ([1.0, 0, 0, 0], [2.0, 0, 0, 0], [3.0, 0, 0, 0]):
        velocity = clipup_velocity(velocity, np.array(gradient), 0.15, 0.3, 0.9)
        speeds.append(float(np.linalg.norm(velocity)))
    assert speeds[0] == pytest.approx(0.15) and speeds[1] == pytest.approx(0.15 * 0.9 + 0.15)
    assert speeds[2] == pytest.approx(0.3)  # 0.285 * 0.9 + 0.15 = 0.4065 clipped to 0.3


def test_pgpe_default_max_speed_is_clipups_rule_of_a_fifteenth_of_the_radius():
    pgpe = make_strategy(settings_for("pgpe", sigma=0.1), 8832)
    assert pgpe.max_speed == pytest.approx(0.1 * math.sqrt(8832) / 15) and pgpe.lr == pytest.approx(pgpe.max_speed / 2)
    given = make_strategy(settings_for("pgpe", sigma=0.1, clipup_max_speed=0.15, pgpe_lr=0.1125), 8832)
    assert (given.max_speed, given.lr) == (0.15, 0.1125)


def test_pgpe_steps_as_evotorchs_pgpe_on_the_same_samples():
    """EvoTorch 0.6.1's PGPE (its symmetric separable Gaussian's gradients, centred ranks, ClipUp, the
    sigma change limit), fed this strategy's members and fitness: the same centre, sigma and velocity
    after each of 3 generations."""
    need("bench")
    import torch
    from evotorch.distributions import SymmetricSeparableGaussian
    from evotorch.optimizers import ClipUp
    from evotorch.tools import modify_tensor

    dim, popsize = 7, 8
    strategy = make_strategy(settings_for("pgpe", popsize=popsize, sigma=0.3), dim)
    noise = NoiseTable(np.random.default_rng(2).standard_normal(256).astype(np.float32))
    state = strategy.initial_state(np.random.default_rng(3).normal(size=dim).astype(np.float32))
    clipup = ClipUp(solution_length=dim, dtype=torch.float64, stepsize=strategy.lr, max_speed=strategy.max_speed,
                    momentum=strategy.momentum)
    for generation in range(3):
        population = strategy.ask(state, np.random.default_rng([9, generation]), noise)
        mu, sigma = torch.tensor(state.theta, dtype=torch.float64), torch.tensor(state.strategy["sigma"])
        samples = torch.stack([mu + int(sign) * sigma * torch.tensor(noise.slice(index, dim), dtype=torch.float64)
                               for index, sign in zip(population.indices, population.signs)])
        fitness = np.random.default_rng(generation).permutation(popsize).astype(np.float64)  # no ties
        theirs = SymmetricSeparableGaussian({"mu": mu, "sigma": sigma, "divide_mu_grad_by": "num_directions",
                                             "divide_sigma_grad_by": "num_directions"}, dtype=torch.float64)
        gradients = theirs.compute_gradients(samples, torch.tensor(fitness), objective_sense="max",
                                             ranking_method="centered")
        their_mu = mu + clipup.ascent(gradients["mu"])
        their_sigma = modify_tensor(sigma, sigma + strategy.sigma_lr * gradients["sigma"],
                                    max_change=strategy.max_sigma_change)
        state, _ = strategy.tell(state, noise, population, fitness)
        np.testing.assert_allclose(state.theta, their_mu.numpy(), rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(state.strategy["sigma"], their_sigma.numpy(), rtol=1e-12)
        np.testing.assert_allclose(state.optimizer["velocity"], clipup._velocity.numpy(), rtol=1e-9, atol=1e-12)


# --- SNES against Schaul et al. 2011 ------------------------------------------------------------------


def plain_snes(theta, sigma, samples, fitness, lr_mu, lr_sigma):
    population, dim = len(fitness), len(theta)
    order = sorted(range(population), key=lambda member: -fitness[member])  # best first
    numerators = [max(0.0, math.log(population / 2 + 1) - math.log(k)) for k in range(1, population + 1)]
    utility = [0.0] * population
    for k, member in enumerate(order):
        utility[member] = numerators[k] / sum(numerators) - 1 / population
    grad_mu = [sum(utility[m] * samples[m][i] for m in range(population)) for i in range(dim)]
    grad_sigma = [sum(utility[m] * (samples[m][i] ** 2 - 1) for m in range(population)) for i in range(dim)]
    new_theta = [theta[i] + lr_mu * sigma[i] * grad_mu[i] for i in range(dim)]
    new_sigma = [sigma[i] * math.exp(lr_sigma / 2 * grad_sigma[i]) for i in range(dim)]
    return new_theta, new_sigma


def test_snes_step_is_schaul_et_al():
    rng = np.random.default_rng(6)
    noise = NoiseTable(rng.standard_normal(64).astype(np.float32))
    dim = 4
    strategy = make_strategy(settings_for("snes", popsize=7, sigma=0.2), dim)
    assert strategy.sigma_lr == pytest.approx((3 + math.log(4)) / (5 * 2)) == default_sigma_lr(4)
    state = replace(strategy.initial_state(rng.normal(size=dim).astype(np.float32)),
                    strategy={"sigma": rng.uniform(0.1, 0.4, dim)})
    population = strategy.ask(state, np.random.default_rng(7), noise)
    assert not population.mirrored and len(set(population.indices.tolist())) == 7
    fitness = rng.normal(size=7)
    samples = [noise.slice(index, dim).astype(np.float64) for index in population.indices]
    theta, sigma = plain_snes(state.theta.astype(np.float64), state.strategy["sigma"], samples, fitness, 1.0,
                              strategy.sigma_lr)
    new_state, _ = strategy.tell(state, noise, population, fitness)
    np.testing.assert_allclose(new_state.theta, theta, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(new_state.strategy["sigma"], sigma, rtol=1e-12)


# --- ARS against Mania et al. 2018 ----------------------------------------------------------------


def plain_ars(theta, deltas, rewards_plus, rewards_minus, alpha, top):
    best = sorted(range(len(deltas)), key=lambda k: -max(rewards_plus[k], rewards_minus[k]))[:top]
    used = [rewards_plus[k] for k in best] + [rewards_minus[k] for k in best]
    mean = sum(used) / len(used)
    sigma_r = math.sqrt(sum((r - mean) ** 2 for r in used) / len(used))
    return [theta[i] + alpha / (top * sigma_r) * sum((rewards_plus[k] - rewards_minus[k]) * deltas[k][i]
                                                    for k in best) for i in range(len(theta))]


@pytest.mark.parametrize("top", [None, 2])
def test_ars_step_is_mania_et_al(top):
    rng = np.random.default_rng(8)
    noise = NoiseTable(rng.standard_normal(64).astype(np.float32))
    dim = 5
    strategy = make_strategy(settings_for("ars", popsize=8, ars_lr=0.03, ars_top=top), dim)
    state = strategy.initial_state(rng.normal(size=dim).astype(np.float32))
    population = strategy.ask(state, np.random.default_rng(9), noise)
    fitness = np.array([10.0, 4.0, -2.0, 1.0, 8.0, 12.0, 3.0, 0.0])
    deltas = [noise.slice(index, dim).astype(np.float64) for index in population.indices[0::2]]
    expected = plain_ars(state.theta.astype(np.float64), deltas, fitness[0::2], fitness[1::2], 0.03, top or 4)
    new_state, info = strategy.tell(state, noise, population, fitness)
    np.testing.assert_allclose(new_state.theta, expected, rtol=1e-6, atol=1e-7)
    assert not info["skipped"]


# --- CMA-ES and sep-CMA-ES against Hansen's tutorial ----------------------------------------------------


def tutorial_constants(n: int, population: int, separable: bool) -> dict:
    mu = population // 2
    if separable:  # Ros & Hansen 2008: positive weights only
        weights = np.array([math.log(mu + 1) - math.log(i + 1) for i in range(mu)])
        weights /= weights.sum()
        mu_eff = 1 / np.sum(weights ** 2)
    else:  # eqs. 49-53, with negative weights
        prime = np.array([math.log((population + 1) / 2) - math.log(i + 1) for i in range(population)])
        mu_eff = prime[:mu].sum() ** 2 / np.sum(prime[:mu] ** 2)
        mu_eff_minus = prime[mu:].sum() ** 2 / np.sum(prime[mu:] ** 2)
    c1 = 2 / ((n + 1.3) ** 2 + mu_eff)
    if separable:
        cmu_full = 2 / mu_eff / (n + math.sqrt(2)) ** 2 + (1 - 1 / mu_eff) * min(1, (2 * mu_eff - 1) /
                                                                                ((n + 2) ** 2 + mu_eff))
        cmu, c_sigma, cc = (n + 2) / 3 * cmu_full, (mu_eff + 2) / (n + mu_eff + 3), 4 / (n + 4)
    else:
        cmu = min(1 - c1 - 1e-8, 2 * (mu_eff - 2 + 1 / mu_eff) / ((n + 2) ** 2 + mu_eff))
        alpha = min(1 + c1 / cmu, 1 + 2 * mu_eff_minus / (mu_eff + 2), (1 - c1 - cmu) / (n * cmu))
        positive, negative = prime[prime > 0].sum(), -prime[prime < 0].sum()
        weights = np.where(prime >= 0, prime / positive, alpha * prime / negative)
        c_sigma, cc = (mu_eff + 2) / (n + mu_eff + 5), (4 + mu_eff / n) / (n + 4 + 2 * mu_eff / n)
    d_sigma = 1 + 2 * max(0, math.sqrt((mu_eff - 1) / (n + 1)) - 1) + c_sigma
    chi_n = math.sqrt(n) * (1 - 1 / (4 * n) + 1 / (21 * n * n))
    return dict(mu=mu, weights=weights, mu_eff=mu_eff, c1=c1, cmu=cmu, c_sigma=c_sigma, cc=cc, d_sigma=d_sigma,
                chi_n=chi_n)


def tutorial_update(saved: dict, samples: np.ndarray, fitness: np.ndarray, separable: bool) -> dict:
    """One generation of Hansen's tutorial (eqs. 39-47) on ``samples``; fitness is maximised."""
    mean, sigma, C = saved["mean"], float(saved["sigma"]), saved["C"]
    p_sigma, pc, g = saved["p_sigma"], saved["pc"], int(saved["g"]) + 1
    n, population = mean.size, len(fitness)
    k = tutorial_constants(n, population, separable)
    y = (samples[np.argsort(-fitness, kind="stable")] - mean) / sigma  # best first
    y_w = sum(k["weights"][i] * y[i] for i in range(k["mu"]))
    inv_sqrt = 1 / np.sqrt(C) if separable else _inverse_sqrt(C)
    new_mean = mean + sigma * y_w
    p_sigma = (1 - k["c_sigma"]) * p_sigma + math.sqrt(k["c_sigma"] * (2 - k["c_sigma"]) * k["mu_eff"]) * (
        inv_sqrt * y_w if separable else inv_sqrt @ y_w)
    norm = np.linalg.norm(p_sigma)
    new_sigma = sigma * math.exp(k["c_sigma"] / k["d_sigma"] * (norm / k["chi_n"] - 1))
    corrected = norm / math.sqrt(1 - (1 - k["c_sigma"]) ** (2 * (g + 1)))
    h_sigma = 1.0 if corrected < (1.4 + 2 / (n + 1)) * k["chi_n"] else 0.0
    pc = (1 - k["cc"]) * pc + h_sigma * math.sqrt(k["cc"] * (2 - k["cc"]) * k["mu_eff"]) * y_w
    delta = (1 - h_sigma) * k["cc"] * (2 - k["cc"])
    if separable:
        rank_mu = sum(k["weights"][i] * y[i] ** 2 for i in range(k["mu"]))
        rank_one = pc ** 2
    else:
        scaled = [w if w >= 0 else w * n / np.linalg.norm(inv_sqrt @ y[i]) ** 2 for i, w in enumerate(k["weights"])]
        rank_mu = sum(scaled[i] * np.outer(y[i], y[i]) for i in range(population))
        rank_one = np.outer(pc, pc)
    decay = 1 + k["c1"] * delta - k["c1"] - k["cmu"] * k["weights"].sum()
    new_C = decay * C + k["c1"] * rank_one + k["cmu"] * rank_mu
    return dict(mean=new_mean, sigma=new_sigma, C=new_C, p_sigma=p_sigma, pc=pc)


def _inverse_sqrt(C: np.ndarray) -> np.ndarray:
    values, vectors = np.linalg.eigh(C)
    return vectors @ np.diag(1 / np.sqrt(values)) @ vectors.T


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_cma_updates_are_hansens_tutorial(name):
    need("strategies")
    separable = name == "sep_cma_es"
    strategy = make_strategy(settings_for(name, popsize=10, sigma=0.5), 6)
    state = strategy.initial_state(np.linspace(-1, 1, 6, dtype=np.float32))
    rng = np.random.default_rng(10)
    for generation in range(3):  # from the identity covariance, then from an adapted one
        population = strategy.ask(state, np.random.default_rng([10, generation]), None)
        fitness = rng.normal(size=10)
        expected = tutorial_update(state.strategy, population.rows.astype(np.float64), fitness, separable)
        state, _ = strategy.tell(state, None, population, fitness)
        for key, value in expected.items():
            # atol: the library rebuilds C from its eigendecomposition before sampling (round-off ~1e-10)
            np.testing.assert_allclose(state.strategy[key], value, rtol=1e-9, atol=1e-9, err_msg=key)
        assert state.theta.tobytes() == state.strategy["mean"].astype(np.float32).tobytes()


def test_full_cma_es_refuses_a_covariance_larger_than_half_the_memory():
    check_covariance_fits(8, 1000, memory=2**30)  # 11 x 1000^2 x 8 bytes = 84 MiB of 1 GiB
    with pytest.raises(ValueError, match=r"--strategy cma_es .* 8\.2 GiB.* use --strategy sep_cma_es"):
        check_covariance_fits(8, 10_000, memory=2**30)


def test_full_cma_es_refuses_a_covariance_over_its_budget_on_any_machine():
    check_covariance_fits(8, 3493, memory=2**50)  # 11 x 3493^2 x 8 bytes: just under 1 GiB
    with pytest.raises(ValueError, match=r"keeps 11 matrices of 3494 x 3494 .* about 1\.0 GiB, over its budget of "
                                         r"1\.0 GiB .* use --strategy sep_cma_es"):
        check_covariance_fits(8, 3494, memory=2**50)


# --- on the loop: 1 and 2 workers, resume ---------------------------------------------------------------


class LinearPolicy(WeightFile):
    """A linear map from observation to action values, no bias (ARS's policies): a test-sized problem, so that
    full CMA-ES runs in seconds."""

    def __init__(self, n_observations: int, n_actions: int):
        self.layout = Layout([("fc1", (n_actions, n_observations))])
        self.num_params = self.layout.size
        self.penalised = slice(0, self.num_params)

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(-0.5, 0.5, self.num_params).astype(np.float32)

    def reset(self, params, rng=None):
        return None

    def act(self, params, state, obs):
        return self.layout.view(params, "fc1") @ obs.astype(np.float32), state


class LinearProblem(Problem):
    def __init__(self, spec: ProblemSpec):
        super().__init__(spec)
        self.policy = LinearPolicy(self.net.obs_shape[0], self.net.n_actions)


def build_linear_problem():
    return LinearProblem(ProblemSpec(("CartPole-v1",)))


def linear_run(folder: Path, name: str, threads: int, generations: int, checkpoint: Checkpoint | None = None):
    """A CartPole run of the linear policy through the real Trainer and backend; its final checkpoint."""
    es = settings_for(name, popsize=8, sigma=0.5)
    run = RunSettings(generations=generations, threads=threads, seed=5, backend="process")
    trainer = Trainer.start(es, run, build_linear_problem(), build_linear_problem, ("CartPole-v1",),
                            RunFolder(folder), "CartPole-v1", log=lambda line: None)
    try:
        if checkpoint is not None:
            trainer.restore(checkpoint)
        assert trainer.train().value == "done"
        return Checkpoint.of(trainer.state, trainer.history, trainer.observations)
    finally:
        trainer.close()


def same_checkpoints(one: Checkpoint, other: Checkpoint) -> None:
    first, second = np.load(io.BytesIO(one.to_bytes())), np.load(io.BytesIO(other.to_bytes()))
    assert sorted(first.files) == sorted(second.files)
    for key in first.files:
        if key != "total_seconds":
            assert first[key].tobytes() == second[key].tobytes(), key


@pytest.mark.parametrize("name", list(STRATEGIES))
def test_linear_policy_runs_alike_on_one_and_two_workers_and_when_resumed(name, tmp_path):
    needs_extra(name)
    folders = [tmp_path / label for label in ("serial", "pool", "resumed")]
    for folder in folders:
        folder.mkdir()
    serial = linear_run(folders[0], name, 1, 3)
    same_checkpoints(serial, linear_run(folders[1], name, 2, 3))
    half = linear_run(folders[2], name, 1, 1)
    same_checkpoints(serial, linear_run(folders[2], name, 2, 3, checkpoint=half))
    assert serial.generation == 3 and np.isfinite(serial.theta).all()


MAINS = {"static": train_static.main, "hebbian": train_hebb.main}


def same_run(first: Path, second: Path) -> None:
    """Every last*/best* parameter file and the checkpoint bit for bit, the metrics but for wall clock
    (``assert_same_run``, for the Hebbian files too)."""
    names = sorted(path.name for path in [*first.glob("last*.dat"), *first.glob("best*.dat")])
    assert names and names == sorted(path.name for path in [*second.glob("last*.dat"), *second.glob("best*.dat")])
    for name in names:
        assert load_dat(first / name).tobytes() == load_dat(second / name).tobytes(), name
    assert_same_checkpoint_and_metrics(first, second)


def script(kind: str, *argv: str) -> None:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = MAINS[kind](list(argv))
    assert code == 0, out.getvalue()[-3000:]


TINY = ("--environment", "CartPole-v1", "--popsize", "8", "--seed", "13")
NETWORK = {"static": ("--network", "small"), "hebbian": ()}


@pytest.mark.parametrize("kind", ["static", "hebbian"])
@pytest.mark.parametrize("name", sorted(set(STRATEGIES) - FULL_COVARIANCE))
def test_scripts_give_the_same_bits_on_one_and_two_workers_and_when_resumed(name, kind, tmp_path):
    """Through train_static.py and train_hebb.py: 2 generations on 1 worker, on 2 workers, and 1 + 1 resumed."""
    needs_extra(name)
    argv = (*TINY, *NETWORK[kind], "--strategy", name)
    runs = {}
    for label, threads in (("serial", "1"), ("pool", "2")):
        script(kind, *argv, "--generations", "2", "--threads", threads, "--folder", str(tmp_path / label))
        runs[label] = only_run(tmp_path / label)
    script(kind, *argv, "--generations", "1", "--threads", "1", "--folder", str(tmp_path / "resumed"))
    runs["resumed"] = only_run(tmp_path / "resumed")
    script(kind, "--resume", str(runs["resumed"]), "--generations", "2", "--threads", "2")
    same_run(runs["serial"], runs["pool"])
    same_run(runs["serial"], runs["resumed"])


@pytest.mark.parametrize("name", ["ars", "snes"])  # ARS V2-t; members that are not mirrored pairs
def test_observation_statistics_are_the_same_on_one_and_two_workers(name, tmp_path):
    argv = (*TINY, "--network", "small", "--strategy", name, "--generations", "2", "--obs_norm", "--obs_norm_prob", "1")
    for label, threads in (("serial", "1"), ("pool", "2")):
        script("static", *argv, "--threads", threads, "--folder", str(tmp_path / label))
    serial, pool = only_run(tmp_path / "serial"), only_run(tmp_path / "pool")
    same_run(serial, pool)
    with np.load(serial / "last.obs_norm.npz") as saved:
        assert int(saved["observations"]) > 0


@pytest.mark.parametrize("name", ["pgpe", "sep_cma_es"])  # a per-parameter sigma, and the members' vectors
def test_ray_gives_the_bits_of_one_worker(name, tmp_path):
    need("ray")
    needs_extra(name)
    argv = (*TINY, "--network", "small", "--strategy", name, "--generations", "2")
    script("static", *argv, "--threads", "1", "--folder", str(tmp_path / "serial"))
    script("static", *argv, "--threads", "2", "--backend", "ray", "--folder", str(tmp_path / "ray"))
    same_run(only_run(tmp_path / "serial"), only_run(tmp_path / "ray"))


# --- the scripts' checks ------------------------------------------------------------------------------


def refused(kind: str, *argv: str) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = MAINS[kind](list(argv))
    assert code == 2, out.getvalue()
    lines = out.getvalue().strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize("argv, message", [
    (("--strategy", "snes", "--pgpe_sigma_lr", "0.2"), "--pgpe_sigma_lr has an effect only with --strategy pgpe"),
    (("--strategy", "pgpe", "--lr", "0.1"), "--lr has an effect only with --strategy openai"),
    (("--ars_top", "2"), "--ars_top has an effect only with --strategy ars"),
    (("--strategy", "pgpe", "--pgpe_optimizer", "adam", "--clipup_momentum", "0.5"),
     "--clipup_momentum has an effect only with --strategy pgpe --pgpe_optimizer clipup"),
    (("--strategy", "ars", "--ars_top", "5"), "--ars_top must be a whole number from 1 to 4"),
    (("--strategy", "pgpe", "--clipup_max_speed", "0"), "--clipup_max_speed must be a number > 0"),
])
def test_strategy_flags_are_checked_in_one_line(argv, message, tmp_path):
    assert message in refused("static", *TINY, *argv, "--folder", str(tmp_path))
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("name", [name for name, entry in STRATEGIES.items() if entry.pairs])
def test_a_strategy_of_mirrored_pairs_refuses_an_odd_population_in_one_line(name, tmp_path):
    line = refused("static", "--environment", "CartPole-v1", "--strategy", name, "--popsize", "5", "--folder",
                   str(tmp_path))
    assert line == (f"train_static.py: error: --popsize 5 is odd, but --strategy {name} samples mirrored pairs; give "
                    "an even --popsize such as 4 or 6")
    assert not any(tmp_path.iterdir())


def test_snes_runs_the_population_given_odd_or_not(tmp_path):
    """``--strategy snes --popsize 5``: 5 members (and the centre) per generation, as recorded and counted."""
    script("static", "--environment", "CartPole-v1", "--strategy", "snes", "--popsize", "5", "--generations", "2",
           "--seed", "3", "--threads", "1", "--folder", str(tmp_path))
    run = only_run(tmp_path)
    assert json.loads((run / "config.json").read_text())["es"]["popsize"] == 5
    rows = read_metrics(run / "metrics.csv")
    assert len(rows) == 2 and all(1 <= int(row["center_rank"]) <= 6 for row in rows)  # of the 5 members + 1
    assert len(list(run.glob("CartPole-v1__rew_*__pop_5__*.dat"))) == 2


def test_full_cma_es_on_a_large_network_is_refused_naming_sep_cma_es(tmp_path, monkeypatch):
    need("strategies")
    monkeypatch.setattr("es.strategies.cma.physical_memory", lambda: 2**30)
    line = refused("static", *TINY, "--strategy", "cma_es", "--folder", str(tmp_path))
    assert "--strategy cma_es keeps 11 matrices of 8832 x 8832" in line and "--strategy sep_cma_es" in line
    assert not any(tmp_path.iterdir())
