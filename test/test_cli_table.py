"""The CLI's text table agrees with the tool: whole names, ISO ratios on the verdict's side of 1,
infeasible posture summaries that count the IK seeds as the reason does, the header's sample
counts for planned joint trajectories, and ``iso_ts_15066: {regions: []}`` as no assessment."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

from grasp_safety_ros.cli.main import main
from grasp_safety_ros.cli.report_values import force_ratio_text
from grasp_safety_ros.core.analyses.iso15066 import ADMISSIBLE_RATIO_TOLERANCE
from grasp_safety_ros.core.model.robot import RobotModel
from grasp_safety_ros.paths import config_file

GOOD = yaml.safe_load(config_file("book_baxter.yaml").read_text())
LONG = "side_minus_x_high_approach_long_name"


def _scenario(tmp_path: Path, **changes: object) -> Path:
    data = json.loads(json.dumps(GOOD))
    data["trajectory"].update({"duration_s": 2.0, "dt_s": 0.1})
    data.update(changes)
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _rank(path: Path, capsys: pytest.CaptureFixture[str], *extra: str) -> str:
    assert main(["rank", str(path), *extra]) == 0
    return capsys.readouterr().out


def test_long_names_are_printed_whole_in_every_section(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    grasps = json.loads(json.dumps(GOOD["grasps"]))
    grasps[1]["name"] = LONG
    path = _scenario(tmp_path, grasps=grasps, posture={"restarts": 2}, uncertainty={"samples": 4})
    out = _rank(path, capsys)
    sections = {
        "ranking": out.split("posture selection")[0],
        "posture": out.split("posture selection")[1].split("ISO/TS 15066")[0],
        "iso": out.split("ISO/TS 15066")[1].split("inertia uncertainty")[0],
        "uncertainty": out.split("inertia uncertainty")[1],
    }
    for name, text in sections.items():
        assert LONG in text, name
    rows = [line for line in sections["ranking"].splitlines() if re.match(r"\s+\d+\s+\d+\s", line)]
    assert len(rows) == 3
    # the columns stay aligned: every score starts at the same offset
    offsets = {len(line) - len(line.split(maxsplit=3)[3].lstrip()) for line in rows}
    assert len(offsets) == 1


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        (1.0029, "1.003"),  # was "1.00" beside "ok where allowed: no"
        (0.996, "1.00"),  # rounds up to 1.00 and is admissible: two digits say it
        (1.0 + 0.5 * ADMISSIBLE_RATIO_TOLERANCE, "1.00"),  # admissible by the tolerance
        (1.0000004, "1.0000004"),
        (0.23456, "0.23"),
        (float("inf"), "n/p"),
    ],
)
def test_ratio_is_printed_on_the_side_of_one_of_its_verdict(value: float, shown: str) -> None:
    assert force_ratio_text(value) == shown


def test_iso_ratio_near_one_agrees_with_the_verdict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The force ratio scales as 1/T when the path is sampled at the same fractions of it
    (M_eff depends on the path only): a duration T·r/1.0029 makes the worst permitted ratio
    exactly 1.0029, which the table must print above 1 beside the verdict "no"."""
    first = tmp_path / "first.json"
    _rank(_scenario(tmp_path), capsys, "--json", str(first))
    grasps = json.loads(first.read_text())["grasps"]
    worst = max(
        region["worst_force_ratio"]
        for grasp in grasps
        for region in grasp["iso_ts_15066"]["regions"].values()
        if region["transient_contact_permitted"]
    )
    target = 1.0029
    duration = 2.0 * worst / target
    trajectory = {**GOOD["trajectory"], "duration_s": duration, "dt_s": duration / 20}
    second = tmp_path / "second.json"
    out = _rank(_scenario(tmp_path, trajectory=trajectory), capsys, "--json", str(second))
    ratios = [
        region["worst_force_ratio"]
        for grasp in json.loads(second.read_text())["grasps"]
        for region in grasp["iso_ts_15066"]["regions"].values()
        if region["transient_contact_permitted"]
    ]
    assert max(ratios) == pytest.approx(target, rel=1e-9)
    table = out.split("ISO/TS 15066")[1].splitlines()
    header = table[1].split()[1:]
    verdict_row = next(k for k, line in enumerate(table) if line.startswith("ok where allowed"))
    verdicts = table[verdict_row].split()[3:]
    cells = [line.split()[1:] for line in table[2:verdict_row]]
    assert "1.003" in {cell for row in cells for cell in row}
    for column, verdict in enumerate(verdicts):
        printed = [float(row[column]) for row in cells if row[column] != "n/p"]
        assert verdict == ("no" if max(printed) > 1.0 else "yes"), header[column]
    assert "no" in verdicts


def test_infeasible_posture_summary_counts_the_seeds_of_its_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    grasps = json.loads(json.dumps(GOOD["grasps"]))
    grasps[0]["position_m"] = [5.0, 0.0, 0.0]  # the tip 5 m from the book: out of reach
    out = _rank(_scenario(tmp_path, grasps=grasps, posture={"restarts": 8}), capsys)
    reason = re.search(r"infeasible: no feasible posture from (\d+) IK seeds", out)
    assert reason is not None and reason.group(1) == "9"
    summary = out.split("posture selection")[1].splitlines()
    line = next(line for line in summary if grasps[0]["name"] in line)
    assert "no feasible posture from 9 IK seeds" in line
    assert "(1 tried)" not in line


def test_header_counts_the_samples_of_planned_joint_trajectories(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    robot = RobotModel.from_urdf(
        GOOD["robot"]["urdf"], GOOD["robot"]["base_frame"], GOOD["robot"]["tip_frame"]
    )
    seed = [float(x) for x in GOOD["robot"]["seed"]]
    points = [{"time_s": 0.25 * k, "positions": [x + 0.05 * k for x in seed]} for k in range(5)]
    grasps = json.loads(json.dumps(GOOD["grasps"]))
    grasps[2]["joint_trajectory"] = {"joint_names": list(robot.joint_names), "points": points}
    out = _rank(_scenario(tmp_path, grasps=grasps), capsys)
    header = out.splitlines()[0]
    assert "3 grasps: 2 x 21 samples, 1 x 5 samples (planned)" in header, header
    out = _rank(_scenario(tmp_path), capsys)
    assert "3 grasps x 21 samples" in out.splitlines()[0]


def test_empty_iso_region_list_means_no_assessment(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """docs/cli.md: ``iso_ts_15066: {regions: []}`` turns the ISO/TS 15066 assessment off."""
    out_json = tmp_path / "out.json"
    path = _scenario(tmp_path, iso_ts_15066={"regions": []})
    out = _rank(path, capsys, "--json", str(out_json))
    assert "ISO/TS 15066" not in out
    grasps = json.loads(out_json.read_text())["grasps"]
    assert all("iso_ts_15066" not in grasp for grasp in grasps)
    assert all(grasp["feasible"] for grasp in grasps)  # the ranking itself is unchanged
    docs = (Path(__file__).resolve().parents[1] / "docs" / "cli.md").read_text()
    assert "iso_ts_15066: {regions: []}" in docs and "no ISO/TS 15066 assessment" in docs
