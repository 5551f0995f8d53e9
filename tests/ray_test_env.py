"""A problem whose worker fails on purpose, for the Ray backend's fault tests (tests/test_ray.py).

``CrashingSpec(seed, how, marker, driver_pid).build`` stands in for ``ProblemSpec.build``: CartPole-v1,
except that an episode with episode seed ``seed`` ends its worker process with ``os._exit(3)``
(``how="exit"``) or raises (``how="raise"``). With ``marker`` set, only the first such episode fails
(it creates the file, later ones find it), so the retry succeeds; without it, every one fails.
Nothing ever exits in ``driver_pid``, the test process itself.

(tests/failing_env.py exits only where ``multiprocessing.parent_process()`` is set, which is not
the case in a Ray actor; hence this module.)
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from envs import ProblemSpec

ENV_ID = "CartPole-v1"


@dataclass(frozen=True)
class CrashingSpec:
    seed: int
    how: str = "exit"  # "exit" or "raise"
    marker: str | None = None
    driver_pid: int = -1

    def build(self) -> CrashingProblem:
        return CrashingProblem(self)


class CrashingProblem:
    """CartPole-v1 through the ``Problem`` interface, with one failing episode seed."""

    def __init__(self, spec: CrashingSpec):
        self.spec = spec
        self.inner = ProblemSpec((ENV_ID,)).build()
        self.policy = self.inner.policy

    def evaluate(self, params, env_index: int, seed: int, max_steps: int | None = None):
        if seed == self.spec.seed and self._should_fail():
            if self.spec.how == "exit" and os.getpid() != self.spec.driver_pid:
                os._exit(3)
            raise RuntimeError(f"failure on purpose at episode seed {seed}")
        return self.inner.evaluate(params, env_index, seed, max_steps)

    def _should_fail(self) -> bool:
        if self.spec.marker is None:
            return True
        try:  # O_EXCL: only the first episode to get here fails
            os.close(os.open(self.spec.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return False
        return True

    def rebuild(self, env_index: int) -> None:
        self.inner.rebuild(env_index)

    def close(self) -> None:
        self.inner.close()
