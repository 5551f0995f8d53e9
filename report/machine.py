"""The machine a process runs on, as a run's config.json and a benchmark's record name it."""

from __future__ import annotations

import os
import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name ("AMD EPYC 7B13"), from /proc/cpuinfo where there is one."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return " ".join(line.split(":", 1)[1].split())
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine(workers: int) -> dict:
    """The CPU model, its cores and the workers a run uses on it."""
    return {"cpu": cpu_model(), "cores": os.cpu_count(), "workers": workers}


def machines_text(recorded: list[dict]) -> str:
    """The machines a run's config.json lists, in order, a machine that goes on from the entry before left out:
    "AMD EPYC 7B13, 2 workers" for a run made on one machine; "…, 2 workers from generation 204" where the
    record begins later (a run started before machines were recorded); "" for none."""
    parts, previous = [], None
    for entry in recorded:
        if (entry["cpu"], entry["workers"]) != previous:
            start = entry["from_generation"]
            workers = f"{entry['workers']} worker" + ("s" if entry["workers"] != 1 else "")
            parts.append(f"{entry['cpu']}, {workers}" + (f" from generation {start}" if start else ""))
        previous = (entry["cpu"], entry["workers"])
    return "; ".join(parts)
