#!/usr/bin/env python
"""The pixel CNN: the original's as torch computes it and the project's (``policies.conv``'s ordered kernels
and the project's tanh), in one run.

    python benchmarks/cnn.py

- per frame: both paths on the same real CarRacing-v3 observations and the same weights, one thread,
  CPU time of this process, alternating round by round; the medians over ``--rounds``; and whether two
  instances of the project's give the same bits on every frame;
- the features: the largest difference between the two paths on those frames, for PyTorch's default
  initialisation (the static network's generation 0) and N(0, 1) (the Hebbian network's CNN);
- tanh: the largest error of the project's rational tanh against ``math.tanh`` (double), and how
  often it steps down, over every ``--tanh_every``-th float32 of [0, 8] (1: all of them).

Each run writes its record to benchmarks/results/ (benchmarks/record.py): the times per frame and their
ratio round by round, the differences as notes. (Before 0.1.0 it also measured ``--fast_conv``, a
compiled pass summing in another order; by then the default was faster per frame, and the flag went.)
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit
from record import Record, add_results_flag

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from cli.flags import positive_int
from envs import ProblemSpec
from policies import PolicySettings
from policies.conv import ConvFeatures
from policies.elementary import rational_tanh
from policies.init import default_init
from policies.network import Layout, conv_shapes

SHAPES = conv_shapes(3)


def observations(count: int, seed: int = 0) -> list[np.ndarray]:
    """``count`` CarRacing-v3 observations (the network's input) under random actions."""
    problem = ProblemSpec(("CarRacing-v3",), PolicySettings("static")).build()
    env, rng, frames = problem.envs[0], np.random.default_rng(seed), []
    try:
        observation, _ = env.reset(seed=seed)
        while len(frames) < count:
            frames.append(np.array(observation, dtype=np.float32))
            observation, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                observation, _ = env.reset(seed=int(rng.integers(2**31)))
    finally:
        problem.close()
    return frames


def conv_weights(kind: str, seed: int) -> np.ndarray:
    """The CNN of a static network's generation 0 (``default``) or of a Hebbian one (``normal``)."""
    rng = np.random.default_rng(seed)
    if kind == "normal":
        return rng.standard_normal(sum(int(np.prod(shape)) for shape in SHAPES), dtype=np.float32)
    layout = Layout([("conv1", SHAPES[0]), ("conv2", SHAPES[1])])
    return default_init(layout, rng, {name: int(np.prod(part.shape[1:])) for name, part in layout.parts.items()})


class TorchCNN:
    """The original's CNN as torch computes it: conv2d, tanh, max_pool2d, twice (one thread)."""

    def __init__(self, weights: np.ndarray):
        import torch

        torch.set_num_threads(1)
        self.torch = torch
        split = int(np.prod(SHAPES[0]))
        self.conv1 = torch.from_numpy(weights[:split].reshape(SHAPES[0]).copy())
        self.conv2 = torch.from_numpy(weights[split:].reshape(SHAPES[1]).copy())

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        functional = self.torch.nn.functional
        with self.torch.inference_mode():
            x = self.torch.from_numpy(np.ascontiguousarray(frame, dtype=np.float32))[None]
            hidden = functional.max_pool2d(functional.conv2d(x, self.conv1).tanh(), 2)
            return functional.max_pool2d(functional.conv2d(hidden, self.conv2, stride=2).tanh(), 2).reshape(-1).numpy()


def per_frame(features, frames: list[np.ndarray]) -> float:
    start = time.process_time()
    for frame in frames:
        features(frame)
    return (time.process_time() - start) / len(frames)


def speed(record: Record, frames: list[np.ndarray], rounds: int) -> None:
    weights = conv_weights("default", 1)
    paths = {"torch": TorchCNN(weights), "default": ConvFeatures(weights, SHAPES)}
    for features in paths.values():
        per_frame(features, frames[:1])  # compiled (or loaded from numba's cache) before timing
    again = ConvFeatures(weights, SHAPES)
    same = all(np.array_equal(paths["default"](frame).view(np.uint32), again(frame).view(np.uint32))
               for frame in frames)
    times: dict[str, list[float]] = {name: [] for name in paths}
    for _ in range(rounds):
        for name, features in paths.items():
            times[name].append(per_frame(features, frames))
    torch_us, default_us = (statistics.median(times[name]) * 1e6 for name in paths)
    for name in paths:
        record.add(f"{name}_per_frame", f"the CNN's {name} path, CPU time per CarRacing frame", "us",
                   [seconds * 1e6 for seconds in times[name]])
    record.add("default_against_torch", "the CNN's default path against torch's, per frame", "x",
               [torch / other for torch, other in zip(times["torch"], times["default"])])
    record.note("default_same_bits_twice", same)
    print(f"per frame ({len(frames)} CarRacing frames, median of {rounds} rounds): torch {torch_us:.0f} us; "
          f"the default ({paths['default'].path}) {default_us:.0f} us, {torch_us / default_us:.2f}x, the same bits "
          f"twice on every frame: {same}")


def differences(record: Record, frames: list[np.ndarray]) -> None:
    for kind in ("default", "normal"):
        weights = conv_weights(kind, 2)
        torch_path, default = TorchCNN(weights), ConvFeatures(weights, SHAPES)
        largest = max(float(np.abs(torch_path(frame) - default(frame)).max()) for frame in frames)
        record.note(f"features_{kind}_weights", {"largest_torch_minus_default": largest})
        print(f"features, {kind} weights, over {len(frames)} frames: largest |torch - default| {largest:.2e}")


@njit(cache=True)
def tanh_error(every: int) -> tuple[float, float, float, float, int]:
    """On float32 x in [0, 8] (every ``every``-th; tanh and ``rational_tanh`` are odd): the largest absolute
    error of ``rational_tanh`` and its x, the largest in float32 ulps and its x, and how often it
    decreases from one float32 checked to the next (then a window's tanh of the max, which the pass
    takes, may be 1 ulp from the max of the tanhs)."""
    bits = np.zeros(1, dtype=np.int32)
    top = np.array([8.0], dtype=np.float32).view(np.int32)[0]
    largest, at, largest_ulp, at_ulp, decreases, previous = 0.0, 0.0, 0.0, 0.0, 0, np.float32(0.0)
    for pattern in range(0, top + 1, every):
        bits[0] = pattern
        x = bits.view(np.float32)[0]
        got = rational_tanh(x)
        exact = math.tanh(np.float64(x))
        error = abs(np.float64(got) - exact)
        ulps = error / max(math.ldexp(1.0, math.frexp(exact)[1] - 24), 2.0**-149)  # float32's spacing there
        if error > largest:
            largest, at = error, x
        if ulps > largest_ulp:
            largest_ulp, at_ulp = ulps, x
        decreases += got < previous
        previous = got
    return largest, at, largest_ulp, at_ulp, decreases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=positive_int, default=5)
    parser.add_argument("--frames", type=positive_int, default=300, help="CarRacing frames timed per path and round")
    parser.add_argument("--tanh_every", type=positive_int, default=64,
                        help="1: every float32 of [0, 8] for the rational tanh (about a minute)")
    add_results_flag(parser)
    args = parser.parse_args()
    record = Record("cnn")
    frames = observations(args.frames)
    speed(record, frames, args.rounds)
    differences(record, frames)
    largest, at, ulps, at_ulp, decreases = tanh_error(args.tanh_every)
    record.note("rational_tanh", {"every": args.tanh_every, "largest_error": largest, "at": float(at),
                                  "largest_ulps": ulps, "at_ulps": float(at_ulp), "decreasing_steps": decreases})
    checked = "every float32" if args.tanh_every == 1 else f"every {args.tanh_every}th float32"
    print(f"tanh on {checked} of [0, 8]: largest error {largest:.2e} (at x = {at:.6g}), {ulps:.1f} ulp "
          f"(at x = {at_ulp:.6g}); decreasing steps: {decreases}")
    record.write(args.results)


if __name__ == "__main__":
    main()
