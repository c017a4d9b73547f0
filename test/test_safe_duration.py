"""The retiming as an analysis of the pipeline (core.analyses.safe_duration): the scenario's
retime: section, rank_by safe_duration (order, posture selection never worse than the single
IK), the JSON, the batch column, and the standard's m_R = M/2 + m_L beside the exact mass."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from test_site_speeds import one_link

from grasp_safety_ros.cli.main import rank_scenario
from grasp_safety_ros.cli.report import report_to_dict
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


def test_batch_column_is_the_safe_duration(ranked) -> None:
    columns = report_columns(ranked)
    assert columns["safe_duration_s"] == [m.safe_duration_s for m in ranked.retimed]


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
