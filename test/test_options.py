"""The one table of options (core.options): every interface's defaults and bounds derive from
it, and the core's dataclasses agree with it. A mismatch anywhere fails here, naming the
option and the interface."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from grasp_safety_ros.core.analyses.safe_duration import RetimeOptions
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions
from grasp_safety_ros.core.analyses.uncertainty import InertiaUncertainty
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.method.ik import IKConfig
from grasp_safety_ros.core.method.posture import PostureConfig
from grasp_safety_ros.core.options import LIMITS, OPTIONS, default, help_text
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.scenario.schema import parse_scenario

BOOK = yaml.safe_load(config_file("book_baxter.yaml").read_text())

OPTIONS_OF: dict[str, Callable[[Any], Any]] = {
    "metric_point": lambda o: o.metric_point,
    "safety_weight": lambda o: o.safety_weight,
    "redundancy.enabled": lambda o: o.redundancy,
    "effort.enabled": lambda o: o.effort,
    "effort.criterion": lambda o: o.effort_criterion,
    "rank_by": lambda o: o.rank_by,
    "whole_arm.enabled": lambda o: o.whole_arm,
    "whole_arm.region": lambda o: o.whole_arm_region,
    "redundancy.iterations": lambda o: o.redundancy_settings.iterations,
    "redundancy.profile_degree": lambda o: o.redundancy_settings.profile_degree,
    "redundancy.max_rate_ratio": lambda o: o.redundancy_settings.max_rate_ratio,
    "redundancy.max_effort_fraction": lambda o: o.redundancy_settings.max_effort_fraction,
}
"""Option key -> its value in an AnalysisOptions."""

IK_OF: dict[str, Callable[[IKConfig], Any]] = {
    "ik.max_iterations": lambda c: c.max_iterations,
    "ik.position_tolerance_m": lambda c: c.position_tolerance_m,
    "ik.orientation_tolerance_rad": lambda c: c.orientation_tolerance_rad,
    "ik.random_restarts": lambda c: c.random_restarts,
}
"""Option key -> its value in an IKConfig (the evaluator's)."""

TUNED = {
    "ik.max_iterations": 7,
    "ik.position_tolerance_m": 2e-6,
    "ik.orientation_tolerance_rad": 3e-6,
    "ik.random_restarts": 4,
    "redundancy.iterations": 9,
    "redundancy.profile_degree": 2,
    "redundancy.max_rate_ratio": 1.25,
    "redundancy.max_effort_fraction": 0.75,
}
"""A value other than the default for every IK and redundancy setting."""

UNCERTAINTY_OF: dict[str, Callable[[Any], Any]] = {
    "uncertainty.mass_fraction": lambda u: u.mass_fraction,
    "uncertainty.com_offset_m": lambda u: u.com_offset_m,
    "uncertainty.inertia_fraction": lambda u: u.inertia_fraction,
    "uncertainty.samples": lambda u: u.num_random_samples,
    "uncertainty.percentile": lambda u: u.percentile,
    "uncertainty.seed": lambda u: u.seed,
}
"""Option key -> its value in an InertiaUncertainty."""

RETIME_OF: dict[str, Callable[[Any], Any]] = {
    "retime.safety_factor": lambda r: r.safety_factor,
}
"""Option key -> its value in a RetimeOptions (the retiming is off by default)."""

SECTIONS_OF = {**UNCERTAINTY_OF, **RETIME_OF}
"""The options of sections that are off by default (checked when the section is given)."""

ACCELERATIONS = [3.0] * 7
"""Joint acceleration limits that turn the retiming on (Baxter's 7 joints) [rad/s^2]."""


def values_of(
    metric: str, options: AnalysisOptions, posture: PostureConfig, ik: IKConfig
) -> dict[str, Any]:
    """Every option's value in what an interface built (uncertainty: see UNCERTAINTY_OF)."""
    values = {key: get(options) for key, get in OPTIONS_OF.items()}
    values |= {key: get(ik) for key, get in IK_OF.items()}
    return {**values, "metric": metric, "posture.restarts": posture.restarts}


def test_every_option_is_read_by_the_test() -> None:
    read = set(OPTIONS_OF) | set(IK_OF) | set(SECTIONS_OF) | {"metric", "posture.restarts"}
    assert set(OPTIONS) == read
    assert set(TUNED) == {key for key in OPTIONS if key.startswith(("ik.", "redundancy."))} - {
        "redundancy.enabled"
    }


def test_the_core_defaults_are_the_tables() -> None:
    assert values_of(default("metric"), AnalysisOptions(), PostureConfig(), IKConfig()) == {
        key: option.default for key, option in OPTIONS.items() if key not in SECTIONS_OF
    }
    for key, get in UNCERTAINTY_OF.items():
        assert get(InertiaUncertainty()) == default(key), key
    for key, get in RETIME_OF.items():
        assert get(RetimeOptions(ACCELERATIONS)) == default(key), key


def test_the_scenario_defaults_are_the_tables(tmp_path: Path) -> None:
    data = {key: BOOK[key] for key in ("robot", "object", "trajectory", "grasps")}  # no metric
    data["object"] = {"mass_kg": 0.34, "sphere": {"radius_m": 0.05}}  # no points
    scenario = parse_scenario(data, tmp_path)
    got = values_of(scenario.metric, scenario.options, scenario.posture, scenario.ik)
    assert got == {key: o.default for key, o in OPTIONS.items() if key not in SECTIONS_OF}
    with_uncertainty = parse_scenario({**data, "uncertainty": {}}, tmp_path)
    for key, get in UNCERTAINTY_OF.items():
        assert get(with_uncertainty.options.uncertainty) == default(key), key
    retime = {"joint_acceleration_limits": ACCELERATIONS}
    with_retime = parse_scenario({**data, "retime": retime}, tmp_path)
    for key, get in RETIME_OF.items():
        assert get(with_retime.options.retime) == default(key), key


def test_the_node_defaults_and_help_are_the_tables() -> None:
    from grasp_safety_ros.ros.parameters import PARAMETERS, settings_from_parameters

    for key in OPTIONS:
        assert PARAMETERS[key].default == default(key), key
        assert PARAMETERS[key].description == help_text(key), key
    settings = settings_from_parameters({"urdf": "x", "base_frame": "b", "tip_frame": "t"})
    got = values_of(settings.metric, settings.analysis, settings.posture, settings.ik)
    assert got == {key: o.default for key, o in OPTIONS.items() if key not in SECTIONS_OF}
    retime = {"retime.joint_acceleration_limits": ACCELERATIONS}
    with_retime = settings_from_parameters(
        {"urdf": "x", "base_frame": "b", "tip_frame": "t"} | retime
    )
    for key, get in RETIME_OF.items():
        assert get(with_retime.analysis.retime) == default(key), key
    for limit in LIMITS.values():
        if limit.node:
            assert PARAMETERS[limit.node].default == limit.budget <= limit.value, limit


def flat(section: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A parameter YAML's nested sections as dotted keys (rclpy's parameter names)."""
    result: dict[str, Any] = {}
    for key, value in section.items():
        if isinstance(value, dict):
            result.update(flat(value, f"{prefix}{key}."))
        else:
            result[f"{prefix}{key}"] = value
    return result


def test_the_node_config_file_sets_the_tables_defaults() -> None:
    """config/grasp_safety_node.yaml (the file users start from) sets every option it names
    to the table's default, and every node budget to LIMITS' (it once turned effort off)."""
    document = yaml.safe_load(config_file("grasp_safety_node.yaml").read_text())
    parameters = flat(document["grasp_safety"]["ros__parameters"])
    expected = {key: option.default for key, option in OPTIONS.items()}
    expected |= {limit.node: limit.budget for limit in LIMITS.values() if limit.node}
    checked = sorted(set(parameters) & set(expected))
    assert checked, "no option of the table in the node's config file"
    for key in checked:
        assert parameters[key] == expected[key], (
            f"{key}: config/grasp_safety_node.yaml sets {parameters[key]!r}, "
            f"the table's default is {expected[key]!r}"
        )


def test_the_batch_defaults_are_the_tables(tmp_path: Path) -> None:
    from grasp_safety_ros.dataset.spec import parse_spec

    spec = parse_spec({"sources": [{"format": "scenarios", "path": "*.yaml"}]}, tmp_path)
    got = values_of(spec.metric, spec.options, spec.posture, spec.ik)
    assert got == {key: o.default for key, o in OPTIONS.items() if key not in SECTIONS_OF}


BOUNDED = [key for key, option in OPTIONS.items() if option.bounds is not None]


@pytest.mark.parametrize("key", BOUNDED)
def test_the_node_bounds_are_the_tables(key: str) -> None:
    from grasp_safety_ros.ros.parameters import check_parameter, parameter_constraints

    low, high = OPTIONS[key].bounds  # type: ignore[misc]
    assert parameter_constraints(key).value_range == (low, high)  # the declared ROS range
    kind = OPTIONS[key].type
    step = 1 if kind is int else 1e-9 * max(1.0, abs(high))
    assert check_parameter(key, kind(high)) == high
    with pytest.raises(InvalidInputError, match=key):
        check_parameter(key, kind(high + step))
    with pytest.raises(InvalidInputError, match=key):
        check_parameter(key, kind(low - step))


SCENARIO_VALUES: dict[str, Callable[[Any], dict[str, Any]]] = {
    "safety_weight": lambda v: {"safety_weight": v},
    "posture.restarts": lambda v: {"posture": {"restarts": v}},
    "redundancy.profile_degree": lambda v: {"redundancy": {"profile_degree": v}},
    "uncertainty.samples": lambda v: {"uncertainty": {"mass_fraction": 0.1, "samples": v}},
    "uncertainty.percentile": lambda v: {"uncertainty": {"mass_fraction": 0.1, "percentile": v}},
}
"""A bounded option's value as scenario sections."""


@pytest.mark.parametrize("key", BOUNDED)
def test_the_scenario_bounds_are_the_tables(key: str, tmp_path: Path) -> None:
    low, high = OPTIONS[key].bounds  # type: ignore[misc]
    kind = OPTIONS[key].type
    step = 1 if kind is int else 1e-9 * max(1.0, abs(high))
    data = {k: BOOK[k] for k in ("robot", "object", "trajectory", "grasps", "metric")}
    data["grasps"] = data["grasps"][:1]
    parse_scenario({**data, **SCENARIO_VALUES[key](kind(high))}, tmp_path)
    for value in (high + step, low - step):
        with pytest.raises(InvalidInputError) as error:
            parse_scenario({**data, **SCENARIO_VALUES[key](kind(value))}, tmp_path)
        assert error.value.field.endswith(key.rpartition(".")[2]), (key, error.value)


def tuned(values: dict[str, Any]) -> dict[str, Any]:
    """The IK and redundancy settings' values in ``values`` (an interface's, by key)."""
    return {key: values[key] for key in TUNED}


def test_every_interface_sets_the_ik_and_redundancy_settings(tmp_path: Path) -> None:
    """The scenario's ``ik`` and ``redundancy`` sections, the node's parameters and the batch
    SPEC each carry a non-default value of every setting to the configs the core runs with."""
    from grasp_safety_ros.dataset.spec import parse_spec
    from grasp_safety_ros.ros.parameters import settings_from_parameters

    sections: dict[str, dict[str, Any]] = {"ik": {}, "redundancy": {"enabled": True}}
    for key, value in TUNED.items():
        section, name = key.split(".")
        sections[section][name] = value
    data = {key: BOOK[key] for key in ("robot", "object", "trajectory", "grasps")}
    scenario = parse_scenario({**data, **sections}, tmp_path)
    assert scenario.options.redundancy
    assert tuned(values_of("mean", scenario.options, PostureConfig(), scenario.ik)) == TUNED
    required = {"urdf": "x", "base_frame": "b", "tip_frame": "t"}
    settings = settings_from_parameters(required | TUNED)
    assert tuned(values_of("mean", settings.analysis, PostureConfig(), settings.ik)) == TUNED
    spec_data = {"sources": [{"format": "scenarios", "path": "*.yaml"}], **sections}
    spec = parse_spec(spec_data, tmp_path)
    assert tuned(values_of("mean", spec.options, PostureConfig(), spec.ik)) == TUNED
    assert parse_scenario({**data, "redundancy": True}, tmp_path).options.redundancy


@pytest.mark.parametrize(
    ("section", "field"),
    [
        ({"ik": {"max_iterations": -1}}, "ik.max_iterations"),
        ({"ik": {"position_tolerance_m": 0.0}}, "ik.position_tolerance_m"),
        ({"ik": {"tolerance": 1e-3}}, "ik.tolerance"),
        ({"redundancy": {"max_rate_ratio": 0.5}}, "redundancy.max_rate_ratio"),
        ({"redundancy": {"step": 0.1}}, "redundancy.step"),
    ],
)
def test_a_bad_ik_or_redundancy_setting_names_its_field(
    section: dict[str, Any], field: str, tmp_path: Path
) -> None:
    data = {key: BOOK[key] for key in ("robot", "object", "trajectory", "grasps")}
    with pytest.raises(InvalidInputError) as error:
        parse_scenario({**data, **section}, tmp_path)
    assert error.value.field == field
