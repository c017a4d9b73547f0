"""The retiming as an analysis of the pipeline (core.analyses.safe_duration): the scenario's
retime: section, rank_by safe_duration (order, posture selection never worse than the single
IK), the JSON, the batch column, and the standard's m_R = M/2 + m_L beside the exact mass."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_site_speeds import one_link

from grasp_safety_ros.cli.main import rank_scenario
from grasp_safety_ros.cli.report import report_to_dict
from grasp_safety_ros.cli.retime_report import retime_lines
from grasp_safety_ros.core.analyses import retime
from grasp_safety_ros.core.analyses.safe_duration import (
    compare_with_standard,
    standard_mass_estimate_kg,
)
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.dataset.rows import report_columns
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.scenario.schema import parse_retime, parse_scenario

ACCELERATIONS = [3.0, 3.0, 3.0, 3.0, 4.0, 4.0, 4.0]


def book(**sections) -> dict:
    """The bundled book scenario on Baxter, 11 samples, with ``sections`` added."""
    data = yaml.safe_load(config_file("book_baxter.yaml").read_text())
    data["trajectory"]["dt_s"] = 0.2
    data["effort"] = {"enabled": False}
    return {**data, **sections}


@pytest.fixture(scope="module")
def ranked(tmp_path_factory: pytest.TempPathFactory):
    tmp_path = tmp_path_factory.mktemp("book")
    data = book(
        retime={"joint_acceleration_limits": ACCELERATIONS, "safety_factor": 0.8},
        rank_by="safe_duration",
        whole_arm={"enabled": True},
        posture={"restarts": 2},
    )
    return rank_scenario(parse_scenario(data, tmp_path))


def test_rank_by_safe_duration_orders_by_the_retimed_duration(ranked) -> None:
    durations = {k: m.safe_duration_s for k, m in enumerate(ranked.retimed) if m is not None}
    assert len(durations) == len(ranked.ranking.evaluations)  # all feasible here
    keys = [(durations[k], ranked.scores[k], k) for k in durations]
    assert list(ranked.order) == [k for *_, k in sorted(keys)]


def test_posture_selection_by_safe_duration_is_never_worse_than_the_single_ik(ranked) -> None:
    for posture in ranked.ranking.postures:
        assert posture.criterion == "safe_duration"
        assert posture.criterion_value <= posture.criterion_single_ik
        chosen = ranked.retimed[posture.index].safe_duration_s
        assert chosen == pytest.approx(posture.criterion_value, rel=1e-12)


def test_json_has_the_retimed_trajectory_and_the_standard_estimate(ranked) -> None:
    tree = report_to_dict(ranked)
    assert tree["rank_by"] == "safe_duration"
    n = len(tree["joint_names"])
    for k, grasp in enumerate(tree["grasps"]):
        motion = ranked.retimed[k]
        assert grasp["safe_duration_s"] == motion.safe_duration_s
        retimed = grasp["retimed"]
        t = np.array(retimed["t_s"])
        assert t[0] == 0.0 and t[-1] == pytest.approx(motion.safe_duration_s)
        assert np.all(np.diff(t) > 0)
        for key in ("q", "qd", "qdd"):
            assert np.array(retimed[key]).shape == (len(t), n)
        assert len(retimed["binding"]) == len(t)
        standard = grasp["standard_mass_estimate"]
        assert standard["estimate_kg"] == pytest.approx(ranked.standard_mass_estimate_kg)
        exact = max(ranked.ranking.evaluations[k].effective_mass_kg)
        assert standard["tip_exact_kg"] == pytest.approx(exact)
        assert standard["tip_optimistic"] == (standard["estimate_kg"] < exact)
        assert set(standard["sites"]) == set(ranked.arm_sites.names)


def binding_most_samples(motion: retime.RetimedMotion) -> str:
    """The oracle of retime_binding: the label whose ratio exceeds 0.99 at the most samples
    (at rest left out), the earliest to bind on a tie; "none" when nothing binds."""
    counts: dict[str, int] = {}
    first: dict[str, int] = {}
    for sample, label in enumerate(motion.binding):
        if label != retime.AT_REST and motion.binding_ratio[sample] > 0.99:
            counts[label] = counts.get(label, 0) + 1
            first.setdefault(label, sample)
    return min(counts, key=lambda label: (-counts[label], first[label]), default="none")


def test_batch_columns_are_the_safe_duration_and_what_binds(ranked) -> None:
    columns = report_columns(ranked)
    assert columns["safe_duration_s"] == [m.safe_duration_s for m in ranked.retimed]
    bindings = [binding_most_samples(m) for m in ranked.retimed]
    assert columns["retime_binding"] == bindings
    assert all(b.startswith(("site ", "joint ")) for b in bindings), bindings  # f 0.8 binds
    assert columns["retime_reason"] == [None] * len(bindings)  # every grasp has a timing
    assert [g["retime_binding"] for g in report_to_dict(ranked)["grasps"]] == bindings


def test_retime_requested_without_limits_is_refused_naming_the_field(tmp_path: Path) -> None:
    scenario = parse_scenario(book(), tmp_path)
    assert scenario.options.retime is None and parse_retime(None) is None
    with pytest.raises(InvalidInputError) as error:  # --retime without the section
        parse_retime(None, requested=True)
    assert error.value.field == "retime.joint_acceleration_limits"
    with pytest.raises(InvalidInputError) as error:
        parse_scenario(book(rank_by="safe_duration"), tmp_path)
    assert error.value.field == "retime.joint_acceleration_limits"
    for bad, field in [
        ({"joint_acceleration_limits": ACCELERATIONS, "speed": 1}, "retime"),
        (
            {"joint_acceleration_limits": ACCELERATIONS, "safety_factor": 2.0},
            "retime.safety_factor",
        ),
        ({"joint_acceleration_limits": ACCELERATIONS, "output_dt_s": -1}, "retime.output_dt_s"),
    ]:
        with pytest.raises(InvalidInputError) as error:
            parse_scenario(book(retime=bad), tmp_path)
        assert error.value.field.startswith(field)


def test_standard_estimate_of_a_point_mass_link() -> None:
    """One link of 3 kg: M/2 + m_L = 1.5 kg + the payload."""
    assert standard_mass_estimate_kg(one_link(mass=3.0), 0.7) == pytest.approx(2.2, rel=1e-15)


def test_standard_estimate_is_optimistic_where_the_exact_mass_is_larger() -> None:
    masses = np.array([[1.0, 5.0, 2.0], [3.0, 9.0, 2.5]])
    stationary = np.array([[False, False, True], [False, True, True]])
    result = compare_with_standard(4.0, masses, stationary)
    np.testing.assert_array_equal(result.exact_kg, [3.0, 5.0, np.nan])
    np.testing.assert_array_equal(result.optimistic, [False, True, False])


def test_one_dof_arm_exact_mass_exceeds_the_estimate_far_out() -> None:
    """The 1-DOF closed form: at radius ρ the exact mass is I/ρ², the estimate M/2 + m_L does
    not depend on ρ, so close to the axis the estimate is optimistic and far out it is not."""
    robot = one_link(length=0.5, mass=3.0, reach=0.6, armature=0.1)
    moment = 3.0 * 0.25 + 0.1
    estimate = standard_mass_estimate_kg(robot, 0.0)
    radii = np.array([0.2, 1.0])
    result = compare_with_standard(estimate, (moment / radii**2)[None], np.zeros((1, 2), bool))
    np.testing.assert_array_equal(result.optimistic, moment / radii**2 > 1.5)
    assert result.optimistic.tolist() == [True, False]


def test_node_parameters_build_the_retiming() -> None:
    """The node's retime.* parameters: set limits turn it on; rank_by safe_duration without
    them is refused naming the parameter; a bad safety factor names its parameter."""
    from grasp_safety_ros.ros.parameters import check_parameter, settings_from_parameters

    base = {"urdf": "x", "base_frame": "b", "tip_frame": "t"}
    assert settings_from_parameters(base).analysis.retime is None
    settings = settings_from_parameters(
        {**base, "retime.joint_acceleration_limits": ACCELERATIONS, "rank_by": "safe_duration"}
    )
    retime = settings.analysis.retime
    assert retime.joint_acceleration_limits == tuple(ACCELERATIONS)
    assert retime.joint_velocity_limits is None and retime.safety_factor == 1.0
    with pytest.raises(InvalidInputError) as error:
        settings_from_parameters({**base, "rank_by": "safe_duration"})
    assert error.value.field == "retime.joint_acceleration_limits"
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(InvalidInputError, match=r"retime\.safety_factor"):
            check_parameter("retime.safety_factor", bad)


def test_the_service_orders_by_safe_duration_as_the_cli_does(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    """The node with the retime.* parameters and rank_by safe_duration gives the CLI's order
    for the same book request (the pipeline is the same; the node's defaults are the table's)."""
    pytest.importorskip("rclpy")
    from ros_node_harness import BOOK, BOOK_YAML, NodeUnderTest, book_request

    tmp_path = tmp_path_factory.mktemp("service")
    data = book(
        retime={"joint_acceleration_limits": ACCELERATIONS, "safety_factor": 0.8},
        rank_by="safe_duration",
    )
    data.pop("effort")
    data["grasps"].append({**data["grasps"][0], "name": "out_of_reach", "position_m": [-3, 0, 0]})
    report = rank_scenario(parse_scenario(data, tmp_path))
    request = book_request()
    far = copy.deepcopy(request.grasps.poses[0])
    far.position.x, far.position.y, far.position.z = -3.0, 0.0, 0.0
    request.grasps.poses.append(far)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        patch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log"))
        node = NodeUnderTest(
            {
                "urdf": "example-robot-data:baxter",
                "base_frame": "base",
                "tip_frame": "right_gripper",
                "ik_seed": list(BOOK.robot.seed),
                "object.box_size_m": BOOK_YAML["object"]["box_size_m"],
                "trajectory.dt_s": data["trajectory"]["dt_s"],
                "rank_by": "safe_duration",
                "retime.joint_acceleration_limits": ACCELERATIONS,
                "retime.safety_factor": 0.8,
            }
        )
        try:
            response = node.rank(request)
        finally:
            node.close()
    assert response.success, response.message
    assert response.ranking.rank_by == "safe_duration"
    assert tuple(response.ranking.order) == report.order
    assert len(report.order) == 3
    # The node's inputs pass through messages (a few ulps, times the IK's conditioning); the
    # retiming's LP solution moves with them continuously: equal to 1e-6.
    *retimed, unreached = zip(response.ranking.evaluations, report.retimed, strict=True)
    for got, motion in retimed:
        assert got.safe_duration_s == pytest.approx(motion.safe_duration_s, rel=1e-6)
        assert (got.retime_binding, got.retime_reason) == (binding_most_samples(motion), "")
    got, motion = unreached  # infeasible: no timing, and why
    assert motion is None and report.retime_reasons[3] == "infeasible"
    assert math.isnan(got.safe_duration_s) and not got.retimed_trajectory.points
    assert (got.retime_binding, got.retime_reason) == ("", "infeasible")
    first = response.ranking.evaluations[report.order[0]]
    points = first.retimed_trajectory.points  # response.joint_trajectories 1: the first only
    motion = report.retimed[report.order[0]]
    assert len(points) == len(motion.times_s)
    end = points[-1].time_from_start
    assert end.sec + 1e-9 * end.nanosec == pytest.approx(motion.safe_duration_s, abs=1e-9)
    np.testing.assert_allclose(
        points[len(points) // 2].velocities,
        motion.velocities[len(points) // 2],
        rtol=1e-6,
        atol=1e-9,
    )
    others = [e for e in response.ranking.evaluations if e.index != report.order[0]]
    assert all(not e.retimed_trajectory.points for e in others)


def test_cli_retime_flag_writes_the_json_and_a_figure_per_grasp(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from grasp_safety_ros.cli.main import main

    without = tmp_path / "book.yaml"
    without.write_text(yaml.safe_dump(book()))
    assert main(["rank", str(without), "--retime"]) == 2
    assert "retime.joint_acceleration_limits" in capsys.readouterr().err
    with_limits = tmp_path / "book_retime.yaml"
    data = book(retime={"joint_acceleration_limits": ACCELERATIONS, "enabled": False})
    with_limits.write_text(yaml.safe_dump(data))
    plot, json_path = tmp_path / "out.png", tmp_path / "out.json"
    assert main(["rank", str(with_limits), "--json", str(json_path), "--plot", str(plot)]) == 0
    assert not (tmp_path / "out_retime_0.png").exists()  # enabled: false
    assert main(["rank", str(with_limits), "--retime", "--no-per-sample"]) == 0  # the flag
    assert "safe retiming" in capsys.readouterr().out
    data["retime"].pop("enabled")
    with_limits.write_text(yaml.safe_dump(data))
    assert main(["rank", str(with_limits), "--json", str(json_path), "--plot", str(plot)]) == 0
    assert "safe retiming" in capsys.readouterr().out
    for k in range(3):
        assert (tmp_path / f"out_retime_{k}.png").stat().st_size > 0
    assert "safe_duration_s" in yaml.safe_load(json_path.read_text())["grasps"][0]


def test_region_series_stay_under_their_limits_on_the_grid(ranked) -> None:
    """The figure's data: per region, the worst site's speed <= its f · v_max at every
    retimed sample (grid output), and the planned series' worst ratio is the planner's."""
    for motion in ranked.retimed:
        assert np.all(motion.region_speed_m_s <= motion.region_limit_m_s * (1 + 1e-6))
        planned = motion.planned_region_speed_m_s / motion.planned_region_limit_m_s
        assert planned.max() == pytest.approx(motion.planned_worst_ratio, rel=1e-12)


def test_a_grasp_whose_output_samples_are_too_many_is_left_unretimed_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # f = 0.5 retimes the three grasps to about 2.32, 2.23 and 2.16 s (planned: 2 s); at most
    # 40 samples of 0.057 s cover 2.28 s: only the first is over, by 2 % (no tie to round).
    monkeypatch.setattr(retime, "MAX_OUTPUT_SAMPLES", 40)
    limits = {"joint_acceleration_limits": ACCELERATIONS, "safety_factor": 0.5}
    data = book(
        retime={**limits, "output_dt_s": 0.057}, rank_by="safe_duration", posture={"restarts": 1}
    )
    report = rank_scenario(parse_scenario(data, tmp_path))
    first, *others = report.retimed
    assert first is None and "retime.output_dt_s" in report.retime_reasons[0]
    for motion in others:
        assert motion is not None and motion.safe_duration_s <= 40 * 0.057
        assert np.diff(motion.times_s)[:-1] == pytest.approx(0.057, rel=1e-12)
    assert sorted(report.order) == [1, 2]
    assert "retime.output_dt_s" in " ".join(retime_lines(report))
    assert report_to_dict(report)["grasps"][0]["retime_reason"] == report.retime_reasons[0]
    columns = report_columns(report)  # the batch's columns say the same
    assert columns["retime_reason"] == [report.retime_reasons[0], None, None]
    assert columns["retime_binding"] == [None] + [binding_most_samples(m) for m in others]
    with pytest.raises(InvalidInputError) as error:  # 2 s / 0.049 s: 41 > 40, before any work
        rank_scenario(parse_scenario(book(retime={**limits, "output_dt_s": 0.049}), tmp_path))
    assert error.value.field == "retime.output_dt_s"
