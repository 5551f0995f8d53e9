"""Every policy kind x network x front end the registries hold, trained, evaluated and resumed.

The combinations come from the registries themselves (``policies.registry.KINDS`` and ``NETWORKS``, the
front ends ``--reservoir`` and ``--obs_norm``), on one vector and one pixel environment; the registry
decides which apply: a combination it refuses with a ValueError (a Hebbian ``--network small``,
``--network lstm`` on vectors, a reservoir on pixels), or a front end that leaves the policy as it is
(``--obs_norm`` on pixels), is no case. So a new kind or network is covered without a new test, and
``test_every_registry_entry_is_covered`` fails if one of them never applies. A combination that needs
a missing optional extra is skipped, naming it.

Each case runs the kind's own scripts' entry points (``cli.hints.TRAIN_SCRIPTS`` /
``EVALUATE_SCRIPTS``) in this process, as a user would: one generation (popsize 2, short episodes,
``--threads 1``); then the evaluation command the run prints at its end, word for word but for fewer
episodes; then ``--resume`` for a second generation, which must keep the first generation's row and
files as they were.
"""

from __future__ import annotations

import importlib
import shlex
from pathlib import Path

import pytest

from cli.hints import EVALUATE_SCRIPTS, TRAIN_SCRIPTS
from envs import ProblemSpec
from es.files import load_dat, read_metrics
from policies import KINDS, NETWORKS, PolicySettings
from reservoir_extra import INSTALL_HINT

ENVIRONMENTS = ("CartPole-v1", "CarRacing-v3")  # observation vectors, images
FRONT_ENDS = {"none": {}, "reservoir": {"reservoir": True, "reservoir_units": 8}, "obs_norm": {"obs_norm": True}}
EPISODE_STEPS = 30


def front_end_flags(front_end: str) -> list[str]:
    return [word for name, value in FRONT_ENDS[front_end].items()
            for word in ([f"--{name}"] if value is True else [f"--{name}", str(value)])]


def policy_type(env_id: str, kind: str, network: str, front_end: str) -> type:
    """The class of the policy the registry builds for this combination (a ValueError if it refuses it)."""
    settings = PolicySettings(kind, network=network, **FRONT_ENDS[front_end]).seeded(0)
    problem = ProblemSpec((env_id,), settings).build()
    try:
        return type(problem.policy)
    finally:
        problem.close()


def combinations() -> list:
    cases = []
    for env_id in ENVIRONMENTS:
        for kind in KINDS:
            for network in NETWORKS:
                try:
                    bare = policy_type(env_id, kind, network, "none")
                except ValueError:  # the registry refuses this network for this kind or environment
                    continue
                for front_end in FRONT_ENDS:
                    case = (env_id, kind, network, front_end)
                    try:
                        if front_end == "none" or policy_type(*case) is not bare:
                            cases.append(pytest.param(*case, id="-".join(case)))
                    except ValueError as error:
                        if INSTALL_HINT in str(error):  # applies, but needs the reservoirs' extra
                            cases.append(pytest.param(*case, id="-".join(case), marks=pytest.mark.skip(
                                reason=f"needs the reservoirs' optional extra: {INSTALL_HINT}")))
    return cases


CASES = combinations()


def test_every_registry_entry_is_covered():
    covered = [case.values for case in CASES]
    assert {case[1] for case in covered} == set(KINDS)
    assert {case[2] for case in covered} == set(NETWORKS)
    assert {case[3] for case in covered} == set(FRONT_ENDS)


def script_main(script: str):
    """The ``main`` of one of the project's scripts (``train_static.py`` -> ``train_static.main``)."""
    return importlib.import_module(Path(script).stem).main


def only_run(folder: Path) -> Path:
    (run_dir,) = [path for path in folder.iterdir() if path.is_dir()]
    return run_dir


def printed_command(output: str, prefix: str) -> list[str]:
    """The words after ``prefix`` of the one line that holds it."""
    (line,) = [line for line in output.splitlines() if prefix in line]
    return shlex.split(line.split(prefix, 1)[1])


@pytest.mark.parametrize("env_id, kind, network, front_end", CASES)
def test_train_evaluate_and_resume(env_id, kind, network, front_end, tmp_path, capsys):
    train = script_main(TRAIN_SCRIPTS[kind])
    folder = tmp_path / "runs"
    argv = ["--environment", env_id, "--generations", "1", "--popsize", "2", "--seed", "7", "--threads", "1",
            "--max_episode_steps", str(EPISODE_STEPS), "--folder", str(folder), *front_end_flags(front_end)]
    if network != "default":
        argv += ["--network", network]
    assert train(argv) == 0, capsys.readouterr().err
    run_dir = only_run(folder)
    first_rows = read_metrics(run_dir / "metrics.csv")
    assert [int(row["generation"]) for row in first_rows] == [1]
    first_files = {path.name: load_dat(path).tobytes() for path in run_dir.glob("*__0.dat")}
    assert first_files, "the first generation saved no parameter files"

    # the evaluation command the run printed, with 2 episodes instead of 10
    _, script, *words = printed_command(capsys.readouterr().out, "evaluate with: ")
    assert Path(script).name == EVALUATE_SCRIPTS[kind]
    words[words.index("--episodes") + 1] = "2"
    assert script_main(script)(words) == 0, capsys.readouterr().err
    evaluated = capsys.readouterr().out
    assert env_id in evaluated

    assert train(["--resume", str(run_dir), "--generations", "2"]) == 0, capsys.readouterr().err
    rows = read_metrics(run_dir / "metrics.csv")
    assert [int(row["generation"]) for row in rows] == [1, 2]
    assert rows[0] == first_rows[0]
    assert {name: load_dat(run_dir / name).tobytes() for name in first_files} == first_files
    assert len(list(run_dir.glob("*__1.dat"))) == len(first_files)  # the second generation's, named alike
