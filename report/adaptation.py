"""The paper's adaptation figure (Najarro & Risi 2020): one episode, step by step.

Per step: the reward, or for ants the distance walked from the start; and for plastic networks the
Frobenius norm of each dense layer's weights, which start random and settle within the first ~100
steps. The data comes from ``envs.evaluation.trace_episode``; drawing uses matplotlib's Agg canvas,
so no display is ever needed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from envs.evaluation import Trace
from report.plots import write_figure


def plot_adaptation(trace: Trace, path: str | Path) -> None:
    """A picture of the trace (PNG, PDF or SVG, as the suffix says); drawn with matplotlib's Agg canvas, so
    no display is ever needed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    panels = 2 if trace.layer_norms else 1
    figure = Figure(figsize=(8, 3.2 * panels), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(panels, 1, sharex=True, squeeze=False)[:, 0]
    steps = np.arange(1, len(trace.rewards) + 1)
    if trace.distances:
        axes[0].plot(steps, trace.distances, color="tab:blue", label="straight-line distance")
        axes[0].plot(steps, trace.forward, color="tab:orange", label="forward (x) displacement")
        axes[0].axhline(0.0, color="grey", linewidth=0.5)
        axes[0].set_ylabel("torso from start (m)")
        axes[0].legend(loc="best")
    else:
        axes[0].plot(steps, trace.rewards, color="tab:blue", linewidth=0.8)
        axes[0].set_ylabel("reward per step")
    axes[0].set_title(f"{trace.env_id}, seed {trace.seed}: return {trace.episode.total_return:.2f}")
    if trace.layer_norms:
        norms = np.array(trace.layer_norms)
        for layer, (n_out, n_in) in enumerate(trace.layer_shapes):
            axes[1].plot(steps, norms[:, layer], label=f"layer {layer + 1} ({n_in}→{n_out})")
        axes[1].set_ylabel("weight norm (Frobenius)")
        axes[1].set_yscale("log")
        axes[1].legend(loc="best")
    axes[-1].set_xlabel("policy step")
    axes[-1].xaxis.set_major_locator(MaxNLocator(integer=True))
    write_figure(figure, Path(path), dpi=100)
