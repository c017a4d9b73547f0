#!/usr/bin/env python3
"""Benchmark of the ranking hot path (IK + effective mass per grasp and sample), issue #5.

Workload per arm (Panda and Baxter's right arm, example-robot-data): a box, 100 grasps
around it, a 2 s quintic object trajectory sampled every 0.01 s (201 samples), metric mean.
The same on a chain with continuous joints (Kinova Jaco2, ``--continuous-arm``): ours only,
serial, and its CPU time per sample relative to the slowest revolute arm's.
Measured in one process, interleaved, repeated (median and spread):

Sections (SECTIONS, each a key of the results, in run order; ``arms`` is bench/arm.py):

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
- a newcomer's first table (bench/fresh_demo.py): ``make demo`` in a fresh clone of HEAD with
  empty pip and kernel caches, to the ranking table, with the longest silence on the way;
- issue 21's and issue 30's target tables from the figures above (bench/targets.py; a row
  not measured says why), and issue 28's no-regression table: the core's µs per sample, the
  CLI and the service rows against the previous committed results (``previous``: the figures
  of the file --json overwrites; with --merge, the previous run that file carries).

Each section records its run, wall time and load average (``sections``). A section that
raises is recorded with its error, its rows say so, the others are still measured and written,
and the run exits with status 1.

Usage: .venv/bin/python bench/run.py --json bench/results.json   (``make bench``; not a test;
about 3 minutes on 2 cores at load 1.3-2.7: the service 77 s, the arms 48, the pipeline 34,
the rest 15; ``make bench`` first runs ``make setup``, which compiles the kernels after an edit of
them: 3-5 more minutes, once)
       .venv/bin/python bench/run.py --only pipeline,batch_per_worker --merge --json
       bench/results.json   (re-measure some sections, keep the others)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from arm import bench_arm
from continuous import bench_continuous
from fresh_demo import bench_fresh_demo, print_fresh_demo
from kdl_chain import load_pykdl
from pipeline import bench_batch_per_worker, bench_pipeline, print_pipeline
from postures import bench_postures, print_postures
from run_report import (
    issue21_rows,
    print_arms,
    print_continuous,
    print_issue21,
    print_service,
)
from targets import (
    REGRESSION_TOLERANCE,
    issue30_rows,
    no_regression_rows,
    print_issue30,
    print_no_regression,
    regression_figures,
)
from whole_arm import bench_whole_arm, print_whole_arm
from workload import ARMS

from grasp_safety_ros.core.method.ik import compiled_available
from grasp_safety_ros.core.method.pool import default_workers


# ----------------------------------------------------------------------------- service
def service_latency(repeats: int) -> dict[str, Any]:
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


# ----------------------------------------------------------------------------- sections
SECTIONS = (
    "arms",
    "continuous_arm",
    "posture_selection",
    "whole_arm",
    "pipeline",
    "batch_per_worker",
    "service",
    "fresh_demo",
)
"""The measured sections, in run order; each is a key of the results."""


def section_runners(args: argparse.Namespace, kdl: Any) -> dict[str, Callable[[], Any]]:
    """Each section's measurement (module docstring), by its key in the results."""
    names = args.arms.split(",")
    return {
        "arms": lambda: {name: bench_arm(ARMS[name], args, kdl) for name in names},
        "continuous_arm": lambda: (
            None
            if args.continuous_arm == "none"
            else bench_continuous(ARMS[args.continuous_arm], args.repeats)
        ),
        "posture_selection": lambda: bench_postures(args.posture_grasps),
        "whole_arm": lambda: {name: bench_whole_arm(ARMS[name]) for name in names},
        "pipeline": bench_pipeline,
        "batch_per_worker": bench_batch_per_worker,
        "service": lambda: (
            {"median_ms": None, "reason": "skipped (--no-service)"}
            if args.no_service
            else service_latency(args.service_repeats)
        ),
        "fresh_demo": bench_fresh_demo,
    }


def summarise(sections: dict[str, Any], failed: dict[str, str]) -> dict[str, Any]:
    """The top-level figures (worst arm) and issue 21's and 30's target rows from the
    sections' results (sections not present give None or rows that say so, with the error of
    those in ``failed``)."""
    arms = sections.get("arms") or {}
    continuous = sections.get("continuous_arm")

    def worst(key: str, pick: Callable[[Any], float] = max) -> float | None:
        values = [
            a[key]["median"] if isinstance(a[key], dict) else a[key]
            for a in arms.values()
            if key in a
        ]
        return pick(values) if values else None

    def over_arms(pick: Callable[[dict[str, Any]], Any], combine: Callable = max) -> Any:
        return combine(pick(a) for a in arms.values()) if arms else None

    pykdl = [a["pykdl"] for a in arms.values() if "pykdl" in a]
    slowest_cpu = worst("cpu_us_per_sample_with_ik")
    pipeline, service = sections.get("pipeline"), sections.get("service") or {}
    return {
        "us_per_sample_with_ik": worst("us_per_sample_with_ik"),
        "us_per_sample_without_ik": worst("us_per_sample_without_ik"),
        "cpu_us_per_sample_with_ik": slowest_cpu,
        "us_per_sample_with_ik_parallel": worst("us_per_sample_with_ik_parallel"),
        "wall_s_100x201_serial": worst("wall_s_serial"),
        "wall_s_100x201_parallel": worst("wall_s_parallel"),
        "ik_iterations_per_sample": worst("ik_iterations_per_sample"),
        "us_per_sample_with_ik_continuous": (
            continuous["us_per_sample_with_ik"]["median"] if continuous else None
        ),
        "continuous_vs_revolute_cpu": (
            continuous["cpu_us_per_sample_with_ik"]["median"] / slowest_cpu
            if continuous and slowest_cpu
            else None
        ),
        "pykdl_us_per_sample_with_ik": max(
            (p["us_per_sample_with_ik"]["median"] for p in pykdl), default=None
        ),
        "speedup_vs_pykdl": worst("speedup_vs_pykdl", min),
        "max_rel_diff_vs_pykdl": max((p["max_rel_diff"] for p in pykdl), default=None),
        "max_rel_diff_compiled_vs_python": over_arms(lambda a: a["python_backend_max_rel_diff"]),
        "compiled_vs_python_same_feasibility_and_iterations": over_arms(
            lambda a: (
                a["python_backend_same_feasibility"] and a["python_backend_same_ik_iterations"]
            ),
            all,
        ),
        "max_rel_diff_vs_reference_effective_mass": over_arms(
            lambda a: a["reference"]["effective_mass_max_rel_diff_on_our_paths"]
        ),
        "feasible_grasps": {name: a["feasible_grasps"] for name, a in arms.items()},
        "feasible_grasps_reference_secant": {
            name: a["reference"]["feasible_grasps"] for name, a in arms.items()
        },
        "self_motion_fraction_max": over_arms(lambda a: a["self_motion_fraction"]["ours_max"]),
        "self_motion_fraction_max_reference_secant": over_arms(
            lambda a: a["self_motion_fraction"]["reference_max"]
        ),
        "floor_us_per_sample": worst("floor_us_per_sample", min),
        "distance_to_floor": worst("distance_to_floor"),
        "service_latency_ms_median": service.get("median_ms"),
        "issue21_targets": issue21_rows(arms, pipeline, service) if pipeline else None,
        "issue30_targets": issue30_rows(sections, failed),
    }


def git_revision(path: Path) -> str:
    """The last commit that changed ``path`` (short hash and date), or "" outside git."""
    done = subprocess.run(
        ["git", "log", "-1", "--format=%h %cs", "--", path.name],
        cwd=path.parent,
        capture_output=True,
        text=True,
        check=False,
    )
    return done.stdout.strip() if done.returncode == 0 else ""


def previous_run(path: Path, merge: bool) -> dict[str, Any] | None:
    """What this run's figures are compared with: the figures of the results at ``path`` (the
    previous committed run), with its load average (lowest and highest of its sections); when
    ``merge`` adds sections to that file, the previous run it already carries."""
    if not path.exists():
        return None
    old = json.loads(path.read_text())
    if merge and old.get("previous"):
        return old["previous"]
    machine = old.get("machine") or {}
    loads = [machine.get("load_average_1min_before"), machine.get("load_average_1min_after")]
    if old.get("sections"):
        every = [load for s in old["sections"].values() for load in s["load_average_1min"]]
        loads = [min(every), max(every)]
    revision = git_revision(path)
    return {
        "source": f"{path.name} at {revision}" if revision else path.name,
        "load_average_1min": loads,
        "figures": regression_figures(old),
    }


# ----------------------------------------------------------------------------- main
def parse_arguments(argv: Sequence[str] | None) -> argparse.Namespace:
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
        "--only",
        help=f"comma-separated sections to run (of {','.join(SECTIONS)}; default: all)",
    )
    parser.add_argument(
        "--merge",
        action="store_true",
        help="keep the other sections of the existing --json file (each section records its "
        "run; the previous run the file is compared with is kept)",
    )
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
    args.chosen = SECTIONS if args.only is None else tuple(args.only.split(","))
    unknown = sorted(set(args.chosen) - set(SECTIONS))
    if unknown:
        parser.error(f"--only: unknown sections {unknown}; valid: {','.join(SECTIONS)}")
    if args.merge and not (args.json and args.json.exists()):
        parser.error("--merge needs an existing --json file")
    return args


def kept_sections(
    old: dict[str, Any], previous: dict[str, Any] | None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The sections of an existing results file (--merge) and their runs; a file written
    before runs were recorded per section gives its sections the previous run's name and its
    machine's load."""
    machine = old.get("machine") or {}
    sections, provenance = {}, {}
    for name in SECTIONS:
        if name in old:
            sections[name] = old[name]
            provenance[name] = (old.get("sections") or {}).get(name) or {
                "run": previous["source"] if previous else "earlier",
                "load_average_1min": [
                    machine.get("load_average_1min_before"),
                    machine.get("load_average_1min_after"),
                ],
            }
    return sections, provenance


def measure(
    args: argparse.Namespace, kdl: Any, sections: dict[str, Any], provenance: dict[str, Any]
) -> None:
    """Run the chosen sections in order into ``sections``, each one's run, wall time and load
    average (and the error of a section that raised one, which is then left out) into
    ``provenance``."""
    run = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    runners = section_runners(args, kdl)
    for name in SECTIONS:
        if name not in args.chosen:
            continue
        print(f"[{name}] started", file=sys.stderr)
        before, start = os.getloadavg()[0], time.perf_counter()
        error = None
        try:
            sections[name] = runners[name]()
        except Exception as raised:  # one failing section must not lose the others' figures
            traceback.print_exc()
            error = f"{type(raised).__name__}: {raised}"
            sections.pop(name, None)  # --merge: not the earlier run's figures either
        wall_s = time.perf_counter() - start
        print(f"[{name}] {'FAILED' if error else 'done'} in {wall_s:.0f} s", file=sys.stderr)
        provenance[name] = {
            "run": run,
            "wall_s": wall_s,
            "load_average_1min": [before, os.getloadavg()[0]],
        }
        if error:
            provenance[name]["error"] = error


def print_results(results: dict[str, Any], chosen: Sequence[str]) -> None:
    """The tables of the sections this run measured, then the target and no-regression
    tables and each section's wall time and load."""
    measured = [name for name in chosen if name in results]
    if "arms" in measured:
        print_arms(results["arms"])
    if "continuous_arm" in measured:
        print_continuous(results)
    if "service" in measured:
        print_service(results["service"])
    if "posture_selection" in measured:
        print_postures(results["posture_selection"])
    if "whole_arm" in measured:
        print_whole_arm(results["whole_arm"])
    if "fresh_demo" in measured:
        print_fresh_demo(results["fresh_demo"])
    if "pipeline" in measured:
        print_pipeline(results["pipeline"])
        print_issue21(results["issue21_targets"])
    print_issue30(results["issue30_targets"])
    print_no_regression(results["no_regression"], results["previous"])
    spent = []
    for name in chosen:
        run = results["sections"][name]
        before, after = run["load_average_1min"]
        spent.append(f"{name} {run['wall_s']:.0f} s (load {before:.1f} -> {after:.1f})")
    print(f"\nsections, wall time and 1-min load average: {', '.join(spent)}")


def write_json(path: Path | None, results: dict[str, Any]) -> None:
    if path:
        path.parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps(results, indent=2, default=lambda x: None if x != x else x)
        path.write_text(text + "\n")


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_arguments(argv)
    if args.pipeline_only:
        pipeline = bench_pipeline()
        write_json(args.json, {"pipeline": pipeline})
        print_pipeline(pipeline)
        print_issue30(issue30_rows({"pipeline": pipeline}))
        return 0
    if args.postures_only:
        postures = bench_postures(args.posture_grasps)
        write_json(args.json, {"posture_selection": postures})
        print_postures(postures)
        return 0
    previous = previous_run(args.json, args.merge) if args.json else None
    old = json.loads(args.json.read_text()) if args.merge else {}
    sections, provenance = kept_sections(old, previous) if args.merge else ({}, {})
    kdl: Any = None
    kdl_reason: str | None = "skipped (--no-peer)"
    if "arms" not in args.chosen:
        kdl_reason = old.get("pykdl_unavailable_reason") if args.merge else "arms not run"
    elif not args.no_peer:
        kdl, kdl_reason = load_pykdl()
    if kdl is None and "arms" in args.chosen:
        print(f"bench: PyKDL peer skipped: {kdl_reason}", file=sys.stderr)
    load_before = os.getloadavg()
    measure(args, kdl, sections, provenance)
    failed = {name: run["error"] for name, run in provenance.items() if "error" in run}
    results = {
        **summarise(sections, failed),
        **sections,
        "no_regression": no_regression_rows(sections, previous),
        "no_regression_tolerance": REGRESSION_TOLERANCE,
        "previous": previous,
        "sections": provenance,
        "pykdl_unavailable_reason": kdl_reason or None,
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
            "(see sections.*.load_average_1min), CPU times (cpu_*) much less"
        ),
    }
    write_json(args.json, results)
    print_results(results, args.chosen)
    for name, error in failed.items():
        print(f"bench: section {name} FAILED: {error}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
