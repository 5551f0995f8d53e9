"""Test defaults: headless rendering, and the repository root importable."""

import os
import sys
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def pytest_addoption(parser):
    parser.addoption("--every-run", action="store_true",
                     help="tests/test_paper_runs.py: train again the first generations of every committed campaign "
                          "run, not only one run of each experiment, kind and variant (CI's step 4 does)")
