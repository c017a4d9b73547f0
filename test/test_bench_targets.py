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
    assert rows[0]["met"] is None  # by hand
    assert all(r["met"] is True for r in rows[1:])  # every figure just inside its bound


def test_figures_past_the_bounds_are_not_met() -> None:
    # x1.12 puts every figure past its bound (each sits 3-10 % inside); the batch's rate drops.
    rows = targets.issue30_rows(sections(scale=1.12))
    assert [r["met"] for r in rows[1:]] == [False] * (len(rows) - 1)


def test_rows_not_measured_say_why() -> None:
    partial = sections()
    del partial["batch_per_worker"], partial["pipeline"]
    partial["service"] = {"median_ms": None, "reason": "node not measurable: no rclpy"}
    rows = targets.issue30_rows(partial)
    missing = {r["measure"]: r["value"] for r in rows if r["value"].startswith("not measured")}
    assert len(missing) == 8  # 5 pipeline rows, the batch, the two service rows
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
