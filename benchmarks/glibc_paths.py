#!/usr/bin/env python
"""What one fixed path through the C library would cost: the simulators' steps on glibc's code for this CPU
against glibc's code for an x86-64 without FMA and AVX2, in instructions.

    python benchmarks/glibc_paths.py
    python benchmarks/glibc_paths.py --rounds 5 --steps 200

glibc picks its exp, log, sin, cos, atan2, pow (and memcpy, strlen ...) by the CPU's features when a program
starts; ``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-AVX`` makes it take the code of a CPU without FMA and
AVX2, the one path every x86-64 can take. Making every process of the tool take it (the tool re-executing
itself with the variable set) would give the simulators' runs the same bits on x86-64 CPUs with and without
FMA (docs/reproducibility.md). This measures its cost where the C library is called: ``env.step`` of the
project's CarRacing (its track is drawn at each reset, here every ``--reset_every`` steps), MuJoCo's
HalfCheetah and the pyBullet ant, the same seeds and random actions on both paths. Each is counted in a
child process under valgrind's callgrind, only inside the steps (callgrind collects inside
``itertools.starmap``, through which the child steps), both paths alternating round by round: instructions
per step, and their ratio (the non-FMA path's over this CPU's). Counts, not times: the machine's load does
not move them (the record is made with ``timed=False``). An FMA instruction does the work of two, so the
ratio of instructions can exceed the ratio of times.

Needs valgrind (``apt-get install valgrind``) and glibc on x86-64.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from record import Record, add_results_flag

from cli.flags import positive_int

ROOT = Path(__file__).resolve().parent.parent
WITHOUT_FMA = "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX"
ENVIRONMENTS = ("CarRacing-v3", "HalfCheetah-v5", "AntBulletEnv-v0")
PATHS = {"this_cpu": {}, "without_fma": {"GLIBC_TUNABLES": WITHOUT_FMA}}


def steps_in_child(env_id: str, steps: int, reset_every: int) -> None:
    """The child: ``steps`` steps of ``env_id`` through itertools.starmap (what callgrind counts)."""
    from collections import deque
    from itertools import starmap

    import gymnasium as gym
    import numpy as np

    import envs  # noqa: F401  (registers the project's environments)
    from envs import quiet_output

    with quiet_output():
        env = gym.make(env_id)
    actions = np.random.default_rng(11).uniform(-1, 1, size=(steps, *env.action_space.shape)).astype(np.float32)
    env.reset(seed=4)
    env.step(actions[0])  # compiled code compiles (or loads from numba's cache) before the count
    env.reset(seed=5)

    def step(index: int) -> None:
        _, _, terminated, truncated, _ = env.step(actions[index])
        if terminated or truncated or (index + 1) % reset_every == 0:
            env.reset(seed=5 + index)

    deque(starmap(step, ((index,) for index in range(steps))), maxlen=0)
    env.close()


def counted(env_id: str, steps: int, reset_every: int, path: dict[str, str]) -> int:
    """Instructions inside the steps of one child under callgrind."""
    with tempfile.TemporaryDirectory() as folder:
        command = ["valgrind", "--tool=callgrind", "--collect-atstart=no", "--toggle-collect=starmap_next",
                   f"--callgrind-out-file={folder}/callgrind.out", sys.executable, __file__, "--child", env_id,
                   str(steps), str(reset_every)]
        done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=3600,
                              env={**os.environ, "SDL_VIDEODRIVER": "dummy", "MUJOCO_GL": "egl", **path})
    found = re.search(r"Collected : (\d+)", done.stderr)
    if done.returncode != 0 or found is None:
        raise SystemExit(f"glibc_paths.py: error: {env_id} under callgrind failed: {done.stderr[-2000:]}")
    return int(found.group(1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=positive_int, default=5)
    parser.add_argument("--steps", type=positive_int, default=300, help="steps of each environment per count")
    parser.add_argument("--reset_every", type=positive_int, default=100, metavar="STEPS")
    parser.add_argument("--environment", choices=ENVIRONMENTS, action="append",
                        help="one of the environments (repeatable; default: all three)")
    add_results_flag(parser)
    args = parser.parse_args(argv)
    record = Record("glibc_paths", timed=False)
    record.note("paths", {name: path.get("GLIBC_TUNABLES", "glibc's choice for this CPU")
                          for name, path in PATHS.items()})
    for env_id in args.environment or ENVIRONMENTS:
        per_step: dict[str, list[float]] = {name: [] for name in PATHS}
        for round_index in range(args.rounds):
            order = list(PATHS) if round_index % 2 == 0 else list(PATHS)[::-1]
            for name in order:
                per_step[name].append(counted(env_id, args.steps, args.reset_every, PATHS[name]) / args.steps)
        key = env_id.split("-")[0]
        for name, values in per_step.items():
            record.add(f"{key}_{name}", f"{env_id}: instructions per step, {name.replace('_', ' ')}", "", values)
        ratio = record.add(f"{key}_ratio", f"{env_id}: instructions per step without FMA / with", "x",
                           [b / a for a, b in zip(per_step["this_cpu"], per_step["without_fma"])])
        print(f"{env_id}: {ratio.median:.3f}x the instructions per step on the path without FMA "
              f"({ratio.min:.3f}-{ratio.max:.3f}, {ratio.rounds} rounds)")
    record.write(args.results)
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        steps_in_child(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
        sys.exit(0)
    sys.exit(main())
