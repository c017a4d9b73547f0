"""Benchmark section: the whole pipeline at the core's speed (issue 21), each figure beside the
core's own figure of the same run.

Workload: the paper's book on Baxter (config/book_baxter.yaml) with G grasps spread evenly
over the spine (y from -0.1 to +0.1 m), dt 0.01 s (201 samples), the scenario's defaults
(8 posture restarts, exposed points of the box, ISO/TS 15066, effort). Measured:

- CLI wall time incl. start-up: ``grasp-safety rank <scenario> --json <file>`` in a fresh
  process, 100 and 1,000 grasps (and 1,000 with ``--no-per-sample``), with the JSON size;
  ``grasp-safety --help``;
- start-up (issue 30): ``grasp-safety rank`` of 1 grasp, whole process, alternated with
  ``python -c 'import pinocchio'`` (their ratio, pair by pair; the package's bytecode written
  first, as a first import does without PYTHONDONTWRITEBYTECODE), the same command with numba
  hidden (the Pinocchio path), and what the command imports (``python -X importtime``: the
  modules, and whether scipy.linalg or .interpolate and numba's lowering registries are in);
- in one process, one core (workers=1), median over repeats: the paper's ranking (single IK),
  posture selection after it, and every default analysis (``safety_report.analyse``) on the
  shared compiled terms and on the Pinocchio per-sample reference path; as ratios to the
  ranking's own time and as µs per (grasp, sample); of those, the effort analysis alone
  (``evaluate_efforts``: one kernel call over every (grasp, sample)) and its Pinocchio
  per-grasp reference.

Run alone: .venv/bin/python bench/run.py --pipeline-only [--json bench/results_pipeline.json]
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from grasp_safety_ros.paths import config_file

SPINE_Y_M = (-0.1, 0.1)
"""Range of the grasps along the book's spine [m] (object y axis)."""
DT_S = 0.01
CLI = Path(sys.executable).with_name("grasp-safety")


def book_scenario(grasps: int, folder: Path) -> Path:
    """The book scenario with ``grasps`` grasps along the spine at dt 0.01 s, written to
    ``folder``; returns its path."""
    data = yaml.safe_load(config_file("book_baxter.yaml").read_text())
    data["trajectory"]["dt_s"] = DT_S
    low, high = SPINE_Y_M
    data["grasps"] = [
        {
            "name": f"spine_{k}",
            "position_m": [-0.075, low + (high - low) * k / max(grasps - 1, 1), 0.0],
            "quat_xyzw": [0, 0, 0, 1],
        }
        for k in range(grasps)
    ]
    path = folder / f"book_{grasps}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _wall(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, timeout=1800)
    return time.perf_counter() - start


START_UP_SCRIPT = """
import json, time
start = time.perf_counter()
import numpy, pinocchio
libraries = time.perf_counter()
import numba
numba_done = time.perf_counter()
from grasp_safety_ros.core.method.warm_up import warm_up
package = time.perf_counter()
warm_up()
kernels = time.perf_counter()
print(json.dumps({"numpy_pinocchio_s": libraries - start, "numba_s": numba_done - libraries,
    "package_s": package - numba_done, "kernels_from_cache_s": kernels - package}))
"""
"""Times the fixed cost of a command that ranks, in a fresh process: importing numpy and
Pinocchio, numba, the package's core, and loading the compiled kernels from numba's cache
(``warm_up``; the first kernel call also loads numba's linear-algebra registry, which
imports scipy.linalg)."""


def bench_start_up(repeats: int = 3) -> dict[str, float]:
    """Medians [s] of START_UP_SCRIPT's spans, and the interpreter's own start
    (``python -c pass``)."""
    runs = []
    for _ in range(repeats):
        done = subprocess.run(
            [sys.executable, "-c", START_UP_SCRIPT], check=True, capture_output=True, text=True
        )
        runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    result = {key: statistics.median(run[key] for run in runs) for key in runs[0]}
    result["interpreter_s"] = statistics.median(
        _wall([sys.executable, "-c", "pass"]) for _ in range(repeats)
    )
    return result


WITHOUT_NUMBA = (
    "import sys; sys.modules['numba'] = None; from grasp_safety_ros.cli.main import main; "
    "sys.exit(main(sys.argv[1:]))"
)
"""``grasp-safety`` with numba hidden: the evaluator falls back to the Pinocchio path."""


def compile_package_bytecode() -> bool:
    """Write the package's bytecode (``__pycache__``) as Python's first import does, unless
    PYTHONDONTWRITEBYTECODE is set: then every process compiled the package's 75 modules from
    source (0.09 s of a 0.5 s ranking, where the libraries it is compared with load theirs from
    site-packages' bytecode). Returns whether the variable is set (Python writes none then)."""
    import compileall
    import os

    import grasp_safety_ros

    compileall.compile_dir(Path(grasp_safety_ros.__file__).parent, quiet=1)
    return bool(os.environ.get("PYTHONDONTWRITEBYTECODE"))


def bench_rank_start_up(folder: Path, repeats: int = 7) -> dict[str, Any]:
    """``grasp-safety rank`` of 1 grasp x 201 samples (``--json``) as a whole process, each run
    paired with ``python -c 'import pinocchio'`` just before it: medians and [min, max] [s],
    the ratio of each pair; the same with numba hidden; the command's imports. Warm caches:
    numba's (the kernels) and Python's (the package's bytecode, written by ``bench_cli``)."""
    scenario = str(book_scenario(1, folder))
    out = str(folder / "out_start_up.json")
    rank = [str(CLI), "rank", scenario, "--json", out]
    _wall(rank)  # kernels into the page cache
    pairs = [
        (_wall([sys.executable, "-c", "import pinocchio"]), _wall(rank)) for _ in range(repeats)
    ]
    without = [_wall([sys.executable, "-c", WITHOUT_NUMBA, *rank[1:]]) for _ in range(repeats)]
    imports = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "grasp_safety_ros.cli.main", *rank[1:]],
        check=True,
        capture_output=True,
        text=True,
    ).stderr
    modules = [line.rsplit("|", 1)[1].strip() for line in imports.splitlines() if "|" in line]
    modules = modules[1:]  # the header line

    def spread(values: list[float]) -> dict[str, float]:
        return {"median": statistics.median(values), "min": min(values), "max": max(values)}

    return {
        "import_pinocchio_s": spread([p for p, _ in pairs]),
        "rank_1_s": spread([r for _, r in pairs]),
        "rank_1_vs_import_pinocchio": spread([r / p for p, r in pairs]),
        "rank_1_without_numba_s": spread(without),
        "modules_imported": len(modules),
        "scipy_linalg_or_interpolate_imported": any(
            m.startswith(("scipy.linalg", "scipy.interpolate")) for m in modules
        ),
        "numba_lowering_registries_imported": "numba.np.arraymath" in modules,
    }


def bench_cli(folder: Path, repeats: int = 3) -> dict[str, Any]:
    """Median wall times [s] of the CLI in fresh processes, and the JSON sizes [bytes]; the
    package's bytecode written first (``compile_package_bytecode``)."""
    results: dict[str, Any] = {
        "package_bytecode_written_by_bench": compile_package_bytecode(),
        "help_s": statistics.median(_wall([str(CLI), "--help"]) for _ in range(repeats)),
        "start_up": bench_start_up(repeats),
        "rank_start_up": bench_rank_start_up(folder),
    }
    for grasps, flags in ((1, ()), (100, ()), (1000, ()), (1000, ("--no-per-sample",))):
        scenario = book_scenario(grasps, folder)
        out = folder / f"out_{grasps}.json"
        key = f"rank_{grasps}" + ("_no_per_sample" if flags else "")
        times = [
            _wall([str(CLI), "rank", str(scenario), "--json", str(out), *flags])
            for _ in range(repeats)  # issue 30 targets 1,000 x 201 too: one run is too noisy
        ]
        results[key] = {"wall_s": statistics.median(times), "json_bytes": out.stat().st_size}
    return results


def bench_in_process(grasps: int, folder: Path, repeats: int = 3) -> dict[str, Any]:
    """Ranking, posture selection and analyses of the book scenario in this process (one
    core), medians [s], and their ratios to the ranking's time."""
    from grasp_safety_ros.core.analyses.effort import evaluate_efforts
    from grasp_safety_ros.core.analyses.safety_report import analyse
    from grasp_safety_ros.core.method.ranking import EvaluationConfig, GraspSafetyEvaluator
    from grasp_safety_ros.core.pipeline import run_pipeline
    from grasp_safety_ros.scenario.schema import load_scenario

    scenario = load_scenario(book_scenario(grasps, folder))
    robot = scenario.robot.load(scenario.base_dir)
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(metric=scenario.metric, workers=1))
    reference_evaluator = GraspSafetyEvaluator(
        robot, EvaluationConfig(metric=scenario.metric, workers=1, backend="python")
    )
    args = (scenario.grasps, scenario.object_inertia, scenario.trajectory)
    request = scenario.request(robot)
    selected = run_pipeline(evaluator, request).ranking  # warm: kernels loaded, restart seeds
    timings: dict[str, list[float]] = {"ranking": [], "postures": [], "analyses": [], "effort": []}
    reference: list[float] = []
    effort_reference: list[float] = []
    grasps_and_motion = (scenario.grasps, scenario.trajectory)
    effort_args = (robot, selected.evaluations, scenario.object_inertia, *grasps_and_motion)
    for repeat in range(repeats):
        stages: dict[str, float] = {}
        selected = run_pipeline(evaluator, request, timings=stages).ranking
        timings["ranking"].append(stages["rank"])
        timings["postures"].append(stages["postures"])
        timings["analyses"].append(stages["analyses"])
        start = time.perf_counter()
        evaluate_efforts(*effort_args, chain=evaluator.ik.chain)
        timings["effort"].append(time.perf_counter() - start)
        if repeat == 0:  # the Pinocchio per-sample reference paths, once
            start = time.perf_counter()
            analyse(reference_evaluator, *args, scenario.options, ranking=selected)
            reference.append(time.perf_counter() - start)
            start = time.perf_counter()
            evaluate_efforts(*effort_args)
            effort_reference.append(time.perf_counter() - start)
    samples = grasps * len(scenario.trajectory.times_s())
    medians = {name: statistics.median(values) for name, values in timings.items()}
    return {
        "grasps": grasps,
        "samples": len(scenario.trajectory.times_s()),
        "seconds": medians,
        "analyses_reference_s": reference[0],
        "effort_reference_s": effort_reference[0],
        "effort_vs_ranking": medians["effort"] / medians["ranking"],
        "core_us_per_sample": 1e6 * medians["ranking"] / samples,
        "postures_vs_ranking": medians["postures"] / medians["ranking"],
        "analyses_vs_ranking": medians["analyses"] / medians["ranking"],
        "reference_analyses_vs_ranking": reference[0] / medians["ranking"],
        "postures_tried": sum(p.postures_tried for p in selected.postures),
    }


def bench_pipeline(repeats: int = 3) -> dict[str, Any]:
    """Every figure of the section (module docstring)."""
    with tempfile.TemporaryDirectory() as folder:
        return {
            "in_process": bench_in_process(100, Path(folder), repeats),
            "cli": bench_cli(Path(folder), repeats),
        }


def print_pipeline(results: dict[str, Any]) -> None:
    """The section's table (docs/performance_pipeline.md)."""
    core = results["in_process"]
    seconds = core["seconds"]
    cli = results["cli"]
    ranking_ms = 1e3 * seconds["ranking"]
    print(f"\nWhole pipeline, book on Baxter, {core['grasps']} grasps x {core['samples']} samples")
    print(
        f"  core ranking (single IK, one core): {ranking_ms:.1f} ms, "
        f"{core['core_us_per_sample']:.2f} us per (grasp, sample)"
    )
    print(
        f"  posture selection (8 restarts, {core['postures_tried']} postures): "
        f"{1e3 * seconds['postures']:.1f} ms = x{core['postures_vs_ranking']:.1f} the ranking"
    )
    print(
        f"  default analyses on the shared terms: {1e3 * seconds['analyses']:.1f} ms = "
        f"x{core['analyses_vs_ranking']:.1f} the ranking (Pinocchio per sample: "
        f"{1e3 * core['analyses_reference_s']:.0f} ms = "
        f"x{core['reference_analyses_vs_ranking']:.0f})"
    )
    print(
        f"  of which effort (one kernel call): {1e3 * seconds['effort']:.1f} ms = "
        f"x{core['effort_vs_ranking']:.2f} the ranking (Pinocchio per grasp: "
        f"{1e3 * core['effort_reference_s']:.0f} ms)"
    )
    print(f"  CLI --help: {cli['help_s']:.2f} s")
    start_up = cli["start_up"]
    spans = ", ".join(f"{key[:-2].replace('_', ' ')} {s:.2f} s" for key, s in start_up.items())
    print(f"  fixed cost of a ranking command, fresh process: {spans}")
    start = cli["rank_start_up"]
    print(
        f"  rank 1 x 201 whole process: {start['rank_1_s']['median']:.2f} s, import pinocchio "
        f"{start['import_pinocchio_s']['median']:.2f} s (pairwise x"
        f"{start['rank_1_vs_import_pinocchio']['median']:.2f}); numba hidden (Pinocchio "
        f"path): {start['rank_1_without_numba_s']['median']:.2f} s; imports "
        f"{start['modules_imported']} modules, scipy.linalg or .interpolate "
        f"{start['scipy_linalg_or_interpolate_imported']}, numba's "
        f"lowering registries {start['numba_lowering_registries_imported']}"
    )
    for key, label in (
        ("rank_1", "CLI 1 x 201 --json (the floor)"),
        ("rank_100", "CLI 100 x 201 --json"),
        ("rank_1000", "CLI 1,000 x 201 --json"),
        ("rank_1000_no_per_sample", "CLI 1,000 x 201 --json --no-per-sample"),
    ):
        row = cli[key]
        print(
            f"  {label}: {row['wall_s']:.2f} s wall incl. start-up, "
            f"JSON {row['json_bytes'] / 1e6:.1f} MB"
        )


def bench_batch_per_worker(grasps: int = 960) -> dict[str, Any]:
    """bench/batch.py's local one-worker throughput alone (its workload, warm process, the
    fastest of its REPEATS runs) for issue 30's row: (grasp, sample)/s per worker."""
    from batch import CHUNK, REPEATS, _run, write_dataset

    from grasp_safety_ros.dataset.batch import run_batch

    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        spec = write_dataset(root, grasps, CHUNK)
        run_batch(spec, root / "warm", workers=1)
        runs = [_run(spec, root / f"local_1_{k}", workers=1) for k in range(REPEATS)]
    return {
        "grasps": grasps,
        "grasp_samples_per_s": max(r["grasp_samples_per_s"] for r in runs),
        "repeats_per_s": [r["grasp_samples_per_s"] for r in runs],
    }
