#!/usr/bin/env python3
"""Benchmark of the ranking hot path (IK + effective mass per grasp and sample), issue #5.

Workload per arm (Panda and Baxter's right arm, example-robot-data): a box, 100 grasps
around it, a 2 s quintic object trajectory sampled every 0.01 s (201 samples), metric mean.
The same on a chain with continuous joints (Kinova Jaco2, ``--continuous-arm``): ours only,
serial, and its CPU time per sample relative to the slowest revolute arm's.
Measured in one process, interleaved, repeated (median and spread):

- ours, serial (one core): ``GraspSafetyEvaluator.rank`` with the compiled kernels; µs per
  (grasp, sample) with IK (whole rank / (grasps x samples)) and without IK (effective mass
  from given joint positions / feasible samples); total wall time; IK iterations per sample;
- ours, parallel (both cores, the evaluator's pool), and the Python/Pinocchio fallback backend;
- the peer: the same pipeline on PyKDL (bench/pykdl_peer.py), and the ratio;
- identity: per-sample effective masses, feasibility and IK iterations of the compiled vs the
  Python backend, effective masses vs the peer (same algorithm on PyKDL) and vs the pre-issue
  effective-mass code (bench/reference.py) on our joint paths (max relative differences);
- the pre-issue implementation (bench/reference.py, secant IK warm start): its time, its
  feasible grasps, and the self-motion of its joint paths vs ours (the null-space share of
  each joint step, |(I - J^+ J) dq| / |dq|);
- the physical floor (4k flops per evaluation + 2k per IK iteration) and our distance to it;
- where the time goes (cProfile of one ranking, ours and the peer's);
- service cost (bench/service.py): 10 grasps x 101 samples through the running node
  (in-process, rclpy; a client in its own process on rclpy's EventsExecutor; median, p90,
  the ranking's own time; the floor and a spin_until_future_complete client) and 1,000
  grasps x 201 samples end to end with the response's size, when the node and
  grasp_safety_msgs are importable;
- whole-arm exposure (bench/whole_arm.py): µs per (grasp, sample), CPU time;
- posture selection (bench/postures.py): ms per grasp and score gain per restart count on
  Panda, Baxter and the book; alone: ``bench/run.py --postures-only``;
- the whole pipeline (bench/pipeline.py): CLI wall time incl. start-up for the book with 100
  and 1,000 grasps x 201 samples (--json), ``--help``, and posture selection and the default
  analyses as multiples of the ranking's own time, the start-up of a one-grasp ranking against
  ``import pinocchio``; alone: ``bench/run.py --pipeline-only``;
- the batch's throughput per worker (bench/batch.py's workload, one local worker);
- issue 21's and issue 30's target tables from the figures above (rows not measured say so).

Usage: .venv/bin/python bench/run.py --json bench/results.json   (not a test; ~2-4 minutes)
"""

from __future__ import annotations

import argparse
import cProfile
import itertools
import json
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np
from _common import rel_diff, summary, timed, top_functions
from continuous import bench_continuous
from kdl_chain import build_chain, load_pykdl
from pipeline import (
    bench_batch_per_worker,
    bench_pipeline,
    issue30_rows,
    print_issue30,
    print_pipeline,
)
from postures import bench_postures, print_postures
from pykdl_peer import PyKDLPipeline
from reference import ReferenceIK, reference_effective_masses
from run_report import issue21_rows, print_issue21, print_table
from whole_arm import bench_whole_arm, print_whole_arm
from workload import ARMS, ArmWorkload, box_object, grasps_around_box

from grasp_safety_ros.core import GraspSafetyEvaluator
from grasp_safety_ros.core.method.effective_mass import (
    effective_masses_along,
    translational_mobilities_in_base,
)
from grasp_safety_ros.core.method.ik import compiled_available
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


# ----------------------------------------------------------------------------- continuous joints
# ----------------------------------------------------------------------------- service
def service_latency(arm: ArmWorkload, repeats: int) -> dict[str, Any]:
    """The node's service cost (bench/service.py), Baxter: 10 grasps x 101 samples (latency,
    the ranking's own time, spans) and 1,000 grasps x 201 samples end to end, for issue 12's
    comparable configuration (``posture.restarts`` 0, default response: the top-level keys),
    the same with ``response.per_sample`` false (``per_sample_off``), the node's defaults
    (``node_defaults``) and the least the node returns (``least_response``)."""
    try:
        import service as service_bench

        results = service_bench.run(repeats, large_repeats=1)
    except (ImportError, RuntimeError) as error:
        return {"median_ms": None, "reason": f"node not measurable: {error}"}

    def flat(name: str) -> dict[str, Any]:
        measured = results[name]
        return {
            "configuration": measured["description"],
            **measured["latency_10x101"],
            "end_to_end_100x201": measured.get("end_to_end_100x201"),
            "end_to_end_1000x201": measured.get("end_to_end_1000x201"),
        }

    return {
        **flat("issue_comparable"),
        "per_sample_off": flat("issue_comparable_per_sample_off"),
        "node_defaults": flat("node_defaults"),
        "least_response": flat("least_response"),
        "targets": results["targets"],
        "load_average_1min": results["load_average_1min"],
    }


# ----------------------------------------------------------------------------- main
def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the results as JSON here")
    parser.add_argument("--arms", default="panda,baxter", help="comma-separated: panda,baxter")
    parser.add_argument("--grasps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--peer-repeats", type=int, default=3)
    parser.add_argument("--peer-grasps", type=int, default=100)
    parser.add_argument("--service-repeats", type=int, default=30)
    parser.add_argument(
        "--continuous-arm", default="kinova", help="arm with continuous joints, or 'none'"
    )
    parser.add_argument("--no-peer", action="store_true", help="skip PyKDL")
    parser.add_argument("--no-service", action="store_true", help="skip the node latency")
    parser.add_argument(
        "--postures-only",
        action="store_true",
        help="run only the posture-selection section (bench/postures.py, ~1 min)",
    )
    parser.add_argument("--posture-grasps", type=int, default=20)
    parser.add_argument(
        "--pipeline-only",
        action="store_true",
        help="run only the whole-pipeline section (bench/pipeline.py, ~3 min)",
    )
    args = parser.parse_args(argv)
    if args.pipeline_only:
        pipeline = bench_pipeline()
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps({"pipeline": pipeline}, indent=2) + "\n")
        print_pipeline(pipeline)
        print_issue30(issue30_rows(pipeline))
        return 0
    if args.postures_only:
        postures = bench_postures(args.posture_grasps)
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps({"posture_selection": postures}, indent=2) + "\n")
        print_postures(postures)
        return 0

    load_before = os.getloadavg()
    kdl, kdl_reason = (None, "skipped (--no-peer)") if args.no_peer else load_pykdl()
    if kdl is None:
        print(f"bench: PyKDL peer skipped: {kdl_reason}", file=sys.stderr)
    arms = {}
    for name in args.arms.split(","):
        arms[name] = bench_arm(ARMS[name], args, kdl)
    continuous = (
        None
        if args.continuous_arm == "none"
        else bench_continuous(ARMS[args.continuous_arm], args.repeats)
    )
    print("[postures] cost and gain of posture selection", file=sys.stderr)
    posture_selection = bench_postures(args.posture_grasps)
    print("[whole arm] cost of the whole-arm exposure per sample", file=sys.stderr)
    whole_arm = {name: bench_whole_arm(ARMS[name]) for name in arms}
    print("[pipeline] CLI, posture selection and analyses vs the ranking", file=sys.stderr)
    pipeline = bench_pipeline()
    print("[batch] grasp-safety batch per worker (bench/batch.py's workload)", file=sys.stderr)
    batch = bench_batch_per_worker()
    if args.no_service:
        service = {"median_ms": None, "reason": "skipped (--no-service)"}
    else:
        print("[service] 10 grasps x 101 samples through the node", file=sys.stderr)
        service = service_latency(ARMS["baxter"], args.service_repeats)

    def worst(key: str, pick: Callable[[Any], float] = max) -> float | None:
        values = [
            a[key]["median"] if isinstance(a[key], dict) else a[key]
            for a in arms.values()
            if key in a
        ]
        return pick(values) if values else None

    results = {
        "us_per_sample_with_ik": worst("us_per_sample_with_ik"),
        "us_per_sample_without_ik": worst("us_per_sample_without_ik"),
        "cpu_us_per_sample_with_ik": worst("cpu_us_per_sample_with_ik"),
        "us_per_sample_with_ik_parallel": worst("us_per_sample_with_ik_parallel"),
        "wall_s_100x201_serial": worst("wall_s_serial"),
        "wall_s_100x201_parallel": worst("wall_s_parallel"),
        "ik_iterations_per_sample": worst("ik_iterations_per_sample"),
        "us_per_sample_with_ik_continuous": (
            continuous["us_per_sample_with_ik"]["median"] if continuous else None
        ),
        "continuous_vs_revolute_cpu": (
            continuous["cpu_us_per_sample_with_ik"]["median"] / worst("cpu_us_per_sample_with_ik")
            if continuous
            else None
        ),
        "continuous_arm": continuous,
        "pykdl_us_per_sample_with_ik": max(
            (a["pykdl"]["us_per_sample_with_ik"]["median"] for a in arms.values() if "pykdl" in a),
            default=None,
        ),
        "speedup_vs_pykdl": worst("speedup_vs_pykdl", min),
        "max_rel_diff_vs_pykdl": max(
            (a["pykdl"]["max_rel_diff"] for a in arms.values() if "pykdl" in a), default=None
        ),
        "max_rel_diff_compiled_vs_python": max(
            a["python_backend_max_rel_diff"] for a in arms.values()
        ),
        "compiled_vs_python_same_feasibility_and_iterations": all(
            a["python_backend_same_feasibility"] and a["python_backend_same_ik_iterations"]
            for a in arms.values()
        ),
        "max_rel_diff_vs_reference_effective_mass": max(
            a["reference"]["effective_mass_max_rel_diff_on_our_paths"] for a in arms.values()
        ),
        "feasible_grasps": {name: a["feasible_grasps"] for name, a in arms.items()},
        "feasible_grasps_reference_secant": {
            name: a["reference"]["feasible_grasps"] for name, a in arms.items()
        },
        "self_motion_fraction_max": max(
            a["self_motion_fraction"]["ours_max"] for a in arms.values()
        ),
        "self_motion_fraction_max_reference_secant": max(
            a["self_motion_fraction"]["reference_max"] for a in arms.values()
        ),
        "floor_us_per_sample": worst("floor_us_per_sample", min),
        "distance_to_floor": worst("distance_to_floor"),
        "service_latency_ms_median": service.get("median_ms"),
        "service": service,
        "posture_selection": posture_selection,
        "whole_arm": whole_arm,
        "pipeline": pipeline,
        "issue21_targets": issue21_rows(arms, pipeline, service),
        "batch_per_worker": batch,
        "issue30_targets": issue30_rows(pipeline, arms, whole_arm, service, batch),
        "pykdl_unavailable_reason": kdl_reason or None,
        "arms": arms,
        "machine": {
            "python": platform.python_version(),
            "cpu": platform.processor() or platform.machine(),
            "cores_available": default_workers(),
            "numba": compiled_available(),
            "load_average_1min_before": load_before[0],
            "load_average_1min_after": os.getloadavg()[0],
        },
        "note": (
            "top-level figures: medians over repeats, worst arm (slowest time, smallest "
            "speedup); wall-clock times are inflated when other processes share the cores "
            "(see machine.load_average_*), CPU times (cpu_*) much less"
        ),
    }
    text = json.dumps(results, indent=2, default=lambda x: None if x != x else x)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(text + "\n")
    print_table(results)
    print_postures(posture_selection)
    print_whole_arm(whole_arm)
    print_pipeline(pipeline)
    print_issue21(results["issue21_targets"])
    print_issue30(results["issue30_targets"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
