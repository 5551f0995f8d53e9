"""Extreme strategy values, through the real script as a process: a step or a sigma that leaves float32's
range ends the run with one line on stderr and exit code 2, and nothing before it (no traceback, no numpy
RuntimeWarning); ClipUp with a huge step size steps at its maximum speed.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent
CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "8", "--generations", "3", "--threads", "1", "--seed", "5")


def train(folder: Path, *argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-W", "default", str(ROOT / "train_static.py"), *CARTPOLE, *argv,
                           "--folder", str(folder)], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "SDL_VIDEODRIVER": "dummy", "PYTHONUNBUFFERED": "1"})


# flags -> the start of the one line, after "train_static.py: error: "
STOPPED = {
    "snes sigma's learning rate": (("--strategy", "snes", "--snes_sigma_lr", "1000"),
                                   "CartPole-v1 failed in generation 2 with non-finite parameters for member 0"),
    "pgpe sigma's learning rate": (("--strategy", "pgpe", "--pgpe_sigma_lr", "1e300", "--pgpe_max_sigma_change",
                                    "none"), "CartPole-v1 failed in generation 2 with non-finite parameters"),
    "clipup's maximum speed": (("--strategy", "pgpe", "--clipup_max_speed", "1e300"),
                               "generation 1: the update is not finite (lr 5e+299"),
    "snes's learning rate": (("--strategy", "snes", "--snes_lr", "1e300"),
                             "generation 1: the update is not finite (lr 1e+300"),
    "sep-cma-es's sigma": (("--strategy", "sep_cma_es", "--sigma", "3e38"),
                           "CartPole-v1 failed in generation 1 with non-finite parameters for member 0"),
}


@pytest.mark.parametrize("case", list(STOPPED))
def test_a_value_beyond_float32_ends_in_one_line(case, tmp_path):
    flags, start = STOPPED[case]
    if "sep_cma_es" in flags:
        need("strategies")
    done = train(tmp_path, *flags)
    assert done.returncode == 2, done.stderr[-3000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"train_static.py: error: {start}"), done.stderr[-3000:]


def test_clipup_with_a_huge_step_size_steps_at_its_maximum_speed(tmp_path):
    """--pgpe_lr 1e300: the velocity's norm (1e300) is clipped to the maximum speed, not lost to an overflow of
    its sum of squares (which would make the step 0)."""
    done = train(tmp_path, "--strategy", "pgpe", "--pgpe_lr", "1e300", "--generations", "1")
    assert done.returncode == 0 and done.stderr == "", done.stderr[-3000:]
    (run,) = [path for path in tmp_path.iterdir() if path.is_dir()]
    with np.load(run / "checkpoint.npz") as saved:
        velocity = saved["optimizer.velocity"]
    max_speed = 0.1 * np.sqrt(velocity.size) / 15  # ClipUp's rule of thumb, sigma 0.1
    assert np.sqrt(np.sum(velocity * velocity)) == pytest.approx(max_speed, rel=1e-12)
