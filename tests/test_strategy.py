"""The evolution strategy (es/strategy.py, es/shaping.py, es/optimizers.py) and its noise table (es/noise.py).

Exact values where the math is exact: centered ranks, standardisation, the lr and sigma schedules
of docs/original.md, "The evolution strategy", and one SGD step of OpenAI-ES (Salimans et al. 2017) written out
by hand on a four-number noise table.
"""

import math
from multiprocessing import shared_memory

import numpy as np
import pytest

from es.noise import NoiseTable
from es.settings import ESSettings
from es.shaping import centered_ranks, l2_penalty, penalised_fitness, standardise
from es.shaping import rank_std as shape_fitness
from es.strategies.openai import OpenES
from es.strategies.openai import decay_lr as decay_lr_with
from es.strategies.openai import decay_sigma as decay_sigma_with
from es.strategy import ESState, Population

DEFAULTS = ESSettings()


def decay_lr(lr, decay):
    return decay_lr_with(lr, ESSettings(decay=decay))


def decay_sigma(sigma):
    return decay_sigma_with(sigma, DEFAULTS)


def open_es(population_size, decay=0.995):
    return OpenES(ESSettings(popsize=population_size, decay=decay))

# --- fitness shaping -----------------------------------------------------------------------------


def test_centered_ranks_exact_values():
    np.testing.assert_array_equal(centered_ranks(np.array([3.0, 1.0, 2.0])), [0.5, -0.5, 0.0])
    np.testing.assert_array_equal(centered_ranks(np.array([10.0, -4.0, 7.0, 0.5, 2.0])),
                                  [0.5, -0.5, 0.25, -0.25, 0.0])


def test_centered_ranks_are_a_permutation_of_the_grid_without_ties():
    fitness = np.random.default_rng(0).normal(size=200)
    ranks = centered_ranks(fitness)
    np.testing.assert_allclose(np.sort(ranks), np.arange(200) / 199 - 0.5, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.argsort(ranks), np.argsort(fitness))


def test_tied_values_share_their_average_rank():
    # Deliberate difference from the original, which broke ties by sort position.
    # Sorted: 1, 1 take ranks 0 and 1 (average 0.5); 2 rank 2; 3 rank 3; n - 1 = 3.
    np.testing.assert_allclose(centered_ranks(np.array([1.0, 1.0, 2.0, 3.0])),
                               [0.5 / 3 - 0.5, 0.5 / 3 - 0.5, 2 / 3 - 0.5, 0.5], rtol=0, atol=1e-15)
    # Three-way tie in the middle of five: ranks 1, 2, 3 average to 2, i.e. the centre 0.
    np.testing.assert_array_equal(centered_ranks(np.array([4.0, 4.0, 9.0, -1.0, 4.0])),
                                  [0.0, 0.0, 0.5, -0.5, 0.0])


def test_all_equal_fitness_gives_all_zero_ranks():
    np.testing.assert_array_equal(centered_ranks(np.full(6, 2.5)), np.zeros(6))


def test_standardise():
    values = np.array([-0.5, 0.5, 1 / 6, -1 / 6])  # mean 0, variance 5/36
    np.testing.assert_allclose(standardise(values), values * 6 / math.sqrt(5), rtol=1e-15)
    shifted = standardise(np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(shifted, [-math.sqrt(1.5), 0.0, math.sqrt(1.5)], rtol=1e-15)
    assert standardise(np.full(4, 7.0)) is None


def test_shape_fitness_is_none_when_every_value_is_equal():
    assert shape_fitness(np.full(10, -3.0)) is None


def test_shape_fitness_rescales_ranks_by_the_originals_constant():
    # docs/original.md, "The evolution strategy": with n = 200 distinct values, std of the ranks is
    # sqrt((n+1)/(12(n-1))) = 0.2901.
    fitness = np.random.default_rng(1).normal(size=200)
    shaped = shape_fitness(fitness)
    factor = 1 / math.sqrt(201 / (12 * 199))
    np.testing.assert_allclose(shaped, centered_ranks(fitness) * factor, rtol=1e-12, atol=1e-12)
    assert factor == pytest.approx(3.447, abs=1e-3)


# --- schedules -----------------------------------------------------------------------------------


def test_decay_lr_and_sigma_one_step():
    assert decay_lr(0.2, 0.995) == 0.2 * 0.995
    assert decay_sigma(0.1) == 0.1 * 0.999


def test_decay_floors():
    # lr decays only while strictly above 0.001, sigma only while strictly above 0.01.
    assert decay_lr(0.001, 0.995) == 0.001
    assert decay_lr(0.0005, 0.995) == 0.0005
    assert decay_lr(0.0011, 0.995) == 0.0011 * 0.995
    assert decay_sigma(0.01) == 0.01
    assert decay_sigma(0.005) == 0.005
    assert decay_sigma(0.0101) == 0.0101 * 0.999


def run_schedules(generations, lr=0.2, sigma=0.1, decay=0.995):
    for _ in range(generations):
        lr, sigma = decay_lr(lr, decay), decay_sigma(sigma)
    return lr, sigma


def test_schedules_after_300_and_1000_generations():
    lr, sigma = run_schedules(300)
    assert lr == pytest.approx(0.2 * 0.995 ** 300, rel=1e-12)
    assert sigma == pytest.approx(0.1 * 0.999 ** 300, rel=1e-12)
    assert (round(lr, 5), round(sigma, 5)) == (0.04446, 0.07407)  # docs/original.md, "The evolution strategy"
    lr, sigma = run_schedules(1000)
    assert (round(lr, 5), round(sigma, 5)) == (0.00133, 0.03677)


def test_schedules_stop_at_the_first_value_below_the_floor():
    lr, _ = run_schedules(1058)
    assert lr == pytest.approx(0.2 * 0.995 ** 1058, rel=1e-12)
    assert lr < 0.001 < lr / 0.995  # 0.000995: the first value at or below the floor
    assert run_schedules(5000)[0] == lr
    _, sigma = run_schedules(2302)
    assert sigma <= 0.01 < sigma / 0.999  # the floor is reached after 2302 generations (spec)
    assert run_schedules(5000)[1] == sigma


# --- one step of OpenAI-ES -----------------------------------------------------------------------


def pairs(indices):
    """Mirrored members on these noise indices."""
    return Population(np.array(indices), np.tile(np.array([1, -1], dtype=np.int8), len(indices) // 2))


def tiny_table():
    # eps_1 = table[0:2], eps_2 = table[2:4]
    return NoiseTable(np.array([1.0, -2.0, 0.5, 3.0], dtype=np.float32))


def test_ask_returns_mirrored_members_in_order():
    strategy = open_es(6)
    table = NoiseTable(np.arange(100, dtype=np.float32))
    population = strategy.ask(ESState(np.zeros(10, np.float32), 0.2, 0.1), np.random.default_rng(3), table)
    indices, signs = population.indices, population.signs
    assert indices.shape == signs.shape == (6,)
    np.testing.assert_array_equal(indices[0::2], indices[1::2])
    np.testing.assert_array_equal(signs, [1, -1, 1, -1, 1, -1])


def test_one_tell_step_matches_the_formula_written_by_hand():
    strategy = open_es(4)
    table = tiny_table()
    eps1, eps2 = np.array([1.0, -2.0]), np.array([0.5, 3.0])
    theta = np.array([0.25, -1.0], dtype=np.float32)
    state = ESState(theta=theta, lr=0.2, sigma=0.1)
    # Members [+e1, -e1, +e2, -e2]; fitness 1, 4, 3, 2 -> ranks 0, 3, 2, 1 -> centered
    # [-1/2, 1/2, 1/6, -1/6] (mean 0, std sqrt(5)/6) -> standardised [-3, 3, 1, -1] / sqrt(5).
    fitness = np.array([1.0, 4.0, 3.0, 2.0])
    shaped = np.array([-3.0, 3.0, 1.0, -1.0]) / math.sqrt(5)
    members = [eps1, -eps1, eps2, -eps2]
    step = 0.2 / (4 * 0.1) * sum(f * e for f, e in zip(shaped, members))
    expected = theta.astype(np.float64) + step

    new_state, metrics = strategy.tell(state, table, pairs([0, 0, 2, 2]), fitness)

    assert new_state.theta.dtype == np.float32
    np.testing.assert_allclose(new_state.theta, expected, rtol=1e-6)
    # (-6 e1 + 2 e2) / sqrt(5) * 0.5, in closed form:
    np.testing.assert_allclose(new_state.theta - theta, (-6 * eps1 + 2 * eps2) / math.sqrt(5) * 0.5, rtol=1e-6)
    assert metrics["update_factor"] == pytest.approx(0.5)
    assert metrics["skipped"] is False
    assert new_state.lr == 0.2 * 0.995 and new_state.sigma == 0.1 * 0.999
    assert new_state.generation == 1
    np.testing.assert_array_equal(theta, [0.25, -1.0])  # the old state is not modified


def test_mirrored_pair_with_equal_fitness_contributes_nothing():
    strategy = open_es(4)
    table = tiny_table()
    theta = np.zeros(2, dtype=np.float32)
    state = ESState(theta=theta, lr=0.2, sigma=0.1)
    # Pair 1 tied (5, 5); pair 2 (1, 9): -e2 is better, so theta moves along -e2 only.
    new_state, _ = strategy.tell(state, table, pairs([0, 0, 2, 2]), np.array([5.0, 5.0, 1.0, 9.0]))
    ranks = np.array([1.5, 1.5, 0.0, 3.0]) / 3 - 0.5
    shaped = (ranks - ranks.mean()) / ranks.std()
    assert shaped[0] == shaped[1]
    expected = 0.5 * (shaped[2] - shaped[3]) * np.array([0.5, 3.0])
    np.testing.assert_allclose(new_state.theta, expected, rtol=1e-6)
    assert new_state.theta[1] < 0  # along -e2, no component along e1 = (1, -2)
    assert new_state.theta[0] == pytest.approx(new_state.theta[1] / 6, rel=1e-6)


def test_update_factor_is_0_01_at_the_defaults():
    strategy = open_es(200)
    table = NoiseTable.create(seed=0, size=1000)
    state = ESState(theta=np.zeros(5, dtype=np.float32), lr=0.2, sigma=0.1)
    population = strategy.ask(state, np.random.default_rng(0), table)
    fitness = np.random.default_rng(1).normal(size=200)
    _, metrics = strategy.tell(state, table, population, fitness)
    assert metrics["update_factor"] == pytest.approx(0.01, rel=1e-12)


def test_all_equal_fitness_skips_the_step_but_decays_the_schedules():
    strategy = open_es(4)
    theta = np.array([0.25, -1.0], dtype=np.float32)
    state = ESState(theta=theta, lr=0.2, sigma=0.1, generation=7)
    new_state, metrics = strategy.tell(state, tiny_table(), pairs([0, 0, 2, 2]), np.full(4, 3.0))
    np.testing.assert_array_equal(new_state.theta, theta)
    assert np.all(np.isfinite(new_state.theta))
    assert metrics["skipped"] is True
    assert (new_state.lr, new_state.sigma, new_state.generation) == (0.2 * 0.995, 0.1 * 0.999, 8)


@pytest.mark.parametrize("population_size", [0, 1, 3, 201, -2])
def test_odd_or_too_small_population_is_rejected(population_size):
    with pytest.raises(ValueError, match=str(population_size)):
        open_es(population_size)


def test_tell_rejects_the_wrong_number_of_fitness_values():
    strategy = open_es(4)
    state = ESState(theta=np.zeros(2, dtype=np.float32), lr=0.2, sigma=0.1)
    with pytest.raises(ValueError, match="expected 4 fitness values"):
        strategy.tell(state, tiny_table(), pairs([0, 0, 2, 2]), np.ones(6))


# --- noise table ---------------------------------------------------------------------------------


def test_noise_table_is_deterministic_for_a_seed():
    first = NoiseTable.create(seed=123, size=10_000)
    second = NoiseTable.create(seed=123, size=10_000)
    other = NoiseTable.create(seed=124, size=10_000)
    assert first.array.dtype == np.float32 and first.size == 10_000
    np.testing.assert_array_equal(first.array, second.array)
    assert not np.array_equal(first.array, other.array)
    assert abs(first.array.mean()) < 0.05 and first.array.std() == pytest.approx(1.0, abs=0.05)
    np.testing.assert_array_equal(first.slice(17, 5), first.array[17:22])


def test_shared_noise_table_attaches_and_close_unlinks():
    private = NoiseTable.create(seed=5, size=4096)
    table = NoiseTable.create(seed=5, size=4096, shared=True)
    try:
        name = table.name
        assert name is not None
        np.testing.assert_array_equal(table.array, private.array)
        attached = NoiseTable.attach(name, 4096)
        np.testing.assert_array_equal(attached.array, private.array)
        attached.close()  # a reader's close leaves the segment in place
        again = NoiseTable.attach(name, 4096)
        np.testing.assert_array_equal(again.array, private.array)
        again.close()
    finally:
        table.close()
    assert table.name is None
    with pytest.raises(FileNotFoundError):
        shared_memory.SharedMemory(name=name)


def test_sample_indices_stay_within_bounds():
    table = NoiseTable(np.zeros(50, dtype=np.float32))
    indices = table.sample_indices(np.random.default_rng(0), dim=45, count=2000)
    assert indices.min() >= 0 and indices.max() <= 50 - 45
    assert set(indices.tolist()) == set(range(6))  # every valid start is reachable
    assert np.array_equal(table.sample_indices(np.random.default_rng(0), dim=50, count=3), [0, 0, 0])
    with pytest.raises(ValueError, match="smaller than the 51 parameters"):
        table.sample_indices(np.random.default_rng(0), dim=51, count=1)


# --- the fitness penalty and settings as data ----------------------------------------------------


def test_l2_penalty_and_penalised_fitness_exact_values():
    assert l2_penalty(np.array([1.0, -2.0, 3.0], dtype=np.float32)) == 14 / 3
    fitness = penalised_fitness(np.array([10.0, np.nan, 5.0, np.inf]), np.array([1.0, 1.0, 4.0, 0.0]), 0.5)
    np.testing.assert_array_equal(fitness, [9.5, -np.inf, 3.0, -np.inf])


def test_the_constants_the_original_hard_coded_are_settings():
    assert (DEFAULTS.lr_floor, DEFAULTS.sigma_decay, DEFAULTS.sigma_floor, DEFAULTS.fitness_l2) == (0.001, 0.999,
                                                                                                   0.01, 0.01)
    settings = ESSettings(lr_floor=0.15, sigma_decay=0.5, sigma_floor=0.05)
    assert decay_lr_with(0.2, settings) == 0.2 * 0.995 and decay_lr_with(0.15, settings) == 0.15
    assert decay_sigma_with(0.1, settings) == 0.05 and decay_sigma_with(0.05, settings) == 0.05


def test_tasks_are_every_member_on_every_environment_and_seed_member_major():
    from es.worker import make_tasks

    seeds = [[11, 12], [11, 12], [21, 22]]
    record = [[True, False], [True, False], [False, False]]
    tasks = make_tasks(np.arange(3), np.array([5, 5, 9]), np.array([1, -1, 0]), np.array(seeds), n_envs=2,
                       record=np.array(record), max_steps=7)
    expected = [(member, index, sign, env, seed, int(flag), 7)
                for member, index, sign, member_seeds, member_record in zip(range(3), [5, 5, 9], [1, -1, 0], seeds,
                                                                            record)
                for env in range(2) for seed, flag in zip(member_seeds, member_record)]
    assert tasks.tolist() == expected
    assert tasks.dtype.names == ("member", "noise_index", "sign", "env_index", "seed", "record_obs", "max_steps")
