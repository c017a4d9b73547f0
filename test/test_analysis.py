"""The safety report that combines the paper's ranking with the analyses beyond it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from grasp_safety_ros.cli.main import main, rank_scenario
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.scenario.schema import load_scenario, parse_scenario

EXTENDED = yaml.safe_load(config_file("book_baxter_extended.yaml").read_text())


def coarse(data: dict, **changes: object) -> dict:
    """The scenario with a coarse time step (fast tests) and top-level changes."""
    result = json.loads(json.dumps(data))
    result["trajectory"]["dt_s"] = 0.1
    result["uncertainty"] = {**result.get("uncertainty", {}), "samples": 8}
    result.update(changes)
    return {k: v for k, v in result.items() if v is not None}


def test_default_options_reproduce_the_paper_ranking() -> None:
    scenario = load_scenario(config_file("book_baxter.yaml"))
    report = rank_scenario(scenario)
    assert report.order == report.ranking.order == report.safety_order
    for k, evaluation in enumerate(report.ranking.evaluations):
        assert report.scores[k] == evaluation.score


def test_extended_scenario_json(tmp_path: Path) -> None:
    path = tmp_path / "extended.yaml"
    path.write_text(yaml.safe_dump(coarse(EXTENDED)))
    out = tmp_path / "out.json"
    assert main(["rank", str(path), "--json", str(out), "--plot", str(tmp_path / "p.png")]) == 0
    result = json.loads(out.read_text())  # strict JSON: no NaN or Infinity
    assert result["metric_point"] == "leading_point"
    grasps = result["grasps"]
    # The final ranking sorts by the documented combination, best first.
    combined = [grasps[k]["combined_score"] for k in result["ranking"]]
    assert combined == sorted(combined, reverse=True)
    # The safety ranking sorts by the leading point's score, safest first.
    safety = [grasps[k]["safety_score"] for k in result["safety_ranking"]]
    assert safety == sorted(safety)
    for grasp in grasps:
        masses = grasp["samples"]["leading_point_effective_mass_kg"]
        assert grasp["safety_score"] == pytest.approx(np.mean(masses), rel=1e-12)
        assert set(grasp["iso_ts_15066"]["regions"]) == {
            "chest",
            "upper_arm_elbow",
            "lower_arm_wrist",
            "hand_fingers",
            "face",
        }
        assert grasp["iso_ts_15066"]["regions"]["face"]["worst_force_ratio"] is None
        assert grasp["redundancy"]["score"] <= grasp["redundancy"]["score_without"] + 1e-9
        assert len(grasp["samples"]["joint_torques"][0]) == 7
        assert grasp["uncertainty"]["worst_case_score"] >= grasp["score"] - 1e-12
    assert result["uncertainty"]["perturbations"] > 8
    pareto = set(result["pareto_set"])
    assert pareto and pareto <= set(result["ranking"])


def test_rank_by_effort_orders_by_the_effort_score(tmp_path: Path) -> None:
    data = coarse(EXTENDED, rank_by="effort", redundancy=False, uncertainty=None)
    scenario = parse_scenario(data, tmp_path)
    report = rank_scenario(scenario)
    scores = [report.effort[k].score("peak_fraction") for k in report.order]
    assert scores == sorted(scores)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"metric_point": "corner"}, "metric_point: must be one of"),
        ({"safety_weight": 1.5}, r"safety_weight: must be in \[0, 1\]"),
        ({"uncertainty": {"mass_fraction": 1.5}}, "uncertainty.mass_fraction"),
        ({"uncertainty": {"spread": 0.1}}, "uncertainty.spread: unknown field"),
        ({"iso_ts_15066": {"regions": ["tail"]}}, "tail"),
        ({"redundancy": "yes"}, "redundancy: must be true or false"),
        ({"effort": {"criterion": "max"}}, "effort.criterion: must be one of"),
        ({"rank_by": "price"}, "rank_by: must be one of safety, effort"),
    ],
)
def test_bad_options_name_the_field(tmp_path: Path, changes: dict, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        parse_scenario(coarse(EXTENDED, **changes), tmp_path)


def test_point_metric_needs_points(tmp_path: Path) -> None:
    data = coarse(EXTENDED)
    data["object"] = {"mass_kg": 0.3, "inertia_about_com_kgm2": np.eye(3).tolist()}
    data["object"]["inertia_about_com_kgm2"] = (np.eye(3) * 1e-3).tolist()
    with pytest.raises(InvalidInputError, match="metric_point: 'leading_point' needs"):
        parse_scenario(data, tmp_path)
    with pytest.raises(InvalidInputError, match="metric_point"):
        AnalysisOptions(metric_point="worst_point")


def test_partial_quality_is_refused(tmp_path: Path) -> None:
    data = coarse(EXTENDED)
    del data["grasps"][1]["quality"]
    with pytest.raises(InvalidInputError, match="grasps: give a quality for every grasp"):
        parse_scenario(data, tmp_path)


def test_progress_counts_every_unit_and_can_abandon(tmp_path: Path) -> None:
    from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
    from grasp_safety_ros.core.analyses.safety_report import analyse

    scenario = parse_scenario(coarse(EXTENDED, redundancy=False), tmp_path)
    evaluator = GraspSafetyEvaluator(scenario.robot.load(), EvaluationConfig())
    ranking = evaluator.rank(
        scenario.grasps, scenario.object_inertia, scenario.trajectory, scenario.robot.seed
    )
    calls: list[tuple[int, int]] = []
    analyse(
        evaluator,
        scenario.grasps,
        scenario.object_inertia,
        scenario.trajectory,
        scenario.options,
        ranking=ranking,
        progress=lambda d, t: calls.append((d, t)),
    )
    # exposed points and effort per grasp, plus one uncertainty analysis
    assert calls == [(k, 7) for k in range(1, 8)]

    class AbandonError(Exception):
        pass

    def abandon(done: int, total: int) -> None:
        if done == 2:
            raise AbandonError

    with pytest.raises(AbandonError):
        analyse(
            evaluator,
            scenario.grasps,
            scenario.object_inertia,
            scenario.trajectory,
            scenario.options,
            ranking=ranking,
            progress=abandon,
        )


def test_analyses_share_one_augmented_model_per_grasp(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Exposed points, redundancy and effort all need the robot + object model of a grasp:
    it is built once per feasible grasp, not once per analysis (on the compiled path only
    redundancy builds it: exposed points and effort read the shared terms,
    core.method.terms), and the shared one gives the same report as each analysis building
    its own."""
    from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
    from grasp_safety_ros.core.analyses import (
        base,
        effort,
        exposed_points,
        redundancy,
        safety_report,
    )
    from grasp_safety_ros.core.method.effective_mass import augmented_model

    scenario = parse_scenario(coarse(EXTENDED, redundancy=True), tmp_path)
    evaluator = GraspSafetyEvaluator(scenario.robot.load(), EvaluationConfig())
    ranking = evaluator.rank(
        scenario.grasps, scenario.object_inertia, scenario.trajectory, scenario.robot.seed
    )
    options = scenario.options
    assert options.points_in_object_m is not None and options.redundancy and options.effort

    def run() -> safety_report.SafetyReport:
        return safety_report.analyse(
            evaluator,
            scenario.grasps,
            scenario.object_inertia,
            scenario.trajectory,
            options,
            ranking=ranking,
        )

    built: list[int] = []

    def counting(*args: object) -> object:
        built.append(1)
        return augmented_model(*args)  # type: ignore[arg-type]

    for module in (base, exposed_points, redundancy, effort):
        monkeypatch.setattr(module, "augmented_model", counting)
    shared = run()
    feasible = sum(e.feasible for e in ranking.evaluations)
    assert feasible >= 2
    assert len(built) == feasible
    monkeypatch.setattr(base, "augmented_model", lambda *args: None)  # each its own
    separate = run()
    # one more per grasp: redundancy's own (exposed points and effort read the shared terms)
    assert len(built) == 2 * feasible
    np.testing.assert_array_equal(shared.scores, separate.scores)
    for a, b in zip(shared.effort, separate.effort, strict=True):
        np.testing.assert_array_equal(a.joint_torques, b.joint_torques)
