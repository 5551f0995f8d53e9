"""The paper's adaptation figure (Najarro & Risi 2020): one episode, step by step.

Per step: the return so far, or for ants the distance walked from the start; and for plastic networks the
Frobenius norm of each dense layer's weights, which start random in every episode. Where every update
rescales the layers (every environment but pyBullet's) the norms stay bounded; on pyBullet's they grow
as long as the episode runs. The data comes from ``envs.evaluation.trace_episode``; drawing uses
matplotlib's Agg canvas, so no display is ever needed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from envs.evaluation import Trace
from report.plots import write_figure


def burn_in(trace: Trace) -> int:
    """The steps of zero actions before the first policy step (the pyBullet ant's 40), which the episode's
    step count includes and the trace has no data for."""
    return trace.episode.steps - len(trace.rewards)


def steps_text(trace: Trace) -> str:
    """The episode's length as the evaluation table counts it, with its burn-in: "242 steps, the first 40
    of them burn-in"."""
    skipped = burn_in(trace)
    return f"{trace.episode.steps} steps" + (f", the first {skipped} of them burn-in" if skipped else "")


def plot_adaptation(trace: Trace, path: str | Path) -> None:
    """A picture of the trace (PNG, PDF or SVG, as the suffix says)."""
    write_figure(adaptation_figure(trace), Path(path), dpi=100)


def adaptation_figure(trace: Trace):
    """The trace's figure, drawn with matplotlib's Agg canvas, so no display is ever needed. Its title takes
    two lines, the episode and its outcome, so that a long environment id stays inside the figure."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    panels = 2 if trace.layer_norms else 1
    figure = Figure(figsize=(8, 3.2 * panels), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(panels, 1, sharex=True, squeeze=False)[:, 0]
    skipped = burn_in(trace)  # drawn on the environment's steps, as the evaluation table counts them
    steps = np.arange(skipped + 1, skipped + len(trace.rewards) + 1)
    if trace.distances:
        axes[0].plot(steps, trace.distances, color="tab:blue", label="straight-line distance")
        axes[0].plot(steps, trace.forward, color="tab:orange", label="forward (x) displacement")
        axes[0].axhline(0.0, color="grey", linewidth=0.5)
        axes[0].set_ylabel("torso from start (m)")
        axes[0].legend(loc="best")
    else:
        axes[0].plot(steps, np.cumsum(trace.rewards), color="tab:blue")  # (CarRacing's per-step rewards: spikes)
        axes[0].set_ylabel("return so far")
    axes[0].set_title(f"{trace.env_id}, seed {trace.seed}\n"
                      f"return {trace.episode.total_return:.2f}, {steps_text(trace)}")
    if trace.layer_norms:
        norms = np.array(trace.layer_norms)
        for layer, (n_out, n_in) in enumerate(trace.layer_shapes):
            axes[1].plot(steps, norms[:, layer], label=f"layer {layer + 1} ({n_in}→{n_out})")
        axes[1].set_ylabel("weight norm (Frobenius)")
        axes[1].set_yscale("log")
        axes[1].legend(loc="best")
    axes[-1].set_xlabel("environment step" + (f" (1-{skipped}: burn-in, zero actions, not drawn)" if skipped else ""))
    axes[-1].xaxis.set_major_locator(MaxNLocator(integer=True))
    return figure
