"""No number moves: fixed-seed runs give the parameters pinned here, with every backend and on resume.

The hashes were computed on the code as it stood before the layout refactor (issue 10), at commit
2170917, and are kept as they are: a change that moves one of them changes what a user's fixed-seed
run produces, and is a bug unless an issue says otherwise. A hash covers the final parameters a run
leaves, every ``last*.dat`` and ``best*.dat`` file (loaded as float32 arrays, in file-name order), so
it pins the static weights, the Hebbian coefficients, the CNN and the co-evolved initial weights
alike, and the choice of ``best``.

Each case runs in this process through the scripts' ``main(argv)`` with ``--threads 1``; a few run
again with two worker processes, with Ray, and split by a resume, and must give the same hash.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
from pathlib import Path

import pytest

import train_hebb
import train_static
from es.files import load_dat
from tests.extras import need

CARTPOLE = ("--environment", "CartPole-v1", "--popsize", "8", "--generations", "2")
RULES = ("A", "AD", "AD_lr", "ABC", "ABC_lr", "ABCD", "ABCD_lr", "ABCD_lr_D_out", "ABCD_lr_D_in_and_out")

# case -> (script, argv)
CASES: dict[str, tuple[str, tuple[str, ...]]] = {
    "static CartPole": ("static", (*CARTPOLE, "--seed", "11")),
    "static CartPole, 2 episodes": ("static", (*CARTPOLE, "--seed", "12", "--episodes", "2", "--lr", "0.05",
                                               "--sigma", "0.3", "--decay", "0.9")),
    **{f"hebbian {rule}": ("hebbian", (*CARTPOLE, "--seed", "21", "--hebb_rule", rule)) for rule in RULES},
    "hebbian uniform, normal init": ("hebbian", (*CARTPOLE, "--seed", "22", "--distribution", "uniform",
                                                 "--init_weights", "normal")),
    "hebbian co-evolved": ("hebbian", (*CARTPOLE, "--seed", "23", "--init_weights", "coevolve")),
    "hebbian discrete observations": ("hebbian", ("--environment", "FrozenLake-v1", "--popsize", "6",
                                                  "--generations", "2", "--seed", "24")),
    "static pixels": ("static", ("--environment", "CarRacing-v3", "--popsize", "2", "--generations", "1",
                                 "--seed", "31")),
    "hebbian pixels": ("hebbian", ("--environment", "CarRacing-v3", "--popsize", "2", "--generations", "1",
                                   "--seed", "32")),
    "hebbian pixels co-evolved": ("hebbian", ("--environment", "CarRacing-v3", "--popsize", "2",
                                              "--generations", "1", "--seed", "33", "--init_weights", "coevolve")),
    "static several bodies": ("static", ("--environment", "AntBulletEnv-v0,AntAsymRightBulletEnv-v0",
                                         "--popsize", "2", "--generations", "1", "--seed", "41")),
    "hebbian several bodies": ("hebbian", ("--environment", "AntBulletEnv-v0,AntAsymRightBulletEnv-v0",
                                           "--popsize", "2", "--generations", "1", "--seed", "42")),
    "static MuJoCo": ("static", ("--environment", "HalfCheetah-v5", "--popsize", "4", "--generations", "2",
                                 "--seed", "51")),
    "hebbian MuJoCo, two bodies": ("hebbian", ("--environment", "Ant-v5,AntAsymRight-v5", "--popsize", "4",
                                               "--generations", "1", "--seed", "52", "--hebb_rule", "ABC")),
}

# case -> sha256 of its final parameter files, computed at commit 2170917
PINNED = {
    "static CartPole": "48317aaca0d19a125a37deb36b590e584258a5cab9350fe4e5c709396c7bdb87",
    "static CartPole, 2 episodes": "5628c1346b46e9c6a88c5b307015c8274e935841681940b446510a33653a571d",
    "hebbian A": "d3af4b03520b2ed9ce69917a1cae203c1b7140b8140e6b9504039cfbee7f6dc0",
    "hebbian AD": "5faf5bc61b5b5b54fe06e9f569c14d43fdbbb0b74c04f48d8b4ff8251a18cdda",
    "hebbian AD_lr": "79a3ef2eeed64ad2dd654196089d030155f8771d77fd4d3a50d48308cf8fbc8f",
    "hebbian ABC": "e174e8d06d55b6d967e531a1623d7f1bfdf87a6c23927ea2f4b6c3b2b271bc01",
    "hebbian ABC_lr": "6e288f886d5e69a58409375bd331b7c9308138931ec51fb41b7125e37f14fd01",
    "hebbian ABCD": "74ddc7f6175261272b8f9e678d37503a744dfc0afe4c3802a96b0a3dba912432",
    "hebbian ABCD_lr": "2a3879c148712a0b31e6a3446c60ded2db93ad69a8b676ba1a67cbe8305afd7e",
    "hebbian ABCD_lr_D_out": "62272e1c0537986d23e5767cc747288e347e66a9188792e179b0090a8c55c116",
    "hebbian ABCD_lr_D_in_and_out": "68877c1098c13b60d6bcea0583686c00ee5967abb6ca407d7f34326fae616803",
    "hebbian uniform, normal init": "40aca9ac38a03e382054ac986d2483a7f2b8d1d638f1bb9f66f077336d4a4479",
    "hebbian co-evolved": "17ff235a358c447c7cacfeaeb73b30d7b02d8509d0a529ab02eab9eb8d81edef",
    "hebbian discrete observations": "74068784c63e554a7fea2ff00e31e0ddeef226ec0026dfec0fbeb664b9eb8019",
    "static pixels": "8a0fa07386e0a657ba07ba524fcd3b31ab1a631514bd821b936cc124cbf3cd96",
    "hebbian pixels": "ca429860ee5e23f4abd44adc0ef192b4b13f6cf6347531cf01c01247f2ebd52e",
    "hebbian pixels co-evolved": "f1cd8aca6ef30384ff3db53fcf71ec78f85eec6fb4406bf61dbb56b7412a1223",
    "static several bodies": "e21128b09970d0f109031581dcec55ac9e4400f5fbc9a240e692bbf5dde5faa1",
    "hebbian several bodies": "6b54aea2477d2f95c27575692afbc576c15a796d48004a3b48f0fb220fa06de6",
    "static MuJoCo": "3be51edccbe68036c7852d19c9e0344a3b9bb5360e75d2b0c30151f17dd21230",
    "hebbian MuJoCo, two bodies": "427a146c031d895b1a5c25e696fdcbe2a5ffb60d43506dbfa2216fcf2c3b405f",
}

MAINS = {"static": train_static.main, "hebbian": train_hebb.main}


def parameters_hash(run_dir: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted([*run_dir.glob("last*.dat"), *run_dir.glob("best*.dat")]):
        digest.update(path.name.encode())
        digest.update(load_dat(path).tobytes())
    return digest.hexdigest()


def train(kind: str, folder: Path, *argv: str) -> Path:
    """Run a training in this process; its run folder."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = MAINS[kind]([*argv, "--folder", str(folder)] if "--resume" not in argv else list(argv))
    assert code == 0, out.getvalue()[-3000:]
    (run_dir,) = [path for path in folder.iterdir() if path.is_dir()]
    return run_dir


@pytest.mark.parametrize("case", list(CASES))
def test_serial_runs_give_the_pinned_parameters(case, tmp_path):
    (kind, argv), expected = CASES[case], PINNED[case]
    assert parameters_hash(train(kind, tmp_path, *argv, "--threads", "1")) == expected


@pytest.mark.parametrize("case", ["static CartPole", "hebbian ABCD_lr", "hebbian co-evolved", "static pixels",
                                  "hebbian several bodies"])
def test_two_worker_processes_give_the_pinned_parameters(case, tmp_path):
    (kind, argv), expected = CASES[case], PINNED[case]
    assert parameters_hash(train(kind, tmp_path, *argv, "--threads", "2")) == expected


@pytest.mark.parametrize("case", ["static CartPole", "hebbian ABCD_lr", "hebbian co-evolved"])
def test_resumed_runs_give_the_pinned_parameters(case, tmp_path):
    (kind, argv), expected = CASES[case], PINNED[case]
    first = list(argv)
    first[first.index("--generations") + 1] = "1"
    run_dir = train(kind, tmp_path, *first, "--threads", "1")
    train(kind, tmp_path, "--resume", str(run_dir), "--generations", "2", "--threads", "2")
    assert parameters_hash(run_dir) == expected


@pytest.mark.parametrize("case", ["static CartPole", "hebbian several bodies"])
def test_ray_gives_the_pinned_parameters(case, tmp_path):
    need("ray")
    (kind, argv), expected = CASES[case], PINNED[case]
    assert parameters_hash(train(kind, tmp_path, *argv, "--threads", "2", "--backend", "ray")) == expected
