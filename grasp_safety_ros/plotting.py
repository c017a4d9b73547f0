"""Figures: the paper's effective-mass heatmap (grasps x time) and per-grasp curves."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .core.ranking import Ranking


def plot_ranking(ranking: Ranking, path: str | Path, title: str = "") -> Path:
    """Write a PNG with the heatmap of effective mass and the per-grasp curves."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    feasible = [e for e in ranking.evaluations if e.feasible]
    fig, (heat_ax, curve_ax) = plt.subplots(
        1, 2, figsize=(12, 0.35 * max(len(ranking.evaluations), 6) + 2.0), constrained_layout=True
    )
    if feasible:
        times = feasible[0].times_s
        grid = np.full((len(ranking.evaluations), len(times)), np.nan)
        for e in feasible:
            grid[e.index] = e.effective_mass_kg
        image = heat_ax.imshow(
            np.ma.masked_invalid(grid),
            aspect="auto",
            origin="lower",
            extent=(times[0], times[-1], -0.5, len(ranking.evaluations) - 0.5),
            cmap="viridis",
            interpolation="nearest",
        )
        fig.colorbar(image, ax=heat_ax, label="effective mass [kg]")
        for e in feasible:
            curve_ax.plot(e.times_s, e.effective_mass_kg, label=e.name or f"grasp {e.index}")
    labels = [
        (e.name or f"grasp {e.index}") + ("" if e.feasible else " (infeasible)")
        for e in ranking.evaluations
    ]
    heat_ax.set_yticks(range(len(labels)), labels)
    heat_ax.set_xlabel("time [s]")
    heat_ax.set_title("effective mass along the trajectory")
    curve_ax.set_xlabel("time [s]")
    curve_ax.set_ylabel("effective mass [kg]")
    curve_ax.set_title(f"per grasp (legend: safest first by {ranking.metric})")
    if feasible:
        handles, names = curve_ax.get_legend_handles_labels()
        position = {e.index: k for k, e in enumerate(feasible)}
        order = [position[i] for i in ranking.order]
        curve_ax.legend(
            [handles[k] for k in order], [names[k] for k in order], fontsize="small", ncol=2
        )
    curve_ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
