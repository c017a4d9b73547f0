"""bench/run.py's section per arm (issue #5): the ranking hot path (IK + effective mass per grasp
and sample) of Panda and Baxter's right arm on bench/workload.py's workload (a box, 100 grasps
around it, a 2 s quintic trajectory sampled every 0.01 s), measured in one process, interleaved,
repeated (median and spread): ours serial, parallel and on the Python/Pinocchio path; the PyKDL
peer (bench/pykdl_peer.py); the pre-issue implementation (bench/reference.py); identities
between them; the physical floor; cProfile of one ranking (run.py's docstring lists each)."""

from __future__ import annotations

import argparse
import cProfile
import itertools
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from _common import rel_diff, summary, timed, top_functions
from kdl_chain import build_chain
from pykdl_peer import PyKDLPipeline
from reference import ReferenceIK, reference_effective_masses
from workload import ArmWorkload, box_object, grasps_around_box

from grasp_safety_ros.core import GraspSafetyEvaluator
from grasp_safety_ros.core.method.effective_mass import (
    effective_masses_along,
    translational_mobilities_in_base,
)
from grasp_safety_ros.core.method.pool import default_workers
from grasp_safety_ros.core.method.ranking import EvaluationConfig, Ranking
from grasp_safety_ros.core.model.robot import resolve_urdf

FLOPS_PER_EVALUATION = 4000.0
FLOPS_PER_IK_ITERATION = 2000.0
FLOPS_PER_US = 6000.0
"""Assumed sustained scalar double rate of one core: 6 GFLOP/s (one FMA per cycle, 3 GHz)."""


def self_motion_fractions(robot: Any, q_path: np.ndarray) -> np.ndarray:
    """|(I - J^+ J) dq| / |dq| of each joint step dq of q_path, J the tip Jacobian at its
    start: the share of the step that moves the arm along its self-motion manifold."""
    import pinocchio as pin

    model, data = robot.model, robot.model.createData()
    jacobians = np.array(
        [
            pin.computeFrameJacobian(model, data, q, robot.tip_frame_id, pin.LOCAL)
            for q in q_path[:-1]
        ]
    )
    steps = np.array([pin.difference(model, a, b) for a, b in itertools.pairwise(q_path)])
    row_space = np.einsum("nij,nj->ni", np.linalg.pinv(jacobians) @ jacobians, steps)
    norms = np.linalg.norm(steps, axis=1)
    moving = norms > 0
    return np.linalg.norm(steps - row_space, axis=1)[moving] / norms[moving]


# ----------------------------------------------------------------------------- one arm
def bench_arm(arm: ArmWorkload, args: argparse.Namespace, kdl: Any) -> dict[str, Any]:
    robot = arm.robot()
    trajectory = arm.trajectory(2.0, 0.01)
    obj = box_object()
    grasps = grasps_around_box(np.array(arm.approach_from), args.grasps)
    seed = np.array(arm.seed_positions)
    samples = trajectory.num_samples
    total = len(grasps) * samples
    serial = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1))
    pooled = GraspSafetyEvaluator(robot, EvaluationConfig(workers=0, parallel_min_samples=1))
    fallback = GraspSafetyEvaluator(robot, EvaluationConfig(backend="python", workers=1))
    out: dict[str, Any] = {
        "robot": f"{arm.urdf} {arm.base_frame} -> {arm.tip_frame}",
        "grasps": len(grasps),
        "samples_per_grasp": samples,
        "backend": "compiled" if serial.ik.compiled else "python",
        "workers": default_workers(),
    }

    def rank(evaluator: GraspSafetyEvaluator) -> Ranking:
        return evaluator.rank(grasps, obj, trajectory, seed_positions=seed)

    print(f"[{arm.name}] warm-up (numba compiles or loads its cache)", file=sys.stderr)
    warm_s, ranking = timed(lambda: rank(serial))
    out["first_call_s"] = warm_s
    rank(pooled)
    feasible = [e for e in ranking.evaluations if e.feasible]
    feasible_samples = sum(len(e.times_s) for e in feasible)
    iterations = np.concatenate([e.ik_iterations for e in feasible])
    out["feasible_grasps"] = len(feasible)
    out["ik_iterations_per_sample"] = float(iterations.mean())
    out["ik_iterations_per_sample_excluding_first"] = float(
        np.concatenate([e.ik_iterations[1:] for e in feasible]).mean()
    )

    # The pre-issue implementation (every grasp): the body of reference_evaluate, timed.
    print(f"[{arm.name}] the pre-issue implementation (secant warm start)", file=sys.stderr)
    reference_ik = ReferenceIK(robot)
    seed_q = robot.q_from_positions(seed)
    times_s = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times_s)
    reference_paths: list[np.ndarray | None] = []
    start = time.perf_counter()
    for grasp in grasps:
        poses, tangents = trajectory.tip_path(grasp.transform_tip_to_object, s_values)
        q_path, _, reason = reference_ik.solve_trajectory(poses, times_s, s_values, seed_q)
        if not reason:
            reference_effective_masses(robot, grasp.transform_tip_to_object, obj, q_path, tangents)
        reference_paths.append(None if reason else q_path)
    reference_s = time.perf_counter() - start
    # Its effective-mass code on our joint paths (the identity that still holds), and how its
    # joint paths differ from ours (self-motion).
    worst, path_diff = 0.0, 0.0
    ours_self_motion, reference_self_motion = [], []
    for grasp, evaluation, q_reference in zip(
        grasps, ranking.evaluations, reference_paths, strict=True
    ):
        if q_reference is not None and len(q_reference) > 1:
            reference_self_motion.append(float(self_motion_fractions(robot, q_reference).max()))
        if not evaluation.feasible:
            continue
        q_ours = np.array([robot.q_from_positions(p) for p in evaluation.joint_positions])
        _, tangents = trajectory.tip_path(grasp.transform_tip_to_object, s_values)
        masses = reference_effective_masses(
            robot, grasp.transform_tip_to_object, obj, q_ours, tangents
        )
        worst = max(worst, rel_diff(evaluation.effective_mass_kg, masses))
        if len(q_ours) > 1:
            ours_self_motion.append(float(self_motion_fractions(robot, q_ours).max()))
        if q_reference is not None:
            path_diff = max(path_diff, float(np.abs(q_reference - q_ours).max()))
    names_ours = {g.name for g, e in zip(grasps, ranking.evaluations, strict=True) if e.feasible}
    names_reference = {
        g.name for g, q in zip(grasps, reference_paths, strict=True) if q is not None
    }
    out["reference"] = {
        "ik_warm_start": "secant (extrapolates the previous joint step)",
        "wall_s": reference_s,
        "us_per_sample_with_ik": reference_s / total * 1e6,
        "feasible_grasps": len(names_reference),
        "feasible_only_with_ours": sorted(names_ours - names_reference),
        "feasible_only_with_reference": sorted(names_reference - names_ours),
        "effective_mass_max_rel_diff_on_our_paths": worst,
        "max_joint_path_diff_rad": path_diff,
    }
    out["self_motion_fraction"] = {
        "ours_max": max(ours_self_motion, default=0.0),
        "ours_median_of_grasp_max": float(np.median(ours_self_motion)),
        "reference_max": max(reference_self_motion, default=0.0),
        "reference_median_of_grasp_max": float(np.median(reference_self_motion)),
    }

    # Peer.
    peer = None
    if kdl is not None:
        path, is_xml = resolve_urdf(arm.urdf)
        urdf_text = path if is_xml else Path(path).read_text()
        chain = build_chain(kdl, urdf_text, arm.base_frame, arm.tip_frame)
        peer = PyKDLPipeline(kdl, chain, serial.config.ik)
    peer_grasps = grasps[: args.peer_grasps]
    peer_total = len(peer_grasps) * samples

    def run_peer() -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        assert peer is not None
        return [
            peer.evaluate(
                trajectory,
                np.array(g.transform_tip_to_object.rotation),
                np.array(g.transform_tip_to_object.translation),
                obj.mass_kg,
                np.array(obj.com_in_object_m),
                np.array(obj.inertia_about_com_kgm2),
                seed,
            )
            for g in peer_grasps
        ]

    # Effective mass only (IK excluded): from the joint positions found above.
    chain_arrays = serial.ik.chain if serial.ik.compiled else None
    moving = [(g, e) for g, e in zip(grasps, ranking.evaluations, strict=True) if e.feasible]

    def effective_mass_only() -> None:
        for grasp, evaluation in moving:
            mobilities = translational_mobilities_in_base(
                robot,
                obj,
                grasp.transform_tip_to_object,
                evaluation.joint_positions,
                chain_arrays,
            )
            effective_masses_along(mobilities, evaluation.directions_in_base)

    def peer_effective_mass_only(results: list) -> None:
        assert peer is not None
        for grasp, (reason, _, q_all, _) in zip(peer_grasps, results, strict=True):
            if reason:
                continue
            s_values, _, _ = trajectory.path_parameter(trajectory.times_s())
            r = np.array(grasp.transform_tip_to_object.rotation)
            p = np.array(grasp.transform_tip_to_object.translation)
            _, _, tangents = peer.tip_path(trajectory, r, p, s_values)
            peer.effective_masses(
                q_all,
                tangents,
                r,
                p,
                obj.mass_kg,
                np.array(obj.com_in_object_m),
                np.array(obj.inertia_about_com_kgm2),
            )

    effective_mass_only()  # compiles (or loads) the batch kernel before timing
    timings: dict[str, list[float]] = {
        k: [] for k in ("serial", "without_ik", "parallel", "peer", "peer_without_ik")
    }
    peer_results: list = []
    cpu: dict[str, list[float]] = {"serial": [], "peer": []}
    for repeat in range(args.repeats):
        print(f"[{arm.name}] repeat {repeat + 1}/{args.repeats}", file=sys.stderr)
        cpu_start = time.process_time()
        timings["serial"].append(timed(lambda: rank(serial))[0])
        cpu["serial"].append(time.process_time() - cpu_start)
        timings["without_ik"].append(timed(effective_mass_only)[0])
        timings["parallel"].append(timed(lambda: rank(pooled))[0])
        if peer is not None and repeat < args.peer_repeats:
            cpu_start = time.process_time()
            elapsed, peer_results = timed(run_peer)
            cpu["peer"].append(time.process_time() - cpu_start)
            timings["peer"].append(elapsed)
            start = time.perf_counter()
            peer_effective_mass_only(peer_results)
            timings["peer_without_ik"].append(time.perf_counter() - start)
    fallback_s, fallback_ranking = timed(lambda: rank(fallback))

    with_ik = summary([t / total * 1e6 for t in timings["serial"]])
    without_ik = summary([t / feasible_samples * 1e6 for t in timings["without_ik"]])
    out["us_per_sample_with_ik"] = with_ik
    out["cpu_us_per_sample_with_ik"] = summary([t / total * 1e6 for t in cpu["serial"]])
    out["us_per_sample_without_ik"] = without_ik
    out["wall_s_serial"] = summary(timings["serial"])
    out["wall_s_parallel"] = summary(timings["parallel"])
    out["us_per_sample_with_ik_parallel"] = summary([t / total * 1e6 for t in timings["parallel"]])
    out["parallel_speedup"] = with_ik["median"] / out["us_per_sample_with_ik_parallel"]["median"]
    out["python_backend_us_per_sample_with_ik"] = fallback_s / total * 1e6
    pairs = list(zip(fallback_ranking.evaluations, ranking.evaluations, strict=True))
    out["python_backend_max_rel_diff"] = max(
        (
            rel_diff(a.effective_mass_kg, b.effective_mass_kg)
            for a, b in pairs
            if a.feasible and b.feasible
        ),
        default=0.0,
    )
    out["python_backend_same_feasibility"] = all(a.feasible == b.feasible for a, b in pairs)
    # The last iterate of a sample that does not converge (100 iterations) is chaotic: the
    # joints it leaves at a limit, named in the reason, may differ by rounding.
    out["python_backend_reasons_differ"] = [b.name for a, b in pairs if a.reason != b.reason]
    out["python_backend_same_ik_iterations"] = all(
        np.array_equal(a.ik_iterations, b.ik_iterations) for a, b in pairs
    )
    floor = (
        FLOPS_PER_EVALUATION + FLOPS_PER_IK_ITERATION * out["ik_iterations_per_sample"]
    ) / FLOPS_PER_US
    out["floor_us_per_sample"] = floor
    out["distance_to_floor"] = with_ik["median"] / floor
    out["distance_to_floor_without_ik"] = without_ik["median"] / (
        FLOPS_PER_EVALUATION / FLOPS_PER_US
    )

    if peer is not None:
        peer_feasible_samples = sum(len(m) for reason, m, _, _ in peer_results if not reason)
        out["pykdl"] = {
            "grasps": len(peer_grasps),
            "us_per_sample_with_ik": summary([t / peer_total * 1e6 for t in timings["peer"]]),
            "cpu_us_per_sample_with_ik": summary([t / peer_total * 1e6 for t in cpu["peer"]]),
            "us_per_sample_without_ik": summary(
                [t / max(peer_feasible_samples, 1) * 1e6 for t in timings["peer_without_ik"]]
            ),
        }
        # The KDL solver calls alone (FK + Jacobian + mass matrix at each solved sample, with
        # q set from Python): what the peer would cost with all its numpy glue compiled away.
        q_rows = [row for reason, _, q_all, _ in peer_results if not reason for row in q_all]
        start = time.perf_counter()
        for row in q_rows:
            peer._set_q(row)
            peer.fk.JntToCart(peer._q, peer._frame)
            peer.jac.JntToJac(peer._q, peer._jacobian)
            peer.dyn.JntToMass(peer._q, peer._mass)
        out["pykdl"]["kdl_calls_us_per_sample"] = (
            (time.perf_counter() - start) / max(len(q_rows), 1) * 1e6
        )
        diffs, agree = [], True
        for (reason, masses, _, _), evaluation in zip(
            peer_results, ranking.evaluations, strict=False
        ):
            agree &= (not reason) == evaluation.feasible
            if not reason and evaluation.feasible:
                diffs.append(rel_diff(masses, evaluation.effective_mass_kg))
        out["pykdl"]["max_rel_diff"] = max(diffs, default=float("nan"))
        out["pykdl"]["same_feasibility"] = agree
        ours_peer_subset = out["us_per_sample_with_ik"]["median"]
        out["speedup_vs_pykdl"] = (
            out["pykdl"]["us_per_sample_with_ik"]["median"] / ours_peer_subset
        )
        out["speedup_vs_pykdl_cpu"] = (
            out["pykdl"]["cpu_us_per_sample_with_ik"]["median"]
            / out["cpu_us_per_sample_with_ik"]["median"]
        )
        out["speedup_vs_pykdl_without_ik"] = (
            out["pykdl"]["us_per_sample_without_ik"]["median"] / without_ik["median"]
        )

    # Where the time goes.
    profile = cProfile.Profile()
    elapsed, _ = timed(lambda: profile.runcall(rank, serial))
    out["profile_ours"] = top_functions(profile, elapsed)
    if peer is not None:
        profile = cProfile.Profile()
        few = peer_grasps[:5]
        start = time.perf_counter()
        for g in few:
            profile.runcall(
                peer.evaluate,
                trajectory,
                np.array(g.transform_tip_to_object.rotation),
                np.array(g.transform_tip_to_object.translation),
                obj.mass_kg,
                np.array(obj.com_in_object_m),
                np.array(obj.inertia_about_com_kgm2),
                seed,
            )
        out["profile_pykdl"] = top_functions(profile, time.perf_counter() - start)
    return out
