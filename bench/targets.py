"""bench/run.py's verdicts: issue 30's target table, each row beside this run's figure, and
issue 28's "no regression" table (the core's µs per sample, the CLI and the service rows of this
run against the previous committed ``bench/results.json``).

Both read the results of ``bench/run.py`` (its section keys: ``arms``, ``whole_arm``,
``pipeline``, ``batch_per_worker``, ``service``, ``fresh_demo``); a row whose section was not
measured says so and why, never silently.
"""

from __future__ import annotations

import os
from typing import Any

NOT_RUN = "not measured: section not run"
DEMO_SILENCE_S = 30.0
"""The longest time ``make demo`` may print nothing before its table (the issue's "visible
progress throughout"): pip's silent unpacking of the core's packages is the longest on a
machine whose pip reads local wheels (5 s at load 2); a minute of silence would read as hung."""
REGRESSION_TOLERANCE = 1.25
"""A figure more than this multiple of the previous run's is reported as slower: runs of the
same code on this shared 2-core machine spread by up to ±20 % (``spread_rel`` of the arms'
repeats); a real regression is then re-checked at the same load."""


def _row(measure: str, value: str, target: str, met: bool | None) -> dict[str, Any]:
    return {"measure": measure, "value": value, "target": target, "met": met}


_START_UP = "grasp-safety rank 1 x 201, whole process, warm caches"
_START_UP_TARGET = "<= 0.5 s and <= x1.5 import pinocchio"
_PIPELINE_ROWS = (
    ("CLI 100 x 201 --json", "<= 1 s", ("cli", "rank_100", "wall_s"), 1.0, "{:.2f} s"),
    ("CLI 1,000 x 201 --json", "<= 3 s", ("cli", "rank_1000", "wall_s"), 3.0, "{:.2f} s"),
    (
        "posture selection (8 restarts) / single-IK ranking",
        "<= x2, never worse than the single IK (proved by test)",
        ("in_process", "postures_vs_ranking"),
        2.0,
        "x{:.2f}",
    ),
    (
        "default analyses / ranking",
        "<= x1.5",
        ("in_process", "analyses_vs_ranking"),
        1.5,
        "x{:.2f}",
    ),
)
"""bench/pipeline.py's rows after the start-up: measure, target, path of the figure in the
section's results, bound, format."""


def _pipeline_rows(pipeline: dict[str, Any] | None, absent: str) -> list[dict[str, Any]]:
    """Start-up, the CLI, posture selection and the analyses (bench/pipeline.py); ``absent``
    is the value of each row when the section is missing."""
    if pipeline is None:
        return [
            _row(measure, absent, target, None)
            for measure, target, *_ in ((_START_UP, _START_UP_TARGET), *_PIPELINE_ROWS)
        ]
    start = pipeline["cli"].get("rank_start_up")
    if start is None:
        rows = [_row(_START_UP, "not measured: this run predates it", _START_UP_TARGET, None)]
    else:
        rank_s, ratio = start["rank_1_s"], start["rank_1_vs_import_pinocchio"]
        rows = [
            _row(
                _START_UP,
                f"{rank_s['median']:.2f} s [{rank_s['min']:.2f}..{rank_s['max']:.2f}], "
                f"x{ratio['median']:.2f} [{ratio['min']:.2f}..{ratio['max']:.2f}] import "
                f"pinocchio ({start['import_pinocchio_s']['median']:.2f} s)",
                _START_UP_TARGET,
                rank_s["median"] <= 0.5 and ratio["median"] <= 1.5,
            )
        ]
    for measure, target, path, bound, text in _PIPELINE_ROWS:
        value: Any = pipeline
        for key in path:
            value = value[key]
        rows.append(_row(measure, text.format(value), target, value <= bound))
    return rows


def _whole_arm_row(whole_arm: dict[str, Any] | None, absent: str) -> dict[str, Any]:
    """The whole arm's cost against the compiled ranking of the same grasps in the same
    section (both CPU time per (grasp, sample): wall time of one and CPU time of the other
    would not compare under load)."""
    measure = "whole arm per (grasp, sample), Panda, default sites + 8 points"
    if not whole_arm or "panda" not in whole_arm:
        return _row(measure, absent, "<= x2 the core's", None)
    panda = whole_arm["panda"]
    site_us, core_us = panda["us_per_sample"], panda["ranking_us_per_sample"]
    return _row(
        measure,
        f"{site_us:.2f} us = x{site_us / core_us:.2f} the ranking's {core_us:.2f} us of the "
        "same grasps (CPU time)",
        "<= x2 the core's",
        site_us <= 2 * core_us,
    )


def _fresh_demo_row(demo: dict[str, Any] | None, absent: str) -> dict[str, Any]:
    measure = "fresh clone, empty caches: make demo to its table"
    target = f"<= 150 s, no silence > {DEMO_SILENCE_S:g} s"
    if demo is None:
        return _row(measure, absent, target, None)
    table_s, silence_s = demo["to_table_s"], demo["longest_silence_s"]
    if table_s is None:
        return _row(measure, f"no table ({demo['exit']})", target, False)
    return _row(
        measure,
        f"{table_s:.1f} s, longest silence {silence_s:.1f} s",
        target,
        table_s <= 150.0 and silence_s <= DEMO_SILENCE_S,
    )


def issue30_rows(
    results: dict[str, Any], failed: dict[str, str] | None = None
) -> list[dict[str, Any]]:
    """Issue 30's targets, each beside this run's figure: measure, value (text), target
    (text), met (True, False, or None where not measured or measured by hand). ``failed``:
    the error of each section that raised one, which its rows give as the reason."""

    def absent(section: str) -> str:
        error = (failed or {}).get(section)
        return NOT_RUN if error is None else f"not measured: section {section} failed: {error}"

    pipeline_rows = _pipeline_rows(results.get("pipeline"), absent("pipeline"))
    rows = [
        _fresh_demo_row(results.get("fresh_demo"), absent("fresh_demo")),
        *pipeline_rows[:3],
        _whole_arm_row(results.get("whole_arm"), absent("whole_arm")),
        *pipeline_rows[3:],
    ]
    batch = results.get("batch_per_worker")
    rows.append(
        _row(
            "batch per worker, bench/batch.py (1 local worker, fastest of its repeats)",
            absent("batch_per_worker")
            if batch is None
            else f"{batch['grasp_samples_per_s']:,.0f} /s",
            ">= 20,000 /s, rows unchanged",
            None if batch is None else batch["grasp_samples_per_s"] >= 20_000,
        )
    )
    service = results.get("service")
    targets = {t["row"]: t for t in (service or {}).get("targets") or ()}
    missing = absent("service") if service is None else f"not measured: {service.get('reason')}"
    for key, label, target_ms in (
        ("10 grasps x 101 samples, median", "service, node defaults, 10 x 101", 15.0),
        ("100 grasps x 201 samples, one client", "service, node defaults, 100 x 201", 100.0),
    ):
        measured = targets.get(key)
        value = None if measured is None else measured["measured_ms"]
        rows.append(
            _row(
                label,
                missing if value is None else f"{value:.1f} ms",
                f"<= {target_ms:g} ms",
                None if value is None else value <= target_ms,
            )
        )
    arms = results.get("arms") or {}
    for name, target in (("panda", 1.0), ("baxter", 1.3)):
        value = arms[name]["us_per_sample_with_ik"]["median"] if name in arms else None
        rows.append(
            _row(
                f"core us per (grasp, sample), {name.capitalize()}",
                absent("arms") if value is None else f"{value:.2f} us",
                f"<= {target:g} us",
                None if value is None else value <= target,
            )
        )
    return rows


def unmeasured(rows: list[dict[str, Any]]) -> list[str]:
    """The measures of ``rows`` this run did not measure (by-hand rows excepted)."""
    return [r["measure"] for r in rows if r["value"].startswith("not measured")]


def print_issue30(rows: list[dict[str, Any]]) -> None:
    """The rows of ``issue30_rows`` as a table, with the load average now."""
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"\nIssue 30's targets, this run (load average {load}):")
    for r in rows:
        verdict = {True: "met", False: "NOT met", None: ""}[r["met"]]
        print(f"  {r['measure']}: {r['value']} (target {r['target']}) {verdict}".rstrip())
    missing = unmeasured(rows)
    if missing:
        print(f"  WARNING: {len(missing)} rows not measured this run: {'; '.join(missing)}")


# ----------------------------------------------------------------------------- issue 28
_CLI_FIGURES = (
    ("help_s", "CLI --help"),
    ("rank_1", "CLI 1 x 201 --json"),
    ("rank_100", "CLI 100 x 201 --json"),
    ("rank_1000", "CLI 1,000 x 201 --json"),
    ("rank_1000_no_per_sample", "CLI 1,000 x 201 --json --no-per-sample"),
)
_SERVICE_FIGURES: tuple[tuple[str | None, str], ...] = (
    (None, "posture.restarts 0"),
    ("per_sample_off", "posture.restarts 0, per_sample false"),
    ("node_defaults", "node defaults"),
    ("least_response", "least response"),
)


def regression_figures(results: dict[str, Any]) -> dict[str, list[Any]]:
    """The figures issue 28 wants unchanged, by measure: [value, unit] (the core's µs per
    (grasp, sample) per arm, the CLI's wall times, the service's round trips)."""
    figures: dict[str, list[Any]] = {}
    for name, arm in (results.get("arms") or {}).items():
        figures[f"core us per (grasp, sample), {name}"] = [
            arm["us_per_sample_with_ik"]["median"],
            "us",
        ]
    cli = (results.get("pipeline") or {}).get("cli") or {}
    for key, label in _CLI_FIGURES:
        if key in cli:
            figures[label] = [cli[key] if key == "help_s" else cli[key]["wall_s"], "s"]
    service = results.get("service") or {}
    for configuration, label in _SERVICE_FIGURES:
        measured = service if configuration is None else service.get(configuration)
        if not measured or "latency_ms" not in measured:
            continue
        figures[f"service, {label}, 10 x 101 median"] = [measured["latency_ms"]["median"], "ms"]
        for size in ("100x201", "1000x201"):
            end_to_end = measured.get(f"end_to_end_{size}")
            if end_to_end:
                what = size.replace("x", " x ").replace("1000", "1,000")
                figures[f"service, {label}, {what} end to end"] = [
                    1e3 * end_to_end["wall_s"],
                    "ms",
                ]
    return figures


def no_regression_rows(
    results: dict[str, Any], previous: dict[str, Any] | None
) -> list[dict[str, Any]]:
    """Each of ``regression_figures`` of this run beside the previous run's: measure, value,
    previous, unit, ratio (value / previous) and verdict."""
    before = (previous or {}).get("figures") or {}
    rows = []
    for measure, (value, unit) in regression_figures(results).items():
        old = before.get(measure, [None])[0]
        ratio = None if not old else value / old
        if ratio is None:
            verdict = "no previous figure"
        elif value == old:
            verdict = "same figure (not re-measured)"
        elif ratio <= REGRESSION_TOLERANCE:
            verdict = "no regression"
        else:
            verdict = "slower: re-check at the same load"
        rows.append(
            {
                "measure": measure,
                "value": value,
                "previous": old,
                "unit": unit,
                "ratio": ratio,
                "verdict": verdict,
            }
        )
    return rows


def print_no_regression(rows: list[dict[str, Any]], previous: dict[str, Any] | None) -> None:
    """The rows of ``no_regression_rows`` as a table."""
    where = (previous or {}).get("source", "none")
    print(f"\nIssue 28, no regression: this run against the previous committed run ({where}):")
    for r in rows:
        old = "n/a" if r["previous"] is None else f"{r['previous']:.3g}"
        ratio = "" if r["ratio"] is None else f" = x{r['ratio']:.2f}"
        print(
            f"  {r['measure']}: {r['value']:.3g} {r['unit']} (previous {old}{ratio}): "
            f"{r['verdict']}"
        )
