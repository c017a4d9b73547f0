"""bench/run.py's results as text: the per-arm table, the service rows, and issue 21's
target table measured in the run."""

from __future__ import annotations

import math
from typing import Any


def issue21_rows(
    arms: dict[str, Any], pipeline: dict[str, Any], service: dict[str, Any]
) -> list[dict[str, Any]]:
    """Issue 21's target table, measured in this run: (measure, value, unit, target, met)."""
    core = pipeline["in_process"]
    cli = pipeline["cli"]

    def row(measure: str, value: float | None, unit: str, target: float) -> dict[str, Any]:
        met = None if value is None else value <= target
        return {"measure": measure, "value": value, "unit": unit, "target": target, "met": met}

    rows = [
        row(
            "CLI, 100 x 201, defaults, --json, wall incl. start-up",
            cli["rank_100"]["wall_s"],
            "s",
            1.5,
        ),
        row("CLI, 1,000 x 201, defaults, --json", cli["rank_1000"]["wall_s"], "s", 6.0),
        row("default analyses vs the ranking's own time", core["analyses_vs_ranking"], "x", 1.0),
        row(
            "posture selection (8 restarts) vs single-IK ranking",
            core["postures_vs_ranking"],
            "x",
            1.5,
        ),
    ]
    targets = {t["row"]: t for t in service.get("targets") or ()}
    for label, key, target_ms in (
        ("service, node defaults, 10 x 101, median", "10 grasps x 101 samples, median", 20.0),
        (
            "service, node defaults, 100 x 201, one client",
            "100 grasps x 201 samples, one client",
            200.0,
        ),
        (
            "service, node defaults, 1,000 x 201, end to end",
            "1,000 grasps x 201 samples, end to end",
            3000.0,
        ),
    ):
        measured = targets.get(key)
        rows.append(
            row(label, None if measured is None else measured["measured_ms"], "ms", target_ms)
        )
    for name, arm in arms.items():
        rows.append(
            row(
                f"core us per (grasp, sample), {name} (no regression: <= 2.2)",
                arm["us_per_sample_with_ik"]["median"],
                "us",
                2.2,
            )
        )
    return rows


def print_issue21(rows: list[dict[str, Any]]) -> None:
    """The rows of ``issue21_rows`` as a table."""
    print("\nIssue 21's targets, this run (one machine, same minutes):")
    for r in rows:
        value = "n/a" if r["value"] is None else f"{r['value']:.3g} {r['unit']}"
        verdict = {True: "met", False: "NOT met", None: "not measured"}[r["met"]]
        print(f"  {r['measure']}: {value} (target <= {r['target']:g} {r['unit']}): {verdict}")


def fmt(value: Any, spec: str = ".2f") -> str:
    """A figure as text, "n/a" for None and NaN."""
    return (
        "n/a"
        if value is None or (isinstance(value, float) and math.isnan(value))
        else (format(value, spec))
    )


def print_arms(arms: dict[str, Any]) -> None:
    """The arms section (bench/arm.py), a few lines per arm."""
    for name, arm in arms.items():
        w, wo = arm["us_per_sample_with_ik"], arm["us_per_sample_without_ik"]
        print(
            f"{name}: {arm['grasps']} grasps x {arm['samples_per_grasp']} samples, "
            f"{arm['feasible_grasps']} feasible, backend {arm['backend']}"
        )
        print(
            f"  ours, 1 core : {fmt(w['median'])} us/sample with IK "
            f"[{fmt(w['min'])}..{fmt(w['max'])}], {fmt(wo['median'])} without IK "
            f"[{fmt(wo['min'])}..{fmt(wo['max'])}], "
            f"wall {fmt(arm['wall_s_serial']['median'], '.3f')} s, "
            f"{fmt(arm['ik_iterations_per_sample'])} IK iterations/sample; CPU time "
            f"{fmt(arm['cpu_us_per_sample_with_ik']['median'])} us/sample"
        )
        print(
            f"  ours, {arm['workers']} cores: "
            f"{fmt(arm['us_per_sample_with_ik_parallel']['median'])} "
            f"us/sample, wall {fmt(arm['wall_s_parallel']['median'], '.3f')} s "
            f"(x{fmt(arm['parallel_speedup'])})"
        )
        same = arm["python_backend_same_feasibility"] and arm["python_backend_same_ik_iterations"]
        print(
            f"  python backend: {fmt(arm['python_backend_us_per_sample_with_ik'])} us/sample, "
            f"max rel diff {fmt(arm['python_backend_max_rel_diff'], '.1e')}, "
            f"{'same' if same else 'DIFFERENT'} feasibility and IK iterations"
        )
        ref, motion = arm["reference"], arm["self_motion_fraction"]
        print(
            f"  pre-issue code (secant warm start): {fmt(ref['us_per_sample_with_ik'])} "
            f"us/sample, {ref['feasible_grasps']} feasible; its effective masses on our paths: "
            f"max rel diff {fmt(ref['effective_mass_max_rel_diff_on_our_paths'], '.1e')}; "
            f"self-motion share of joint steps: ours max {fmt(motion['ours_max'], '.1e')}, "
            f"secant max {fmt(motion['reference_max'], '.2f')} "
            f"(median {fmt(motion['reference_median_of_grasp_max'], '.2f')})"
        )
        if "pykdl" in arm:
            p = arm["pykdl"]
            print(
                f"  PyKDL: {fmt(p['us_per_sample_with_ik']['median'])} us/sample with IK, "
                f"{fmt(p['us_per_sample_without_ik']['median'])} without; ours is "
                f"x{fmt(arm['speedup_vs_pykdl'], '.0f')} faster; max rel diff "
                f"{fmt(p['max_rel_diff'], '.1e')}; the KDL calls alone (FK + J + M) "
                f"{fmt(p['kdl_calls_us_per_sample'])} us/sample"
            )
        print(
            f"  floor ~{fmt(arm['floor_us_per_sample'])} us/sample; ours is "
            f"x{fmt(arm['distance_to_floor'], '.1f')} from it"
        )


def print_continuous(results: dict[str, Any]) -> None:
    """The continuous-joint arm's section beside the slowest revolute arm."""
    continuous = results["continuous_arm"]
    if continuous is not None:
        w = continuous["us_per_sample_with_ik"]
        same = (
            continuous["python_backend_same_feasibility"]
            and continuous["python_backend_same_ik_iterations"]
        )
        joints = ", ".join(continuous["continuous_joints"])
        print(
            f"continuous joints ({continuous['robot']}; {joints}"
            f"; nq, nv = {continuous['nq_nv']}): {continuous['feasible_grasps']} feasible, "
            f"backend {continuous['backend']}"
        )
        print(
            f"  ours, 1 core : {fmt(w['median'])} us/sample with IK [{fmt(w['min'])}.."
            f"{fmt(w['max'])}]; CPU time {fmt(continuous['cpu_us_per_sample_with_ik']['median'])}"
            f" us/sample = x{fmt(results['continuous_vs_revolute_cpu'])} the slowest revolute "
            f"arm's; python backend {fmt(continuous['python_backend_us_per_sample_with_ik'])} "
            f"us/sample, max rel diff {fmt(continuous['python_backend_max_rel_diff'], '.1e')}, "
            f"{'same' if same else 'DIFFERENT'} feasibility and IK iterations"
        )


def print_service(service: dict[str, Any]) -> None:
    """The service section (bench/service.py through run.py's service_latency)."""
    if service.get("median_ms") is None:
        print(f"service latency: n/a ({service.get('reason')})")
        return
    for label, measured in (
        ("posture.restarts 0", service),
        ("posture.restarts 0, response.per_sample false", service["per_sample_off"]),
        ("node defaults", service["node_defaults"]),
        ("the least the node returns", service["least_response"]),
    ):
        print(
            f"service latency (10 x 101, Baxter, {label}): median {fmt(measured['median_ms'])} "
            f"ms, p90 {fmt(measured['latency_ms']['p90'])} ms "
            f"[{fmt(measured['latency_ms']['min'])}..{fmt(measured['latency_ms']['max'])}], "
            f"ranking alone {fmt(measured['ranking_ms']['median'])} ms "
            f"(x{fmt(measured['latency_over_ranking'])}; client: {measured.get('client')})"
        )
        if "latency_spin_until_ms" in measured:
            print(
                f"  client waiting with spin_until_future_complete: median "
                f"{fmt(measured['latency_spin_until_ms']['median'])} ms; empty request "
                f"{fmt(measured['empty_request_ms']['median'])} ms (fast client), "
                f"{fmt(measured['empty_request_spin_until_ms']['median'])} ms "
                "(spin_until_future_complete)"
            )
        for key in ("end_to_end_100x201", "end_to_end_1000x201"):
            large = measured.get(key)
            if large:
                print(
                    f"service end to end ({large['grasps']} x {large['samples_per_grasp']}, "
                    f"Baxter, {label}): {fmt(large['wall_s'], '.3f')} s, response "
                    f"{large['response_bytes']} bytes"
                )
    for row in service.get("targets") or ():
        print(
            f"service target, node defaults, {row['row']}: {fmt(row['measured_ms'])} ms "
            f"(target {fmt(row['target_ms'])} ms), core ranking {fmt(row['core_ranking_ms'])} "
            f"ms (x{fmt(row['over_core_ranking'])}), the node's own work "
            f"{fmt(row['node_share_ms'])} ms"
        )
