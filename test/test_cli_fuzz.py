"""Hostile scenario files: whatever the file holds, the CLI exits 0 or exits 2 with exactly one
line ``grasp-safety: error: <field>: <reason>``; never a traceback, never a hang.

Property tests drive ``main`` in-process (fast); two subprocess runs prove that nothing else
(no traceback, no native parser output) reaches the user's terminal.
"""

from __future__ import annotations

import contextlib
import copy
import io
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import ARM6_AXES, serial_arm_urdf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from grasp_safety_ros.cli.main import main
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.scenario import fields as scenario_module
from grasp_safety_ros.scenario.fields import (
    MAX_EXPANDED_NODES,
    MAX_NESTING_DEPTH,
    MAX_SCENARIO_BYTES,
)
from grasp_safety_ros.scenario.schema import (
    MAX_GRASP_SAMPLES,
    MAX_GRASPS,
    MAX_POINTS,
    MAX_UNCERTAINTY_SAMPLES,
    OPTIONAL_SECTIONS,
)

BOOK = yaml.safe_load(config_file("book_baxter.yaml").read_text())
SMALL = {  # the book scenario cut down to 2 grasps x 3 samples, so a valid run is quick
    **BOOK,
    "trajectory": {**BOOK["trajectory"], "dt_s": 1.0},
    "grasps": BOOK["grasps"][:2],
}
SECTIONS = {"robot", "object", "trajectory", "grasps", "metric", "scenario"} | OPTIONAL_SECTIONS
ERROR_LINE = re.compile(r"grasp-safety: error: ([A-Za-z_0-9-][\w.\[\]-]*): \S")
UNKNOWN_FIELD = re.compile(r"grasp-safety: error: (.+?): unknown field; allowed: ")
FUZZ = settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow])


def run_cli(content: str | bytes, *extra: str) -> tuple[int, str]:
    """Write ``content`` as a scenario file, run ``grasp-safety rank`` in-process."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "scenario.yaml"
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(["rank", str(path), *extra])
    return code, err.getvalue()


def assert_one_line_error(code: int, err: str, fields: set[str] = SECTIONS) -> str:
    """Exit 2 and one stderr line naming a field whose first part is in ``fields``; the field."""
    assert code == 2, err
    assert err.endswith("\n") and len(err.splitlines()) == 1, err
    unknown = UNKNOWN_FIELD.match(err)
    if unknown is not None:  # names the unexpected key itself, whatever its text
        return unknown.group(1)
    match = ERROR_LINE.match(err)
    assert match is not None, err
    field = match.group(1)
    assert re.split(r"[.\[]", field)[0] in fields, err
    return field


def dump(data: Any) -> str:
    return yaml.safe_dump(data, allow_unicode=True)


# --- random edits of a valid scenario --------------------------------------------------------


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    paths = []
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for key, value in items:
        paths.append((*prefix, key))
        if isinstance(value, dict | list) and not isinstance(value, str):
            paths.extend(_paths(value, (*prefix, key)))
    return paths


PATHS = _paths(SMALL)
KEYS = st.text(alphabet="abcxyz_", min_size=1, max_size=6)
HOSTILE = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), 5e-324, -0.0, 1e308]),
    st.text(max_size=12),
    st.sampled_from(["", "\x00", "base\x00", "ümlaut", "example-robot-data:", "<robot"]),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=5),
    st.builds(lambda x: [x] * (MAX_GRASPS + 1), st.integers(-5, 5)),
    st.recursive(st.integers(-3, 3), lambda inner: st.lists(inner, max_size=3), max_leaves=8),
    st.dictionaries(KEYS, st.integers(-3, 3), max_size=3),
)
EDIT = st.tuples(
    st.sampled_from(PATHS), st.sampled_from(["delete", "replace", "rename"]), HOSTILE, KEYS
)


def _edited(edits: list[tuple[tuple[Any, ...], str, Any, str]]) -> tuple[Any, set[str]]:
    data = copy.deepcopy(SMALL)
    new_keys = set()
    for path, action, value, key in edits:
        node = data
        try:
            for part in path[:-1]:
                node = node[part]
            leaf = path[-1]
            node[leaf]  # the path may be gone after an earlier edit
        except (KeyError, IndexError, TypeError):
            continue
        if action == "delete":
            del node[leaf]
        elif action == "rename" and isinstance(node, dict):
            node[key] = node.pop(leaf)
            new_keys.add(key)
        else:
            node[leaf] = value
    return data, new_keys


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # norms of 1e308
@FUZZ
@given(st.lists(EDIT, min_size=1, max_size=3))
def test_edited_scenarios_run_or_name_the_field(edits: list[Any]) -> None:
    data, new_keys = _edited(edits)
    code, err = run_cli(dump(data))
    if code != 0:
        assert_one_line_error(code, err, SECTIONS | new_keys)


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (("grasps",), [SMALL["grasps"][0]] * (MAX_GRASPS + 1), f"at most {MAX_GRASPS}"),
        (("grasps",), [SMALL["grasps"][0]] * 20, f"at most {MAX_GRASP_SAMPLES}"),
        (("object", "points_m"), [[0.0, 0.0, 0.0]] * (MAX_POINTS + 1), f"at most {MAX_POINTS}"),
        (("uncertainty",), {"samples": MAX_UNCERTAINTY_SAMPLES + 1}, "must be at most"),
    ],
)
def test_huge_lists_are_refused_naming_the_field_and_the_limit(
    path: tuple[str, ...], value: Any, message: str
) -> None:
    data = copy.deepcopy(SMALL)
    node = data
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    if path == ("grasps",):  # 10001 grasps x 2 samples; 20 grasps x 10**6 samples
        data["trajectory"]["dt_s"] = 2.0 if len(value) > MAX_GRASPS else 2.0 / 10**6
    code, err = run_cli(dump(data))
    field = assert_one_line_error(code, err)
    assert field.startswith(path[0]) and message in err


# --- garbage, nesting, aliases, size ---------------------------------------------------------


@FUZZ
@given(st.binary(max_size=400))
def test_binary_garbage_exits_2_with_one_line(content: bytes) -> None:
    assert_one_line_error(*run_cli(content))


@FUZZ
@given(st.text(max_size=300))
def test_text_garbage_exits_2_with_one_line(content: str) -> None:
    assert_one_line_error(*run_cli(content))


@FUZZ
@given(
    st.integers(MAX_NESTING_DEPTH + 1, 5000),
    st.sampled_from(["[", "{a: ", "- ", "[{b: "]),
    st.booleans(),
)
def test_deep_nesting_exits_2_with_one_line(depth: int, opener: str, closed: bool) -> None:
    closer = {"[": "]", "{a: ": "}", "- ": "", "[{b: ": "}]"}[opener]
    text = opener * depth + "1" + (closer * depth if closed else "")
    code, err = run_cli(text)
    assert_one_line_error(code, err)
    assert "nesting deeper than" in err or "not valid YAML" in err


def test_nesting_limit_is_exact() -> None:
    for levels, message in ((MAX_NESTING_DEPTH - 1, "must be a mapping"), (MAX_NESTING_DEPTH, "")):
        nested: list[Any] = []
        for _ in range(levels - 1):
            nested = [nested]
        text = dump({**SMALL, "robot": None}).replace("robot: null", f"robot: {nested}")
        code, err = run_cli(text)  # the root mapping is level 1
        field = assert_one_line_error(code, err)
        if message:
            assert field == "robot" and message in err
        else:
            assert field == "scenario" and "nesting deeper than" in err


@pytest.mark.parametrize("loader", ["CSafeLoader", "SafeLoader"])
def test_either_parser_limit_gives_our_nesting_message(
    monkeypatch: pytest.MonkeyPatch, loader: str
) -> None:
    """libyaml (PyYAML >= 6.0.4) refuses more than 1000 flow levels in its scanner, before our
    event loop counts MAX_NESTING_DEPTH; the pure-Python parser has no limit, so ours trips. The
    user sees the same one line either way."""
    if not hasattr(yaml, loader):
        pytest.skip(f"PyYAML built without {loader}")
    monkeypatch.setattr(scenario_module, "_SAFE_LOADER", getattr(yaml, loader))
    text = "[" * 5000
    if loader == "CSafeLoader":  # the parser's own limit is the one that trips here
        with pytest.raises(yaml.YAMLError, match="maximum nesting depth"):
            list(yaml.parse(text, Loader=yaml.CSafeLoader))
    code, err = run_cli(text)
    assert assert_one_line_error(code, err) == "scenario"
    assert f"nesting deeper than {MAX_NESTING_DEPTH} levels at line 1" in err


@settings(max_examples=12)
@given(st.integers(2, 12), st.integers(2, 12))
def test_alias_bombs_are_refused(width: int, depth: int) -> None:
    lines = ["a0: &a0 [lol]"]
    for level in range(1, depth + 1):
        lines.append(f"a{level}: &a{level} [{', '.join([f'*a{level - 1}'] * width)}]")
    code, err = run_cli("\n".join(lines) + "\n")
    assert_one_line_error(code, err, SECTIONS | {f"a{level}" for level in range(depth + 1)})
    expanded = sum(width**level for level in range(depth + 1))  # nodes, under-counted
    if expanded > MAX_EXPANDED_NODES:
        assert "expands to more than" in err


def test_aliases_within_the_limit_are_fine() -> None:
    text = """
robot: {urdf: "example-robot-data:baxter", base_frame: base, tip_frame: right_gripper}
object: {mass_kg: 0.34, box_size_m: [0.15, 0.22, 0.015]}
trajectory:
  start: {position_m: [1.0, 0.0, 0.03], quat_xyzw: &q [0.5, 0.5, 0.5, 0.5]}
  goal: {position_m: [1.1, -0.38, 0.16], quat_xyzw: *q}
  duration_s: 2.0
  dt_s: 1.0
grasps:
  - &g {name: a, position_m: [-0.075, -0.1, 0.0], quat_xyzw: [0, 0, 0, 1]}
  - *g
"""
    assert run_cli(text) == (0, "")


def test_oversized_and_special_files_are_refused(tmp_path: Path) -> None:
    code, err = run_cli(dump(SMALL) + "#" * MAX_SCENARIO_BYTES)
    assert_one_line_error(code, err)
    assert f"larger than {MAX_SCENARIO_BYTES} bytes" in err
    for special in ("/dev/zero", str(tmp_path)):
        err_text = io.StringIO()
        with contextlib.redirect_stderr(err_text):
            code = main(["rank", special])
        assert_one_line_error(code, err_text.getvalue())


def test_nul_bytes_give_one_line() -> None:
    code, err = run_cli(dump(SMALL).replace("metric: mean", "metric: me\x00an"))
    assert_one_line_error(code, err)
    assert "not valid YAML" in err


# --- broken URDF XML -------------------------------------------------------------------------

ARM_URDF = serial_arm_urdf(ARM6_AXES)
ARM = {**SMALL, "robot": {"urdf": ARM_URDF, "base_frame": "base_link", "tip_frame": "tool"}}


@FUZZ
@given(
    st.integers(0, len(ARM_URDF) - 1),
    st.integers(0, 40),
    st.sampled_from(["", "<", ">", '"', "=", "/", "x", "-", "0", "&", "\u00e9"]),
)
def test_broken_urdf_xml_runs_or_names_robot_urdf(start: int, length: int, insert: str) -> None:
    urdf = ARM_URDF[:start] + insert + ARM_URDF[start + length :]
    code, err = run_cli(dump({**ARM, "robot": {**ARM["robot"], "urdf": urdf}}))
    if code != 0:
        assert assert_one_line_error(code, err).startswith("robot.")


def test_malformed_inertial_is_refused_not_massless() -> None:
    urdf = ARM_URDF.replace('<mass value="', '<mass value="x', 1)
    code, err = run_cli(dump({**ARM, "robot": {**ARM["robot"], "urdf": urdf}}))
    assert assert_one_line_error(code, err) == "robot.urdf"
    assert "Could not parse inertial element for Link [link1]" in err


# --- what the user sees ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        ("[" * 5000, "grasp-safety: error: scenario: nesting deeper than"),
        (
            dump(
                {
                    **SMALL,
                    "robot": {
                        "urdf": "example-robot-data:panda",
                        "base_frame": "panda_link0",
                        "tip_frame": "panda_rightfinger",
                    },
                }
            ),
            "grasp-safety: error: robot.tip_frame: joint 'panda_finger_joint2' on the chain",
        ),
        (
            dump({**ARM, "robot": {**ARM["robot"], "urdf": "<robot name='r'><link></robot>"}}),
            "grasp-safety: error: robot.urdf: cannot read URDF XML",
        ),
    ],
)
def test_console_shows_one_line_and_no_traceback(
    tmp_path: Path, content: str, expected: str
) -> None:
    scenario = tmp_path / "bad.yaml"
    scenario.write_text(content)
    completed = subprocess.run(
        [sys.executable, "-m", "grasp_safety_ros.cli.main", "rank", str(scenario)],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert completed.returncode == 2
    assert completed.stderr.startswith(expected), completed.stderr
    assert len(completed.stderr.splitlines()) == 1, completed.stderr


def test_unwritable_outputs_name_the_option(tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for option, target, message in (
        ("--json", blocker / "out.json", "--json: cannot write"),
        ("--plot", tmp_path / "out.unknown_format", "--plot: cannot write"),
    ):
        code, err = run_cli(dump(SMALL), option, str(target))
        assert code == 2 and len(err.splitlines()) == 1, err
        assert err.startswith(f"grasp-safety: error: {message} '{target}'"), err


@pytest.mark.parametrize(
    ("obj", "message"),
    [
        (
            {"mass_kg": 0.34, "box_size_m": [7e7, 0.22, 0.015]},
            "object.box_size_m: must be at most",
        ),
        ({"mass_kg": 0.34, "sphere": {"radius_m": 1e200}}, "object.sphere.radius_m: must be at"),
        ({"mass_kg": 1e300, "sphere": {"radius_m": 0.1}}, "object.mass_kg: must be in (0, 10000]"),
        (
            {"mass_kg": 0.34, "inertia_about_com_kgm2": [[1e6, 0, 0], [0, 1e6, 0], [0, 0, 1e6]]},
            "object.inertia_about_com_kgm2: radius of gyration",
        ),
    ],
)
def test_absurd_objects_are_refused_before_the_numbers_break(obj: Any, message: str) -> None:
    code, err = run_cli(dump({**SMALL, "object": obj}))
    assert_one_line_error(code, err)
    assert err.startswith(f"grasp-safety: error: {message}"), err


def test_core_field_names_are_the_file_s() -> None:
    code, err = run_cli(dump({**SMALL, "iso_ts_15066": {"regions": ["elbow"]}}))
    assert assert_one_line_error(code, err) == "iso_ts_15066.regions"
