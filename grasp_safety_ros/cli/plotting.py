"""Figures: the paper's effective-mass heatmap (grasps x time), per-grasp curves, and the
ISO/TS 15066 force ratios per body region."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.analyses.safety_report import SafetyReport

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


def _label(name: str, index: int) -> str:
    return name or f"grasp {index}"


def plot_report(report: SafetyReport, path: str | Path, title: str = "") -> Path:
    """Write a PNG: heatmap of the tip effective mass, per-grasp curves (dashed: with
    redundancy resolution; dotted: the leading object point), and ISO/TS 15066 ratios."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    ranking = report.ranking
    evaluations = ranking.evaluations
    feasible = [e for e in evaluations if e.feasible]
    panels = 3 if report.iso and feasible else 2
    fig, axes = plt.subplots(
        1,
        panels,
        figsize=(6.0 * panels, 0.35 * max(len(evaluations), 6) + 2.2),
        constrained_layout=True,
    )
    heat_ax, curve_ax = axes[0], axes[1]
    labels = [
        _label(e.name, e.index) + ("" if e.feasible else " (infeasible)") for e in evaluations
    ]
    if feasible:
        # One time grid for all grasps (sample times may differ: waypoint times, planned
        # joint trajectories); each row interpolated onto it, blank outside its own times.
        times = np.linspace(
            min(e.times_s[0] for e in feasible),
            max(e.times_s[-1] for e in feasible),
            max(len(e.times_s) for e in feasible),
        )
        grid = np.full((len(evaluations), len(times)), np.nan)
        for e in feasible:
            grid[e.index] = np.interp(
                times, e.times_s, e.effective_mass_kg, left=np.nan, right=np.nan
            )
        image = heat_ax.imshow(
            np.ma.masked_invalid(grid),
            aspect="auto",
            origin="lower",
            extent=(times[0], times[-1], -0.5, len(evaluations) - 0.5),
            cmap="viridis",
            interpolation="nearest",
        )
        fig.colorbar(image, ax=heat_ax, label="effective mass at the tip [kg]")
        position = {e.index: k for k, e in enumerate(feasible)}
        colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for k in report.order:
            e = evaluations[k]
            colour = colours[position[k] % len(colours)]
            curve_ax.plot(e.times_s, e.effective_mass_kg, color=colour, label=labels[k])
            if report.redundancy and report.redundancy[k].applied:
                curve_ax.plot(
                    e.times_s, report.redundancy[k].effective_mass_kg, "--", color=colour
                )
            if report.exposed and report.options.metric_point != "tip":
                curve_ax.plot(
                    e.times_s, report.exposed[k].leading_effective_mass_kg, ":", color=colour
                )
        curve_ax.legend(fontsize="small", ncol=2, title="safest first", title_fontsize="small")
    heat_ax.set_yticks(range(len(labels)), labels)
    heat_ax.set_xlabel("time [s]")
    heat_ax.set_title("effective mass along the trajectory")
    curve_ax.set_xlabel("time [s]")
    curve_ax.set_ylabel("effective mass [kg]")
    curve_ax.set_title(f"per grasp (score: {ranking.metric})")
    curve_ax.grid(True, alpha=0.3)
    if panels == 3:
        _plot_iso(report, axes[2], fig)
    if title:
        fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _plot_iso(report: SafetyReport, ax: Axes, fig: Figure) -> None:
    assessments = [a for a in report.iso if a.feasible]
    regions = [r.region.name for r in assessments[0].regions]
    ratios = np.array([[r.worst_force_ratio for r in a.regions] for a in assessments])
    shown = np.ma.masked_invalid(np.where(np.isinf(ratios), np.nan, ratios))
    image = ax.imshow(shown, aspect="auto", cmap="RdYlGn_r", vmin=0.0, vmax=2.0, origin="lower")
    fig.colorbar(image, ax=ax, label="worst F / F_max (transient)")
    ax.set_xticks(range(len(regions)), regions, rotation=60, ha="right", fontsize="small")
    ax.set_yticks(range(len(assessments)), [a.name or f"grasp {a.index}" for a in assessments])
    for i in range(ratios.shape[0]):
        for j in range(ratios.shape[1]):
            text = "n/p" if np.isinf(ratios[i, j]) else f"{ratios[i, j]:.2f}"
            ax.text(j, i, text, ha="center", va="center", fontsize="x-small")
    ax.set_title("ISO/TS 15066 (n/p: no transient contact permitted)")
