"""``--fast_conv``: the pixel CNN's compiled pass (``policies.conv.fast_features``) against torch's path and
against the equations written out, its determinism, the flag's declaration end to end (train, config.json,
evaluate, refusals), and run folders written before the flag.

The default path keeps torch's bits: tests/test_pinned.py's pixel cases pin it (tests/test_ordered_conv.py: how).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from envs import ProblemSpec
from es.loop import EVAL_SEEDS, EVAL_STREAM, stream_rng
from policies import PolicySettings, make_policy
from policies.conv import ConvFeatures, _convolve, _tanh_of_pooled, fast_features
from policies.elementary import _TANH_CLAMP, _TANH_P, _TANH_Q, rational_tanh
from policies.network import NetworkSpec, conv_shapes
from tests.test_pinned import CASES, PINNED, parameters_hash, train

ROOT = Path(__file__).resolve().parent.parent
# measured (benchmarks/fast_conv.py, 300 frames): 1.2e-5 with N(0, 1) weights, 2.4e-7 with PyTorch's default init
TOLERANCE = 5e-5


def weights_for(channels: int, rng: np.random.Generator, scale: float) -> np.ndarray:
    size = sum(int(np.prod(shape)) for shape in conv_shapes(channels))
    return (rng.standard_normal(size) * scale).astype(np.float32)


def both_paths(weights: np.ndarray, channels: int) -> tuple[ConvFeatures, ConvFeatures]:
    return ConvFeatures(weights, conv_shapes(channels)), ConvFeatures(weights, conv_shapes(channels), fast=True)


@pytest.mark.parametrize("channels", [3, 4])
@pytest.mark.parametrize("scale", [1.0, 0.1])
def test_fast_features_match_torch_on_random_frames(channels, scale):
    rng = np.random.default_rng(channels)
    for _ in range(3):
        torch_path, fast = both_paths(weights_for(channels, rng, scale), channels)
        for _ in range(3):
            frame = rng.random((channels, 84, 84), dtype=np.float32)
            expected, got = torch_path(frame), fast(frame)
            assert got.shape == (648,) and got.dtype == np.float32
            assert np.abs(got - expected).max() < TOLERANCE


def car_racing_frames(count: int) -> list[np.ndarray]:
    problem = ProblemSpec(("CarRacing-v3",), PolicySettings("static")).build()
    env, frames = problem.envs[0], []
    try:
        observation, _ = env.reset(seed=3)
        env.action_space.seed(3)
        while len(frames) < count:
            frames.append(np.array(observation))
            observation, *_ = env.step(env.action_space.sample())
    finally:
        problem.close()
    return frames


def test_fast_features_match_torch_on_car_racing_frames():
    frames = car_racing_frames(60)
    assert frames[0].shape == (3, 84, 84) and len({frame.tobytes() for frame in frames}) > 30
    rng = np.random.default_rng(5)
    for scale in (1.0, 0.2):
        torch_path, fast = both_paths(weights_for(3, rng, scale), 3)
        largest = max(float(np.abs(fast(frame) - torch_path(frame)).max()) for frame in frames)
        assert largest < TOLERANCE


# --- the pass against the equations, in float32, each sum in the pass's order ---------------------------


def reference_tanh(x: np.ndarray) -> np.ndarray:
    """The rational tanh's formula, in numpy float32, the operations in the same order."""
    x = np.clip(x, -_TANH_CLAMP, _TANH_CLAMP)
    x2 = x * x
    p = np.full_like(x, _TANH_P[0])
    for coefficient in _TANH_P[1:]:
        p = p * x2 + coefficient
    q = np.full_like(x, _TANH_Q[0])
    for coefficient in _TANH_Q[1:]:
        q = q * x2 + coefficient
    return x * p / q


def reference_conv(planes: np.ndarray, weights: np.ndarray, stride: int) -> np.ndarray:
    """out[o, y, x] = sum over c, ky, kx (in that order, from 0) of w[o, c, ky, kx] * in[c, s y + ky, s x + kx]."""
    outs, channels, size, _ = weights.shape
    height = (planes.shape[1] - size) // stride + 1
    out = np.zeros((outs, height, height), dtype=np.float32)
    span = stride * (height - 1) + 1
    for o in range(outs):
        for c in range(channels):
            for ky in range(size):
                for kx in range(size):
                    window = planes[c, ky:ky + span:stride, kx:kx + span:stride]
                    out[o] = out[o] + weights[o, c, ky, kx] * window
    return out


def reference_pool(planes: np.ndarray) -> np.ndarray:
    """Floor-mode 2 x 2 max-pooling."""
    channels, height, width = planes.shape
    h, w = height // 2, width // 2
    return planes[:, :2 * h, :2 * w].reshape(channels, h, 2, w, 2).max(axis=(2, 4))


def test_the_pass_is_the_equations():
    """Each convolution exactly the equations' sums in the pass's order; the features conv -> tanh -> pool
    within 1 ulp (the pass takes tanh of a window's max, and the rational tanh decreases by 1 ulp at
    some steps: benchmarks/fast_conv.py counts them)."""
    rng = np.random.default_rng(11)
    frame = rng.random((3, 84, 84), dtype=np.float32)
    conv1 = rng.standard_normal((6, 3, 3, 3)).astype(np.float32)
    conv2 = rng.standard_normal((8, 6, 5, 5)).astype(np.float32)
    planes1 = np.empty((6, 82, 82), np.float32)
    _convolve(planes1, frame, conv1, 82, 3, 1)
    np.testing.assert_array_equal(planes1, reference_conv(frame, conv1, 1))
    pooled1 = reference_pool(reference_tanh(planes1))
    planes2 = np.empty((8, 18, 18), np.float32)
    _convolve(planes2, pooled1, conv2, 18, 5, 2)
    full2 = reference_conv(pooled1, conv2, 2)
    assert full2.shape == (8, 19, 19)
    np.testing.assert_array_equal(planes2, full2[:, :18, :18])  # the 19th row and column: dropped by the pooling
    expected = reference_pool(reference_tanh(full2)).reshape(-1)
    buffers = (np.empty((6, 82, 82), np.float32), np.empty((6, 41, 41), np.float32),
               np.empty((8, 18, 18), np.float32), np.empty(648, np.float32))
    got = fast_features(frame, conv1, conv2, *buffers)
    np.testing.assert_array_max_ulp(got, expected, maxulp=1)
    assert np.mean(got == expected) > 0.95


def test_rational_tanh_is_the_formula_and_close_to_tanh():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.uniform(-9, 9, 20_000), rng.standard_normal(20_000) * 1e-3,
                        [0.0, -0.0, 7.9, 7.91, 20.0, -20.0, np.inf, -np.inf]]).astype(np.float32)
    buffers = np.empty((1, 2, 2 * x.size), np.float32)
    buffers[0] = np.repeat(x, 2)[None]  # each value a 2 x 2 window of itself: the pass's tanh of its max
    pooled = np.empty((1, 1, x.size), np.float32)
    _tanh_of_pooled(buffers, pooled)
    got = pooled.reshape(-1)
    np.testing.assert_array_equal(got, reference_tanh(x))
    assert np.abs(got.astype(np.float64) - np.tanh(x.astype(np.float64))).max() < 5e-7  # 4.1e-7 over all floats
    assert np.isnan(rational_tanh(np.float32(np.nan)))
    assert math.copysign(1.0, rational_tanh(np.float32(-0.0))) == -1.0


def test_twice_the_same_bits():
    rng = np.random.default_rng(9)
    weights, frame = weights_for(3, rng, 1.0), rng.random((3, 84, 84), dtype=np.float32)
    first = ConvFeatures(weights, conv_shapes(3), fast=True)(frame).copy()
    again = ConvFeatures(weights, conv_shapes(3), fast=True)
    assert again(frame).tobytes() == first.tobytes()
    again(rng.random((3, 84, 84), dtype=np.float32))
    assert again(frame).tobytes() == first.tobytes()  # the buffers carry nothing from one call to the next


# --- the flag ---------------------------------------------------------------------------------------------


def run_script(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SDL_VIDEODRIVER": "dummy"}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)


def test_a_fast_conv_run_records_the_flag_and_evaluates_to_its_numbers(tmp_path):
    """train_hebb.py --fast_conv: its config.json records the flag, and evaluate_hebb.py on its best
    coefficients (the centre of generation 0) gives the return of the centre's evaluation episode."""
    seed = 5
    trained = run_script("train_hebb.py", "--environment", "CarRacing-v3", "--fast_conv", "--popsize", "2",
                         "--generations", "1", "--max_episode_steps", "30", "--eval_every", "1", "--eval_episodes",
                         "1", "--seed", str(seed), "--threads", "1", "--folder", str(tmp_path / "runs"))
    assert trained.returncode == 0, trained.stderr[-2000:]
    run, = (tmp_path / "runs").iterdir()
    assert json.loads((run / "config.json").read_text())["policy"]["fast_conv"] is True
    header, row = (run / "metrics.csv").read_text().splitlines()[:2]
    centre_eval = float(dict(zip(header.split(","), row.split(","), strict=True))["center_eval_mean"])
    episode_seed = int(stream_rng(seed, EVAL_STREAM, 0).integers(*EVAL_SEEDS, size=(1, 1))[0, 0])
    out = tmp_path / "eval.json"
    evaluated = run_script("evaluate_hebb.py", "--path_hebb", str(run / "best_coeffs.dat"), "--seed",
                           str(episode_seed), "--json", str(out))
    assert evaluated.returncode == 0, evaluated.stderr[-2000:]
    entry, = json.loads(out.read_text())["environments"]
    assert entry["returns"] == [centre_eval]
    config = json.loads((run / "config.json").read_text())
    config["policy"]["fast_conv"] = False  # as a run without the flag records it
    (run / "config.json").write_text(json.dumps(config))
    refused = run_script("evaluate_hebb.py", "--path_hebb", str(run / "best_coeffs.dat"), "--fast_conv")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1 and "--fast_conv" in refused.stderr


def test_state_vectors_refuse_the_flag_in_one_line(tmp_path):
    result = run_script("train_static.py", "--environment", "CartPole-v1", "--fast_conv", "--popsize", "2",
                        "--generations", "1", "--folder", str(tmp_path / "runs"))
    assert result.returncode == 2
    assert result.stderr.strip() == ("train_static.py: error: --fast_conv computes the CNN of pixel observations, "
                                     "but these observations are vectors (4,); leave --fast_conv out")
    assert not (tmp_path / "runs").exists()


def test_pytorch_es_networks_refuse_the_flag():
    with pytest.raises(ValueError, match="--fast_conv computes the default network's CNN, which --network lstm"):
        make_policy(PolicySettings("static", network="lstm", fast_conv=True), NetworkSpec((4, 84, 84), 6))


def test_a_run_folder_from_before_the_flag_resumes_to_the_pinned_numbers(tmp_path):
    """A config.json without fast_conv (as every run before it) resumes with the torch path, to the pinned hash."""
    kind, argv = CASES["static CartPole"]
    first = list(argv)
    first[first.index("--generations") + 1] = "1"
    run = train(kind, tmp_path, *first, "--threads", "1")
    config = json.loads((run / "config.json").read_text())
    assert config["policy"].pop("fast_conv") is False
    (run / "config.json").write_text(json.dumps(config, indent=2))
    train(kind, tmp_path, "--resume", str(run), "--generations", "2", "--threads", "1")
    assert parameters_hash(run) == PINNED["static CartPole"]
