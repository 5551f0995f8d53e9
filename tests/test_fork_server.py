"""The process pool's fork server loads what a pixel policy's episodes import (torch) once, before it
forks the workers, so that they share those pages instead of each loading its own copy.

Each case runs in a fresh interpreter: a process starts one fork server, with the modules of the
first pool it makes, so a pytest process that made a pool already could not show it.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from envs import ProblemSpec
from policies import PolicySettings

ROOT = Path(__file__).resolve().parent.parent

POOL = textwrap.dedent("""
    import os, sys
    from pathlib import Path
    from envs import ProblemSpec
    from es.backends import make_evaluator
    from es.noise import NoiseTable
    from es.settings import RunSettings
    from policies import PolicySettings

    spec = ProblemSpec((sys.argv[1],), PolicySettings(kind=sys.argv[2]))
    problem = spec.build()
    dim = problem.policy.num_params
    noise = NoiseTable.create(1, dim + 10, shared=True)
    evaluator = make_evaluator(RunSettings(threads=2, backend="process"), spec.build, noise, dim, spec.env_ids, problem)

    def children(pid):
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    if int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                        yield int(entry.name)
                except (OSError, IndexError, ValueError):
                    pass

    def maps_torch(pid):
        return "libtorch_cpu" in Path(f"/proc/{pid}/maps").read_text()

    server = [pid for pid in children(os.getpid()) if b"forkserver" in Path(f"/proc/{pid}/cmdline").read_bytes()]
    workers = [pid for pid in children(server[0])]
    print(len(server), len(workers), maps_torch(server[0]), all(maps_torch(pid) for pid in workers))
    evaluator.close()
    noise.close()
""")


def pool_processes(env_id: str, kind: str) -> str:
    result = subprocess.run([sys.executable, "-c", POOL, env_id, kind], cwd=ROOT, capture_output=True, text=True,
                            timeout=300, env={"PYTHONPATH": str(ROOT), "SDL_VIDEODRIVER": "dummy",
                                              "PATH": "/usr/bin:/bin"})
    assert result.returncode == 0, result.stderr
    return result.stdout.strip()


@pytest.mark.parametrize("kind", ["static", "hebbian"])
def test_pixel_policies_name_torch_and_state_policies_nothing(kind):
    assert ProblemSpec(("CarRacing-v3",), PolicySettings(kind=kind)).build().policy.worker_modules == ("torch",)
    assert ProblemSpec(("CartPole-v1",), PolicySettings(kind=kind)).build().policy.worker_modules == ()
    normalised = ProblemSpec(("CartPole-v1",), PolicySettings(kind=kind, obs_norm=True)).build().policy
    assert normalised.worker_modules == ()  # (a front end's are its inner policy's)


def test_the_fork_server_loads_torch_before_the_workers_of_a_pixel_policy():
    # one fork server, two workers forked from it; torch's libraries in all three
    assert pool_processes("CarRacing-v3", "hebbian") == "1 2 True True"


def test_the_fork_server_loads_no_torch_for_a_state_policy():
    assert pool_processes("CartPole-v1", "static") == "1 2 False False"
