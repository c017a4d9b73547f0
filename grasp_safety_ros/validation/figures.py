"""PNG figures of the validation, in the spirit of the paper's (matplotlib, Agg backend)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from .records import Experiment, GraspRun

DPI = 110
ZOOM_BEFORE_S = 0.005
ZOOM_AFTER_S = 0.06


def _min_mid_max(runs: Sequence[GraspRun]) -> list[tuple[str, GraspRun]]:
    """The grasps of smallest, middle and largest effective mass at impact."""
    order = np.argsort([run.collision.effective_mass_at_impact_kg for run in runs], kind="stable")
    if len(order) < 3:
        return [("", runs[k]) for k in order]
    picks = (("min", order[0]), ("middle", order[len(order) // 2]), ("max", order[-1]))
    return [(label, runs[k]) for label, k in picks]


def _heatmap(path: Path, experiment: Experiment, runs: Sequence[GraspRun]) -> Path:
    masses = np.array([run.evaluation.effective_mass_kg for run in runs])
    times = runs[0].evaluation.times_s
    fig, ax = plt.subplots(figsize=(8.0, 0.25 * len(runs) + 1.8))
    image = ax.imshow(
        masses,
        aspect="auto",
        origin="lower",
        cmap="viridis",
        extent=(times[0], times[-1], 0.5, len(runs) + 0.5),
        interpolation="nearest",
    )
    contact = float(np.nanmean([run.collision.contact_time_s for run in runs]))
    ax.axvline(contact, color="white", linestyle="--", linewidth=1.0, label="impact")
    ax.set_yticks(np.arange(1, len(runs) + 1))
    ax.set_yticklabels([run.grasp.name for run in runs], fontsize="small")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("grasp")
    ax.set_title(f"{experiment.title}: effective mass along the trajectory")
    ax.legend(loc="upper left", fontsize="small")
    fig.colorbar(image, ax=ax, label="effective mass [kg]")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _mass_curves(path: Path, experiment: Experiment, runs: Sequence[GraspRun]) -> Path:
    fig, ax = plt.subplots(figsize=(7.0, 4.0))
    for run in runs:
        ax.plot(run.evaluation.times_s, run.evaluation.effective_mass_kg, label=run.grasp.name)
    contact = float(np.nanmean([run.collision.contact_time_s for run in runs]))
    ax.axvline(contact, color="grey", linestyle="--", linewidth=1.0, label="impact")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("effective mass along the motion [kg]")
    ax.set_title(f"{experiment.title}\neffective mass along the trajectory (core)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _forces(path: Path, experiment: Experiment, picks: list[tuple[str, GraspRun]]) -> Path:
    fig, (whole, zoom) = plt.subplots(1, 2, figsize=(11.0, 4.0))
    for label, run in picks:
        result = run.collision
        name = f"{run.grasp.name} ({label}, M_eff {result.effective_mass_at_impact_kg:.3f} kg)"
        if not label:
            name = f"{run.grasp.name} (M_eff {result.effective_mass_at_impact_kg:.3f} kg)"
        (line,) = whole.plot(result.times_s, result.sensor_force_n, linewidth=0.7, label=name)
        window = (result.times_s >= result.contact_time_s - ZOOM_BEFORE_S) & (
            result.times_s <= result.contact_time_s + ZOOM_AFTER_S
        )
        zoom.plot(
            result.times_s[window],
            result.sensor_force_n[window],
            color=line.get_color(),
            label=f"{run.grasp.name}: peak {result.peak_force_n:.2f} N",
        )
        zoom.plot(result.peak_time_s, result.peak_force_n, "o", color=line.get_color(), ms=4)
    whole.set_title("sensor force over the whole record", fontsize=10)
    zoom.set_title("first impact", fontsize=10)
    for ax in (whole, zoom):
        ax.set_xlabel("time [s]")
        ax.set_ylabel("force on the sensor [N]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    fig.suptitle(f"{experiment.title}: simulated impact forces (MuJoCo)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _scatter(
    path: Path,
    experiments: Sequence[tuple[Experiment, Sequence[GraspRun]]],
    results: dict[str, Any],
) -> Path:
    fig, axes = plt.subplots(1, len(experiments), figsize=(5.5 * len(experiments), 4.2))
    axes = np.atleast_1d(axes)
    for ax, (experiment, runs) in zip(axes, experiments, strict=True):
        masses = np.array([run.collision.effective_mass_at_impact_kg for run in runs])
        peaks = np.array([run.collision.peak_force_n for run in runs])
        summary = results[experiment.key]
        ax.plot(
            masses,
            peaks,
            "o",
            label=f"main (Spearman {summary['spearman_meff_vs_peak_force']:.3f})",
        )
        for name, mass, peak in zip([run.grasp.name for run in runs], masses, peaks, strict=True):
            ax.annotate(name, (mass, peak), fontsize=6, xytext=(2, 2), textcoords="offset points")
        if "main_from_1.3s" in runs[0].variants:
            repeat = np.array([run.variants["main_from_1.3s"].peak_force_n for run in runs])
            spearman = summary["variants"]["main_from_1.3s"]["spearman_meff_vs_peak_force"]
            ax.plot(
                masses,
                repeat,
                "x",
                ms=4,
                label=f"main, repeated from 1.3 s (Spearman {spearman:.3f})",
            )
        variant = runs[0].variants.get("frictionless")
        if variant is not None:
            free = np.array([run.variants["frictionless"].peak_force_n for run in runs])
            spearman = summary["variants"]["frictionless"]["spearman_meff_vs_peak_force"]
            ax.plot(
                masses,
                free,
                "s",
                mfc="none",
                label=f"frictionless contact (Spearman {spearman:.3f})",
            )
        ax.set_xlabel("effective mass at impact (core) [kg]")
        ax.set_ylabel("peak impact force (MuJoCo) [N]")
        ax.set_title(experiment.title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _impulses(path: Path, results: dict[str, Any]) -> Path:
    check = results["impulse_check"]
    cases = check["per_case"]
    predicted = np.array([case["predicted_impulse_n_s"] for case in cases])
    measured = np.array([case["impulse_n_s"] for case in cases])
    errors = np.array([case["rel_error"] for case in cases])
    fig, (parity, spread) = plt.subplots(1, 2, figsize=(10.0, 4.0))
    for key in dict.fromkeys(case["experiment"] for case in cases):
        chosen = np.array([case["experiment"] == key for case in cases])
        parity.plot(predicted[chosen], measured[chosen], ".", ms=5, label=key.replace("_", " "))
    span = np.array([predicted.min(), predicted.max()])
    parity.plot(span, span, "k--", linewidth=0.8, label="measured = (1 + e) M_eff v")
    parity.set_xlabel("(1 + e) M_eff v, M_eff from the core [N s]")
    parity.set_ylabel("contact impulse in MuJoCo [N s]")
    parity.set_title(f"{check['cases']} free impacts, joints unactuated", fontsize=10)
    parity.grid(alpha=0.3)
    parity.legend(fontsize="small")
    spread.semilogy(np.arange(len(errors)), np.maximum(errors, 1e-12), ".", ms=5)
    spread.axhline(0.03, color="red", linestyle="--", linewidth=0.8, label="3 % (issue #4)")
    spread.set_xlabel("case")
    spread.set_ylabel("relative error")
    spread.set_title(f"worst {check['worst_rel_error']:.2e}", fontsize=10)
    spread.grid(alpha=0.3, which="both")
    spread.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def write_figures(
    out_dir: Path,
    tensor: Experiment,
    tensor_runs: Sequence[GraspRun],
    book: Experiment,
    book_runs: Sequence[GraspRun],
    results: dict[str, Any],
) -> list[Path]:
    """Write every figure into ``out_dir``; return their paths."""
    return [
        _heatmap(out_dir / "tensor_effective_mass_heatmap.png", tensor, tensor_runs),
        _forces(out_dir / "tensor_impact_forces.png", tensor, _min_mid_max(tensor_runs)),
        _mass_curves(out_dir / "book_effective_mass.png", book, book_runs),
        _forces(out_dir / "book_impact_forces.png", book, [("", run) for run in book_runs]),
        _scatter(
            out_dir / "effective_mass_vs_peak_force.png",
            [(tensor, tensor_runs), (book, book_runs)],
            results,
        ),
        _impulses(out_dir / "impulse_check.png", results),
    ]
