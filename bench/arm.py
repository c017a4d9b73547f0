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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from _common import python_backend_agreement, rel_diff, summary, timed, top_functions
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
@dataclass
class ArmCase:
    """One arm's workload, its three evaluators and the compiled ranking of its grasps."""

    name: str
    robot: Any
    trajectory: Any
    obj: Any
    grasps: list[Any]
    seed: np.ndarray
    serial: GraspSafetyEvaluator
    pooled: GraspSafetyEvaluator
    fallback: GraspSafetyEvaluator
    ranking: Ranking | None = None

    @classmethod
    def build(cls, arm: ArmWorkload, grasps: int) -> ArmCase:
        robot = arm.robot()
        return cls(
            arm.name,
            robot,
            arm.trajectory(2.0, 0.01),
            box_object(),
            grasps_around_box(np.array(arm.approach_from), grasps),
            np.array(arm.seed_positions),
            GraspSafetyEvaluator(robot, EvaluationConfig(workers=1)),
            GraspSafetyEvaluator(robot, EvaluationConfig(workers=0, parallel_min_samples=1)),
            GraspSafetyEvaluator(robot, EvaluationConfig(backend="python", workers=1)),
        )

    @property
    def total(self) -> int:
        """(grasp, sample) pairs of a ranking."""
        return len(self.grasps) * self.trajectory.num_samples

    def rank(self, evaluator: GraspSafetyEvaluator) -> Ranking:
        return evaluator.rank(self.grasps, self.obj, self.trajectory, seed_positions=self.seed)

    def evaluations(self) -> list[Any]:
        assert self.ranking is not None
        return list(self.ranking.evaluations)

    def effective_mass_only(self) -> None:
        """The effective masses (IK excluded) from the joint positions the ranking found."""
        chain_arrays = self.serial.ik.chain if self.serial.ik.compiled else None
        for grasp, evaluation in zip(self.grasps, self.evaluations(), strict=True):
            if not evaluation.feasible:
                continue
            mobilities = translational_mobilities_in_base(
                self.robot,
                self.obj,
                grasp.transform_tip_to_object,
                evaluation.joint_positions,
                chain_arrays,
            )
            effective_masses_along(mobilities, evaluation.directions_in_base)


def reference_figures(case: ArmCase) -> dict[str, Any]:
    """The pre-issue implementation on every grasp (the body of reference_evaluate, timed),
    its effective-mass code on our joint paths (the identity that still holds), and how its
    joint paths differ from ours (self-motion)."""
    robot, trajectory, obj = case.robot, case.trajectory, case.obj
    reference_ik = ReferenceIK(robot)
    seed_q = robot.q_from_positions(case.seed)
    times_s = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times_s)
    reference_paths: list[np.ndarray | None] = []
    start = time.perf_counter()
    for grasp in case.grasps:
        poses, tangents = trajectory.tip_path(grasp.transform_tip_to_object, s_values)
        q_path, _, reason = reference_ik.solve_trajectory(poses, times_s, s_values, seed_q)
        if not reason:
            reference_effective_masses(robot, grasp.transform_tip_to_object, obj, q_path, tangents)
        reference_paths.append(None if reason else q_path)
    reference_s = time.perf_counter() - start
    worst, path_diff = 0.0, 0.0
    ours_self_motion, reference_self_motion = [], []
    evaluations = case.evaluations()
    for grasp, evaluation, q_reference in zip(
        case.grasps, evaluations, reference_paths, strict=True
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
    names_ours = {g.name for g, e in zip(case.grasps, evaluations, strict=True) if e.feasible}
    names_reference = {
        g.name for g, q in zip(case.grasps, reference_paths, strict=True) if q is not None
    }
    return {
        "reference": {
            "ik_warm_start": "secant (extrapolates the previous joint step)",
            "wall_s": reference_s,
            "us_per_sample_with_ik": reference_s / case.total * 1e6,
            "feasible_grasps": len(names_reference),
            "feasible_only_with_ours": sorted(names_ours - names_reference),
            "feasible_only_with_reference": sorted(names_reference - names_ours),
            "effective_mass_max_rel_diff_on_our_paths": worst,
            "max_joint_path_diff_rad": path_diff,
        },
        "self_motion_fraction": {
            "ours_max": max(ours_self_motion, default=0.0),
            "ours_median_of_grasp_max": float(np.median(ours_self_motion)),
            "reference_max": max(reference_self_motion, default=0.0),
            "reference_median_of_grasp_max": float(np.median(reference_self_motion)),
        },
    }


@dataclass
class Peer:
    """The PyKDL pipeline on a case's first ``count`` grasps."""

    pipeline: PyKDLPipeline
    case: ArmCase
    count: int

    @property
    def grasps(self) -> list[Any]:
        return self.case.grasps[: self.count]

    @property
    def total(self) -> int:
        return len(self.grasps) * self.case.trajectory.num_samples

    def evaluate(self, grasp: Any) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
        obj = self.case.obj
        return self.pipeline.evaluate(
            self.case.trajectory,
            np.array(grasp.transform_tip_to_object.rotation),
            np.array(grasp.transform_tip_to_object.translation),
            obj.mass_kg,
            np.array(obj.com_in_object_m),
            np.array(obj.inertia_about_com_kgm2),
            self.case.seed,
        )

    def run(self) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        return [self.evaluate(g) for g in self.grasps]

    def effective_mass_only(self, results: list) -> None:
        trajectory, obj = self.case.trajectory, self.case.obj
        for grasp, (reason, _, q_all, _) in zip(self.grasps, results, strict=True):
            if reason:
                continue
            s_values, _, _ = trajectory.path_parameter(trajectory.times_s())
            r = np.array(grasp.transform_tip_to_object.rotation)
            p = np.array(grasp.transform_tip_to_object.translation)
            _, _, tangents = self.pipeline.tip_path(trajectory, r, p, s_values)
            self.pipeline.effective_masses(
                q_all,
                tangents,
                r,
                p,
                obj.mass_kg,
                np.array(obj.com_in_object_m),
                np.array(obj.inertia_about_com_kgm2),
            )

    def kdl_calls_us_per_sample(self, results: list) -> float:
        """The KDL solver calls alone (FK + Jacobian + mass matrix at each solved sample, with
        q set from Python): what the peer would cost with all its numpy glue compiled away."""
        peer = self.pipeline
        q_rows = [row for reason, _, q_all, _ in results if not reason for row in q_all]
        start = time.perf_counter()
        for row in q_rows:
            peer._set_q(row)
            peer.fk.JntToCart(peer._q, peer._frame)
            peer.jac.JntToJac(peer._q, peer._jacobian)
            peer.dyn.JntToMass(peer._q, peer._mass)
        return (time.perf_counter() - start) / max(len(q_rows), 1) * 1e6


def timed_repeats(
    case: ArmCase, args: argparse.Namespace, peer: Peer | None
) -> tuple[dict[str, list[float]], dict[str, list[float]], list]:
    """Wall times of each repeat (serial, effective mass only, parallel; the peer's first
    ``args.peer_repeats``), CPU times of the serial ranking and the peer, the peer's results."""
    timings: dict[str, list[float]] = {
        k: [] for k in ("serial", "without_ik", "parallel", "peer", "peer_without_ik")
    }
    peer_results: list = []
    cpu: dict[str, list[float]] = {"serial": [], "peer": []}
    for repeat in range(args.repeats):
        print(f"[{case.name}] repeat {repeat + 1}/{args.repeats}", file=sys.stderr)
        cpu_start = time.process_time()
        timings["serial"].append(timed(lambda: case.rank(case.serial))[0])
        cpu["serial"].append(time.process_time() - cpu_start)
        timings["without_ik"].append(timed(case.effective_mass_only)[0])
        timings["parallel"].append(timed(lambda: case.rank(case.pooled))[0])
        if peer is not None and repeat < args.peer_repeats:
            cpu_start = time.process_time()
            elapsed, peer_results = timed(peer.run)
            cpu["peer"].append(time.process_time() - cpu_start)
            timings["peer"].append(elapsed)
            start = time.perf_counter()
            peer.effective_mass_only(peer_results)
            timings["peer_without_ik"].append(time.perf_counter() - start)
    return timings, cpu, peer_results


def ours_figures(
    case: ArmCase, timings: dict[str, list[float]], cpu: dict[str, list[float]]
) -> dict[str, Any]:
    """Our µs per sample (serial, without IK, parallel), the Python backend's and its identity
    with the compiled one, the physical floor."""
    feasible = [e for e in case.evaluations() if e.feasible]
    feasible_samples = sum(len(e.times_s) for e in feasible)
    total = case.total
    fallback_s, fallback_ranking = timed(lambda: case.rank(case.fallback))
    with_ik = summary([t / total * 1e6 for t in timings["serial"]])
    without_ik = summary([t / feasible_samples * 1e6 for t in timings["without_ik"]])
    parallel = summary([t / total * 1e6 for t in timings["parallel"]])
    pairs = list(zip(fallback_ranking.evaluations, case.evaluations(), strict=True))
    iterations = float(np.concatenate([e.ik_iterations for e in feasible]).mean())
    floor = (FLOPS_PER_EVALUATION + FLOPS_PER_IK_ITERATION * iterations) / FLOPS_PER_US
    return {
        "us_per_sample_with_ik": with_ik,
        "cpu_us_per_sample_with_ik": summary([t / total * 1e6 for t in cpu["serial"]]),
        "us_per_sample_without_ik": without_ik,
        "wall_s_serial": summary(timings["serial"]),
        "wall_s_parallel": summary(timings["parallel"]),
        "us_per_sample_with_ik_parallel": parallel,
        "parallel_speedup": with_ik["median"] / parallel["median"],
        "python_backend_us_per_sample_with_ik": fallback_s / total * 1e6,
        **python_backend_agreement(pairs),
        # The last iterate of a sample that does not converge (100 iterations) is chaotic: the
        # joints it leaves at a limit, named in the reason, may differ by rounding.
        "python_backend_reasons_differ": [b.name for a, b in pairs if a.reason != b.reason],
        "floor_us_per_sample": floor,
        "distance_to_floor": with_ik["median"] / floor,
        "distance_to_floor_without_ik": without_ik["median"]
        / (FLOPS_PER_EVALUATION / FLOPS_PER_US),
    }


def peer_figures(
    peer: Peer,
    results: list,
    timings: dict[str, list[float]],
    cpu: dict[str, list[float]],
    ours: dict[str, Any],
) -> dict[str, Any]:
    """The peer's µs per sample, its solver calls alone, its identity with ours, and our
    speed-ups over it."""
    feasible_samples = sum(len(m) for reason, m, _, _ in results if not reason)
    figures: dict[str, Any] = {
        "grasps": len(peer.grasps),
        "us_per_sample_with_ik": summary([t / peer.total * 1e6 for t in timings["peer"]]),
        "cpu_us_per_sample_with_ik": summary([t / peer.total * 1e6 for t in cpu["peer"]]),
        "us_per_sample_without_ik": summary(
            [t / max(feasible_samples, 1) * 1e6 for t in timings["peer_without_ik"]]
        ),
        "kdl_calls_us_per_sample": peer.kdl_calls_us_per_sample(results),
    }
    diffs, agree = [], True
    for (reason, masses, _, _), evaluation in zip(results, peer.case.evaluations(), strict=False):
        agree &= (not reason) == evaluation.feasible
        if not reason and evaluation.feasible:
            diffs.append(rel_diff(masses, evaluation.effective_mass_kg))
    figures["max_rel_diff"] = max(diffs, default=float("nan"))
    figures["same_feasibility"] = agree

    def ratio(key: str) -> float:
        return figures[key]["median"] / ours[key]["median"]

    return {
        "pykdl": figures,
        "speedup_vs_pykdl": ratio("us_per_sample_with_ik"),
        "speedup_vs_pykdl_cpu": ratio("cpu_us_per_sample_with_ik"),
        "speedup_vs_pykdl_without_ik": ratio("us_per_sample_without_ik"),
    }


def profiles(case: ArmCase, peer: Peer | None) -> dict[str, Any]:
    """Where the time goes: cProfile of one ranking, and of the peer on 5 grasps."""
    profile = cProfile.Profile()
    elapsed, _ = timed(lambda: profile.runcall(case.rank, case.serial))
    out = {"profile_ours": top_functions(profile, elapsed)}
    if peer is not None:
        profile = cProfile.Profile()
        start = time.perf_counter()
        for g in peer.grasps[:5]:
            profile.runcall(peer.evaluate, g)
        out["profile_pykdl"] = top_functions(profile, time.perf_counter() - start)
    return out


def bench_arm(arm: ArmWorkload, args: argparse.Namespace, kdl: Any) -> dict[str, Any]:
    """Every figure of one arm (module docstring; bench/run.py's lists each)."""
    case = ArmCase.build(arm, args.grasps)
    out: dict[str, Any] = {
        "robot": f"{arm.urdf} {arm.base_frame} -> {arm.tip_frame}",
        "grasps": len(case.grasps),
        "samples_per_grasp": case.trajectory.num_samples,
        "backend": "compiled" if case.serial.ik.compiled else "python",
        "workers": default_workers(),
    }
    print(f"[{arm.name}] warm-up (numba compiles or loads its cache)", file=sys.stderr)
    out["first_call_s"], case.ranking = timed(lambda: case.rank(case.serial))
    case.rank(case.pooled)
    feasible = [e for e in case.evaluations() if e.feasible]
    out["feasible_grasps"] = len(feasible)
    out["ik_iterations_per_sample"] = float(
        np.concatenate([e.ik_iterations for e in feasible]).mean()
    )
    out["ik_iterations_per_sample_excluding_first"] = float(
        np.concatenate([e.ik_iterations[1:] for e in feasible]).mean()
    )
    print(f"[{arm.name}] the pre-issue implementation (secant warm start)", file=sys.stderr)
    out.update(reference_figures(case))
    peer = None
    if kdl is not None:
        path, is_xml = resolve_urdf(arm.urdf)
        urdf_text = path if is_xml else Path(path).read_text()
        chain = build_chain(kdl, urdf_text, arm.base_frame, arm.tip_frame)
        peer = Peer(PyKDLPipeline(kdl, chain, case.serial.config.ik), case, args.peer_grasps)
    case.effective_mass_only()  # compiles (or loads) the batch kernel before timing
    timings, cpu, peer_results = timed_repeats(case, args, peer)
    out.update(ours_figures(case, timings, cpu))
    if peer is not None:
        out.update(peer_figures(peer, peer_results, timings, cpu, out))
    out.update(profiles(case, peer))
    return out
