"""What the campaign's remaining runs will cost, projected from what its completed runs cost.

A run not yet complete is projected from the completed runs of its group: the same experiment, kind and
settings, another seed (``carracing hebbian``: seeds 1, 2 and 3). Each of them gives the training time of the
generations the run has still to do, the ``seconds`` of their rows in its ``metrics.csv`` summed; the projection
is their mean, with the fastest and the slowest of them as its range, on the machines their ``config.json``
records. Generations grow longer as a run learns to stay in its episodes, and some seeds learn sooner: so a
run's own last generations say too little early on (``Progress.hours_left``), and the runs of its group say
how far apart seeds fall.

On more workers than the campaign's runs had, a figure is given only where a benchmark's record projects that
kind's runs on them (``SCALING``): the group's figure times the ratio of the record's projections. Where no
record does, the projection says so instead of a number.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path

from benchmarks import record as records
from experiments.progress import Progress

MORE_WORKERS = 16  # the larger machine the docs give the campaign's remaining time for


@dataclass(frozen=True)
class Scaling:
    """A benchmark's record that projects a kind's runs on several numbers of workers: the newest record of
    ``record`` (``benchmarks/results/<record>-<time>.json``), its projection on each number of workers, and how
    it projects."""

    record: str
    measures: dict[int, str]  # workers -> the record's measure of the run's hours on them
    how: str


# the kinds a record projects on MORE_WORKERS: (experiment, kind) -> its Scaling
SCALING = {
    ("carracing", "hebbian"): Scaling(
        "car_racing", {2: "projection_fast_2_workers", 16: "projection_fast_16_workers"},
        "it divides the CPU time per environment step it measured by the workers, so it takes the workers to "
        "scale linearly, which no record measures beyond 2"),
}


@dataclass(frozen=True)
class Planned:
    """One run of the campaign as the projection sees it."""

    name: str  # "carracing hebbian seed 4"
    experiment: str
    kind: str
    group: str  # the experiment, the kind and the settings the run asks for but its seed: "carracing hebbian"
    seed: int
    total: int  # the generations it asks for
    progress: Progress | None  # its newest run's, None where it has not started

    @property
    def done(self) -> int:
        return 0 if self.progress is None else self.progress.done

    @property
    def complete(self) -> bool:
        return self.done >= self.total


@dataclass(frozen=True)
class Estimate:
    """Hours of training: the mean of the completed runs a projection is taken from, the fastest and the
    slowest of them."""

    hours: float
    fastest: float
    slowest: float

    def times(self, factor: float) -> Estimate:
        return Estimate(self.hours * factor, self.fastest * factor, self.slowest * factor)

    def text(self) -> str:
        """"about 4.2 h (1.4–7.7 h)"; "about 2.7 h" where its runs took the same; "about 32 min (10 min–1.0 h)"."""
        low, high = duration(self.fastest), duration(self.slowest)
        if low == high:
            return f"about {duration(self.hours)}"
        if low.split()[1] == high.split()[1]:  # one unit: "1.4–7.7 h"
            low = low.split()[0]
        return f"about {duration(self.hours)} ({low}–{high})"


def duration(hours: float) -> str:
    """"4.2 h"; below an hour "32 min"; below a minute "4.5 s" (a small run's)."""
    if hours >= 1:
        return f"{hours:.1f} h"
    return f"{hours * 60:.0f} min" if hours * 60 >= 1 else f"{hours * 3600:.1f} s"


def total(estimates: list[Estimate]) -> Estimate:
    return Estimate(*(sum(values) for values in zip(*((e.hours, e.fastest, e.slowest) for e in estimates))))


@dataclass(frozen=True)
class Projection:
    """A remaining run's training time on its group's workers (None: no completed run of its group), and on
    MORE_WORKERS (None, with the reason in ``basis``, where no record projects its kind there)."""

    planned: Planned
    sources: tuple[Planned, ...]  # the completed runs of its group it is taken from
    estimate: Estimate | None
    factor: float | None  # MORE_WORKERS' time over the sources' workers', as the record projects them
    basis: str  # the record ``factor`` comes from (its path), or why there is none

    @property
    def more(self) -> Estimate | None:
        return None if self.estimate is None or self.factor is None else self.estimate.times(self.factor)

    @property
    def workers(self) -> list[int]:
        """The numbers of workers the runs it is taken from ran on."""
        return sorted({workers for source in self.sources for _, workers in source.progress.on})

    def sources_text(self) -> str:
        """"carracing hebbian seeds 1, 2, 3"."""
        seeds = ", ".join(str(source.seed) for source in self.sources)
        return f"{self.planned.group} seed{'s' if len(self.sources) > 1 else ''} {seeds}"

    def machines(self) -> str:
        """The CPUs and workers the runs it is taken from ran on: "AMD EPYC, 2 workers"."""
        pairs = sorted({pair for source in self.sources for pair in source.progress.on})
        return "; ".join(f"{cpu}, {workers} worker{'s' if workers != 1 else ''}" for cpu, workers in pairs) \
            or "machines not recorded"

    def line(self) -> str:
        """The projection in a line of the status: "projected from carracing hebbian seeds 1, 2, 3 (AMD EPYC, 2
        workers): about 4.2 h (1.4–7.7 h) of training left; on 16 workers about 32 min (10–58 min)"."""
        if self.estimate is None:
            return f"no completed run of {self.planned.group} to project from"
        more = (f"on {MORE_WORKERS} workers {self.more.text()}" if self.more is not None
                else f"on {MORE_WORKERS} workers no figure: {self.basis}")
        return (f"projected from {self.sources_text()} ({self.machines()}): {self.estimate.text()} of training left; "
                f"{more}")


def hours_left(planned: Planned, source: Planned) -> float:
    """The training time of the generations ``planned`` has still to do, as the completed run ``source`` took
    them (metrics.csv's ``seconds``)."""
    return sum(source.progress.seconds[planned.done:planned.total]) / 3600


def on_more_workers(planned: Planned, workers: list[int], results: Path) -> tuple[float | None, str]:
    """The ratio of MORE_WORKERS' time to that on ``workers`` (those of the runs ``planned`` is projected from), as
    the record that projects ``planned``'s kind projects them, and that record's path; None and the reason where
    there is none."""
    scaling = SCALING.get((planned.experiment, planned.kind))
    if scaling is None:
        return None, f"no benchmark record measures or projects such runs on {MORE_WORKERS} workers"
    if len(workers) != 1 or workers[0] not in scaling.measures or MORE_WORKERS not in scaling.measures:
        return None, (f"the runs it is taken from ran on {', '.join(map(str, workers)) or 'unrecorded'} workers, "
                      f"and the {scaling.record} record projects from {', '.join(map(str, scaling.measures))}")
    try:
        path, record = records.newest(scaling.record, results)
        base, more = (record["measures"][scaling.measures[count]] for count in (workers[0], MORE_WORKERS))
        if min(base["rounds"], more["rounds"]) < records.MIN_ROUNDS:
            raise ValueError(f"its projections have fewer than {records.MIN_ROUNDS} rounds")
        factor = more["median"] / base["median"]
    except (ValueError, KeyError, TypeError, ZeroDivisionError) as error:  # none, only loaded ones, not its measures
        return None, f"{scaling.record}: {error}"
    return factor, str(path.relative_to(records.ROOT) if path.is_relative_to(records.ROOT) else path)


def project(plan: list[Planned], results: Path = records.RESULTS) -> list[Projection]:
    """The projection of each run of ``plan`` not yet complete, in its order."""
    projections = []
    for planned in plan:
        if planned.complete:
            continue
        sources = tuple(other for other in plan if other.group == planned.group and other.complete
                        and other.progress is not None and len(other.progress.seconds) >= planned.total)
        if not sources:
            projections.append(Projection(planned, (), None, None, ""))
            continue
        left = [hours_left(planned, source) for source in sources]
        projection = Projection(planned, sources, Estimate(sum(left) / len(left), min(left), max(left)), None, "")
        factor, basis = on_more_workers(planned, projection.workers, results)
        projections.append(dataclasses.replace(projection, factor=factor, basis=basis))
    return projections


def summary(projections: list[Projection], page: Path | None = None) -> str:
    """The campaign's remaining runs in a paragraph: their training time in all, on the workers of the runs they
    are projected from and on MORE_WORKERS. With a ``page``, the records are linked from it (Markdown);
    without, named by their paths."""
    if not projections:
        return "No run of the campaign remains to be trained."
    projected = [projection for projection in projections if projection.estimate is not None]
    missing = [projection.planned.name for projection in projections if projection.estimate is None]
    first = f"{len(projections)} run{'s' if len(projections) > 1 else ''} to train"
    if projected:
        machines = "; ".join(sorted({projection.machines() for projection in projected}))
        some = f" for the {len(projected)} projected" if missing else ""
        first += (f": {total([projection.estimate for projection in projected]).text()} of training{some}, each run "
                  f"projected from the completed runs of its experiment and kind, on their machines ({machines}), the "
                  "range adding up the fastest of them, and the slowest")
    if missing:
        first += f"{'; ' if projected else ': '}not projected, no completed run of their kind yet: {', '.join(missing)}"
    lines = [first + "."]
    scaled = [projection for projection in projected if projection.more is not None]
    for basis in sorted({projection.basis for projection in scaled}):
        runs = [projection for projection in scaled if projection.basis == basis]
        shown = f"[{Path(basis).name}]({Path(os.path.relpath(records.ROOT / basis, page.parent)).as_posix()})" \
            if page is not None else basis
        how = SCALING[(runs[0].planned.experiment, runs[0].planned.kind)].how
        scaled_total = total([projection.more for projection in runs]).text()
        lines.append(f"On {MORE_WORKERS} workers, {groups(runs)}: {scaled_total}, their projection times "
                     f"{runs[0].factor:.3g}, the ratio of the projections on {MORE_WORKERS} workers and on "
                     f"{runs[0].workers[0]} in the benchmark's record {shown} ({how}).")
    unscaled = [projection for projection in projected if projection.more is None]
    for basis in sorted({projection.basis for projection in unscaled}):
        runs = [projection for projection in unscaled if projection.basis == basis]
        lines.append(f"On {MORE_WORKERS} workers no figure for {groups(runs)}: {basis}.")
    return " ".join(lines)


def groups(projections: list[Projection]) -> str:
    """"carracing hebbian (2 runs), ant static (1 run)": the groups of ``projections``, in their order."""
    counts: dict[str, int] = {}
    for projection in projections:
        counts[projection.planned.group] = counts.get(projection.planned.group, 0) + 1
    return ", ".join(f"{group} ({count} run{'s' if count > 1 else ''})" for group, count in counts.items())
