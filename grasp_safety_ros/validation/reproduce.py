"""``reproduce``: run every validation experiment and write results.json, results.md and the
figures (the top of the validation package: nothing in it imports this module)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import replace
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np

from ..core.method.ranking import Grasp
from ..core.model.robot import RobotModel
from .armature_check import armature_impulse_check
from .elbow import elbow_impact, format_elbow
from .experiments import (
    ARMATURE_IMPACTS,
    ARMATURE_IMPACTS_QUICK,
    BASE_FRAME,
    COMMAND,
    DURATION_S,
    FULL,
    GOAL_POSITION_M,
    PAPER_BOOK_PEAK_FORCES_N,
    QUAT_XYZW,
    QUICK,
    ROBOT_SOURCE,
    SAMPLE_PERIOD_S,
    SEED_POSITIONS,
    START_POSITION_M,
    TIP_FRAME,
    book_experiment,
    book_waypoints_experiment,
    compare_paths,
    posture_comparison,
    run_experiment,
    summarise_experiment,
    summarise_impulses,
    tensor_experiment,
)
from .figures import write_figures
from .records import RunConfig
from .report import results_markdown


def _package_version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "unknown"


def _setup_dict(config: RunConfig, quick: bool) -> dict[str, Any]:
    setup = config.setup
    return {
        "quick": quick,
        "robot": {
            "urdf": ROBOT_SOURCE,
            "base_frame": BASE_FRAME,
            "tip_frame": TIP_FRAME,
            "seed": list(SEED_POSITIONS),
        },
        "tip_or_object_trajectory": {
            "start_position_m": list(START_POSITION_M),
            "goal_position_m": list(GOAL_POSITION_M),
            "quat_xyzw": list(QUAT_XYZW),
            "duration_s": DURATION_S,
            "dt_s": SAMPLE_PERIOD_S,
        },
        "pillar": {
            "planned_impact_time_s": setup.impact_time_s,
            "simulated_from_s": setup.start_time_s,
            "simulated_to_s": setup.end_time_s,
            "timestep_s": setup.timestep_s,
            "impact_timestep_s": setup.impact_timestep_s,
            "tip_sphere_radius_m": setup.tip_sphere_radius_m,
            "peak_window_s": setup.peak_window_s,
            "contact": vars(setup.contact),
            "sensor": vars(setup.sensor),
            "controller": vars(setup.gains),
        },
        "variants_simulated_from_to_s": [
            config.variant_setup.start_time_s,
            config.variant_setup.end_time_s,
        ],
        "impulse_sample_times_s": list(config.impulse_times_s),
        "versions": {
            name: _package_version(name)
            for name in ("mujoco", "pin", "example-robot-data", "numpy", "scipy")
        },
    }


def reproduce(
    out_dir: Path, quick: bool = False, log: Callable[[str], None] | None = None
) -> dict[str, Any]:
    """Run the validation, write results.json, results.md and the figures into ``out_dir``.

    Args:
        out_dir: Output folder (created).
        quick: The reduced run (QUICK) instead of the full one (FULL).
        log: Called with one progress line per grasp, if given.

    Returns:
        The results, as written to results.json.
    """
    started = time.perf_counter()
    config = QUICK if quick else FULL
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    robot = RobotModel.from_urdf(ROBOT_SOURCE, BASE_FRAME, TIP_FRAME)
    tensor = tensor_experiment(config.tensor_indices)
    book = book_experiment()
    tensor_runs = run_experiment(robot, tensor, config, log)
    book_runs = run_experiment(robot, book, config, log)
    postures = posture_comparison(robot, book, book_runs, config.setup, log=log)
    waypoints = book_waypoints_experiment()
    waypoint_runs = run_experiment(
        robot, waypoints, replace(config, variants=(), impulse_times_s=()), log
    )
    simulated = time.perf_counter()
    command = COMMAND.format(out=out_dir) + (" --quick" if quick else "")
    results: dict[str, Any] = {
        "schema_version": 1,
        "command": command,
        "setup": _setup_dict(config, quick),
        "tensor_object": {
            "description": tensor.description,
            **summarise_experiment(tensor_runs, config.variants),
        },
        "book": {
            "description": book.description,
            **summarise_experiment(book_runs, config.variants),
        },
        "book_waypoints": {
            "description": waypoints.description,
            **summarise_experiment(waypoint_runs, ()),
            "change_from_straight_path": compare_paths(book_runs, waypoint_runs),
        },
        "impulse_check": summarise_impulses(
            [(tensor.key, tensor_runs), (book.key, book_runs)], config.impulse
        ),
        "posture_selection": postures,
        "elbow_impact": elbow_impact(
            robot,
            ROBOT_SOURCE,
            book.grasps[0].object_inertia,
            Grasp(book.grasps[0].transform_tip_to_object, book.grasps[0].name),
            book_runs[0].evaluation,
            book.trajectory,
            config.impulse,
        ),
        "impulse_check_armature": armature_impulse_check(
            ARMATURE_IMPACTS_QUICK if quick else ARMATURE_IMPACTS, config.impulse, log=log
        ),
    }
    low, high = PAPER_BOOK_PEAK_FORCES_N
    results["book"]["paper_gazebo"] = {
        "peak_force_safest_n": low,
        "peak_force_least_safe_n": high,
        "peak_force_ratio_worst_to_best": high / low,
    }
    figures = write_figures(out_dir, tensor, tensor_runs, book, book_runs, results)
    results["figures"] = [path.name for path in figures]
    results["timing_s"] = {
        "simulation": round(simulated - started, 2),
        "total": round(time.perf_counter() - started, 2),
    }
    results = _json_safe(results)
    (out_dir / "results.json").write_text(
        json.dumps(results, indent=1, allow_nan=False) + "\n", encoding="utf-8"
    )
    (out_dir / "results.md").write_text(results_markdown(results), encoding="utf-8")
    return results


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(item) for item in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def format_summary(results: dict[str, Any]) -> str:
    """The headline figures, for the terminal."""
    tensor, book, impulse = results["tensor_object"], results["book"], results["impulse_check"]
    paper = book["paper_gazebo"]
    lines = [
        f"validation ({'quick' if results['setup']['quick'] else 'full'} run, "
        f"{results['timing_s']['total']:.1f} s)",
        f"  tensor object: Spearman(M_eff at impact, peak force) = "
        f"{tensor['spearman_meff_vs_peak_force']:.3f} over {len(tensor['grasps'])} grasps; "
        f"peak force worst/best = {tensor['peak_force_ratio_worst_to_best']:.4f} "
        f"(M_eff worst/best = {tensor['effective_mass_ratio_worst_to_best']:.4f})",
        f"  book: peak force worst/best = {book['peak_force_ratio_worst_to_best']:.4f} "
        f"({min(g['peak_force_n'] for g in book['grasps']):.1f} N to "
        f"{max(g['peak_force_n'] for g in book['grasps']):.1f} N); paper (Gazebo): "
        f"{paper['peak_force_ratio_worst_to_best']:.2f} ({paper['peak_force_safest_n']:.0f} N to "
        f"{paper['peak_force_least_safe_n']:.0f} N); ordering by M_eff holds: "
        f"{'yes' if book['ordering_holds'] else 'NO'}",
        f"  impulse check: worst |P - (1+e) M_eff v| / P_pred = "
        f"{impulse['worst_rel_error']:.2e} over {impulse['cases']} free impacts "
        f"(e = {impulse['restitution_min']:.3f}..{impulse['restitution_max']:.3f})",
    ]
    if results.get("elbow_impact"):
        lines.append(format_elbow(results["elbow_impact"]))
    geared = results.get("impulse_check_armature")
    if geared and geared["valid_cases"]:
        lines.append(
            f"  impulse check with rotor inertia (Panda, FR3 armature): worst error "
            f"{geared['worst_rel_error']:.2e} with armature; the impulse exceeds the links-only "
            f"prediction by {geared['links_only_min_rel_error']:.1%} or more (median "
            f"{geared['links_only_median_rel_error']:.1%}, {geared['valid_cases']} free impacts); "
            f"peak force / (M_eff v) spread x{geared['peak_force_per_mass_spread']:.3f} "
            f"(links only x{geared['links_only_peak_force_per_mass_spread']:.3f})"
        )
    postures = results.get("posture_selection")
    if postures:
        changes = ", ".join(
            f"{g['name']} M_eff {100 * g['effective_mass_at_impact_change']:+.1f} % / force "
            f"{100 * g['peak_force_change']:+.1f} %"
            for g in postures["grasps"]
        )
        lines.append(f"  posture selection vs single IK (book, at impact): {changes}")
    return "\n".join(lines)
