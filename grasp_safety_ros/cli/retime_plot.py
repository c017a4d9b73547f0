"""Per grasp, each body region's worst site speed against its admissible speed along the
motion, for the planner's timing and the retimed one (core.analyses.retime)."""

from __future__ import annotations

from pathlib import Path

from ..core.analyses.safety_report import SafetyReport


def plot_retimed(report: SafetyReport, path: str | Path, title: str = "") -> list[Path]:
    """One PNG per retimed grasp beside ``path`` (``<stem>_retime_<k>.png``): two panels
    (planned, retimed) with, per region, the speed of the site closest to its limit (solid)
    and that limit f · v_max (dashed) [m/s] against time [s]. Returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    written = []
    for k, motion in enumerate(report.retimed):
        if motion is None or not motion.regions:
            continue
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True, constrained_layout=True)
        panels = (
            (
                "planned",
                motion.planned_times_s,
                motion.planned_region_speed_m_s,
                motion.planned_region_limit_m_s,
                motion.planned_duration_s,
            ),
            (
                "retimed",
                motion.times_s,
                motion.region_speed_m_s,
                motion.region_limit_m_s,
                motion.safe_duration_s,
            ),
        )
        colours = plt.get_cmap("tab10")
        for ax, (label, times, speeds, limits, duration) in zip(axes, panels, strict=True):
            for r, region in enumerate(motion.regions):
                colour = colours(r % 10)
                ax.plot(times, speeds[:, r], color=colour, label=region)
                ax.plot(times, limits[:, r], color=colour, linestyle="--", linewidth=0.8)
            ax.set_title(f"{label} ({duration:.3f} s)")
            ax.set_xlabel("time [s]")
        axes[0].set_ylabel("worst site speed (solid), admissible f·v_max (dashed) [m/s]")
        axes[1].legend(fontsize=7, loc="upper right")
        name = report.ranking.evaluations[k].name or f"grasp {k}"
        fig.suptitle(f"{title}: {name}" if title else name)
        out = path.with_name(f"{path.stem}_retime_{k}{path.suffix or '.png'}")
        fig.savefig(out, dpi=110)
        plt.close(fig)
        written.append(out)
    return written
