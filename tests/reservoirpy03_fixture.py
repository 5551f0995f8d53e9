"""Writes tests/data/reservoirpy_0_3_states.npz: what reservoirpy 0.3.9.post1, the version ER-MRL ran on,
computes for one small reservoir, so that tests/test_reservoirs.py can hold reservoirs.esn to it.

It must run with reservoirpy 0.3.9.post1 importable, which the project does not install; from the
repository root:

    pip install --no-deps --target /tmp/rpy039 reservoirpy==0.3.9.post1 dill
    PYTHONPATH=/tmp/rpy039 python tests/reservoirpy03_fixture.py

The reservoir is built as ER-MRL's ReservoirWrapper built it, ``Reservoir(units, lr, sr, input_scaling,
seed)``, and fed as ER-MRL fed it, one (1, features) row per call, with a reset in the middle.
"""

from pathlib import Path

import numpy as np

FIXTURE = Path(__file__).resolve().parent / "data" / "reservoirpy_0_3_states.npz"
UNITS, INPUT_DIM, LEAK_RATE, SPECTRAL_RADIUS, INPUT_SCALING, SEED = 30, 5, 0.4, 1.3, 0.7, 3
STEPS, RESET_AFTER = 25, 12


def inputs() -> np.ndarray:
    return np.random.default_rng(0).normal(size=(STEPS, INPUT_DIM))


def main() -> None:
    import reservoirpy
    from reservoirpy.nodes import Reservoir

    assert reservoirpy.__version__ == "0.3.9.post1", reservoirpy.__version__
    reservoir = Reservoir(units=UNITS, lr=LEAK_RATE, sr=SPECTRAL_RADIUS, input_scaling=INPUT_SCALING, seed=SEED)
    states = []
    for step, row in enumerate(inputs()):
        states.append(reservoir(row.reshape(1, -1)).ravel().copy())
        if step == RESET_AFTER:
            reservoir.reset()
    np.savez_compressed(FIXTURE, states=np.array(states), W=reservoir.W.toarray(), Win=reservoir.Win.toarray(),
             bias=np.asarray(reservoir.bias.todense()).ravel())
    print(f"wrote {FIXTURE}")


if __name__ == "__main__":
    main()
