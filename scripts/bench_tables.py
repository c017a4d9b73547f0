"""The generated blocks rendered from committed benchmark results (``bench/results.json`` of
``make bench``, ``bench/results_batch.json``, ``bench/results_monitor.json``), one renderer per
block (``scripts/doc_tables.py`` registers them in GENERATORS)."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "results.json"
BENCH_BATCH = ROOT / "bench" / "results_batch.json"
BENCH_MONITOR = ROOT / "bench" / "results_monitor.json"


def _bench() -> dict[str, Any]:
    return json.loads(BENCH.read_text())


def _arms_load(results: dict[str, Any]) -> list[float]:
    """The 1-min load average before and after the arms' section (bench/run.py --merge keeps
    sections of several runs; older results have the whole run's)."""
    if "sections" in results:
        return results["sections"]["arms"]["load_average_1min"]
    machine = results["machine"]
    return [machine["load_average_1min_before"], machine["load_average_1min_after"]]


def render_bench_arms() -> str:
    """The ranking's speed per (grasp, sample) on Panda and Baxter, from bench/results.json."""
    arms = _bench()["arms"]
    names = [name for name in ("panda", "baxter") if name in arms]

    def row(label: str, pick: Callable[[dict[str, Any]], str]) -> str:
        return f"| {label} | " + " | ".join(pick(arms[name]) for name in names) + " |"

    def ours(arm: dict[str, Any]) -> str:
        figure = arm["us_per_sample_with_ik"]
        return f"**{figure['median']:.2f}** [{figure['min']:.2f}..{figure['max']:.2f}]"

    lines = [
        "| µs per (grasp, sample) | " + " | ".join(name.capitalize() for name in names) + " |",
        "|---" * (len(names) + 1) + "|",
        row("ours, 1 core, IK included", ours),
        row(
            "ours, 1 core, effective mass only, per grasp (the analyses' path)",
            lambda a: f"{a['us_per_sample_without_ik']['median']:.2f}",
        ),
        row(
            "ours, 2 cores",
            lambda a: (
                f"{a['us_per_sample_with_ik_parallel']['median']:.2f} "
                f"(×{a['parallel_speedup']:.2f})"
            ),
        ),
        row("Python/Pinocchio path", lambda a: f"{a['python_backend_us_per_sample_with_ik']:.0f}"),
        row(
            "first implementation (`bench/reference.py`)",
            lambda a: f"{a['reference']['us_per_sample_with_ik']:.0f}",
        ),
    ]
    if all("pykdl" in arms[name] for name in names):
        lines += [
            row(
                "PyKDL pipeline, IK included",
                lambda a: f"{a['pykdl']['us_per_sample_with_ik']['median']:.0f}",
            ),
            row("speed-up over PyKDL, same run", lambda a: f"**×{a['speedup_vs_pykdl']:.0f}**"),
            row(
                "KDL's solver calls alone (FK, Jacobian, mass matrix)",
                lambda a: f"{a['pykdl']['kdl_calls_us_per_sample']:.1f}",
            ),
        ]
    lines += [
        row(
            "Gauss-Newton iterations per sample (after sample 0)",
            lambda a: f"{a['ik_iterations_per_sample_excluding_first']:.3f}",
        ),
        row("feasible grasps of 100", lambda a: f"{a['feasible_grasps']}"),
        row("physical floor (flop count)", lambda a: f"{a['floor_us_per_sample']:.2f}"),
    ]
    results = _bench()
    continuous = results.get("continuous_arm")
    if continuous:
        figure = continuous["us_per_sample_with_ik"]
        lines += [
            "",
            "| continuous joints (Kinova Jaco2), same run | |",
            "|---|---|",
            f"| ours, 1 core, IK included | {figure['median']:.2f} "
            f"[{figure['min']:.2f}..{figure['max']:.2f}] µs per sample, "
            f"**×{results['continuous_vs_revolute_cpu']:.2f}** the slowest revolute arm "
            "(CPU time) |",
            f"| Python/Pinocchio path | {continuous['python_backend_us_per_sample_with_ik']:.0f} "
            "µs per sample |",
            f"| compiled vs Python: max rel. diff of M_eff | "
            f"{continuous['python_backend_max_rel_diff']:.1e} |",
            f"| feasible grasps of {continuous['grasps']} | {continuous['feasible_grasps']} |",
        ]
    machine = results["machine"]
    before, after = _arms_load(results)
    lines += [
        "",
        f"Machine: {machine['cores_available']} cores, Python {machine['python']}, load average "
        f"{before:.1f} before and {after:.1f} after the run.",
    ]
    return "\n".join(lines) + "\n"


def render_bench_postures() -> str:
    """CPU cost and score gain of posture selection per restart count, from bench/results.json."""
    workloads = _bench()["posture_selection"]
    counts = [row["restarts"] for row in next(iter(workloads.values())) if row["restarts"]]
    header = " | ".join(f"**{c}**" if c == 8 else str(c) for c in counts)
    lines = [f"| restarts | {header} |", "|---" * (len(counts) + 1) + "|"]
    for name, rows in workloads.items():
        by_count = {row["restarts"]: row for row in rows}
        cells = []
        for count in counts:
            row = by_count[count]
            cell = f"{row['cpu_ms_per_grasp']:.1f} / {row['mean_gain_percent']:.1f} %"
            cells.append(f"**{cell}**" if count == 8 else cell)
        lines.append(f"| {name}: ms per grasp / mean gain | " + " | ".join(cells) + " |")
    lines.append("")
    for name, rows in workloads.items():
        row = next(row for row in rows if row["restarts"] == 8)
        lines.append(
            f"- {name}, 8 restarts: largest gain of one grasp {row['max_gain_percent']:.1f} %, "
            f"{row['postures_tried_mean']:.1f} distinct start postures on average, "
            f"{row['feasible']} feasible, {row['rescued_by_selection']} feasible only with "
            "selection."
        )
    return "\n".join(lines) + "\n"


_SERVICE_ROWS = (
    (None, "`posture.restarts: 0`, default response"),
    ("per_sample_off", "same, `response.per_sample: false`"),
    ("node_defaults", "node defaults (`posture.restarts: 8`)"),
    ("least_response", "the least the node returns"),
)


def render_bench_service() -> str:
    """The service round trip per configuration, from bench/results.json."""
    service = _bench()["service"]
    lines = [
        "| | 10 × 101 median, p90 | ranking alone | ratio | 1,000 × 201 end to end | response |",
        "|---|---|---|---|---|---|",
    ]
    for key, label in _SERVICE_ROWS:
        figures = service if key is None else service.get(key)
        if figures is None:
            continue
        large = figures["end_to_end_1000x201"]
        latency = figures["latency_ms"]
        lines.append(
            f"| {label} | {latency['median']:.1f}, {latency['p90']:.1f} ms | "
            f"{figures['ranking_ms']['median']:.1f} ms | ×{figures['latency_over_ranking']:.1f} | "
            f"{large['wall_s']:.2f} s | {large['response_bytes']:,} B |"
        )
    spans = ", ".join(f"{name} {value:.1f}" for name, value in service["spans_ms"].items())
    lines += [
        "",
        f"Where 10 × 101 goes, `posture.restarts: 0`, default response (ms, medians): {spans}.",
        f"The floor of an empty request: {service['empty_request_ms']['median']:.1f} ms with "
        f"`EventsExecutor`, {service['empty_request_spin_once_ms']['median']:.1f} with a "
        f"`spin_once` loop, {service['empty_request_spin_until_ms']['median']:.1f} with "
        "`spin_until_future_complete`; the 10 × 101 ranking "
        f"{service['latency_ms']['median']:.1f}, {service['latency_spin_once_ms']['median']:.1f} "
        f"and {service['latency_spin_until_ms']['median']:.1f} ms.",
    ]
    return "\n".join(lines) + "\n"


def render_bench_batch() -> str:
    """The batch's throughput, per-chunk overhead and the ACRONYM estimate, from
    bench/results_batch.json."""
    batch = json.loads(BENCH_BATCH.read_text())
    runs = (
        ("local_1", "local, `--workers 1`", 1),
        ("local_2", "local, `--workers 2` (package pool, threads)", 2),
        ("dask_2", "Dask `LocalCluster`, 2 worker processes x 1 thread", 2),
    )
    lines = [
        "| run | (grasp, sample)/s | per worker | wall of the 3 runs [s] | peak memory per worker "
        "[MiB] |",
        "| --- | ---: | ---: | ---: | ---: |",
    ]
    for key, label, workers in runs:
        run = batch[key]
        rate = run["grasp_samples_per_s"]
        walls = ", ".join(f"{wall:.1f}" for wall in run["wall_s_repeats"])
        lines.append(
            f"| {label} | {rate:.0f} | {rate / workers:.0f} | {walls} | "
            f"{run['peak_memory_per_worker_mib']:.0f} |"
        )
    one = batch["local_1"]["grasp_samples_per_s"]
    samples = batch["local_1"]["grasp_samples"] // batch["grasps"]
    overhead = batch["per_chunk_overhead_s"]
    chunk_s = batch["chunk_grasps"] * samples / one
    repeats = ", ".join(f"{1000 * x:.0f}" for x in batch["per_chunk_overhead_s_repeats"])
    local_efficiency = batch["local_2"]["grasp_samples_per_s"] / (2 * one)
    hours, ideal = batch["acronym_hours"], batch["acronym_hours_ideal"]
    counts = list(hours)
    lines += [
        "",
        f"- Per-chunk overhead: {1000 * overhead:.0f} ms (median of {repeats} ms: "
        f"{batch['chunks_of_1']['chunks']} chunks of 1 grasp against "
        f"{batch['chunk_per_file']['chunks']} chunks of "
        f"{batch['chunks_of_1']['chunks'] // batch['chunk_per_file']['chunks']}, 1 local "
        f"worker); a chunk of {batch['chunk_grasps']} grasps is {batch['chunk_grasps']} x "
        f"{samples} / {one:.0f} = {chunk_s:.2f} s of work at the 1-worker rate, so the "
        f"overhead is about {100 * overhead / chunk_s:.0f} %.",
        f"- 2-worker efficiency (2-worker rate / twice the 1-worker rate): Dask "
        f"{batch['dask_efficiency_2_workers']:.2f}, local pool {local_efficiency:.2f}. The Dask "
        f"parts were {'' if batch['dask_parts_identical_to_local'] else 'not '}byte-identical "
        "to the local ones.",
        f"- All of ACRONYM (17.7 M grasps x {samples} samples) at the 1-worker rate: "
        f"{batch['acronym_core_hours']:.0f} core-hours; with one Dask worker per core:",
        "",
        "| machines of 16 cores | " + " | ".join(counts) + " |",
        "| --- |" + " ---: |" * len(counts),
        f"| hours at the measured efficiency {batch['dask_efficiency_2_workers']:.2f} | "
        + " | ".join(f"{hours[c]:.2g}" for c in counts)
        + " |",
        "| hours at ideal scaling | " + " | ".join(f"{ideal[c]:.2g}" for c in counts) + " |",
    ]
    return "\n".join(lines) + "\n"


def render_bench_whole_arm() -> str:
    """The whole-arm analysis' cost per (grasp, sample) and of posture selection by it, from
    bench/results.json."""
    arms = _bench()["whole_arm"]
    lines = [
        "| arm | whole arm on the shared compiled terms, per (grasp, sample) | the Pinocchio "
        "reference path | the compiled ranking, same run | posture selection by the tip score, "
        "per grasp | by the whole arm (chest) |",
        "|---|---|---|---|---|---|",
    ]
    for name, arm in arms.items():
        posture = arm["posture_ms_per_grasp"]
        lines.append(
            f"| {name.capitalize()} | {arm['us_per_sample']:.1f} µs | "
            f"{arm['us_per_sample_pinocchio']:.1f} µs | {arm['ranking_us_per_sample']:.1f} µs | "
            f"{posture['score']:.1f} ms | {posture['whole_arm']:.1f} ms "
            f"(×{posture['whole_arm'] / posture['score']:.1f}) |"
        )
    first = next(iter(arms.values()))
    lines += [
        "",
        f"{first['feasible_grasps']} feasible grasps x "
        f"{first['samples'] // first['feasible_grasps']} samples, {first['sites']} sites, "
        f"posture selection with {first['posture_restarts']} restarts.",
    ]
    return "\n".join(lines) + "\n"


_UNITS = {"s": " s", "ms": " ms", "us": " µs", "x": ""}


def _typeset(text: str) -> str:
    """A bench row's plain text as the docs write it: ≤, ≥, ×, µs."""
    text = text.replace("<=", "≤").replace(">=", "≥").replace(" us", " µs")
    return re.sub(r"(?<![\w.])x(?=\d)", "×", text).replace("|", "\\|")


def _measured(value: float, unit: str) -> str:
    return (f"{value:,.0f}" if value >= 100 else f"{value:.3g}") + _UNITS[unit]


def _runs(results: dict[str, Any]) -> str:
    """Which run measured each section, with its 1-min load average before and after."""
    by_run: dict[str, list[str]] = {}
    for name, section in results["sections"].items():
        before, after = section["load_average_1min"]
        loads = "" if before is None else f", load {before:.1f} → {after:.1f}"
        spent = f", {section['wall_s']:.0f} s" if "wall_s" in section else ""
        by_run.setdefault(str(section["run"]), []).append(f"{name}{spent}{loads}")
    return "; ".join(f"{run}: {', '.join(names)}" for run, names in sorted(by_run.items()))


def render_bench_targets() -> str:
    """Issue 30's targets, each beside the figure of the last ``make bench``, and issue 28's
    no-regression rows (this run against the previous committed one), from
    bench/results.json."""
    results = _bench()
    verdicts = {True: "met", False: "not met", None: ""}
    lines = ["| measure | this run | target | |", "|---|---|---|---|"]
    lines += [
        f"| {_typeset(r['measure'])} | {_typeset(r['value'])} | {_typeset(r['target'])} | "
        f"{verdicts[r['met']]} |"
        for r in results["issue30_targets"]
    ]
    previous = results["previous"] or {"source": "none", "load_average_1min": [None, None]}
    before, after = previous["load_average_1min"]
    loads = "" if before is None else f", load {before:.1f} → {after:.1f}"
    lines += [
        "",
        f"Sections by run: {_runs(results)}.",
        "",
        f"No regression (issue 28): this run beside the previous committed run "
        f"({previous['source']}{loads}); a ratio above "
        f"×{results['no_regression_tolerance']:g} is reported as slower:",
        "",
        "| measure | this run | previous | ratio | |",
        "|---|---|---|---|---|",
    ]
    for r in results["no_regression"]:
        unit = r["unit"]
        old = "" if r["previous"] is None else _measured(r["previous"], unit)
        ratio = "" if r["ratio"] is None else f"×{r['ratio']:.2f}"
        lines.append(
            f"| {_typeset(r['measure'])} | {_measured(r['value'], unit)} | {old} | {ratio} | "
            f"{r['verdict']} |"
        )
    return "\n".join(lines) + "\n"


def render_bench_start_up() -> str:
    """The start-up spans of a ranking command (fresh process, medians), from
    bench/results.json."""
    spans = _bench()["pipeline"]["cli"]["start_up"]
    names = {
        "interpreter_s": "interpreter",
        "numpy_pinocchio_s": "numpy + Pinocchio",
        "numba_s": "numba",
        "package_s": "the package",
        "kernels_from_cache_s": "loading the compiled kernels from numba's cache",
    }
    text = ", ".join(f"{label} {spans[key]:.2f} s" for key, label in names.items())
    return f"Start-up of a ranking command (fresh process, medians): {text}.\n"


def render_bench_monitor() -> str:
    """The speed-scaling monitor's cost per joint state and its end-to-end latency, from
    bench/results_monitor.json (``bench/monitor.py``)."""
    monitor = json.loads(BENCH_MONITOR.read_text())
    compute, end_to_end = monitor["compute"], monitor["end_to_end"]
    load = " / ".join(f"{value:.1f}" for value in monitor["load_average"])
    rate_hz = end_to_end["publish_rate_hz"]
    rows = (
        (
            compute["on_state"],
            "per state, `Governor.on_state` (names matched, the core's "
            "analysis, rate limit), wall",
        ),
        (compute["on_state_cpu"], "the same, this thread's CPU time"),
        (compute["core"], "the core's analysis alone (`SpeedScaling.assess`), wall"),
        (
            end_to_end["latency"],
            f"`/joint_states` publish to the factor's arrival (end to end, "
            f"{rate_hz:.0f} Hz for {end_to_end['published_states'] / rate_hz:.0f} s)",
        ),
    )
    lines = [
        f"Load average {load} at the start; {monitor['sites']} sites, {monitor['regions']} "
        "regions.",
        "",
        "| | median | p99 | max |",
        "|---|---|---|---|",
        *(
            f"| {label} | {f['median_ms']:.2f} ms | {f['p99_ms']:.2f} ms | {f['max_ms']:.2g} ms |"
            for f, label in rows
        ),
    ]
    wall, cpu = compute["on_state"]["p99_ms"], compute["on_state_cpu"]["p99_ms"]
    below, answered = end_to_end["states_below_1"], end_to_end["states_below_1_with_a_factor"]
    lines += [
        "",
        f"The target, p99 compute <= 1 ms, is {'met' if max(wall, cpu) <= 1.0 else 'not met'} "
        f"({wall:.2f} ms wall, {cpu:.2f} ms CPU). Of the {below} published states with a factor "
        f"below 1 (each recognisable by its value), {answered} ({100 * answered / below:.0f} %) "
        f"got their own factor back at {rate_hz:.0f} Hz.",
    ]
    return "\n".join(lines) + "\n"
