"""Node parameter validation, without rclpy: every bad value is refused naming the parameter."""

from __future__ import annotations

import array
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from conftest import ARM6_AXES, serial_arm_urdf

from grasp_safety_ros.core import FrameNotFoundError, InvalidInputError, solid_box
from grasp_safety_ros.core.analyses.exposed_points import (
    box_corners_in_object,
    cylinder_rim_points_in_object,
)
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.ros.parameters import (
    PARAMETERS,
    check_parameter,
    settings_from_parameters,
)
from grasp_safety_ros.ros.robot.bundle import build_robot
from grasp_safety_ros.ros.service.response import ResponseContent

MINIMAL = {"base_frame": "base_link", "tip_frame": "tool"}


def flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested params-file keys to dotted parameter names, as rcl does."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


def node_yaml() -> dict[str, Any]:
    data = yaml.safe_load(config_file("grasp_safety_node.yaml").read_text())
    return flatten(data["grasp_safety"]["ros__parameters"])


def test_params_file_declares_exactly_the_node_parameters() -> None:
    assert set(node_yaml()) == set(PARAMETERS)


def test_every_parameter_is_documented() -> None:
    """docs/ros/parameters.md holds the reference rendered from PARAMETERS, as it renders now
    (a parameter added or changed fails this until ``make docs`` re-renders the page)."""
    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "scripts"))
    import render_docs

    page = (root / "docs" / "ros" / "parameters.md").read_text()
    blocks = dict(render_docs.generated_blocks(page))
    assert blocks["parameters"] == render_docs.GENERATORS["parameters"](), "stale: run make docs"
    for name in PARAMETERS:
        assert f"| `{name}` |" in blocks["parameters"], name


def test_parameter_reference_gives_type_unit_and_constraints() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import render_docs

    rows = {
        line.split(" | ")[0].strip("| `"): line.split(" | ")
        for line in render_docs.GENERATORS["parameters"]().splitlines()[2:]
    }
    assert set(rows) == set(PARAMETERS)
    assert rows["posture.restarts"][1:4] == ["integer", "`8`", "in [0, 1,000]"]
    assert rows["trajectory.dt_s"][1:5] == ["double", "`0.02`", "> 0", "s"]
    assert rows["ik_seed"][1] == "double array" and rows["ik_seed"][4] == "rad or m"
    assert rows["object.inertia_about_com_kgm2"][4] == "kg m²"
    assert "read-only" in rows["robot_description_timeout_s"][3]
    assert rows["iso_ts_15066.regions"][1:3] == ["string array", "`[]`"]


def test_params_file_is_the_book_scenario() -> None:
    settings = settings_from_parameters(node_yaml())
    book = solid_box(0.34, [0.15, 0.22, 0.015])
    assert settings.object_inertia is not None
    assert settings.object_inertia.mass_kg == book.mass_kg
    np.testing.assert_allclose(
        settings.object_inertia.inertia_about_com_kgm2, book.inertia_about_com_kgm2, rtol=1e-15
    )
    assert settings.ik_seed == (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0)
    assert (settings.base_frame, settings.tip_frame) == ("base", "right_gripper")
    bundle = build_robot(settings, None)
    assert bundle is not None and bundle.origin == "urdf" and bundle.robot.num_joints == 7


def test_defaults() -> None:
    settings = settings_from_parameters(MINIMAL)
    assert settings.object_inertia is None  # object.mass_kg 0: no default object
    assert settings.ik_seed is None
    assert settings.metric == "mean"
    assert settings.object_frame == "object"
    assert settings.robot_source == ""
    assert build_robot(settings, None) is None


def test_parameter_types_from_rclpy_are_accepted() -> None:
    values = {
        **MINIMAL,
        "ik_seed": array.array("d", [0.1] * 6),  # DOUBLE_ARRAY values arrive as array.array
        "object.mass_kg": 1,  # an integer where a double is meant
        "object.inertia_about_com_kgm2": array.array("q", [1, 0, 0, 1, 0, 1]),
        "object.com_in_object_m": None,  # an empty list in a params file arrives NOT_SET
    }
    with pytest.raises(InvalidInputError, match=r"object\.com_in_object_m: must have shape"):
        settings_from_parameters(values)
    values["object.com_in_object_m"] = [0.0, 0.0, 0.1]
    settings = settings_from_parameters(values)
    assert settings.ik_seed == (0.1,) * 6
    assert settings.object_inertia is not None and settings.object_inertia.mass_kg == 1.0
    assert settings_from_parameters({**MINIMAL, "ik_seed": None}).ik_seed is None
    assert settings_from_parameters({**MINIMAL, "ik_seed": []}).ik_seed is None


BAD: list[tuple[dict[str, Any], str]] = [
    ({"base_frame": ""}, r"^base_frame: must be set"),
    ({"tip_frame": 3}, r"^tip_frame: must be a string, got 3"),
    ({"object_frame": ""}, r"^object_frame: must be a non-empty frame name"),
    ({"object_frame": "base_link"}, r"^object_frame: must differ from base_frame"),
    ({"robot_description": "robots/arm.urdf"}, r"^robot_description: must be URDF XML"),
    ({"metric": "median"}, r"^metric: must be one of mean, max, integral, got 'median'"),
    ({"ik_seed": ["a", "b"]}, r"^ik_seed: must be a list of numbers"),
    ({"ik_seed": [0.0, float("nan")]}, r"^ik_seed: must be finite"),
    ({"ik_seed": 0.5}, r"^ik_seed: must be a list of numbers"),
    ({"use_joint_states_seed": "yes"}, r"^use_joint_states_seed: must be true or false"),
    ({"object.mass_kg": -1.0}, r"^object\.mass_kg: must be in \[0, inf\], got -1"),
    ({"object.mass_kg": float("inf")}, r"^object\.mass_kg: must be finite"),
    ({"object.mass_kg": 2000.0}, r"^object\.mass_kg: must be at most max_mass_kg=1000"),
    ({"object.mass_kg": True}, r"^object\.mass_kg: must be a number"),
    ({"object.mass_kg": 1.0}, r"^object\.inertia_about_com_kgm2: must be positive definite"),
    ({"object.inertia_about_com_kgm2": [1.0] * 5}, r"inertia_about_com_kgm2: must have shape"),
    (
        {"object.mass_kg": 1.0, "object.inertia_about_com_kgm2": [1.0, 0, 0, 1.0, 0, 5.0]},
        r"^object\.inertia_about_com_kgm2: principal moments must satisfy the triangle",
    ),
    ({"object.com_in_object_m": [0.0, 0.0]}, r"^object\.com_in_object_m: must have shape \[3\]"),
    ({"trajectory.dt_s": 0.0}, r"^trajectory\.dt_s: must be in \(0, inf\], got 0"),
    ({"trajectory.dt_s": 3.0}, r"^trajectory\.dt_s: must be at most trajectory\.duration_s=2"),
    ({"trajectory.dt_s": 1e-5}, r"^trajectory\.dt_s: gives 200001 samples .* max_samples=20000"),
    ({"trajectory.duration_s": -2.0}, r"^trajectory\.duration_s: must be in \(0, inf\]"),
    ({"max_grasps": 0}, r"^max_grasps: must be in \[1, "),
    ({"max_grasps": 10.0}, r"^max_grasps: must be an integer, got 10\.0"),
    ({"max_samples": False}, r"^max_samples: must be an integer"),
    ({"max_mass_kg": 0.0}, r"^max_mass_kg: must be in \(0, inf\]"),
    ({"max_compute_time_s": float("nan")}, r"^max_compute_time_s: must be finite"),
    ({"service_busy_timeout_s": -1.0}, r"^service_busy_timeout_s: must be in \(0, inf\]"),
    ({"diagnostics_period_s": "1"}, r"^diagnostics_period_s: must be a number"),
    ({"robot_description_timeout_s": -1.0}, r"^robot_description_timeout_s: must be in \[0,"),
    # analyses beyond the paper
    ({"metric_point": "centre"}, r"^metric_point: must be one of tip, leading_point, worst_po"),
    ({"metric_point": "leading_point"}, r"^metric_point: 'leading_point' needs the object's po"),
    ({"object.points_in_object_m": [0.0] * 4}, r"^object\.points_in_object_m: must hold x y z"),
    ({"object.points_in_object_m": [0.0, "a", 1.0]}, r"^object\.points_in_object_m: must be a"),
    ({"object.box_size_m": [0.1, 0.2]}, r"^object\.box_size_m: must be empty or 3 edge lengths"),
    ({"object.box_size_m": [0.1, 0.0, 0.2]}, r"^object\.box_size_m: must be empty or 3 edge"),
    ({"object.cylinder_radius_m": 0.05}, r"^object\.cylinder_length_m: must be > 0 too"),
    ({"object.cylinder_length_m": -0.1}, r"^object\.cylinder_length_m: must be in \[0, inf\]"),
    (
        {
            "object.box_size_m": [0.1] * 3,
            "object.cylinder_radius_m": 0.1,
            "object.cylinder_length_m": 0.1,
        },
        r"^object\.box_size_m: give a box or a cylinder",
    ),
    ({"iso_ts_15066.regions": ["chest", "knee"]}, r"^iso_ts_15066\.regions: unknown body reg"),
    ({"iso_ts_15066.regions": ["chest", "chest"]}, r"^iso_ts_15066\.regions: regions repeat"),
    ({"iso_ts_15066.regions": "chest"}, r"^iso_ts_15066\.regions: must be a list of region"),
    ({"iso_ts_15066.regions": [1.0]}, r"^iso_ts_15066\.regions: must be a list of region"),
    ({"uncertainty.mass_fraction": 1.0}, r"^uncertainty\.mass_fraction: must be in \[0, 1\)"),
    ({"uncertainty.inertia_fraction": -0.1}, r"^uncertainty\.inertia_fraction: must be in"),
    ({"uncertainty.com_offset_m": float("inf")}, r"^uncertainty\.com_offset_m: must be finite"),
    ({"uncertainty.samples": -1}, r"^uncertainty\.samples: must be in \[0, "),
    ({"uncertainty.samples": 4.0}, r"^uncertainty\.samples: must be an integer"),
    ({"uncertainty.percentile": 101.0}, r"^uncertainty\.percentile: must be in \[0, 100\]"),
    ({"uncertainty.seed": "x"}, r"^uncertainty\.seed: must be an integer"),
    ({"safety_weight": 1.5}, r"^safety_weight: must be in \[0, 1\], got 1\.5"),
    ({"redundancy.enabled": 1}, r"^redundancy\.enabled: must be true or false"),
    ({"effort.enabled": "yes"}, r"^effort\.enabled: must be true or false"),
    ({"effort.criterion": "max"}, r"^effort\.criterion: must be one of peak_fraction, rms_fr"),
    (
        {"rank_by": "quality"},
        r"^rank_by: must be one of safety, effort, whole_arm, safe_duration, got 'quality'",
    ),
    # what the result messages carry
    (
        {"response.joint_trajectories": -1},
        r"^response\.joint_trajectories: must be in \[0, 1000000000\], got -1$",
    ),
    ({"response.joint_trajectories": 2.0}, r"^response\.joint_trajectories: must be an integer"),
    ({"response.per_sample": "false"}, r"^response\.per_sample: must be true or false"),
    # the whole arm
    ({"whole_arm.enabled": 1}, r"^whole_arm\.enabled: must be true or false"),
    ({"whole_arm.region": "elbow"}, r"^whole_arm\.region: must be one of skull_forehead, "),
    ({"whole_arm.point_links": "link3"}, r"^whole_arm\.point_links: must be a list of link n"),
    ({"whole_arm.point_links": ["link3", ""]}, r"^whole_arm\.point_links: must be a list of"),
    ({"whole_arm.points_m": [0.0, "a", 1.0]}, r"^whole_arm\.points_m: must be a list of numb"),
    ({"whole_arm.points_m": [0.0, float("nan"), 1.0]}, r"^whole_arm\.points_m: must be finite"),
    ({"whole_arm.points_m": [0.0] * 4}, r"^whole_arm\.points_m: must hold x y z per point"),
    ({"whole_arm.points_m": [0.0] * 3003}, r"^whole_arm\.points_m: must hold at most 1000 po"),
    (
        {"whole_arm.point_links": ["link3", "link4"], "whole_arm.points_m": [0.0] * 3},
        r"^whole_arm\.points_m: must hold x y z for each of the 2 whole_arm\.point_links "
        r"\(6 numbers\), got 3 numbers$",
    ),
    (
        {"whole_arm.points_m": [0.0] * 3},
        r"^whole_arm\.points_m: must hold x y z for each of the 0 whole_arm\.point_links",
    ),
    (
        {"rank_by": "whole_arm", "iso_ts_15066.regions": ["face", "hand_fingers"]},
        r"^whole_arm\.region: rank_by whole_arm ranks by 'chest', which is not among the "
        r"assessed iso_ts_15066\.regions \(face, hand_fingers\); add it there or set "
        r"whole_arm\.region to one of them$",
    ),
]


@pytest.mark.parametrize(("change", "pattern"), BAD, ids=[p for _, p in BAD])
def test_bad_parameter_is_refused_naming_it(change: dict[str, Any], pattern: str) -> None:
    with pytest.raises(InvalidInputError, match=pattern):
        settings_from_parameters({**MINIMAL, **change})


def test_response_defaults_and_values() -> None:
    assert settings_from_parameters(MINIMAL).response == ResponseContent(1, True)
    values = {**MINIMAL, "response.joint_trajectories": 0, "response.per_sample": False}
    assert settings_from_parameters(values).response == ResponseContent(0, False)


def test_response_joint_trajectories_takes_the_final_order_first() -> None:
    order = (3, 1)  # grasps 0 and 2 are not in the final order
    chosen = {n: ResponseContent(n).with_joint_trajectory(order, 4) for n in range(6)}
    assert chosen == {
        0: frozenset(),
        1: {3},
        2: {3, 1},
        3: {3, 1, 0},
        4: {0, 1, 2, 3},
        5: {0, 1, 2, 3},
    }
    assert ResponseContent().with_joint_trajectory((), 3) == {0, 1, 2}  # default: all


def test_default_analyses_are_the_paper() -> None:
    analysis = settings_from_parameters(MINIMAL).analysis
    assert analysis.metric_point == "tip" and analysis.points_in_object_m is None
    assert analysis.iso_regions is None  # all regions
    assert analysis.uncertainty is None and analysis.grasp_quality is None
    assert not analysis.redundancy and analysis.rank_by == "safety"
    assert analysis.effort  # on everywhere (core.options): adds torques, leaves the order
    assert analysis.safety_weight == 0.5 and analysis.effort_criterion == "peak_fraction"


def test_analysis_parameters() -> None:
    values = {
        **MINIMAL,
        "metric_point": "worst_point",
        "object.com_in_object_m": [0.0, 0.0, 0.01],
        "object.box_size_m": [0.1, 0.2, 0.3],
        "iso_ts_15066.regions": ["face", "chest"],
        "uncertainty.com_offset_m": 0.01,
        "uncertainty.samples": 5,
        "uncertainty.percentile": 90,
        "uncertainty.seed": 3,
        "safety_weight": 1,
        "redundancy.enabled": True,
        "rank_by": "effort",
        "effort.criterion": "rms_fraction",
    }
    analysis = settings_from_parameters(values).analysis
    assert analysis.metric_point == "worst_point"
    points = analysis.points_in_object_m
    np.testing.assert_array_equal(points, box_corners_in_object([0.1, 0.2, 0.3], [0, 0, 0.01]))
    assert analysis.iso_regions == ("face", "chest")
    uncertainty = analysis.uncertainty
    assert uncertainty is not None
    assert (uncertainty.mass_fraction, uncertainty.com_offset_m) == (0.0, 0.01)
    assert (uncertainty.num_random_samples, uncertainty.percentile, uncertainty.seed) == (5, 90, 3)
    assert analysis.safety_weight == 1.0 and analysis.redundancy
    assert analysis.effort and analysis.rank_by == "effort"  # rank_by effort turns effort on
    assert analysis.effort_criterion == "rms_fraction"


def test_whole_arm_parameters() -> None:
    """The scenario's whole_arm section and robot.exposed_points_m, as node parameters."""
    analysis = settings_from_parameters(MINIMAL).analysis
    assert not analysis.whole_arm and analysis.arm_points_m is None
    assert analysis.whole_arm_region == "chest"
    values = {
        **MINIMAL,
        "whole_arm.enabled": True,
        "whole_arm.region": "upper_arm_elbow",
        "iso_ts_15066.regions": ["upper_arm_elbow", "face"],
        "rank_by": "whole_arm",
    }
    analysis = settings_from_parameters(values).analysis
    assert analysis.whole_arm and analysis.rank_by == "whole_arm"
    assert analysis.whole_arm_region == "upper_arm_elbow" and analysis.arm_points_m is None
    # extra points turn the analysis on; a link's points keep their order, links their first
    points = {
        "whole_arm.point_links": ["link4", "link3", "link4"],
        "whole_arm.points_m": [0.1, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.3],
    }
    analysis = settings_from_parameters({**MINIMAL, **points}).analysis
    assert analysis.whole_arm and analysis.arm_points_m is not None
    assert list(analysis.arm_points_m) == ["link4", "link3"]
    np.testing.assert_array_equal(analysis.arm_points_m["link4"], [[0.1, 0, 0], [0, 0, 0.3]])
    np.testing.assert_array_equal(analysis.arm_points_m["link3"], [[0, 0.2, 0]])
    # rank_by whole_arm with all regions (the default) takes any region
    analysis = settings_from_parameters({**MINIMAL, "rank_by": "whole_arm"}).analysis
    assert analysis.whole_arm and analysis.iso_regions is None
    # whole_arm.region outside the assessed regions is fine unless it orders the ranking
    outside = {"whole_arm.enabled": True, "iso_ts_15066.regions": ["face"]}
    assert settings_from_parameters({**MINIMAL, **outside}).analysis.whole_arm
    # empty lists from a params file arrive NOT_SET (None) or as empty arrays
    empty = {"whole_arm.point_links": None, "whole_arm.points_m": array.array("d")}
    assert settings_from_parameters({**MINIMAL, **empty}).analysis.arm_points_m is None


def test_object_points_precedence() -> None:
    cylinder = {"object.cylinder_radius_m": 0.04, "object.cylinder_length_m": 0.2}
    analysis = settings_from_parameters({**MINIMAL, **cylinder}).analysis
    np.testing.assert_array_equal(
        analysis.points_in_object_m, cylinder_rim_points_in_object(0.04, 0.2)
    )
    given = {**cylinder, "object.points_in_object_m": [0.1, 0.0, 0.0, 0.0, 0.2, 0.0]}
    analysis = settings_from_parameters({**MINIMAL, **given}).analysis
    np.testing.assert_array_equal(analysis.points_in_object_m, [[0.1, 0, 0], [0, 0.2, 0]])
    # empty lists from a params file arrive NOT_SET (None) or as empty arrays
    empty = {"object.points_in_object_m": None, "iso_ts_15066.regions": None}
    analysis = settings_from_parameters({**MINIMAL, **empty, "object.box_size_m": []}).analysis
    assert analysis.points_in_object_m is None and analysis.iso_regions is None
    raw = {"iso_ts_15066.regions": array.array("q"), "object.box_size_m": array.array("d")}
    assert settings_from_parameters({**MINIMAL, **raw}).analysis.iso_regions is None


def test_single_parameter_check_ignores_foreign_names() -> None:
    assert check_parameter("use_sim_time", True) is True
    assert check_parameter("trajectory.dt_s", 1) == 1.0
    with pytest.raises(InvalidInputError, match=r"^metric:"):
        check_parameter("metric", "median")


# --- Robot -------------------------------------------------------------------------------------

URDF = serial_arm_urdf(ARM6_AXES)


def test_robot_sources_in_order_of_precedence(tmp_path: Any) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(URDF)
    from_xml = build_robot(settings_from_parameters({**MINIMAL, "robot_description": URDF}), "x")
    from_path = build_robot(settings_from_parameters({**MINIMAL, "urdf": str(path)}), "x")
    from_topic = build_robot(settings_from_parameters(MINIMAL), URDF)
    both = settings_from_parameters({**MINIMAL, "robot_description": URDF, "urdf": "nonsense"})
    assert from_xml is not None and from_xml.origin == "robot_description"
    assert from_path is not None and from_path.origin == "urdf"
    assert from_topic is not None and from_topic.origin == "/robot_description"
    bundle = build_robot(both, None)
    assert bundle is not None and bundle.origin == "robot_description"
    assert bundle.robot.num_joints == 6


def test_robot_errors_name_the_parameter() -> None:
    with pytest.raises(FrameNotFoundError, match=r"^tip_frame: frame 'flange' not found") as info:
        build_robot(settings_from_parameters({**MINIMAL, "tip_frame": "flange"}), URDF)
    assert "tool" in info.value.available
    with pytest.raises(FrameNotFoundError, match=r"^base_frame: frame 'world' not found"):
        build_robot(settings_from_parameters({**MINIMAL, "base_frame": "world"}), URDF)
    with pytest.raises(InvalidInputError, match=r"^ik_seed: must have shape \[6\], got shape"):
        build_robot(settings_from_parameters({**MINIMAL, "ik_seed": [0.0, 0.0]}), URDF)
    with pytest.raises(InvalidInputError, match=r"^ik_seed: joint 'j2' = 4 is outside its limits"):
        build_robot(settings_from_parameters({**MINIMAL, "ik_seed": [0, 4, 0, 0, 0, 0]}), URDF)
    with pytest.raises(InvalidInputError, match=r"^urdf: no URDF file at '/nonexistent.urdf'"):
        build_robot(settings_from_parameters({**MINIMAL, "urdf": "/nonexistent.urdf"}), None)
    with pytest.raises(InvalidInputError, match=r"^urdf: example-robot-data robot 'r2d2' not"):
        build_robot(settings_from_parameters({**MINIMAL, "urdf": "example-robot-data:r2d2"}), None)
    broken = settings_from_parameters({**MINIMAL, "robot_description": "<robot><link"})
    with pytest.raises(InvalidInputError, match=r"^robot_description: cannot read URDF XML"):
        build_robot(broken, None)
    with pytest.raises(InvalidInputError, match=r"^/robot_description: cannot read URDF XML"):
        build_robot(settings_from_parameters(MINIMAL), "<robot><link")


def test_whole_arm_point_links_are_links_of_the_robot() -> None:
    points = {"whole_arm.point_links": ["link3", "lnk4"], "whole_arm.points_m": [0.0] * 6}
    settings = settings_from_parameters({**MINIMAL, **points})
    pattern = r"^whole_arm\.point_links: unknown link 'lnk4'; did you mean link4"
    with pytest.raises(InvalidInputError, match=pattern):
        build_robot(settings, URDF)
    points["whole_arm.point_links"] = ["link3", "link4"]
    bundle = build_robot(settings_from_parameters({**MINIMAL, **points}), URDF)
    assert bundle is not None
