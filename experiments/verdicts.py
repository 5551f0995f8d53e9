"""The paper's claims, and the rules that decide each one's verdict from the campaign's runs (experiments/replication.py
writes the page).

The verdict rules. A claim about two kinds ("X scores higher than Y") is *reproduced* where the lower end of P(X > Y)'s
interval is above 0.5, *not reproduced* where its upper end is below 0.5, and *not yet decided* otherwise. A cited
figure m ± s of one kind is *reproduced* where m lies within the interval of that kind's mean over runs, *not
reproduced* where that interval does not meet [m - s, m + s], and *not yet decided* otherwise. The adaptation claim is
*reproduced* where on every body most Hebbian runs walk from step 100 (``walks``), *not reproduced* where on some body
most do not. Any claim is *not yet decided* with fewer than ``MIN_RUNS`` runs of a kind it needs; a row's verdict is
*not reproduced* if any of its parts is, *reproduced* if all are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from experiments.replication_files import Report, Run

MIN_RUNS = 3  # runs of each kind a claim needs before any verdict: one run cannot be told from its seed's luck
REPRODUCED, NOT_REPRODUCED, UNDECIDED = "reproduced", "not reproduced", "not yet decided"
# the adaptation row: "learns to walk ... in less than 100 timesteps" (the paper's abstract)
WALK_FROM = 100  # the policy step by which the network is to walk
WALK_UNTIL = 200  # ... judged over the steps that follow, up to this one
WALK_DISTANCE = 0.5  # metres forward over those steps (the shipped Hebbian ant walks about 1.7 m per 100 steps)
ALIVE_HEIGHT = 0.26  # metres: pyBullet's ant is alive while its torso is higher (a lower torso ends an episode)
TRACE_EPISODES = 3  # episodes traced per run and body: the evaluation's first seeds
ANT_BODIES = ("AntBulletEnv-v0", "AntAsymRightBulletEnv-v0", "AntAsymLeftBulletEnv-v0")
BODY_NAMES = {"AntBulletEnv-v0": "standard", "AntAsymRightBulletEnv-v0": "right-damaged (seen)",
              "AntAsymLeftBulletEnv-v0": "left-damaged (unseen)"}
KIND_NAMES = {"static": "static", "hebbian": "Hebbian"}


# --- the claims ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cited:
    """A figure cited for the paper: one kind's mean ± spread."""
    kind: str
    mean: float
    spread: float


@dataclass(frozen=True)
class Claim:
    what: str  # the claim, in words
    paper: str  # what is cited for the paper
    experiment: str  # the campaign's experiment: its report is results/paper/<experiment>_report/<environment>/
    environment: str
    higher: tuple[str, str] | None = None  # (X, Y): the paper has X scoring higher than Y
    cited: tuple[Cited, ...] = ()


ANT_SEEN = (Cited("static", 1604, 171), Cited("hebbian", 1051, 113))
CLAIMS = (
    Claim("CarRacing: the Hebbian network drives better than the static one",
          "Hebbian 872 ± 11, static 711 ± 16 (100 rollouts)", "carracing", "CarRacing-v3", ("hebbian", "static"),
          (Cited("hebbian", 872, 11), Cited("static", 711, 16))),
    Claim("The quadruped on its standard body (trained on): the static network walks further than the Hebbian one",
          "static 1604 ± 171, Hebbian 1051 ± 113 (the source does not say which body it trained on)", "ant",
          "AntBulletEnv-v0", ("static", "hebbian"), ANT_SEEN),
    Claim("The quadruped on its right-damaged body (trained on): the static network walks further",
          "the same figures, for a body trained on", "ant", "AntAsymRightBulletEnv-v0", ("static", "hebbian"),
          ANT_SEEN),
    Claim("The quadruped on its left-damaged body (never seen): the Hebbian network walks further than the static one",
          "no figure cited; the Hebbian network better on this body only", "ant", "AntAsymLeftBulletEnv-v0",
          ("hebbian", "static")),
)
ADAPTATION = ("Within an episode, the Hebbian network goes from random weights to walking in less than 100 steps, on "
              "each body", "\"in less than 100 timesteps\" (abstract)")


# --- the verdicts --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Verdict:
    status: str
    reason: str


def too_few(report: Report, kinds: tuple[str, ...]) -> Verdict | None:
    counts = {kind: report.groups[kind].runs if kind in report.groups else 0 for kind in kinds}
    short = {kind: count for kind, count in counts.items() if count < MIN_RUNS}
    if not short:
        return None
    named = ", ".join(f"{count} {KIND_NAMES[kind]} run{'s' * (count != 1)}" for kind, count in short.items())
    return Verdict(UNDECIDED, f"{named} evaluated so far; a verdict needs at least {MIN_RUNS} runs of each kind, so "
                              "that a seed's luck cannot decide it")


def higher_verdict(report: Report, higher: tuple[str, str]) -> Verdict:
    x, y = higher
    probability, low, high = report.better[x, y]
    said = f"P({KIND_NAMES[x]} > {KIND_NAMES[y]}) is {probability:.2f} [{low:.2f}, {high:.2f}]"
    if low > 0.5:
        return Verdict(REPRODUCED, f"{said}: the {KIND_NAMES[x]} runs score higher")
    if high < 0.5:
        return Verdict(NOT_REPRODUCED, f"{said}: the {KIND_NAMES[y]} runs score higher")
    return Verdict(UNDECIDED, f"{said}; the interval holds 0.5, so the runs do not rank the kinds")


def level_verdict(report: Report, cited: Cited) -> Verdict:
    mean, low, high = report.groups[cited.kind].mean
    said = (f"the {KIND_NAMES[cited.kind]} runs' mean {mean:.0f} [{low:.0f}, {high:.0f}] against the cited "
            f"{cited.mean:.0f} ± {cited.spread:.0f}")
    if low <= cited.mean <= high:
        return Verdict(REPRODUCED, f"{said}: the cited figure lies within the interval")
    if high < cited.mean - cited.spread or low > cited.mean + cited.spread:
        return Verdict(NOT_REPRODUCED, f"{said}: the interval is {'below' if high < cited.mean else 'above'} it")
    return Verdict(UNDECIDED, f"{said}: the interval reaches the cited range but not the figure")


def combined(parts: list[Verdict]) -> Verdict:
    """A row's verdict: not reproduced if any part is, reproduced if all are, else not yet decided; the reason of the
    part that decides."""
    for status in (NOT_REPRODUCED, UNDECIDED):
        deciding = [part for part in parts if part.status == status]
        if deciding:
            return Verdict(status, "; ".join(part.reason for part in deciding))
    return Verdict(REPRODUCED, "; ".join(part.reason for part in parts))


def verdict_of(claim: Claim, report: Report | None) -> Verdict:
    if report is None:
        return Verdict(UNDECIDED, "no run of this experiment has been evaluated yet")
    kinds = tuple(dict.fromkeys([*(claim.higher or ()), *(cited.kind for cited in claim.cited)]))
    short = too_few(report, kinds)
    if short is not None:
        return short
    parts = ([higher_verdict(report, claim.higher)] if claim.higher else []) + \
            [level_verdict(report, cited) for cited in claim.cited]
    return combined(parts)


# --- the adaptation within an episode ------------------------------------------------------------------------


@dataclass(frozen=True)
class Trace:
    """One traced episode: how it went from step ``WALK_FROM`` on, and how far the weights had turned by then."""
    seed: int
    steps: int  # policy steps
    forward: float  # metres walked forward over steps WALK_FROM + 1 to WALK_UNTIL
    lowest: float  # the torso's lowest height over those steps (0 where the episode ended before WALK_UNTIL)
    turned: float  # the lowest, over the layers, cosine between the weights after step WALK_FROM and at the end

    @property
    def walks(self) -> bool:
        """Walking from step WALK_FROM: the torso up and going forward over the next hundred steps."""
        return self.steps >= WALK_UNTIL and self.lowest > ALIVE_HEIGHT and self.forward >= WALK_DISTANCE


def cosine(weights: list[np.ndarray], final: list[np.ndarray]) -> float:
    """The lowest, over the layers, cosine between two sets of a network's weights (float64 sums)."""
    return min(float(np.sum(w.astype(np.float64) * f) / (np.linalg.norm(w.astype(np.float64)) *
                                                           np.linalg.norm(f.astype(np.float64))))
               for w, f in zip(weights, final))


def trace_run(run: Run) -> dict[str, list[Trace]]:
    """Episodes of a Hebbian ant run's final weights on each body, at its evaluation's first seeds."""
    from cli.config import TrainConfig
    from envs import ProblemSpec, rollout
    from envs.evaluation import track_torso
    from es.files import load_dat
    from es.runfolder import named_file

    config = TrainConfig.from_dict(run.config, str(run.folder / "config.json"))
    problem = ProblemSpec(ANT_BODIES, config.policy).build()
    try:
        policy = problem.policy
        params = policy.load({policy.roles[0]: load_dat(run.folder / named_file("last", policy.roles[0]))})
        traces = {}
        for env, body in zip(problem.envs, ANT_BODIES):
            tracker = track_torso(env)
            traces[body] = []
            for seed in range(int(run.evaluation["seed"]), int(run.evaluation["seed"]) + TRACE_EPISODES):
                forward, heights, early = [], [], []

                def observe(t, reward, state, info, tracker=tracker, forward=forward, heights=heights, early=early):
                    forward.append(tracker.forward)
                    heights.append(float(tracker.unwrapped.robot.body_real_xyz[2]))
                    if t == WALK_FROM:
                        early.extend(weights.copy() for weights in policy.layer_weights(state))

                episode = rollout(tracker, policy, params, seed, observe)
                steps = len(forward)
                whole = steps >= WALK_UNTIL
                traces[body].append(Trace(
                    seed, steps, forward[WALK_UNTIL - 1] - forward[WALK_FROM - 1] if whole else 0.0,
                    min(heights[WALK_FROM:WALK_UNTIL]) if whole else 0.0,
                    cosine(early, policy.layer_weights(episode.state)) if early else 0.0))
        return traces
    finally:
        problem.close()


def adaptation_verdict(traces: dict[str, dict[str, list[Trace]]]) -> Verdict:
    """``traces``: run -> body -> its episodes. A run walks on a body where most of its episodes walk."""
    if len(traces) < MIN_RUNS:
        count = len(traces)
        return Verdict(UNDECIDED, f"{count} Hebbian run{'s' * (count != 1)} of the quadruped evaluated so far; a "
                                  f"verdict needs at least {MIN_RUNS}")
    failing = []
    for body in ANT_BODIES:
        walking = sum(2 * sum(trace.walks for trace in runs[body]) > len(runs[body]) for runs in traces.values())
        if 2 * walking <= len(traces):
            failing.append(f"on the {BODY_NAMES[body]} body {walking} of {len(traces)} runs walk from step {WALK_FROM}")
    if failing:
        return Verdict(NOT_REPRODUCED, "; ".join(failing))
    return Verdict(REPRODUCED, f"on every body most runs walk from step {WALK_FROM}")
