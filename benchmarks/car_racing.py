#!/usr/bin/env python
"""Gymnasium's CarRacing against the project's FastCarRacing, measured in one run.

    python benchmarks/car_racing.py               # speed, the training loops, the projection
    python benchmarks/car_racing.py --memory      # and the paper's Hebbian run's memory (PSS/USS)
    python benchmarks/car_racing.py --identity    # and long episodes compared step by step
    python benchmarks/car_racing.py --baseline DIR    # instead: today's code against another checkout's

Gymnasium's class is ``CarRacingStock-v3``, the project's ``CarRacing-v3``. Everything is timed in
CPU time of this process, the two classes alternating (every 25 steps for ``env.step``, reset by
reset, episode by episode for the training loops) so that this machine's drift and other load fall
on both alike; the medians over rounds are printed.

- environment: ``env.step`` of each class, the same seeds and random actions (resets untimed), the same
  on the actions of the committed trained agent (``results/paper/carracing_hebbian_seed1``, read only) on
  the tracks of ``AGENT_SEEDS``, and ``env.reset`` (track generation, tile bodies, the first frame) on the
  same seeds; then ``env.step``
  by step of the episode (``PHASES``): the camera zooms in over the first 50 steps, with the whole
  track in view at first, and generation-0 episodes end within it;
- training loop, generation 0: the real evaluation path (serial evaluator, worker, recipe wrappers,
  network, rollout) on the same generation of tasks, static and Hebbian (ABCD_lr), so early-stopped
  episodes, resets included; both classes must return the same fitness;
- training loop, capped episodes: what a worker does for a trained agent, ``--length`` steps per
  episode (the early stop left out), reset, resize, network (and Hebbian update), action mapping
  and ``env.step`` all timed, per step. By default a trained agent's whole episode, 1000 steps
  (CarRacing's time limit): each episode's reset and zoom-in then weigh on its steps as they do in
  the run projected;
- the projection of the paper's Hebbian run (population 200, 300 generations, episodes of 1000
  steps) on 2 and 16 workers from the capped Hebbian loop's cost per step, as
  ``experiments/step_cost.py`` does: (popsize + 1) x 1000 x step / workers per generation;
- ``--memory``: ``train_hebb.py`` at the paper's population (200) with 2 workers for one
  generation, its processes' summed PSS and USS (``/proc/PID/smaps_rollup``) sampled while it runs,
  once per round;
- ``--identity``: episodes of up to 1000 steps on seeds and drivers that no test uses, observations,
  rewards, flags and info compared at every step and ``rgb_array`` frames every ``--frame_every``
  steps; exit code 1 on the first difference.

``--baseline DIR`` (a checkout of another commit: ``git worktree add DIR COMMIT``) measures instead today's
code against that checkout's, each in a process of its own that imports its checkout's modules and runs
this script's measuring code (``throughput.Side``), the two taking turns round by round: a generation of
the paper's Hebbian run on the committed agent (``--generation_popsize``, the paper's 200 by default;
sigma 0.1, 1000-step episodes, 2 worker processes; wall time per environment step), whose returns must
be the same on both sides, and the fast class's ``env.step`` on random actions and on the agent's (CPU
time). Its record is ``car_racing-against-baseline``.

Each run writes its record to benchmarks/results/ (benchmarks/record.py): every ratio and rate below
with its rounds, the projections computed round by round.

Targets: env.step >= 8x the stock class (goal 15x), reset >= 2.5x (goal 4x), the Hebbian
training loop per step >= 5x (goal 8x).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

# the checkout whose modules this process imports and measures: this one, or in a side process of --baseline
# the one named after --_side; and this one last where it is missing (benchmarks/record.py would put it first)
sys.path.insert(0, sys.argv[sys.argv.index("--_side") + 1] if "--_side" in sys.argv[:-1]
                else str(Path(__file__).resolve().parent.parent))
sys.path.append(str(Path(__file__).resolve().parent.parent))

import gymnasium as gym
from gymnasium.envs.box2d.car_racing import FPS
from record import Record, add_results_flag
from throughput import SIDE, alternating, baseline_error, generation_tasks, serve, sides

import envs
from cli.flags import positive_int
from envs import ProblemSpec
from envs.make import STOCK_CAR_RACING_ID as STOCK_ID
from envs.rollout import rollout
from envs.wrappers import CarRacingAction, PixelObservation
from es.backends import Generation, ProcessEvaluator, SerialEvaluator
from es.noise import NoiseTable
from policies import PolicySettings

FAST_ID = "CarRacing-v3"
ENV_TARGET, RESET_TARGET, LOOP_TARGET = 8.0, 2.5, 5.0
PAPER_POPSIZE, PAPER_GENERATIONS, FULL_EPISODE = 200, 300, 1000
ZOOM_IN = FPS  # the camera zooms in over an episode's first second
PHASES = ((0, 10), (10, 20), (20, 30), (30, ZOOM_IN), (ZOOM_IN, 120))  # steps of an episode, from its reset
AGENT = Path(__file__).resolve().parent.parent / "results" / "paper" / "carracing_hebbian_seed1"  # read only
AGENT_SEEDS = (5, 1, 3)  # tracks of the committed agent's episodes (seed 5: the whole 1000 steps)
PAPER_SIGMA, GENERATION_WORKERS = 0.1, 2


def make(env_id: str, render_mode: str | None = None) -> gym.Env:
    with envs.quiet_output():
        return gym.make(env_id, render_mode=render_mode)


@contextlib.contextmanager
def both_classes():
    """Gymnasium's class and the fast one, the fast one's compiled code warmed up; closed afterwards."""
    stock, fast = make(STOCK_ID), make(FAST_ID)
    try:
        sum(timed_steps(fast, 0, random_actions(np.random.default_rng(0), 5), 5))  # numba's compiled code
        yield stock, fast
    finally:
        stock.close()
        fast.close()


def random_actions(rng: np.random.Generator, steps: int) -> np.ndarray:
    """Steering as a smoothed random walk, gas and brake at random: the car turns, slides and stays around."""
    steer = np.clip(np.cumsum(rng.normal(0, 0.15, size=steps)), -1, 1)
    gas, brake = rng.uniform(0, 0.6, size=steps), np.where(rng.random(steps) < 0.1, rng.uniform(0, 1, steps), 0)
    return np.stack([steer, gas, brake], axis=1).astype(np.float32)


def timed_steps(env: gym.Env, seed: int, actions: np.ndarray, chunk: int):
    """CPU seconds of ``env.step`` over each ``chunk`` of ``actions`` in turn (a generator), from
    ``reset(seed)``, resetting (untimed) on an end."""
    env.reset(seed=seed)
    for start in range(0, len(actions), chunk):
        seconds = 0.0
        for action in actions[start:start + chunk]:
            started = time.process_time()
            _, _, terminated, truncated, _ = env.step(action)
            seconds += time.process_time() - started
            if terminated or truncated:
                seed += 1000
                env.reset(seed=seed)
        yield seconds


def env_rates(rounds: int, steps: int, chunk: int = 25) -> tuple[list[float], list[float]]:
    """Steps per CPU second of each class, per round, the same seeds and actions for both, the two
    classes alternating every ``chunk`` steps (a round of the stock class lasts seconds: the load
    of this machine changes within one)."""
    stock_rates, fast_rates = [], []
    with both_classes() as (stock, fast):
        for round_index in range(rounds):
            actions = random_actions(np.random.default_rng(500 + round_index), steps)
            chunks = zip(timed_steps(stock, 500 + round_index, actions, chunk),
                         timed_steps(fast, 500 + round_index, actions, chunk))
            stock_seconds, fast_seconds = (sum(seconds) for seconds in zip(*chunks))
            stock_rates.append(len(actions) / stock_seconds)
            fast_rates.append(len(actions) / fast_seconds)
    return stock_rates, fast_rates


def agent_params(policy, folder: Path = AGENT) -> np.ndarray:
    """The committed paper run's last centre (its last_coeffs.dat and last_CNN_parameters.dat) for ``policy``
    (the paper's CarRacing Hebbian network, ABCD_lr)."""
    from es.files import load_dat

    runs = sorted(path for path in folder.iterdir() if path.is_dir()) if folder.is_dir() else []
    if not runs or not (runs[-1] / "last_coeffs.dat").is_file():
        raise ValueError(f"no committed CarRacing Hebbian run in {folder} (its last_coeffs.dat and "
                         "last_CNN_parameters.dat)")
    return policy.load({"coeffs": load_dat(runs[-1] / "last_coeffs.dat"),
                        "CNN_parameters": load_dat(runs[-1] / "last_CNN_parameters.dat")})


def agent_problem():
    """The paper's CarRacing Hebbian problem (``CarRacing-v3``, ABCD_lr, uniform initial weights) and the
    committed agent's parameters."""
    problem = ProblemSpec((FAST_ID,), PolicySettings("hebbian", "ABCD_lr", "uni")).build()
    try:
        return problem, agent_params(problem.policy)
    except BaseException:
        problem.close()
        raise


def agent_episodes(seeds: tuple[int, ...], length: int) -> list[tuple[int, np.ndarray]]:
    """The committed agent's episodes on ``seeds`` (at most ``length`` steps each, the recipe's early stop
    included): each seed and the actions ``env.step`` of the class received, in order."""
    problem, params = agent_problem()
    _, squash, _ = _pixel_chain(problem)
    mapping, actions = squash.action, []

    def recorded(output):
        action = mapping(output)
        actions.append(np.array(action, copy=True))
        return action
    squash.action = recorded
    episodes = []
    try:
        for seed in seeds:
            actions.clear()
            rollout(problem.envs[0], problem.policy, params, seed, max_steps=length)
            episodes.append((seed, np.array(actions)))
    finally:
        problem.close()
    return episodes


def episode_rates(rounds: int, episodes: list[tuple[int, np.ndarray]], chunk: int = 25) -> tuple[list[float],
                                                                                               list[float]]:
    """``env_rates`` on given episodes (seed, actions) instead of random actions: each round all of them."""
    stock_rates, fast_rates = [], []
    with both_classes() as (stock, fast):
        for _ in range(rounds):
            seconds, steps = [0.0, 0.0], 0
            for seed, actions in episodes:
                for pair in zip(timed_steps(stock, seed, actions, chunk), timed_steps(fast, seed, actions, chunk)):
                    seconds = [total + part for total, part in zip(seconds, pair)]
                steps += len(actions)
            stock_rates.append(steps / seconds[0])
            fast_rates.append(steps / seconds[1])
    return stock_rates, fast_rates


def phase_costs(episodes: int, chunk: int = 10) -> list[tuple[float, float]]:
    """CPU seconds per ``env.step`` of each class (stock, fast) over each of ``PHASES``, counted from
    the reset, over ``episodes`` episodes on the same seeds and random actions, the two classes
    alternating every ``chunk`` steps."""
    length = PHASES[-1][1]
    seconds = np.zeros((2, length // chunk))
    with both_classes() as (stock, fast):
        for episode in range(episodes):
            actions = random_actions(np.random.default_rng(700 + episode), length)
            chunks = zip(timed_steps(stock, 700 + episode, actions, chunk),
                         timed_steps(fast, 700 + episode, actions, chunk))
            for index, pair in enumerate(chunks):
                seconds[:, index] += pair
    return [tuple(seconds[:, first // chunk:end // chunk].sum(axis=1) / (episodes * (end - first)))
            for first, end in PHASES]


def reset_rates(rounds: int, resets: int) -> tuple[list[float], list[float]]:
    """Resets per CPU second of each class, per round, on the same seeds, the two classes
    alternating reset by reset."""
    rates: list[list[float]] = [[], []]
    with both_classes() as (stock, fast):
        for round_index in range(rounds):
            seconds = [0.0, 0.0]
            for seed in range(900 + round_index * resets, 900 + (round_index + 1) * resets):
                for index, env in enumerate((stock, fast)):
                    started = time.process_time()
                    env.reset(seed=seed)
                    seconds[index] += time.process_time() - started
            for found, spent in zip(rates, seconds):
                found.append(resets / spent)
    return rates[0], rates[1]


class WithoutEarlyStop(gym.Wrapper):
    """The recipe's pixel and action mapping straight over the class: a worker's episode without the early
    stop, so that every episode runs to its cap."""

    def __init__(self, problem):
        self.pixels, self.squash, env = _pixel_chain(problem)
        super().__init__(env)

    def reset(self, **options):
        frame, info = self.env.reset(**options)
        return self.pixels.observation(frame), info

    def step(self, output):
        frame, reward, terminated, truncated, info = self.env.step(self.squash.action(output))
        return self.pixels.observation(frame), reward, terminated, truncated, info


def capped_episode(problem, params, seed: int, length: int) -> tuple[float, int]:
    """CPU seconds of one episode of at most ``length`` steps, the reset included, and its steps: the
    project's episode loop (``envs.rollout``) without the early stop (resize, network, action mapping,
    env.step)."""
    env = WithoutEarlyStop(problem)
    started = time.process_time()
    episode = rollout(env, problem.policy, params, seed, max_steps=length)
    return time.process_time() - started, episode.steps


def _pixel_chain(problem):
    """The recipe's pixel and action wrappers, and what is below them (Gymnasium's wrappers and the class)."""
    chain, wrappers = problem.envs[0], []
    while isinstance(chain, gym.Wrapper):
        wrappers.append(chain)
        chain = chain.env
    pixels = next(w for w in wrappers if isinstance(w, PixelObservation))
    squash = next(w for w in wrappers if isinstance(w, CarRacingAction))
    return pixels, squash, pixels.env


def capped_loop_rates(kind: str, rounds: int, episodes: int, length: int) -> tuple[list[float], list[float], float]:
    """Steps per CPU second of the capped training loop with each class, per round (resets counted), and
    the fast class's mean steps per episode (fewer than ``length`` where the car leaves the playfield)."""
    problems = [ProblemSpec((env_id,), PolicySettings(kind)).build() for env_id in (STOCK_ID, FAST_ID)]
    params = problems[0].policy.initial_params(np.random.default_rng(0))
    for problem in problems:
        capped_episode(problem, params, 0, 3)  # warm-up: compilation
    rates: list[list[float]] = [[], []]
    fast_steps = 0
    try:
        for round_index in range(rounds):
            seconds, steps = [0.0, 0.0], [0, 0]
            for episode in range(episodes):
                for index, problem in enumerate(problems):
                    spent, count = capped_episode(problem, params, 3000 + round_index * episodes + episode, length)
                    seconds[index] += spent
                    steps[index] += count
            for index in range(2):
                rates[index].append(steps[index] / seconds[index])
            fast_steps += steps[1]
    finally:
        for problem in problems:
            problem.close()
    return rates[0], rates[1], fast_steps / (rounds * episodes)


def loop_rates(kind: str, rounds: int, popsize: int) -> tuple[list[float], list[float], float]:
    """Training-loop steps per CPU second with each class, per round, and the mean episode length."""
    specs = [ProblemSpec((env_id,), PolicySettings(kind)) for env_id in (STOCK_ID, FAST_ID)]
    problem = specs[0].build()
    theta = problem.policy.initial_params(np.random.default_rng(0))
    problem.close()
    noise = NoiseTable.create(0, max(1 << 20, 4 * theta.size))
    evaluators = [SerialEvaluator(spec.build, noise, theta.size, spec.env_ids) for spec in specs]
    tasks = generation_tasks(popsize, theta.size, noise, np.random.default_rng(1))
    for evaluator in evaluators:  # warm-up: compilation, first resets
        evaluator.evaluate(Generation(0, theta, 0.1, tasks[:1]))
    rates: list[list[float]] = [[], []]
    steps = 0
    try:
        for _ in range(rounds):
            seconds, steps = [0.0, 0.0], 0
            for number in range(len(tasks)):
                task, returns = tasks[number:number + 1], []
                for index, evaluator in enumerate(evaluators):
                    started = time.process_time()
                    results = evaluator.evaluate(Generation(0, theta, 0.1, task))
                    seconds[index] += time.process_time() - started
                    returns.append(results.returns[0])
                if returns[0] != returns[1]:
                    raise AssertionError(f"{kind}: the classes' fitness differ on task {task.tolist()}: {returns}")
                steps += int(results.steps[0])
            for index in range(2):
                rates[index].append(steps / seconds[index])
    finally:
        for evaluator in evaluators:
            evaluator.close()
        noise.close()
    return rates[0], rates[1], steps / len(tasks)


def policy_share(kind: str, steps: int) -> dict[str, float]:
    """CPU seconds per step of the fast class: env.step, the resize, the network (with its update)."""
    problem = ProblemSpec((FAST_ID,), PolicySettings(kind)).build()
    pixels, squash, env = _pixel_chain(problem)  # env: the fast class with Gymnasium's own wrappers
    policy = problem.policy
    params = policy.initial_params(np.random.default_rng(0))
    frame, _ = env.reset(seed=0)  # untimed warm-up: numba's kernels
    policy.act(params, policy.reset(params, np.random.default_rng(0)), pixels.observation(frame))
    totals = {"env.step": 0.0, "resize": 0.0, "network": 0.0}
    done, seed = 0, 0
    while done < steps:
        frame, _ = env.reset(seed=seed)
        state = policy.reset(params, np.random.default_rng(seed))
        for _ in range(min(300, steps - done)):  # the early stop left out: episodes of 300 steps
            started = time.process_time()
            observation = pixels.observation(frame)
            resized = time.process_time()
            output, state = policy.act(params, state, observation)
            acted = time.process_time()
            frame, _, terminated, truncated, _ = env.step(squash.action(output))
            stepped = time.process_time()
            totals["resize"] += resized - started
            totals["network"] += acted - resized
            totals["env.step"] += stepped - acted
            done += 1
            if terminated or truncated:
                break
        seed += 1
    problem.close()
    return {part: seconds / done for part, seconds in totals.items()}


def follow_track(speed: float):
    """A driver that steers toward the track six tiles ahead and holds ``speed``: it visits most tiles."""
    def act(car_racing, rng: np.random.Generator) -> np.ndarray:
        car, track = car_racing.car, np.array([point[2:4] for point in car_racing.track])
        x, y = car.hull.position
        nearest = int(np.argmin(np.hypot(track[:, 0] - x, track[:, 1] - y)))
        target_x, target_y = track[(nearest + 6) % len(track)]
        error = math.atan2(target_y - y, target_x - x) - (car.hull.angle + math.pi / 2)
        error = (error + math.pi) % (2 * math.pi) - math.pi
        velocity = float(np.hypot(*car.hull.linearVelocity))
        return np.array([np.clip(-2 * error, -1, 1), 0.4 if velocity < speed else 0.0,
                         0.3 if velocity > 1.3 * speed else 0.0], dtype=np.float32)
    return act


def wander(car_racing, rng: np.random.Generator) -> np.ndarray:
    return random_actions(rng, 1)[0]


def full_throttle(car_racing, rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(-0.3, 0.3), 1.0, 0.0], dtype=np.float32)


def stop_and_go(car_racing, rng: np.random.Generator) -> np.ndarray:
    braking = int(car_racing.t * 50) % 80 >= 50
    return np.array([rng.uniform(-1, 1), 0.0 if braking else 0.8, 0.9 if braking else 0.0], dtype=np.float32)


DRIVERS = {"follow the track at 40": follow_track(40.0), "follow the track at 60": follow_track(60.0),
           "wander": wander, "full throttle": full_throttle, "stop and go": stop_and_go}


def identity(episodes: int, frame_every: int) -> bool:
    """Both classes side by side on seeds 7000, 7001, ...; True if every step and frame matched."""
    stock, fast = make(STOCK_ID, "rgb_array"), make(FAST_ID, "rgb_array")
    drivers = list(DRIVERS.items())
    try:
        for episode in range(episodes):
            seed = 7000 + episode
            name, driver = drivers[episode % len(drivers)]
            rng = np.random.default_rng(seed)
            same = [np.array_equal(a, b) for a, b in zip(stock.reset(seed=seed)[:1], fast.reset(seed=seed)[:1])]
            total, step, end = 0.0, 0, "1000 steps"
            while all(same):
                action = driver(stock.unwrapped, rng)
                expected, got = stock.step(action), fast.step(action)
                same = [np.array_equal(expected[0], got[0]), expected[1:] == got[1:]]
                if step % frame_every == 0:
                    same.append(np.array_equal(stock.render(), fast.render()))
                total, step = total + expected[1], step + 1
                if expected[2] or expected[3]:
                    end = "terminated" if expected[2] else "truncated"
                    break
            print(f"  seed {seed} ({name}): {step} steps, {end}, return {total:.1f}: "
                  + ("identical" if all(same) else f"DIFFERENT at step {step}"))
            if not all(same):
                return False
    finally:
        stock.close()
        fast.close()
    return True


def _process_tree(root: int) -> list[int]:
    """``root`` and its descendants, from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(parent, []).append(int(entry.name))
    tree, queue = [], [root]
    while queue:
        pid = queue.pop()
        tree.append(pid)
        queue.extend(children.get(pid, []))
    return tree


def _pss_uss(pids: list[int]) -> tuple[int, int]:
    """Summed PSS and USS (private clean + dirty) in bytes of these processes (shared pages once)."""
    pss = uss = 0
    for pid in pids:
        try:
            fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()[1:])
        except OSError:
            continue
        kilobytes = {name: int(value.split()[0]) for name, value in fields.items()}
        pss += 1024 * kilobytes.get("Pss", 0)
        uss += 1024 * (kilobytes.get("Private_Clean", 0) + kilobytes.get("Private_Dirty", 0))
    return pss, uss


def paper_run_memory(workers: int, popsize: int) -> tuple[int, int, int]:
    """Peak summed PSS and USS of ``train_hebb.py`` on CarRacing at ``popsize`` with ``workers``
    worker processes, for one generation, sampled every 0.2 s; and its number of processes."""
    import subprocess
    import tempfile

    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as folder:
        command = [sys.executable, str(root / "train_hebb.py"), "--environment", "CarRacing-v0", "--hebb_rule",
                   "ABCD_lr", "--popsize", str(popsize), "--generations", "1", "--threads", str(workers),
                   "--folder", folder, "--seed", "1"]
        process = subprocess.Popen(command, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        peak_pss = peak_uss = most = 0
        while process.poll() is None:
            tree = _process_tree(process.pid)
            pss, uss = _pss_uss(tree)
            peak_pss, peak_uss, most = max(peak_pss, pss), max(peak_uss, uss), max(most, len(tree))
            time.sleep(0.2)
        if process.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} exited with {process.returncode}")
    return peak_pss, peak_uss, most


def projection(record: Record, key: str, step_rates: tuple[list[float], list[float]], label: str,
               length: int) -> None:
    """The paper's Hebbian run's hours on 2 and 16 workers from (stock, fast) steps per CPU second of the
    loop capped at ``length`` steps, round by round."""
    for workers in (2, 16):
        hours = [[(PAPER_POPSIZE + 1) * FULL_EPISODE / rate / workers * PAPER_GENERATIONS / 3600 for rate in rates]
                 for rates in step_rates]
        for name, values in zip(("stock", "fast"), hours):
            record.add(f"{key}_{name}_{workers}_workers", f"the paper's Hebbian run (popsize {PAPER_POPSIZE}, "
                       f"{PAPER_GENERATIONS} generations, {FULL_EPISODE}-step episodes) on {workers} workers, the "
                       f"{name} class{label if name == 'fast' else ''}, projected from the loop capped at {length} "
                       "steps", "h", values)
        print(f"projection, the paper's Hebbian run (popsize {PAPER_POPSIZE}, {PAPER_GENERATIONS} generations, "
              f"{FULL_EPISODE}-step episodes) on {workers} workers, from the loop capped at {length} steps: "
              f"stock {statistics.median(hours[0]):.1f} h, fast{label} {statistics.median(hours[1]):.1f} h")


# --- today's code against a baseline checkout, side by side (--baseline) --------------------------------


def side_requests() -> dict:
    """What a side of ``--baseline`` answers, with its own checkout's code: a generation of the paper's
    Hebbian run on the committed agent (set up once), and the fast class's ``env.step`` on given actions."""
    held: dict = {}

    def generation_start(popsize: int, workers: int, sigma: float, seed: int, agent: str) -> dict:
        spec = ProblemSpec((FAST_ID,), PolicySettings("hebbian", "ABCD_lr", "uni"))
        problem = spec.build()
        theta = agent_params(problem.policy, Path(agent))
        problem.close()
        noise = NoiseTable.create(0, max(1 << 20, 4 * theta.size), shared=True)
        evaluator = ProcessEvaluator(spec.build, noise, theta.size, spec.env_ids, workers)
        tasks = generation_tasks(popsize, theta.size, noise, np.random.default_rng(seed))
        evaluator.evaluate(Generation(0, theta, sigma, tasks[:workers]))  # warm-up: the workers' compilation
        held.update(evaluator=evaluator, noise=noise, theta=theta, tasks=tasks, sigma=sigma)
        return {"parameters": int(theta.size)}

    def generation() -> dict:
        started = time.perf_counter()
        results = held["evaluator"].evaluate(Generation(0, held["theta"], held["sigma"], held["tasks"]))
        return {"seconds": time.perf_counter() - started, "steps": int(results.steps.sum()),
                "returns": [float(value) for value in results.returns]}

    def env_steps(seed: int, actions: list) -> float:
        env = held.get("env")
        if env is None:
            env = held["env"] = make(FAST_ID)
            sum(timed_steps(env, 0, random_actions(np.random.default_rng(0), 5), 5))  # numba's compiled code
        return sum(timed_steps(env, seed, np.array(actions, dtype=np.float32), len(actions)))

    def stop() -> bool:
        if "evaluator" in held:
            held.pop("evaluator").close()
            held.pop("noise").close()
        if "env" in held:
            held.pop("env").close()
        return True
    return {"generation_start": generation_start, "generation": generation, "env_steps": env_steps, "stop": stop}


def against_baseline(args, record: Record) -> None:
    """Today's code against ``args.baseline``'s, each in a side process, taking turns round by round: a
    generation of the paper's Hebbian run on the committed agent (popsize ``--generation_popsize``, 1000-step
    episodes, 2 workers, wall time per step), whose returns must be the same on both sides; and the fast
    class's ``env.step`` on random actions and on the agent's (CPU time)."""
    random_episodes = [(600 + index, random_actions(np.random.default_rng(600 + index), args.steps))
                       for index in range(3)]
    agent = agent_episodes(AGENT_SEEDS, FULL_EPISODE)
    named = sides(__file__, args.baseline)
    try:
        for side in named.values():
            side.ask("generation_start", popsize=args.generation_popsize, workers=GENERATION_WORKERS,
                     sigma=PAPER_SIGMA, seed=1, agent=str(AGENT))
        generations = alternating(args.rounds, named, "generation")
        for kind, episodes in (("random", random_episodes), ("agent", agent)):
            seconds = {name: [0.0] * args.rounds for name in named}
            for seed, actions in episodes:
                answers = alternating(args.rounds, named, "env_steps", seed=seed, actions=actions.tolist())
                for name in named:
                    seconds[name] = [total + part for total, part in zip(seconds[name], answers[name])]
            steps = sum(len(actions) for _, actions in episodes)
            summary(record, f"env_step_{kind}_against_baseline", f"environment (env.step), {kind} actions, today's "
                    "fast class against the baseline's", [steps / spent for spent in seconds["baseline"]],
                    [steps / spent for spent in seconds["today"]], stock_name="the baseline's")
        for side in named.values():
            side.ask("stop")
    finally:
        for side in named.values():
            side.close()
    today, baseline = generations["today"], generations["baseline"]
    if any(ours["returns"] != theirs["returns"] for ours, theirs in zip(today, baseline)):
        raise AssertionError("today's code and the baseline's give different returns on the same generation")
    per_step = {name: [answer["seconds"] / answer["steps"] for answer in answers]
                for name, answers in generations.items()}
    label = (f"a generation of the paper's Hebbian run on the committed agent (popsize {args.generation_popsize}, "
             f"{FULL_EPISODE}-step episodes, {GENERATION_WORKERS} workers, wall time)")
    record.add("generation_against_baseline", f"{label}: the baseline's time per step / today's", "x",
               [theirs / ours for ours, theirs in zip(per_step["today"], per_step["baseline"])])
    for name in named:
        record.add(f"generation_seconds_{name}", f"{label}: {name}'s code, seconds per generation", "s",
                   [answer["seconds"] for answer in generations[name]])
    speedups = record.measures["generation_against_baseline"].values
    print(f"{label}: {today[0]['steps']:,} steps; today's code {statistics.median(speedups):.2f}x as fast as the "
          f"baseline's (rounds: {', '.join(f'{value:.2f}' for value in speedups)}); the same returns on both sides")
    record.note("baseline", str(args.baseline))


def summary(record: Record, key: str, label: str, stock: list[float], fast: list[float], target: float | None = None,
            unit: str = "steps", stock_name: str = "Gymnasium's") -> None:
    ratios = [f / s for s, f in zip(stock, fast)]
    record.add(key, f"{label}: the fast class / {stock_name}, {unit} per CPU second", "x", ratios)
    record.add(f"{key}_stock", f"{label}: {stock_name} class, {unit} per CPU second", f"{unit}/s", stock)
    record.add(f"{key}_fast", f"{label}: the fast class, {unit} per CPU second", f"{unit}/s", fast)
    goal = f" (target >= {target}x)" if target else ""
    print(f"{label}: {stock_name} {statistics.median(stock):,.1f}, the fast class {statistics.median(fast):,.1f} "
          f"{unit} per CPU second; ratio {statistics.median(ratios):.2f}x{goal} (rounds: "
          f"{', '.join(f'{r:.2f}' for r in ratios)})")


def main() -> int:
    if SIDE in sys.argv:
        return serve(side_requests())
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--rounds", type=positive_int, default=5)
    parser.add_argument("--steps", type=positive_int, default=300, help="environment steps per class and round")
    parser.add_argument("--resets", type=positive_int, default=20, help="resets per class and round")
    parser.add_argument("--phase_episodes", type=positive_int, default=6,
                        help="episodes of env.step timed by step of the episode (the zoom-in first)")
    parser.add_argument("--popsize", type=positive_int, default=8, help="episodes per generation-0 training-loop round")
    parser.add_argument("--episodes", type=positive_int, default=1, help="capped episodes per training-loop round")
    parser.add_argument("--length", type=positive_int, default=FULL_EPISODE,
                        help="steps of a capped episode (the projection's cost per step)")
    parser.add_argument("--share_steps", type=positive_int, default=600, help="steps measured for the policy's share")
    parser.add_argument("--memory", action="store_true",
                        help="also measure the paper's Hebbian run's memory (one generation per round)")
    parser.add_argument("--identity", action="store_true", help="also compare long episodes frame by frame")
    parser.add_argument("--episodes_compared", type=positive_int, default=20,
                        help="with --identity: how many episodes")
    parser.add_argument("--frame_every", type=positive_int, default=50,
                        help="with --identity: compare render() this often")
    parser.add_argument("--baseline", type=Path, metavar="DIR",
                        help="instead, today's code against this checkout's (git worktree add DIR COMMIT), side by "
                             "side: a generation of the paper's Hebbian run on the committed agent, and env.step")
    parser.add_argument("--generation_popsize", type=positive_int, default=PAPER_POPSIZE,
                        help="with --baseline: the generation's population (the paper's: 200)")
    add_results_flag(parser)
    args = parser.parse_args()
    if args.baseline is not None:
        args.baseline = args.baseline.expanduser().resolve()
        if error := baseline_error(args.baseline):
            print(f"error: {error}", file=sys.stderr)
            return 2
        record = Record("car_racing-against-baseline")
        try:
            against_baseline(args, record)
        except ValueError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        record.write(args.results)
        return 0
    record = Record("car_racing")
    summary(record, "env_step", "environment (env.step)", *env_rates(args.rounds, args.steps), ENV_TARGET)
    try:
        agent = agent_episodes(AGENT_SEEDS, FULL_EPISODE)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    summary(record, "env_step_agent", "environment (env.step), the committed agent's actions (seeds "
            f"{', '.join(map(str, AGENT_SEEDS))}, {sum(len(actions) for _, actions in agent)} steps)",
            *episode_rates(args.rounds, agent), ENV_TARGET)
    summary(record, "env_reset", "environment (env.reset)", *reset_rates(args.rounds, args.resets), RESET_TARGET,
            unit="resets")
    phases = [f"{first}-{end - 1}: {stock * 1e3:.2f} / {fast * 1e3:.2f} ms, {stock / fast:.1f}x"
              for (first, end), (stock, fast) in zip(PHASES, phase_costs(args.phase_episodes))]
    print(f"environment (env.step) by step of the episode, stock / fast CPU per step (the camera zooms in "
          f"over steps 0-{ZOOM_IN - 1}): {'; '.join(phases)}")
    record.note("env_step_by_phase", phases)
    for kind in ("static", "hebbian"):
        stock, fast, length = loop_rates(kind, args.rounds, args.popsize)
        summary(record, f"loop_generation_0_{kind}", f"training loop, generation 0, {kind} (mean episode "
                f"{length:.0f} steps)", stock, fast)
    capped = f"training loop, episodes capped at {args.length} steps"
    for kind in ("static", "hebbian"):
        stock, fast, mean_steps = capped_loop_rates(kind, args.rounds, args.episodes, args.length)
        summary(record, f"capped_loop_{kind}", f"{capped} ({mean_steps:.0f} on average), {kind}", stock, fast,
                LOOP_TARGET if kind == "hebbian" else None)
        if kind == "hebbian":
            projection(record, "projection", (stock, fast), "", args.length)
    for kind in ("static", "hebbian"):
        parts = policy_share(kind, args.share_steps)
        total = sum(parts.values())
        for part, seconds in parts.items():
            record.add(f"share_{kind}_{part.replace('.', '_')}", f"pixel policy, {kind}: {part}, CPU per step of "
                       f"the fast class over {args.share_steps} steps", "ms", [1e3 * seconds])
        print(f"pixel policy, {kind}: {1e3 * total:.2f} ms CPU per step of the fast class: "
              + ", ".join(f"{part} {1e3 * seconds:.2f} ms ({seconds / total:.0%})" for part, seconds in parts.items())
              + f"; the policy (resize + network) is {(parts['resize'] + parts['network']) / total:.0%} of a step")
    import resource

    print(f"peak memory of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB (RSS)")
    if args.memory:
        samples = [paper_run_memory(2, PAPER_POPSIZE) for _ in range(args.rounds)]
        processes = max(sample[2] for sample in samples)
        for index, name in enumerate(("pss", "uss")):
            record.add(f"memory_{name}", f"train_hebb.py CarRacing-v0 ABCD_lr, popsize {PAPER_POPSIZE}, 2 workers, "
                       f"one generation per round: peak {name.upper()} summed over its processes", "MiB",
                       [sample[index] / 2**20 for sample in samples])
        pss, uss = (statistics.median(sample[index] for sample in samples) / 2**20 for index in (0, 1))
        print(f"memory, train_hebb.py CarRacing-v0 ABCD_lr, popsize {PAPER_POPSIZE}, 2 workers, one generation, "
              f"median of {args.rounds} runs: peak PSS {pss:.0f} MiB, peak USS {uss:.0f} MiB over {processes} "
              "processes (target < 1 GB)")
    if args.identity:
        print(f"identity: {args.episodes_compared} episodes of up to 1000 steps, frames every {args.frame_every} steps")
        same = identity(args.episodes_compared, args.frame_every)
        record.note("identity", {"episodes": args.episodes_compared, "frame_every": args.frame_every,
                                 "identical": same})
        record.write(args.results)
        if not same:
            return 1
        print("identity: every observation, reward, flag, info and compared frame identical")
        return 0
    record.write(args.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
