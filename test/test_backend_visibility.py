"""The backend that ran (compiled or python, with the reason of a fallback) is reported by the
core ranking, the CLI's JSON and header line; the node's report is in test_ros_fuzz.py."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import yaml
from conftest import ARM6_AXES, book_trajectory, serial_arm_urdf

from grasp_safety_ros.cli.main import main
from grasp_safety_ros.core import Grasp, GraspSafetyEvaluator, RobotModel, solid_box
from grasp_safety_ros.core.method import ik as ik_module
from grasp_safety_ros.core.method import ranking as ranking_module
from grasp_safety_ros.core.method.ik import IKSolver, compiled_available
from grasp_safety_ros.core.method.ranking import EvaluationConfig
from grasp_safety_ros.paths import config_file

BOX = solid_box(0.5, [0.1, 0.1, 0.1])
needs_numba = pytest.mark.skipif(not compiled_available(), reason="numba is not installed")


def arm(continuous_joint: str = "") -> RobotModel:
    urdf = serial_arm_urdf(ARM6_AXES)
    if continuous_joint:
        urdf = urdf.replace(
            f'<joint name="{continuous_joint}" type="revolute">',
            f'<joint name="{continuous_joint}" type="continuous">',
        )
    return RobotModel.from_urdf(urdf, "base_link", "tool")


def rank_counting_paths(
    evaluator: GraspSafetyEvaluator, monkeypatch: pytest.MonkeyPatch
) -> tuple[str, dict[str, int]]:
    """Rank two grasps; return the reported backend and how often each path really ran."""
    calls = {"compiled": 0, "python": 0}
    compiled, python = ranking_module.evaluate_grasps_compiled, IKSolver.solve_trajectory_arrays

    def count_compiled(*args: Any, **kwargs: Any) -> Any:
        calls["compiled"] += len(args[2])  # the grasps of the batch
        return compiled(*args, **kwargs)

    def count_python(self: IKSolver, *args: Any, **kwargs: Any) -> Any:
        calls["python"] += 1
        return python(self, *args, **kwargs)

    monkeypatch.setattr(ranking_module, "evaluate_grasps_compiled", count_compiled)
    monkeypatch.setattr(IKSolver, "solve_trajectory_arrays", count_python)
    grasps = [Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, z])), f"g{z}") for z in (0.0, 0.02)]
    trajectory = book_trajectory(dt_s=0.25)
    ranking = evaluator.rank(grasps, BOX, trajectory)
    return ranking.backend, calls


@needs_numba
def test_auto_reports_compiled_when_the_kernels_ran(monkeypatch: pytest.MonkeyPatch) -> None:
    backend, calls = rank_counting_paths(GraspSafetyEvaluator(arm()), monkeypatch)
    assert backend == "compiled"
    assert calls == {"compiled": 2, "python": 0}


def test_python_on_request_is_reported_without_a_reason(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    evaluator = GraspSafetyEvaluator(arm(), EvaluationConfig(backend="python"))
    backend, calls = rank_counting_paths(evaluator, monkeypatch)
    assert backend == "python"
    assert calls == {"compiled": 0, "python": 2}


@needs_numba
def test_continuous_joints_run_compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    backend, calls = rank_counting_paths(GraspSafetyEvaluator(arm("j3")), monkeypatch)
    assert backend == "compiled"
    assert calls == {"compiled": 2, "python": 0}


@needs_numba
def test_fallback_names_the_reason(monkeypatch: pytest.MonkeyPatch) -> None:
    # Every chain RobotModel accepts (1-DOF joints) is compiled: a refusal is simulated.
    reason = "branched chain not supported by the compiled kernels"
    monkeypatch.setattr(ik_module, "chain_arrays_or_reason", lambda robot: reason)
    backend, calls = rank_counting_paths(GraspSafetyEvaluator(arm()), monkeypatch)
    assert backend == f"python ({reason})"
    assert calls == {"compiled": 0, "python": 2}


def test_fallback_without_numba_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ik_module, "NUMBA_AVAILABLE", False)
    backend, calls = rank_counting_paths(GraspSafetyEvaluator(arm()), monkeypatch)
    assert backend == "python (numba not installed)"
    assert calls == {"compiled": 0, "python": 2}


def fast_book_scenario(tmp_path: Path) -> Path:
    data = yaml.safe_load(config_file("book_baxter.yaml").read_text())
    data["trajectory"]["dt_s"] = 0.1
    path = tmp_path / "book.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_cli_json_and_header_line_name_the_backend(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.json"
    assert main(["rank", str(fast_book_scenario(tmp_path)), "--json", str(out)]) == 0
    expected = "compiled" if compiled_available() else "python (numba not installed)"
    assert json.loads(out.read_text())["backend"] == expected
    header = capsys.readouterr().out.splitlines()[0]
    assert header == (
        f"robot baxter (base -> right_gripper), 3 grasps x 21 samples, backend {expected}"
    )


def test_cli_reports_the_fallback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(ik_module, "NUMBA_AVAILABLE", False)
    out = tmp_path / "out.json"
    assert main(["rank", str(fast_book_scenario(tmp_path)), "--json", str(out)]) == 0
    assert json.loads(out.read_text())["backend"] == "python (numba not installed)"
    assert (
        capsys.readouterr().out.splitlines()[0].endswith(", backend python (numba not installed)")
    )
