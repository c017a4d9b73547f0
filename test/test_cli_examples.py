"""The committed examples (examples/) are what examples/make_examples.py writes, and the MJCF
arm is the arm MuJoCo sees. The docs' captured blocks run them (test/test_docs.py)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from grasp_safety_ros.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
sys.path.insert(0, str(EXAMPLES))
import make_examples  # noqa: E402


def test_committed_examples_are_the_script_output(tmp_path: Path) -> None:
    h5py = pytest.importorskip("h5py")
    written = make_examples.write_examples(tmp_path)
    assert written
    for path in written:
        committed = EXAMPLES / path.relative_to(tmp_path)
        if path.suffix != ".h5":
            assert committed.read_text() == path.read_text(), committed
            continue
        with h5py.File(committed, "r") as old, h5py.File(path, "r") as new:
            keys = _datasets(old)
            assert keys and keys == _datasets(new), committed
            for key in keys:
                assert np.array_equal(old[key][()], new[key][()]), f"{committed}: {key}"


def _datasets(h5: Any) -> list[str]:
    """The names of an HDF5 file's datasets, sorted."""
    import h5py

    found: list[str] = []

    def add(name: str, item: Any) -> None:
        if isinstance(item, h5py.Dataset):
            found.append(name)

    h5.visititems(add)
    return sorted(found)


def test_mjcf_arm_is_the_arm_mujoco_sees() -> None:
    """Tip site position and joint-space inertia (armature included) at the seed equal
    MuJoCo's own: values of order 1 from a few hundred flops, so 1e-10 (~5e5 eps) is
    rounding only."""
    mujoco = pytest.importorskip("mujoco")
    from grasp_safety_ros.core import RobotModel

    path = EXAMPLES / "mjcf" / "arm.xml"
    robot = RobotModel.from_urdf(str(path), "base_link", "tool")
    seed = np.array(make_examples.ARM_SEED)
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    data.qpos[:] = seed
    mujoco.mj_forward(model, data)
    site = data.site_xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tool")]
    np.testing.assert_allclose(robot.transform_tip_to_base(seed).translation, site, atol=1e-10)
    inertia = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, inertia)
    q = robot.q_from_positions(seed)
    pinocchio_inertia = pin.crba(robot.model, robot.model.createData(), q)
    pinocchio_inertia = np.triu(pinocchio_inertia) + np.triu(pinocchio_inertia, 1).T
    np.testing.assert_allclose(pinocchio_inertia, inertia, atol=1e-10)
    assert robot.armature_kgm2.tolist() == [link[5] for link in make_examples.LINKS]


def test_example_scenarios_rank_every_grasp(capsys: pytest.CaptureFixture[str]) -> None:
    for scenario in ("mjcf/scenario.yaml", "whole_arm/book.yaml"):
        assert main(["rank", str(EXAMPLES / scenario)]) == 0
        table = capsys.readouterr().out
        assert "infeasible" not in table, scenario
