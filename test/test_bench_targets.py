"""bench/targets.py: issue 30's target rows and issue 28's no-regression rows from bench/run.py's
section results (synthetic figures; the verdicts checked against the issues' bounds)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

import pytest

PATH = Path(__file__).resolve().parents[1] / "bench" / "targets.py"
spec = importlib.util.spec_from_file_location("bench_targets", PATH)
assert spec is not None and spec.loader is not None
targets = importlib.util.module_from_spec(spec)
spec.loader.exec_module(targets)


def spread(median: float) -> dict[str, float]:
    return {"median": median, "min": 0.9 * median, "max": 1.1 * median}


def sections(scale: float = 1.0) -> dict[str, Any]:
    """Every section bench/run.py feeds the rows, figures times ``scale``."""
    return {
        "arms": {
            "panda": {"us_per_sample_with_ik": spread(0.9 * scale)},
            "baxter": {"us_per_sample_with_ik": spread(1.2 * scale)},
        },
        "whole_arm": {"panda": {"us_per_sample": 1.9 * scale, "ranking_us_per_sample": 1.0}},
        "pipeline": {
            "cli": {
                "help_s": 0.2 * scale,
                "rank_1": {"wall_s": 0.4 * scale},
                "rank_100": {"wall_s": 0.9 * scale},
                "rank_1000": {"wall_s": 2.9 * scale},
                "rank_start_up": {
                    "rank_1_s": spread(0.45 * scale),
                    "rank_1_vs_import_pinocchio": spread(1.4 * scale),
                    "import_pinocchio_s": spread(0.3),
                },
            },
            "in_process": {
                "postures_vs_ranking": 1.9 * scale,
                "analyses_vs_ranking": 1.4 * scale,
            },
        },
        "batch_per_worker": {"grasp_samples_per_s": 21_000 / scale},
        "fresh_demo": {
            "to_table_s": 140 * scale,
            "longest_silence_s": 0.9 * targets.DEMO_SILENCE_S * scale,
            "exit": "[exit status 0]",
        },
        "service": {
            "latency_ms": spread(10 * scale),
            "node_defaults": {
                "latency_ms": spread(14 * scale),
                "end_to_end_100x201": {"wall_s": 0.09 * scale},
            },
            "targets": [
                {"row": "10 grasps x 101 samples, median", "measured_ms": 14 * scale},
                {"row": "100 grasps x 201 samples, one client", "measured_ms": 90 * scale},
            ],
        },
    }


def test_a_full_run_measures_every_row_in_the_issues_order() -> None:
    rows = targets.issue30_rows(sections())
    assert [r["measure"].split(",")[0].split(" per ")[0] for r in rows] == [
        "fresh clone",
        "grasp-safety rank 1 x 201",
        "CLI 100 x 201 --json",
        "CLI 1",
        "whole arm",
        "posture selection (8 restarts) / single-IK ranking",
        "default analyses / ranking",
        "batch",
        "service",
        "service",
        "core us",
        "core us",
    ]
    assert targets.unmeasured(rows) == []
    assert all(r["met"] is True for r in rows)  # every figure just inside its bound


def test_figures_past_the_bounds_are_not_met() -> None:
    # x1.12 puts every figure past its bound (each sits 3-10 % inside); the batch's rate drops.
    rows = targets.issue30_rows(sections(scale=1.12))
    assert [r["met"] for r in rows] == [False] * len(rows)


@pytest.mark.parametrize(
    ("table_s", "silence_s", "met"),
    [(149.0, 29.0, True), (151.0, 29.0, False), (149.0, 31.0, False), (None, 1.0, False)],
)
def test_the_first_table_needs_both_its_time_and_visible_progress(
    table_s: float | None, silence_s: float, met: bool
) -> None:
    figures = sections()
    figures["fresh_demo"] = {
        "to_table_s": table_s,
        "longest_silence_s": silence_s,
        "exit": "[exit status 2]",
    }
    (row,) = [r for r in targets.issue30_rows(figures) if r["measure"].startswith("fresh")]
    assert row["met"] is met
    assert ("no table ([exit status 2])" in row["value"]) is (table_s is None)


def test_rows_not_measured_say_why() -> None:
    partial = sections()
    del partial["batch_per_worker"], partial["pipeline"], partial["fresh_demo"]
    partial["service"] = {"median_ms": None, "reason": "node not measurable: no rclpy"}
    rows = targets.issue30_rows(partial)
    missing = {r["measure"]: r["value"] for r in rows if r["value"].startswith("not measured")}
    assert len(missing) == 9  # the demo, 5 pipeline rows, the batch, the two service rows
    assert missing["service, node defaults, 10 x 101"] == (
        "not measured: node not measurable: no rclpy"
    )
    assert all(r["met"] is None for r in rows if r["measure"] in missing)


@pytest.mark.parametrize(
    ("scale", "verdict"),
    [
        (1.0, "same figure (not re-measured)"),
        (0.5, "no regression"),
        (targets.REGRESSION_TOLERANCE * 0.99, "no regression"),
        (targets.REGRESSION_TOLERANCE * 1.01, "slower: re-check at the same load"),
    ],
)
def test_no_regression_compares_each_figure_with_the_previous_run(
    scale: float, verdict: str
) -> None:
    previous = {"figures": targets.regression_figures(sections())}
    rows = targets.no_regression_rows(sections(scale), previous)
    assert {r["measure"] for r in rows} == set(previous["figures"])
    for r in rows:
        assert r["ratio"] == pytest.approx(r["value"] / r["previous"], rel=1e-15)
        assert r["verdict"] == verdict, r


def test_a_figure_without_a_previous_one_says_so() -> None:
    rows = targets.no_regression_rows(sections(), None)
    assert rows and all(r["verdict"] == "no previous figure" for r in rows)


def test_rows_of_a_failed_section_give_its_error() -> None:
    partial = sections()
    del partial["whole_arm"]
    rows = targets.issue30_rows(partial, failed={"whole_arm": "KeyError: 'panda'"})
    (row,) = [r for r in rows if r["measure"].startswith("whole arm")]
    assert row["value"] == "not measured: section whole_arm failed: KeyError: 'panda'"
    assert targets.unmeasured(rows) == [row["measure"]]


def test_the_fresh_demo_times_its_steps_and_its_longest_silence() -> None:
    spec = importlib.util.spec_from_file_location("fresh_demo", PATH.with_name("fresh_demo.py"))
    assert spec is not None and spec.loader is not None
    fresh_demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fresh_demo)
    lines = [
        (0.5, "test -x .venv/bin/python || python3 -m venv .venv"),
        (2.0, "Looking in indexes: https://pypi.org/simple"),
        (3.0, "Installing collected packages: numpy, pin"),
        (11.0, "Successfully installed numpy pin"),  # 8 s of silence ends here
        (12.0, ".venv/bin/python -m pip install --no-deps -e . 2>&1"),
        (14.0, ".venv/bin/grasp-safety demo --out demo_output"),
        (15.5, "rank  index  name   score [kg]"),
        (40.0, "joint effort"),  # after the table: not part of the wait
        (41.0, "[exit status 0]"),
    ]
    summary = fresh_demo.summarise_lines(lines)
    assert summary["to_table_s"] == 15.5
    assert summary["steps_start_s"] == {
        "venv": 0.5,
        "downloads": 2.0,
        "unpacking": 3.0,
        "package": 12.0,
        "demo": 14.0,
    }
    assert summary["longest_silence_s"] == 8.0
    assert summary["longest_silence_ended_by"].startswith("Successfully installed")
    assert fresh_demo.summarise_lines(lines[:5])["to_table_s"] is None
