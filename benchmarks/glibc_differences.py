#!/usr/bin/env python
"""How often glibc's code for this CPU and its code for an x86-64 without FMA and AVX2 give other results: the C
library's functions on fixed inputs, and CarRacing's tracks.

    python benchmarks/glibc_differences.py
    python benchmarks/glibc_differences.py --values 100000 --tracks 20

glibc picks its exp, log, sin, cos, atan2 and pow by the CPU's features when a program starts
(``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX`` makes it take the code of a CPU without FMA and AVX2). Each
path runs in a child process of its own, which computes each function through Python's ``math`` (the C
library's own function) on the same --values inputs drawn from a fixed seed, and the tracks of seeds 0 to
--tracks - 1 of the project's ``CarRacing-v3`` (its track generation calls the C library's atan2, cos and sin,
as Gymnasium's does); the parent counts the results whose bits differ. Counts, not times: the record is made
with ``timed=False``. On a CPU without FMA or AVX2 both children take the same code, and every count is 0.
docs/reproducibility.md renders the record's table.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from record import Record, add_results_flag

from cli.flags import positive_int

ROOT = Path(__file__).resolve().parent.parent
PATHS = {"this_cpu": {}, "without_fma": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX"}}
# each function and the inputs it is given: (name, arity, how its inputs are drawn from a numpy Generator)
FUNCTIONS = {
    "exp": (lambda rng, n: (rng.uniform(-20.0, 20.0, n),), math.exp, "x uniform in [-20, 20]"),
    "log": (lambda rng, n: (10.0 ** rng.uniform(-3.0, 3.0, n),), math.log, "x log-uniform in [1e-3, 1e3]"),
    "sin": (lambda rng, n: (rng.uniform(-10.0, 10.0, n),), math.sin, "x uniform in [-10, 10]"),
    "cos": (lambda rng, n: (rng.uniform(-10.0, 10.0, n),), math.cos, "x uniform in [-10, 10]"),
    "atan2": (lambda rng, n: (rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n)), math.atan2,
              "y and x uniform in [-1, 1]"),
    "pow": (lambda rng, n: (rng.uniform(0.1, 10.0, n), rng.uniform(-3.0, 3.0, n)), math.pow,
            "x uniform in [0.1, 10], y in [-3, 3]"),
}


def child(values: int, tracks: int, folder: str) -> None:
    """Write into ``folder`` each function's results (NAME.npy, float64, bit for bit) and the tracks' digests
    (tracks.json), computed on this process's path."""
    import numpy as np

    for name, (draw, function, _) in FUNCTIONS.items():
        inputs = [column.tolist() for column in draw(np.random.default_rng(17), values)]
        outputs = [function(*arguments) for arguments in zip(*inputs, strict=True)]
        np.save(Path(folder) / f"{name}.npy", np.array(outputs))
    import gymnasium as gym

    import envs  # noqa: F401  (registers the project's CarRacing)

    env = gym.make("CarRacing-v3")
    digests = []
    for seed in range(tracks):
        env.reset(seed=seed)
        digests.append(hashlib.sha256(np.asarray(env.unwrapped.track, dtype=np.float64).tobytes()).hexdigest())
    env.close()
    (Path(folder) / "tracks.json").write_text(json.dumps(digests))


def results(values: int, tracks: int, path: dict[str, str]) -> dict:
    """Each function's results as their bits (uint64), and the tracks' digests, from a child on ``path``."""
    import numpy as np

    with tempfile.TemporaryDirectory() as folder:
        done = subprocess.run([sys.executable, __file__, "--child", str(values), str(tracks), folder], cwd=ROOT,
                              capture_output=True, text=True, timeout=3600,
                              env={**os.environ, "SDL_VIDEODRIVER": "dummy", **path})
        if done.returncode != 0:
            raise SystemExit(f"glibc_differences.py: error: the child on {path or 'this CPU'} failed: "
                             f"{done.stderr[-2000:]}")
        found = {name: np.load(Path(folder) / f"{name}.npy").view(np.uint64) for name in FUNCTIONS}
        found["tracks"] = json.loads((Path(folder) / "tracks.json").read_text())
    return found


def one_in(differing: int, total: int) -> str:
    return f"1 in {total / differing:,.0f}" if differing else "none"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--values", type=positive_int, default=1_000_000, help="inputs per function")
    parser.add_argument("--tracks", type=positive_int, default=100, help="CarRacing tracks, seeds 0 to TRACKS - 1")
    add_results_flag(parser)
    args = parser.parse_args(argv)
    record = Record("glibc_differences", timed=False)
    record.note("paths", {name: path.get("GLIBC_TUNABLES", "glibc's choice for this CPU")
                          for name, path in PATHS.items()})
    ours, other = (results(args.values, args.tracks, path) for path in PATHS.values())
    rows = []
    for name, (_, _, inputs) in FUNCTIONS.items():
        differing = int((ours[name] != other[name]).sum())
        record.add(name, f"math.{name}: results whose bits differ between the two paths, of {args.values}", "",
                   [differing])
        rows.append([f"`{name}`", inputs, f"{differing:,} of {args.values:,}", one_in(differing, args.values)])
    tracks = sum(a != b for a, b in zip(ours["tracks"], other["tracks"], strict=True))
    record.add("tracks", f"CarRacing-v3 tracks of seeds 0-{args.tracks - 1} that differ between the two paths", "",
               [tracks])
    rows.append(["CarRacing-v3 tracks", f"seeds 0-{args.tracks - 1}", f"{tracks} of {args.tracks}",
                 one_in(tracks, args.tracks)])
    record.table("differences", ["what", "inputs", "other bits without FMA", "how often"], rows)
    for row in rows:
        print(" | ".join(row))
    record.write(args.results)
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        child(int(sys.argv[2]), int(sys.argv[3]), sys.argv[4])
        sys.exit(0)
    sys.exit(main())
