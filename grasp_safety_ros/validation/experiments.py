"""The paper's two simulated experiments (tensor object, book) on the bundled Baxter, and the
free-impact check of the effective mass; ``reproduce`` runs them and writes the outputs."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.stats import spearmanr

from ..core.input_checks import pose_from_position_quat
from ..core.method.effective_mass import effective_mass_along, translational_mobility_in_base
from ..core.method.posture import DEFAULT_RESTARTS, PostureConfig, select_posture
from ..core.method.ranking import Grasp, GraspEvaluation, GraspSafetyEvaluator
from ..core.model.inertia import (
    TensorObjectGeometry,
    solid_box,
    tensor_object_configurations,
)
from ..core.model.robot import RobotModel
from ..core.model.trajectory import ObjectTrajectory
from ..core.model.waypoint_trajectory import WaypointTrajectory
from .records import CandidateGrasp, Experiment, GraspRun, RunConfig, Variant
from .scene import ContactConfig, ObjectShape, SensorConfig
from .simulation import (
    CollisionResult,
    CollisionSetup,
    ControllerGains,
    ImpulseChecker,
    ImpulseSetup,
    simulate_collision,
)

ROBOT_SOURCE = "example-robot-data:baxter"
ARMATURE_IMPACTS, ARMATURE_IMPACTS_QUICK = 8, 3
"""Free impacts of the armature check (validation.armature_check): full and quick runs."""
BASE_FRAME = "base"
TIP_FRAME = "right_gripper"
SEED_POSITIONS = (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0)
"""IK seed of the right arm (right_s0 .. right_w2) [rad]."""

START_POSITION_M = (1.0, 0.0, 0.03)
GOAL_POSITION_M = (1.1, -0.38, 0.16)
QUAT_XYZW = (0.5, 0.5, 0.5, 0.5)
DURATION_S = 2.0
SAMPLE_PERIOD_S = 0.01
IMPACT_TIME_S = 1.5

BOOK_MASS_KG = 0.34
BOOK_SIZE_M = (0.15, 0.22, 0.015)
"""Book: x across the pages (15 cm), y along the spine (22 cm), z through it (1.5 cm)."""
BOOK_SPINE_X_M = -0.075
BOOK_GRASP_Y_M = (-0.1, 0.0, 0.1)

TENSOR_GRASP_ROTATION = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Tip axes in the tensor object's frame: tip z (approach) = -x, tip x = +y, tip y = -z."""

VIA_TIME_S = 1.0
VIA_LIFT_M = 0.08
VIA_TURN_RAD = 0.3
"""The waypoint case: the book passes 8 cm above the straight path's midpoint at 1 s, turned
by 0.3 rad about its spine (object y), and reaches the same goal at the same 2 s."""

PAPER_BOOK_PEAK_FORCES_N = (100.0, 130.0)
"""Gazebo peak impact forces of the safest and least safe book grasps in the paper [N]."""

COMMAND = ".venv/bin/grasp-safety reproduce --out {out}"


def tip_start_goal() -> tuple[pin.SE3, pin.SE3]:
    """The paper's end-effector start and goal poses in the base frame."""
    return (
        pose_from_position_quat(START_POSITION_M, QUAT_XYZW, "start"),
        pose_from_position_quat(GOAL_POSITION_M, QUAT_XYZW, "goal"),
    )


def tensor_grasp_pose(geometry: TensorObjectGeometry) -> pin.SE3:
    """The tip holds the end of the handle (+x rod), the handle along the approach axis."""
    return pin.SE3(TENSOR_GRASP_ROTATION, np.array([geometry.rod_length_m, 0.0, 0.0]))


def tensor_shape(geometry: TensorObjectGeometry) -> ObjectShape:
    """Five rods as capsules (visual only)."""
    length, radius = geometry.rod_length_m, geometry.rod_radius_m
    ends = ((length, 0, 0), (-length, 0, 0), (0, length, 0), (0, -length, 0), (0, 0, length))
    return ObjectShape(capsules=tuple(((0.0, 0.0, 0.0), end, radius) for end in ends))


def tensor_experiment(indices: Sequence[int] | None = None) -> Experiment:
    """The tensor object: 20 ring configurations, one grasp pose, one tip trajectory.

    The end-effector moves from p0 to pf with constant orientation (the paper's tip
    trajectory), so the object trajectory is the tip's composed with the inverse grasp.
    """
    geometry = TensorObjectGeometry()
    grasp = tensor_grasp_pose(geometry)
    configurations = tensor_object_configurations(geometry)
    chosen = range(len(configurations)) if indices is None else indices
    grasps = tuple(
        CandidateGrasp(
            name=f"T{index + 1:02d}",
            object_inertia=geometry.inertia(*configurations[index]),
            transform_tip_to_object=grasp,
            parameters={
                "configuration": index + 1,
                "x_ring_distance_m": configurations[index][0],
                "y_ring_distance_m": configurations[index][1],
            },
        )
        for index in chosen
    )
    tip_start, tip_goal = tip_start_goal()
    trajectory = ObjectTrajectory(
        tip_start * grasp.inverse(), tip_goal * grasp.inverse(), DURATION_S, SAMPLE_PERIOD_S
    )
    return Experiment(
        key="tensor_object",
        title="Tensor object (0.43 kg, 20 ring configurations)",
        grasps=grasps,
        trajectory=trajectory,
        shape=tensor_shape(geometry),
        description=(
            "Core model of the tensor object (TensorObjectGeometry: five 0.15 m rods, paired "
            "sliding rings, 0.43 kg). The tip holds the end of the +x rod (the handle) with the "
            "handle along the gripper's approach axis; configuration k sets the x and y ring "
            "distances (a 5 x 4 grid). The tip moves from p0 to pf in 2 s with constant "
            "orientation; the joint trajectory is the same for every configuration."
        ),
    )


def book_experiment() -> Experiment:
    """The book: three grasps along the spine; the book follows the paper's trajectory."""
    book = solid_box(BOOK_MASS_KG, BOOK_SIZE_M)
    grasps = tuple(
        CandidateGrasp(
            name=f"spine {y:+.1f} m",
            object_inertia=book,
            transform_tip_to_object=pin.SE3(np.eye(3), np.array([BOOK_SPINE_X_M, y, 0.0])),
            parameters={"spine_position_m": y},
        )
        for y in BOOK_GRASP_Y_M
    )
    start, goal = tip_start_goal()  # the paper's poses, used here for the book's frame
    half = (0.5 * BOOK_SIZE_M[0], 0.5 * BOOK_SIZE_M[1], 0.5 * BOOK_SIZE_M[2])
    return Experiment(
        key="book",
        title="Book (22 x 15 x 1.5 cm, 0.34 kg, 3 grasps on the spine)",
        grasps=grasps,
        trajectory=ObjectTrajectory(start, goal, DURATION_S, SAMPLE_PERIOD_S),
        shape=ObjectShape(boxes=(((0.0, 0.0, 0.0), half),)),
        description=(
            "Solid box 0.15 x 0.22 x 0.015 m (x, y, z), 0.34 kg, frame at its centre; the spine "
            "is the edge x = -0.075 m and the grasps hold it at y = -0.1, 0, +0.1 m with the "
            "tip axes parallel to the book's (as config/book_baxter.yaml). The book's frame "
            "follows p0 -> pf in 2 s with constant orientation, so each grasp gives another "
            "wrist trajectory."
        ),
    )


def book_waypoints_experiment() -> Experiment:
    """The book's grasps along a three-waypoint path with the straight path's ends and time."""
    straight = book_experiment()
    start, goal = tip_start_goal()
    via = pin.SE3(
        start.rotation @ pin.exp3(np.array([0.0, VIA_TURN_RAD, 0.0])),
        0.5 * (start.translation + goal.translation) + np.array([0.0, 0.0, VIA_LIFT_M]),
    )
    return replace(
        straight,
        key="book_waypoints",
        title="Book along a timed waypoint path (3 waypoints)",
        trajectory=WaypointTrajectory(
            (0.0, VIA_TIME_S, DURATION_S), (start, via, goal), SAMPLE_PERIOD_S
        ),
        description=(
            "The book and grasps above along a timed waypoint path: p0 at 0 s, the midpoint of "
            f"p0 and pf raised by {VIA_LIFT_M:g} m and turned by {VIA_TURN_RAD:g} rad about the "
            f"spine (object y) at {VIA_TIME_S:g} s, pf at {DURATION_S:g} s (C2 quintic-spline "
            "interpolation, at rest at both ends). Main pillar setup only (no ablations, no "
            "free impacts); the change columns compare with the straight path."
        ),
    )


def compare_paths(
    straight: Sequence[GraspRun], waypoints: Sequence[GraspRun]
) -> list[dict[str, Any]]:
    """Per grasp, waypoint path over straight path − 1: effective mass at impact, approach
    speed, peak force, and peak force per unit approach speed (the speed-free part, which a
    spring load cell makes grow like √M_eff)."""
    rows = []
    for a, b in zip(straight, waypoints, strict=True):
        first, second = a.collision, b.collision
        mass = second.effective_mass_at_impact_kg / first.effective_mass_at_impact_kg
        speed = second.approach_speed_m_s / first.approach_speed_m_s
        peak = second.peak_force_n / first.peak_force_n
        rows.append(
            {
                "name": a.grasp.name,
                "effective_mass_at_impact_change": float(mass - 1.0),
                "sqrt_effective_mass_change": float(np.sqrt(mass) - 1.0),
                "approach_speed_change": float(speed - 1.0),
                "peak_force_change": float(peak - 1.0),
                "peak_force_per_speed_change": float(peak / speed - 1.0),
            }
        )
    return rows


VARIANTS = (
    Variant(
        "main_from_1.3s",
        "the main settings, simulated from 1.3 s instead of 0 s: the baseline of the other "
        "ablations and a measure of the numerical noise of the peak force",
    ),
    Variant(
        "frictionless",
        "frictionless contact (condim 1): the impulse is along the normal only, as in the "
        "effective-mass model",
        contact=ContactConfig(friction=0.0),
    ),
    Variant(
        "rigid_plate",
        "sensor plate welded to the pillar (no load cell); force = MuJoCo's soft contact force "
        "(solref 0.3 ms), which MuJoCo scales with the effective mass of the contact",
        sensor=SensorConfig(stiffness_n_m=None),
    ),
    Variant(
        "no_torque_limits",
        "joint torques not clipped to the URDF effort limits (simulated to 3 s)",
        gains=ControllerGains(clip_to_effort_limits=False),
        end_time_s=3.0,
    ),
    Variant(
        "control_1khz",
        "controller updated at 1 kHz with a zero-order hold instead of at every physics step",
        gains=ControllerGains(period_s=1e-3),
    ),
)


FULL = RunConfig(
    tensor_indices=None,
    setup=CollisionSetup(start_time_s=0.0, end_time_s=3.0),
    variant_setup=CollisionSetup(start_time_s=1.3, end_time_s=1.6),
    variants=VARIANTS,
    impulse_times_s=(0.4, 0.8, 1.2, 1.5, 1.8),
)
"""The full run: every grasp, tracked from t = 0, records 3 s as the paper did."""

QUICK = RunConfig(
    tensor_indices=(0, 3, 9, 10, 16, 19),  # the 4 corners and 2 middle cells of the 5 x 4 grid
    setup=CollisionSetup(start_time_s=1.3, end_time_s=1.6),
    variant_setup=CollisionSetup(start_time_s=1.3, end_time_s=1.6),
    variants=(),
    impulse_times_s=(0.75, 1.5),
)
"""The quick run (CI): 6 tensor configurations and the book, simulated from 1.3 s to 1.6 s."""


def _rank_correlation(x: Sequence[float], y: Sequence[float]) -> float:
    if len(x) < 2 or np.ptp(x) == 0.0 or np.ptp(y) == 0.0:
        return float("nan")
    return float(spearmanr(x, y).statistic)


def run_experiment(
    robot: RobotModel,
    experiment: Experiment,
    config: RunConfig,
    log: Callable[[str], None] | None = None,
) -> list[GraspRun]:
    """Core evaluation, pillar impacts (main + variants) and free impacts of each grasp."""
    evaluator = GraspSafetyEvaluator(robot)
    runs = []
    for candidate in experiment.grasps:
        evaluation = evaluator.evaluate(
            Grasp(candidate.transform_tip_to_object, candidate.name),
            candidate.object_inertia,
            experiment.trajectory,
            seed_positions=SEED_POSITIONS,
        )
        arguments = (
            robot,
            ROBOT_SOURCE,
            candidate.object_inertia,
            candidate.transform_tip_to_object,
            evaluation,
        )
        collision = simulate_collision(*arguments, config.setup, experiment.shape)
        variants = {}
        for variant in config.variants:
            setup = replace(
                config.variant_setup,
                contact=variant.contact or config.variant_setup.contact,
                sensor=variant.sensor or config.variant_setup.sensor,
                gains=variant.gains or config.variant_setup.gains,
                end_time_s=variant.end_time_s or config.variant_setup.end_time_s,
            )
            variants[variant.key] = simulate_collision(*arguments, setup, experiment.shape)
        checker = ImpulseChecker(
            robot,
            ROBOT_SOURCE,
            candidate.object_inertia,
            candidate.transform_tip_to_object,
            config.impulse,
        )
        cases = []
        for sample_time in config.impulse_times_s:
            index = int(np.argmin(np.abs(evaluation.times_s - sample_time)))
            cases.append(
                (
                    float(evaluation.times_s[index]),
                    checker.run(
                        evaluation.joint_positions[index],
                        evaluation.directions_in_base[index],
                        float(evaluation.effective_mass_kg[index]),
                    ),
                )
            )
        robot_only = _robot_only_effective_mass(robot, evaluation)
        runs.append(GraspRun(candidate, evaluation, collision, variants, cases, robot_only))
        if log is not None:
            log(
                f"  {experiment.key} {candidate.name}: M_eff at impact "
                f"{collision.effective_mass_at_impact_kg:.4f} kg, peak force "
                f"{collision.peak_force_n:.2f} N"
            )
    return runs


def posture_comparison(
    robot: RobotModel,
    experiment: Experiment,
    runs: Sequence[GraspRun],
    setup: CollisionSetup,
    restarts: int = DEFAULT_RESTARTS,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Pillar impacts of the single-IK posture (``runs``) against the selected posture
    (core.method.posture, ``restarts``) for the same grasps, same object path and same pillar.

    Returns:
        The posture_selection part of results.json: per grasp the mean effective mass, the
        effective mass at impact and the peak force of both postures, their relative changes,
        and the change of the peak force a spring sensor predicts, sqrt(M_sel / M_single) - 1.
    """
    evaluator = GraspSafetyEvaluator(robot)
    config = PostureConfig(restarts=restarts, early_stop=False)  # every posture's score range
    grasps = []
    for run in runs:
        candidate = run.grasp
        chosen, selection = select_posture(
            evaluator,
            Grasp(candidate.transform_tip_to_object, candidate.name),
            candidate.object_inertia,
            experiment.trajectory,
            run.evaluation,
            config,
            "mean",
        )
        collision = run.collision
        if selection.selected > 0:
            collision = simulate_collision(
                robot,
                ROBOT_SOURCE,
                candidate.object_inertia,
                candidate.transform_tip_to_object,
                chosen,
                setup,
                experiment.shape,
            )
        single, selected = run.collision, collision
        mass_ratio = selected.effective_mass_at_impact_kg / single.effective_mass_at_impact_kg
        grasps.append(
            {
                "name": candidate.name,
                "postures_tried": selection.postures_tried,
                "postures_feasible": selection.postures_feasible,
                "selected_is_single_ik": selection.selected == 0,
                "start_positions_single_ik": run.evaluation.joint_positions[0].tolist(),
                "start_positions_selected": chosen.joint_positions[0].tolist(),
                "mean_effective_mass_single_ik_kg": run.evaluation.mean_effective_mass_kg,
                "mean_effective_mass_selected_kg": chosen.mean_effective_mass_kg,
                "score_range_kg": list(selection.score_range),
                "effective_mass_at_impact_single_ik_kg": single.effective_mass_at_impact_kg,
                "effective_mass_at_impact_selected_kg": selected.effective_mass_at_impact_kg,
                "peak_force_single_ik_n": single.peak_force_n,
                "peak_force_selected_n": selected.peak_force_n,
                "mean_effective_mass_change": chosen.mean_effective_mass_kg
                / run.evaluation.mean_effective_mass_kg
                - 1.0,
                "effective_mass_at_impact_change": mass_ratio - 1.0,
                "peak_force_change": selected.peak_force_n / single.peak_force_n - 1.0,
                "predicted_peak_force_change_sqrt": math.sqrt(mass_ratio) - 1.0,
                "first_torque_saturation_time_selected_s": _finite(
                    selected.first_saturation_time_s
                ),
            }
        )
        if log is not None:
            log(
                f"  posture {candidate.name}: M_eff at impact "
                f"{single.effective_mass_at_impact_kg:.4f} -> "
                f"{selected.effective_mass_at_impact_kg:.4f} kg, peak force "
                f"{single.peak_force_n:.2f} -> {selected.peak_force_n:.2f} N"
            )
    return {"experiment": experiment.key, "restarts": restarts, "grasps": grasps}


def _robot_only_effective_mass(robot: RobotModel, evaluation: GraspEvaluation) -> np.ndarray:
    data = robot.model.createData()
    masses = np.empty(len(evaluation.times_s))
    for i, positions in enumerate(evaluation.joint_positions):
        mobility = translational_mobility_in_base(
            robot, robot.model, data, robot.q_from_positions(positions)
        )
        masses[i] = effective_mass_along(mobility, evaluation.directions_in_base[i])
    return masses


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _collision_dict(result: CollisionResult) -> dict[str, Any]:
    record_peak = float(np.max(result.sensor_force_n)) if len(result.sensor_force_n) else math.nan
    return {
        "contact_time_s": _finite(result.contact_time_s),
        "effective_mass_at_impact_kg": _finite(result.effective_mass_at_impact_kg),
        "peak_force_n": _finite(result.peak_force_n),
        "peak_time_s": _finite(result.peak_time_s),
        "impulse_n_s": _finite(result.impulse_n_s),
        "peak_contact_force_n": _finite(result.peak_contact_force_n),
        "approach_speed_m_s": _finite(result.approach_speed_m_s),
        "max_force_whole_record_n": _finite(record_peak),
        "final_force_n": _finite(float(result.sensor_force_n[-1])),
        "tracking_error_before_contact_rad": result.tracking_error_rad,
        "first_torque_saturation_time_s": _finite(result.first_saturation_time_s),
        "first_torque_saturation_joint": result.first_saturation_joint or None,
    }


def _ordering(names: Sequence[str], values: Sequence[float]) -> list[str]:
    return [names[k] for k in np.argsort(values, kind="stable")]


def summarise_experiment(runs: Sequence[GraspRun], variants: Sequence[Variant]) -> dict[str, Any]:
    """The per-experiment part of results.json."""
    names = [run.grasp.name for run in runs]
    at_impact = [run.collision.effective_mass_at_impact_kg for run in runs]
    mean_mass = [run.evaluation.mean_effective_mass_kg for run in runs]
    peaks = [run.collision.peak_force_n for run in runs]
    impulses = [run.collision.impulse_n_s for run in runs]
    grasps = []
    for run in runs:
        entry: dict[str, Any] = {"name": run.grasp.name, **run.grasp.parameters}
        entry["mean_effective_mass_kg"] = run.evaluation.mean_effective_mass_kg
        entry.update(_collision_dict(run.collision))
        entry["robot_only_effective_mass_at_impact_kg"] = _finite(
            float(
                np.interp(
                    run.collision.contact_time_s,
                    run.evaluation.times_s,
                    run.robot_only_effective_mass_kg,
                )
            )
        )
        entry["variants"] = {
            key: {
                "peak_force_n": _finite(result.peak_force_n),
                "impulse_n_s": _finite(result.impulse_n_s),
                "effective_mass_at_impact_kg": _finite(result.effective_mass_at_impact_kg),
                "first_torque_saturation_time_s": _finite(result.first_saturation_time_s),
                "max_force_whole_record_n": _finite(float(np.max(result.sensor_force_n))),
            }
            for key, result in run.variants.items()
        }
        grasps.append(entry)
    summary: dict[str, Any] = {
        "spearman_meff_vs_peak_force": _rank_correlation(at_impact, peaks),
        "spearman_meff_vs_impulse": _rank_correlation(at_impact, impulses),
        "spearman_mean_meff_vs_peak_force": _rank_correlation(mean_mass, peaks),
        "peak_force_ratio_worst_to_best": float(max(peaks) / min(peaks)),
        "effective_mass_ratio_worst_to_best": float(max(at_impact) / min(at_impact)),
        "order_by_effective_mass_at_impact": _ordering(names, at_impact),
        "order_by_mean_effective_mass": _ordering(names, mean_mass),
        "order_by_peak_force": _ordering(names, peaks),
    }
    summary["ordering_holds"] = (
        summary["order_by_effective_mass_at_impact"] == summary["order_by_peak_force"]
    )
    summary["variants"] = {}
    for variant in variants:
        variant_peaks = [run.variants[variant.key].peak_force_n for run in runs]
        variant_impulses = [run.variants[variant.key].impulse_n_s for run in runs]
        variant_mass = [run.variants[variant.key].effective_mass_at_impact_kg for run in runs]
        ratios = np.array(variant_peaks) / np.array(peaks)
        summary["variants"][variant.key] = {
            "description": variant.description,
            "spearman_meff_vs_peak_force": _rank_correlation(variant_mass, variant_peaks),
            "spearman_meff_vs_impulse": _rank_correlation(variant_mass, variant_impulses),
            "peak_force_ratio_worst_to_best": float(max(variant_peaks) / min(variant_peaks)),
            "peak_force_min_n": float(min(variant_peaks)),
            "peak_force_max_n": float(max(variant_peaks)),
            "peak_force_over_main_min": float(ratios.min()),
            "peak_force_over_main_max": float(ratios.max()),
            "order_by_peak_force": _ordering(names, variant_peaks),
            "ordering_holds": _ordering(names, variant_mass) == _ordering(names, variant_peaks),
        }
    summary["grasps"] = grasps
    return summary


def summarise_impulses(
    experiments: Sequence[tuple[str, Sequence[GraspRun]]], setup: ImpulseSetup
) -> dict[str, Any]:
    """The impulse_check part of results.json."""
    per_case: list[dict[str, str | float | bool]] = []
    cases = [case for _, runs in experiments for run in runs for _, case in run.impulse_cases]
    for key, runs in experiments:
        for run in runs:
            for sample_time, case in run.impulse_cases:
                per_case.append(
                    {
                        "experiment": key,
                        "grasp": run.grasp.name,
                        "time_s": sample_time,
                        "effective_mass_kg": case.effective_mass_kg,
                        "engine_effective_mass_kg": case.engine_effective_mass_kg,
                        "impulse_n_s": case.impulse_n_s,
                        "predicted_impulse_n_s": case.predicted_impulse_n_s,
                        "restitution": case.restitution,
                        "rel_error": case.rel_error,
                        "contact_duration_s": case.duration_s,
                        "joint_limit_active": case.limit_active,
                    }
                )
    errors = [case.rel_error for case in cases]
    engine = [abs(case.engine_effective_mass_kg / case.effective_mass_kg - 1.0) for case in cases]
    restitution = [case.restitution for case in cases]
    return {
        "worst_rel_error": float(max(errors)),
        "mean_rel_error": float(np.mean(errors)),
        "cases": len(per_case),
        "speed_m_s": setup.speed_m_s,
        "timestep_s": setup.timestep_s,
        "contact_solref": [setup.contact.timeconst_s, setup.contact.dampratio],
        "restitution_min": float(min(restitution)),
        "restitution_max": float(max(restitution)),
        "engine_vs_core_effective_mass_max_rel_diff": float(max(engine)),
        "joint_limit_active_cases": int(sum(case.limit_active for case in cases)),
        "per_case": per_case,
    }
