"""Without an optional extra, the option that needs it ends in one line naming the install, exit code 2,
and nothing written. These run on every install: where the extra is present, the test hides it.

(The other extras' cases live beside their features: Ray in ``test_ray.py``, ale-py in
``test_atari.py``, TensorBoard in ``test_modern_es.py``, the ER-MRL scripts in
``test_reservoir_scripts.py``.)
"""

from __future__ import annotations

import sys

import train_hebb
from tests.test_modern_es import main as run

RESERVOIR = ("--environment", "CartPole-v1", "--popsize", "8", "--seed", "5", "--reservoir", "--reservoir_units", "30")


def test_without_reservoirpy_reservoir_says_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "reservoirpy", None)  # import reservoirpy now raises ImportError
    code, output = run(train_hebb.main, *RESERVOIR, "--generations", "1", "--folder", tmp_path / "runs")
    assert code == 2 and len(output.strip().splitlines()) == 1, output
    assert "reservoirpy, which is not installed here; pip install -r requirements-reservoirs.txt" in output
    assert not (tmp_path / "runs").exists()
