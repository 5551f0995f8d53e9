#!/usr/bin/env python
"""Where a trained agent's CarRacing step goes: one worker task of the paper's Hebbian run, split into its parts.

    python benchmarks/car_racing_profile.py --callgrind    # instructions, counted by valgrind (no load moves them)
    python benchmarks/car_racing_profile.py                # CPU time, on a quiet machine

The task is what a training worker does for one member: the task arrives through a pipe, the member's
parameters are made (``es.worker.Worker``), the episode runs through the real wrappers (``envs.rollout``),
the result goes back. The agent is the committed paper run's (``results/paper/carracing_hebbian_seed1``,
its last centre, read only), on a track where it drives the whole 1000 steps (``--seed``).

Each part is a function of the code, called through a wrapper that measures it (``PARTS``): its count
includes the parts it calls, and what the table shows is its own (the count less its parts'). What no part
covers is the last row: the episode loop, Gymnasium's wrappers, the stock ``CarRacing.step``'s
bookkeeping and the reset less its track.

- ``--callgrind``: the task runs once under ``valgrind --tool=callgrind``, each part's wrapper a C function
  named after it (a small extension compiled here with ``cc`` against ``valgrind/callgrind.h``; valgrind
  counts only the task, from its start). A part's count is that function's inclusive count. The counts
  are the same from run to run and do not move with the machine's load; instructions are not time (the
  interpreter, Box2D and the compiled drawing run at different instructions per cycle). The record is
  one of counts (``timed=False``);
- otherwise: ``--rounds`` tasks, each part's time around its calls (``time.perf_counter_ns``: wall-clock
  time, which is this thread's CPU time only on a quiet machine; the wrappers add well under 1 % of a
  step, to the parts that call them); the medians over rounds.

Each run writes its record to benchmarks/results/ (benchmarks/record.py), with the table of parts that
docs/speed-carracing.md renders.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.machinery
import importlib.util
import multiprocessing
import os
import re
import shutil
import statistics
import subprocess
import sys
import sysconfig
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from record import Record, add_results_flag  # noqa: E402

from cli.flags import positive_int  # noqa: E402

SEED = 5  # a track on which the committed agent drives the whole 1000 steps
SIGMA = 0.1


@dataclass(frozen=True)
class Part:
    key: str
    label: str
    parent: str | None
    functions: str  # what it measures, as the docs show it


PARTS = (
    Part("task", "the rest: the episode loop, Gymnasium's wrappers, the stock step's bookkeeping, the reset less "
         "its track", None, "es.worker.Worker.run, less the other parts"),
    Part("messages", "the task and its result through a pipe", "task", "Connection.send, Connection.recv"),
    Part("parameters", "the member's parameters and their L2 penalty", "task", "Worker.params"),
    Part("policy_reset", "the network's reset: the rule folded, the initial weights", "task", "HebbianPolicy.reset"),
    Part("track", "the track generated (reset)", "task", "FastCarRacing._create_track"),
    Part("act", "the network, less its parts", "task", "HebbianPolicy.act"),
    Part("cnn", "the CNN", "act", "ConvFeatures.__call__"),
    Part("head", "the dense layers and the Hebbian update", "act", "kernels.hebbian_step"),
    Part("action", "the action mapping (tanh, sigmoids)", "task", "CarRacingAction.action"),
    Part("resize", "the 96 x 96 -> 84 x 84 resize", "task", "PixelObservation.observation"),
    Part("step", "the stock step's Python, less its parts", "task", "FastCarRacing.step"),
    Part("car", "the car: controls, wheels, friction (Python)", "step", "Car.steer, .gas, .brake, _Car.step"),
    Part("world", "Box2D's world step (C++)", "step", "b2World.Step, less the tile contacts"),
    Part("contacts", "tile contacts (Python)", "world", "FrictionDetector.BeginContact, .EndContact"),
    Part("render", "the observation's glue: camera, car state, checks", "step", "FastCarRacing._render"),
    Part("scene", "the scene: culling, car and dashboard polygons", "render",
         "FastCarRacing._compiled_scene, ._indicator_polygons"),
    Part("spans", "the polygons drawn into spans", "render", "SpanObservation.record_polygons"),
    Part("score", "the score's pixels", "render", "FastCarRacing._score_image"),
    Part("shrink", "the 1000 x 800 -> 96 x 96 shrink from the spans", "render", "SpanObservation.observe"),
)
KEYS = tuple(part.key for part in PARTS)


# --- the task, its parts wrapped ---------------------------------------------------------------------


class Task:
    """One worker task on ``problem``: the member is the centre (theta itself), its episode ``seed``,
    capped at ``steps`` policy steps."""

    def __init__(self, problem, params: np.ndarray, seed: int, steps: int):
        from es.noise import NoiseTable
        from es.worker import Worker, make_tasks

        self.problem = problem
        self.noise = NoiseTable.create(0, 1 << 16)
        self.worker = Worker(lambda: problem, self.noise, params)
        self.task = make_tasks(np.array([0]), np.array([-1]), np.array([1]), np.array([[seed]]), 1, max_steps=steps)
        self.sender, self.receiver = multiprocessing.Pipe()
        self.generation = 0
        self.steps = 0

    def run(self) -> None:
        """The task sent and received, run, its outcome sent and received (as ``es.backends.process`` does)."""
        self.generation += 1  # a new generation: the member's parameters are made again
        self.sender.send((self.generation, SIGMA, None, {}, self.task))
        generation, sigma, statistics_, _, chunk = self.receiver.recv()
        outcome = self.worker.run(generation, sigma, chunk[0], statistics_)
        self.receiver.send(outcome)
        kind, payload = self.sender.recv()
        if kind != "result":
            raise RuntimeError(f"the task failed: {payload}")
        self.steps = int(payload[1])

    def close(self) -> None:
        self.sender.close()
        self.receiver.close()
        self.noise.close()


@contextlib.contextmanager
def instrumented(task: Task, through: dict):
    """Every part's functions replaced by wrappers that call them through ``through[key]`` (``(function,
    *args, **kwargs) -> result``); put back afterwards. Instances where the code looks methods up on the
    instance, classes where it looks them up on the class (the car is made anew at each reset)."""
    from gymnasium.envs.box2d import car_dynamics

    import policies.hebbian
    from envs import car_racing
    from envs.wrappers import CarRacingAction, PixelObservation
    from policies.conv import ConvFeatures

    env = task.problem.envs[0]
    chain, wrappers = env, {}
    while hasattr(chain, "env"):
        wrappers[type(chain)] = chain
        chain = chain.env
    fast = chain
    fast.reset(seed=0)  # the drawing's objects exist from the first frame on
    patched = []

    def on(owner, name: str, key: str, bound: bool) -> None:
        original, call = getattr(owner, name), through[key]
        if bound:  # an instance's attribute: the bound method, called as it is
            def wrapper(*args, **kwargs):
                return call(original, *args, **kwargs)
        else:  # a class's function, called with the instance
            def wrapper(self, *args, **kwargs):
                return call(original, self, *args, **kwargs)
        had = name in vars(owner)
        patched.append((owner, name, vars(owner).get(name), had))
        setattr(owner, name, wrapper)

    sender, receiver = task.sender, task.receiver
    instances = [(sender, "send", "messages"), (sender, "recv", "messages"), (receiver, "send", "messages"),
                 (receiver, "recv", "messages"), (task.worker, "params", "parameters"),
                 (task.problem.policy, "reset", "policy_reset"), (task.problem.policy, "act", "act"),
                 (wrappers[CarRacingAction], "action", "action"), (wrappers[PixelObservation], "observation", "resize"),
                 (fast, "_create_track", "track"), (fast, "step", "step"), (fast.world, "Step", "world"),
                 (fast, "_render", "render"),
                 (fast, "_compiled_scene", "scene"), (fast, "_indicator_polygons", "scene"),
                 (fast._spans, "record_polygons", "spans"), (fast, "_score_image", "score"),
                 (fast._spans, "observe", "shrink")]
    listener = type(fast.contactListener_keepref)  # (Box2D calls its methods through the class)
    classes = [(ConvFeatures, "__call__", "cnn"), (car_racing._Car, "step", "car"), (car_racing._Car, "gas", "car"),
               (car_dynamics.Car, "steer", "car"), (car_dynamics.Car, "brake", "car"),
               (listener, "BeginContact", "contacts"), (listener, "EndContact", "contacts")]
    try:
        for owner, name, key in instances:
            on(owner, name, key, bound=True)
        for owner, name, key in classes:
            on(owner, name, key, bound=False)
        kernel = "hebbian_step" if hasattr(policies.hebbian, "hebbian_step") else "hebbian_forward_update"
        original_head = getattr(policies.hebbian, kernel)  # (hebbian_forward_update: the code before its state array)
        setattr(policies.hebbian, kernel, lambda *args: through["head"](original_head, *args))
        patched.append((policies.hebbian, kernel, original_head, True))
        yield
    finally:
        for owner, name, value, had in reversed(patched):
            if had:
                setattr(owner, name, value)
            else:
                delattr(owner, name)


def own_shares(inclusive: dict[str, float]) -> dict[str, float]:
    """Each part's own amount: its inclusive amount less its parts' (``PARTS``' tree)."""
    own = dict(inclusive)
    for part in PARTS:
        if part.parent is not None:
            own[part.parent] -= inclusive[part.key]
    return own


# --- CPU time ----------------------------------------------------------------------------------------


def timers(totals: dict[str, int]) -> dict:
    """Per part, a ``(function, *args)`` caller adding its time (ns) to ``totals[key]``."""
    clock = time.perf_counter_ns

    def timer(key: str):
        def call(function, *args, **kwargs):
            started = clock()
            try:
                return function(*args, **kwargs)
            finally:
                totals[key] += clock() - started
        return call
    return {key: timer(key) for key in KEYS}


def time_rounds(rounds: int, seed: int, steps: int) -> tuple[list[dict[str, float]], int]:
    """Per round (one task), each part's own seconds per step; and the episode's steps."""
    from car_racing import agent_problem

    problem, params = agent_problem()
    task = Task(problem, params, seed, steps)
    try:
        task.run()  # warm-up: numba's kernels, the score texts
        measured = []
        for _ in range(rounds):
            totals = dict.fromkeys(KEYS, 0)
            calls = timers(totals)
            with instrumented(task, calls):
                calls["task"](task.run)
            measured.append({key: value / 1e9 / task.steps for key, value in own_shares(totals).items()})
    finally:
        task.close()
        problem.close()
    return measured, task.steps


# --- instructions, under callgrind ----------------------------------------------------------------------

EXTENSION = "_profile_parts"
C_SOURCE = """#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <valgrind/callgrind.h>

/* function(*args, **kwargs) for a part's C function: the part's count is that function's inclusive count */
static PyObject *through(PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    Py_ssize_t count = PyVectorcall_NARGS(nargsf);
    if (count < 1) {
        PyErr_SetString(PyExc_TypeError, "a part calls a function");
        return NULL;
    }
    return PyObject_Vectorcall(args[0], args + 1, count - 1, kwnames);
}

static PyObject *start_instrumentation(PyObject *self, PyObject *unused) {
    CALLGRIND_START_INSTRUMENTATION;
    Py_RETURN_NONE;
}
%(functions)s
static PyMethodDef methods[] = {
    {"start_instrumentation", start_instrumentation, METH_NOARGS, NULL},
%(entries)s    {NULL, NULL, 0, NULL}
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "%(name)s", NULL, -1, methods};

PyMODINIT_FUNC PyInit_%(name)s(void) { return PyModule_Create(&module); }
"""


def compile_parts(folder: Path) -> Path:
    """The C extension of the parts' functions (``part_KEY``), compiled into ``folder``."""
    compiler = shutil.which(os.environ.get("CC", "cc"))
    if compiler is None:
        raise ValueError("--callgrind compiles a small C extension: no C compiler (cc, or $CC) found")
    functions = "".join(f"\nstatic PyObject *part_{key}(PyObject *self, PyObject *const *args, Py_ssize_t nargs, "
                        f"PyObject *kwnames) {{\n    return through(args, nargs, kwnames);\n}}\n" for key in KEYS)
    entries = "".join(f'    {{"{key}", (PyCFunction)(void (*)(void))part_{key}, METH_FASTCALL | METH_KEYWORDS, '
                      'NULL},\n' for key in KEYS)
    source = folder / f"{EXTENSION}.c"
    source.write_text(C_SOURCE % {"functions": functions, "entries": entries, "name": EXTENSION})
    library = folder / f"{EXTENSION}{sysconfig.get_config_var('EXT_SUFFIX')}"
    # -O0: each part's function stays a function of its own (no folding of identical bodies, no tail calls)
    command = [compiler, "-O0", "-shared", "-fPIC", f"-I{sysconfig.get_paths()['include']}", "-o", str(library),
               str(source)]
    built = subprocess.run(command, capture_output=True, text=True)
    if built.returncode != 0:
        reason = built.stderr.strip().splitlines()
        raise ValueError(f"--callgrind: the parts' C extension does not compile ({reason[0] if reason else ''}); "
                         "it needs Python's headers and valgrind's (valgrind/callgrind.h)")
    return library


def load_parts(library: Path):
    spec = importlib.util.spec_from_file_location(EXTENSION, library,
                                                  loader=importlib.machinery.ExtensionFileLoader(EXTENSION,
                                                                                                 str(library)))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def counted_child(library: Path, seed: int, steps: int, steps_file: Path) -> None:
    """Under callgrind: a warm-up task uninstrumented, then one task through the parts' C functions."""
    from car_racing import agent_problem

    parts = load_parts(library)
    problem, params = agent_problem()
    task = Task(problem, params, seed, steps)
    try:
        task.run()  # numba's kernels loaded, the score texts kept
        with instrumented(task, {key: getattr(parts, key) for key in KEYS}):
            parts.start_instrumentation()
            parts.task(task.run)  # valgrind counts from this call's start to its end (--toggle-collect)
    finally:
        task.close()
        problem.close()
    steps_file.write_text(str(task.steps))


def inclusive_counts(output: Path) -> dict[str, int]:
    """Each part's inclusive instruction count from a callgrind output file (``callgrind_annotate``)."""
    annotate = shutil.which("callgrind_annotate")
    if annotate is None:
        raise ValueError("--callgrind needs callgrind_annotate (it comes with valgrind)")
    text = subprocess.run([annotate, "--inclusive=yes", "--threshold=100", str(output)], capture_output=True,
                          text=True, check=True).stdout
    counts = dict.fromkeys(KEYS, 0)
    for line in text.splitlines():
        match = re.match(r"\s*([\d,]+)\s.*:part_(\w+)\s", line)
        if match and match[2] in counts:
            counts[match[2]] = int(match[1].replace(",", ""))
    return counts


def count_task(seed: int, steps: int) -> tuple[dict[str, float], int]:
    """Each part's own instructions per step of one task, counted by callgrind; and the episode's steps."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        raise ValueError("--callgrind needs valgrind (its callgrind tool) on the PATH")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        library = compile_parts(folder)
        output, steps_file = folder / "callgrind.out", folder / "steps"
        command = [valgrind, "--tool=callgrind", "--instr-atstart=no", "--collect-atstart=no",
                   "--toggle-collect=part_task", f"--callgrind-out-file={output}", sys.executable, __file__,
                   "--_counted_child", str(library), "--seed", str(seed), "--steps", str(steps),
                   "--_steps_file", str(steps_file)]
        # (a fixed hash seed: the same dictionaries in the same order, so that the counts repeat to the instruction)
        run = subprocess.run(command, capture_output=True, text=True, env={**os.environ, "PYTHONHASHSEED": "0"})
        if run.returncode != 0 or not steps_file.is_file():
            raise RuntimeError(f"the task under callgrind failed ({run.returncode}):\n{run.stderr[-3000:]}")
        counts, done = inclusive_counts(output), int(steps_file.read_text())
    if counts["task"] == 0:
        raise RuntimeError("callgrind counted nothing in the task")
    return {key: value / done for key, value in own_shares(counts).items()}, done


# --- the record ------------------------------------------------------------------------------------


def table_rows(values: dict[str, float], unit: str, scale: float, digits: int,
               ranges: dict[str, tuple[float, float]] | None = None) -> list[list]:
    """The parts, largest first (the rest last), as the docs' table."""
    total = sum(values.values())
    order = sorted((part for part in PARTS if part.key != "task"), key=lambda part: -values[part.key])
    rows = []
    for part in [*order, PARTS[0]]:
        value = round(values[part.key] * scale, digits)
        shown = value if ranges is None else {"value": value, "low": round(ranges[part.key][0] * scale, digits),
                                              "high": round(ranges[part.key][1] * scale, digits)}
        rows.append([part.label, part.functions, shown, f"{values[part.key] / total:.1%}"])
    rows.append(["a step in all", "", round(total * scale, digits), "100 %"])
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--callgrind", action="store_true",
                        help="count instructions under valgrind's callgrind (one task) instead of timing rounds")
    parser.add_argument("--rounds", type=positive_int, default=5, help="tasks timed (without --callgrind)")
    parser.add_argument("--seed", type=int, default=SEED, help="the episode's seed (its track)")
    parser.add_argument("--steps", type=positive_int, default=1000, help="the episode's cap on steps")
    parser.add_argument("--_counted_child", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--_steps_file", type=Path, help=argparse.SUPPRESS)
    add_results_flag(parser)
    args = parser.parse_args()
    if args._counted_child is not None:
        counted_child(args._counted_child, args.seed, args.steps, args._steps_file)
        return 0
    try:
        if args.callgrind:
            record = Record("car_racing_profile", timed=False)
            own, steps = count_task(args.seed, args.steps)
            for part in PARTS:
                record.add(part.key, f"{part.label}: instructions per step ({part.functions})", "instructions",
                           [own[part.key]])
            rows = table_rows(own, "M", 1e-6, 3)
            record.table("parts", ["part", "functions", "instructions per step (millions)", "share"], rows)
        else:
            record = Record("car_racing_profile_time")
            rounds, steps = time_rounds(args.rounds, args.seed, args.steps)
            medians = {key: statistics.median(one[key] for one in rounds) for key in KEYS}
            ranges = {key: (min(one[key] for one in rounds), max(one[key] for one in rounds)) for key in KEYS}
            for part in PARTS:
                record.add(part.key, f"{part.label}: time per step ({part.functions})", "ms",
                           [one[part.key] * 1e3 for one in rounds])
            rows = table_rows(medians, "ms", 1e3, 4, ranges)
            record.table("parts", ["part", "functions", "ms per step", "share"], rows)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    from car_racing import AGENT

    record.note("episode", {"agent": str(AGENT.relative_to(ROOT)), "seed": args.seed, "steps": steps})
    width = max(len(row[0]) for row in rows)
    print(f"one worker task of the paper's CarRacing Hebbian run, the committed agent, seed {args.seed}: {steps} "
          f"steps; {'instructions (callgrind)' if args.callgrind else 'time, median of rounds'} per step")
    for row in rows:
        value = row[2]["value"] if isinstance(row[2], dict) else row[2]
        print(f"  {row[0]:<{width}}  {value:>10}  {row[3]:>6}")
    record.write(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
