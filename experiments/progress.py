"""How far a run of the campaign got, from its own files: ``measure`` reads the generation its checkpoint holds,
the total its config.json asks for, whether it was evaluated, and what its generations cost (metrics.csv's
``seconds`` and ``env_steps``), for ``experiments/paper.py campaign --status``, the progress page, the curves and
the projection of the campaign's remaining runs (``experiments/cost.py``). The files are data: a config.json of
the wrong types is named in one ValueError.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from experiments.campaign import EVALUATION

PACE = 10  # the generations whose mean duration projects the rest of a run


@dataclass(frozen=True)
class Progress:
    """How far a run got, from its own files: the generation its checkpoint holds of the total its config.json
    asks for, whether it was evaluated, and what its generations cost (metrics.csv's ``seconds`` and
    ``env_steps``, up to that generation)."""

    done: int
    total: int
    evaluated: bool
    hours: float  # the training so far: the generations' seconds, summed
    paced: int  # the last generations, PACE at most, whose mean seconds and environment steps follow
    pace: float | None
    steps: float | None
    mean: float | None  # the last generation's population mean fitness and centre return
    centre: float | None
    machines: str  # config.json's record of the machines (report.machine.machines_text)
    step_limit: int | None = None  # the most environment steps a generation can take (generation_step_limit)
    seconds: tuple[float, ...] = ()  # each generation's, from the first to the one saved last (metrics.csv)
    on: tuple[tuple[str, int], ...] = ()  # the CPU and the workers of each machine config.json records

    @property
    def complete(self) -> bool:
        return self.done >= self.total

    @property
    def hours_left(self) -> float | None:
        """The remaining generations at the last ones' pace. Generations grow longer as a run learns to stay in
        its episodes, so early on this says too little."""
        return None if self.complete or self.pace is None else (self.total - self.done) * self.pace / 3600

    @property
    def hours_at_most(self) -> float | None:
        """The remaining generations if every episode ran to its time limit, at the last generations' cost per
        environment step: the bound to ``hours_left``, which early in a run says too little. None where an
        environment has no time limit."""
        if self.complete or self.pace is None or not self.steps or self.step_limit is None:
            return None
        return (self.total - self.done) * self.step_limit * (self.pace / self.steps) / 3600


def generation_step_limit(config: dict) -> int | None:
    """The most environment steps one generation of the run ``config`` (its config.json) can take: every
    member's and the centre's episodes, and its share of the centre's evaluation episodes (``eval_episodes``
    every ``eval_every``-th generation, rounded up), on every training environment, each to its time limit
    (``--max_episode_steps``, else the one its registration gives). None where an environment has none, is not
    registered here, or the config does not record its settings.

    config.json is data: a ``module:EnvId`` it names is looked up among what is registered, never imported."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the pyBullet environments, the damaged ants, the fast CarRacing)

    env, es = (config.get(name) if isinstance(config.get(name), dict) else {} for name in ("env", "es"))
    env_ids, cap = env.get("env_ids"), env.get("max_episode_steps")
    numbers = [es.get("popsize"), es.get("episodes", 1), es.get("eval_episodes", 0), es.get("eval_every") or 1,
               cap or 1]
    if (not isinstance(env_ids, list) or not env_ids or not all(isinstance(env_id, str) for env_id in env_ids)
            or not all(isinstance(number, int) and not isinstance(number, bool) and number > 0 for number in numbers)):
        return None  # not the settings a config.json records
    limits = []
    for env_id in env_ids:
        spec = gym.registry.get(env_id.rpartition(":")[2])
        known = [limit for limit in (cap, spec.max_episode_steps if spec is not None else None) if limit]
        if not known:
            return None
        limits.append(min(known))
    episodes = (es["popsize"] + 1) * es.get("episodes", 1)
    if es.get("eval_every"):
        episodes += -(-es.get("eval_episodes", 0) // es["eval_every"])
    return episodes * sum(limits)


MACHINE_KEYS = {"cpu": str, "workers": int, "from_generation": int}  # what report.machine.machines_text reads


def recorded(path: Path) -> dict:
    """A run's config.json, with what ``measure`` reads of it checked: the generations it asks for, the machines
    it ran on; a ValueError names what is wrong (a hand-edited file)."""
    from es import files

    config = files.read_json(path)
    if not isinstance(config, dict):
        raise ValueError(f"{path} is not a JSON object")
    generations = config.get("run", {}).get("generations") if isinstance(config.get("run"), dict) else None
    if not isinstance(generations, int) or isinstance(generations, bool) or generations < 1:
        raise ValueError(f"{path}: run.generations must be a whole number >= 1, got {generations!r}")
    machines = config.get("machines", [])
    if not isinstance(machines, list) or not all(
            isinstance(entry, dict) and all(isinstance(entry.get(key), kind) for key, kind in MACHINE_KEYS.items())
            for entry in machines):
        raise ValueError(f"{path}: machines must be a list of objects with {', '.join(MACHINE_KEYS)}, got "
                         f"{str(machines)[:60]}")
    return config


def measure(run_dir: Path) -> Progress:
    """The ``Progress`` of the run in ``run_dir``."""
    from es import files
    from es.runfolder import read_checkpoint
    from report.machine import machines_text

    config = recorded(run_dir / "config.json")
    done = read_checkpoint(run_dir / "checkpoint.npz").generation
    rows = files.read_metrics(run_dir / "metrics.csv") if (run_dir / "metrics.csv").exists() else []
    rows = [row for row in rows if int(row["generation"]) <= done]  # a generation recorded but not saved: not done
    last = rows[-PACE:]
    return Progress(
        done=done, total=config["run"]["generations"], evaluated=(run_dir / EVALUATION).exists(),
        hours=sum(float(row["seconds"]) for row in rows) / 3600, paced=len(last),
        pace=sum(float(row["seconds"]) for row in last) / len(last) if last else None,
        steps=sum(int(row["env_steps"]) for row in last) / len(last) if last else None,
        mean=float(rows[-1]["fitness_mean"]) if rows else None,
        centre=float(rows[-1]["center_return"]) if rows else None,
        machines=machines_text(config.get("machines", [])), step_limit=generation_step_limit(config),
        seconds=tuple(float(row["seconds"]) for row in rows),
        on=tuple((entry["cpu"], entry["workers"]) for entry in config.get("machines", [])))
