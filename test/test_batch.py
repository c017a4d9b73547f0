"""``grasp-safety batch``: small ACRONYM / GraspGen / scenario datasets built here, run locally,
on an in-process LocalCluster and on a real ``dask scheduler`` + two ``dask worker``s; every
row equals ``rank`` of the equivalent scenario, resume equals an uninterrupted run, bad files
are reported with the file and the key."""

from __future__ import annotations

import json
import math
import shutil
import socket
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import yaml
from conftest import ARM6_AXES, serial_arm_urdf

from grasp_safety_ros.cli.main import main, rank_scenario
from grasp_safety_ros.core import RobotModel
from grasp_safety_ros.core.exceptions import GraspSafetyError, InvalidInputError
from grasp_safety_ros.core.input_checks import quat_xyzw_from_rotation
from grasp_safety_ros.scenario.schema import load_scenario

h5py = pytest.importorskip("h5py")
pa = pytest.importorskip("pyarrow")
pytest.importorskip("distributed")

from grasp_safety_ros.dataset.batch import PARTS, read_batch, run_batch  # noqa: E402
from grasp_safety_ros.dataset.rows import report_columns  # noqa: E402
from grasp_safety_ros.dataset.spec import parse_spec  # noqa: E402

GRIPPER_TO_TIP = pin.SE3(pin.exp3(np.array([0.1, -0.2, 0.05])), np.array([0.0, 0.01, 0.03]))
MOTION = [  # waypoints of the object in its start frame: (time_s, position_m, rotation log)
    (0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
    (0.3, [0.03, -0.02, 0.04], [0.0, 0.1, 0.0]),
    (0.5, [0.06, -0.01, 0.05], [0.05, 0.1, -0.05]),
]
DT_S = 0.1
SEED = [0.3, 0.6, -1.1, 0.4, 0.7, 0.2]  # a bent arm: the object starts at its tip
ROBOT = {"urdf": "arm.urdf", "base_frame": "base_link", "tip_frame": "tool", "seed": SEED}
INERTIA_A = (0.4, [0.01, -0.02, 0.005], np.diag([2e-3, 3e-3, 1.5e-3]))  # mass, com, tensor


def _pose_yaml(pose: pin.SE3) -> dict[str, list[float]]:
    return {
        "position_m": [float(x) for x in pose.translation],
        "quat_xyzw": [float(x) for x in quat_xyzw_from_rotation(pose.rotation)],
    }


def _tip_grasps(count: int, rng: np.random.Generator) -> list[pin.SE3]:
    """T_object_tip near a reachable reference; the last one far out of reach."""
    poses = [
        pin.SE3(pin.exp3(rng.normal(0, 0.05, 3)), rng.normal(0, 0.01, 3)) for _ in range(count)
    ]
    poses[-1] = pin.SE3(np.eye(3), np.array([3.0, 0.0, 0.0]))
    return poses


class Dataset:
    """The files of a small dataset, its SPEC, and the T_object_tip of every grasp."""

    def __init__(self, root: Path) -> None:
        self.root = root
        urdf = serial_arm_urdf(ARM6_AXES)
        (root / "arm.urdf").write_text(urdf)
        robot = RobotModel.from_urdf(urdf, "base_link", "tool")
        tip0 = robot.transform_tip_to_base(np.array(SEED))
        self.start = tip0  # the object frame starts at the tip's pose: T_object_tip ~ identity
        rng = np.random.default_rng(3)
        self.tips: dict[str, list[pin.SE3]] = {}
        self.inertia: dict[str, tuple[float, Any, Any]] = {}
        (root / "acronym").mkdir()
        for name, count, with_mass in (("a", 5, True), ("b", 4, False)):
            tips = _tip_grasps(count, rng)
            grippers = np.array([(t * GRIPPER_TO_TIP.inverse()).homogeneous for t in tips])
            with h5py.File(root / "acronym" / f"{name}.h5", "w") as h5:
                h5["grasps/transforms"] = grippers
                h5["grasps/qualities/flex/object_in_gripper"] = np.arange(count) % 2
                h5["object/file"] = f"meshes/{name}.obj"
                h5["object/scale"] = 0.8
                if with_mass:
                    h5["object/mass"], h5["object/com"], h5["object/inertia"] = INERTIA_A
            self.tips[f"acronym/{name}.h5"] = tips
            self.inertia[f"acronym/{name}.h5"] = INERTIA_A if with_mass else self.default
        tips = _tip_grasps(4, rng)
        grasps = {}
        for k, tip in enumerate(tips):
            gripper = tip * GRIPPER_TO_TIP.inverse()
            x, y, z, w = quat_xyzw_from_rotation(gripper.rotation)
            grasps[f"grasp_{k}"] = {
                "confidence": 0.5 + 0.1 * k,
                "position": gripper.translation.tolist(),
                "orientation": {"w": float(w), "xyz": [float(x), float(y), float(z)]},
                "cspace_position": {"j1": 0.0},
            }
        (root / "graspgen").mkdir()
        (root / "graspgen" / "c.yaml").write_text(
            yaml.safe_dump({"format": "isaac_grasp", "format_version": 1.0, "grasps": grasps})
        )
        self.tips["graspgen/c.yaml"] = tips
        self.inertia["graspgen/c.yaml"] = self.default
        (root / "scenarios").mkdir()
        scenario = self.equivalent_scenario("graspgen/c.yaml")
        for k, grasp in enumerate(scenario["grasps"]):
            grasp["quality"] = 0.1 * k
        scenario["robot"]["urdf"] = "../arm.urdf"
        (root / "scenarios" / "d.yaml").write_text(yaml.safe_dump(scenario))
        self.spec = {
            "robot": dict(ROBOT),
            "gripper_to_tip": _pose_yaml(GRIPPER_TO_TIP),
            "object_start_in_base": _pose_yaml(self.start),
            "motion": {
                "waypoints": [
                    {"time_s": t, **_pose_yaml(pin.SE3(pin.exp3(np.array(r)), np.array(p)))}
                    for t, p, r in MOTION
                ],
                "dt_s": DT_S,
            },
            "object": {"mass_kg": 0.25, "box_size_m": [0.05, 0.08, 0.12]},
            "posture": {"restarts": 2},
            "chunk_grasps": 3,
            "sources": [
                {"format": "acronym", "path": "acronym/*.h5"},
                {"format": "graspgen", "path": "graspgen/*.yaml"},
                {"format": "scenarios", "path": "scenarios/*.yaml"},
            ],
        }
        self.spec_path = self.write_spec("spec.yaml", self.spec)

    @property
    def default(self) -> tuple[float, Any, Any]:
        from grasp_safety_ros.core.model.inertia import solid_box

        box = solid_box(0.25, [0.05, 0.08, 0.12])
        return box.mass_kg, box.com_in_object_m, box.inertia_about_com_kgm2

    def write_spec(self, name: str, spec: dict[str, Any]) -> Path:
        path = self.root / name
        path.write_text(yaml.safe_dump(spec))
        return path

    def equivalent_scenario(self, source: str) -> dict[str, Any]:
        """The scenario ``grasp-safety rank`` gets for a source's grasps: the object's base
        poses T_base_object_start · M(t_i), the grasps T_object_gripper · T_gripper_tip."""
        mass, com, tensor = self.inertia[source]
        waypoints = [
            {
                "time_s": t,
                **_pose_yaml(self.start * pin.SE3(pin.exp3(np.array(r)), np.array(p))),
            }
            for t, p, r in MOTION
        ]
        return {
            "robot": dict(ROBOT),
            "object": {
                "mass_kg": float(mass),
                "com_in_object_m": [float(x) for x in com],
                "inertia_about_com_kgm2": np.asarray(tensor).tolist(),
            },
            "trajectory": {"waypoints": waypoints, "dt_s": DT_S},
            "grasps": [
                {"name": f"g{k}", **_pose_yaml(tip)} for k, tip in enumerate(self.tips[source])
            ],
            "metric": "mean",
            "posture": {"restarts": 2},
        }


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    return Dataset(tmp_path_factory.mktemp("dataset"))


@pytest.fixture(scope="module")
def local_run(dataset: Dataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("local")
    run_batch(dataset.spec_path, out, workers=2)
    return out


def _parts(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((out / PARTS).glob("part-*.parquet"))}


def _close(value: Any, expected: float) -> bool:
    if expected is None or (isinstance(expected, float) and math.isnan(expected)):
        return value is None
    return value is not None and abs(value - expected) <= 1e-12 * max(1.0, abs(expected))


def test_every_row_equals_rank_of_the_equivalent_scenario(
    dataset: Dataset, local_run: Path
) -> None:
    rows = read_batch(local_run).to_pylist()
    assert len(rows) == 5 + 4 + 4 + 4 and [r["grasp_index"] for r in rows[:5]] == list(range(5))
    by_source: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by_source.setdefault(row["source"], []).append(row)
    assert sorted(by_source) == [
        "acronym/a.h5",
        "acronym/b.h5",
        "graspgen/c.yaml",
        "scenarios/d.yaml",
    ]
    checked_feasible = checked_infeasible = 0
    for source, got in by_source.items():
        if source.startswith("scenarios/"):
            scenario = load_scenario(dataset.root / source)
        else:
            path = dataset.write_spec(
                f"equivalent_{source.replace('/', '_')}.yaml", dataset.equivalent_scenario(source)
            )
            scenario = load_scenario(path)
        report = rank_scenario(scenario)
        iso = {a.index: a for a in report.iso}
        for k, (row, e, p) in enumerate(
            zip(got, report.ranking.evaluations, report.ranking.postures, strict=True)
        ):
            assert row["feasible"] == e.feasible and row["reason"] == e.reason, (source, k)
            for column, expected in (
                ("score", e.score),
                ("mean_effective_mass_kg", e.mean_effective_mass_kg),
                ("peak_effective_mass_kg", e.peak_effective_mass_kg),
                ("safety_score", report.scores[k]),
                ("score_single_ik", p.score_single_ik),
                ("score_range_low", p.score_range[0]),
                ("score_range_high", p.score_range[1]),
                ("iso_ts_15066_min_duration_s", iso[k].min_duration_s),
            ):
                assert _close(row[column], expected), (source, k, column, row[column], expected)
            assert (row["postures_tried"], row["postures_feasible"], row["postures_stopped"]) == (
                p.postures_tried,
                p.postures_feasible,
                p.postures_stopped,
            )
            assert row["backend"] == report.ranking.backend and row["metric"] == "mean"
            if e.feasible:
                checked_feasible += 1
                a = iso[k]
                worst = max(
                    r.worst_force_ratio for r in a.regions if r.transient_contact_permitted
                )
                assert _close(row["iso_ts_15066_worst_force_ratio"], worst)
                assert np.allclose(row["start_positions"], p.start_positions, rtol=0, atol=1e-12)
            else:
                checked_infeasible += 1
                assert row["iso_ts_15066_worst_force_ratio"] is None
    assert checked_feasible >= 8 and checked_infeasible >= 4  # the far grasp of each file
    a_rows = by_source["acronym/a.h5"]
    assert [r["label_object_in_gripper"] for r in a_rows] == [0, 1, 0, 1, 0]
    assert a_rows[0]["object_mass_kg"] == INERTIA_A[0] and a_rows[0]["object_scale"] == 0.8
    assert by_source["acronym/b.h5"][0]["object_mass_kg"] == 0.25  # the SPEC's default
    assert [r["label_confidence"] for r in by_source["graspgen/c.yaml"]] == pytest.approx(
        [0.5, 0.6, 0.7, 0.8]
    )
    assert [r["label_quality"] for r in by_source["scenarios/d.yaml"]] == pytest.approx(
        [0.0, 0.1, 0.2, 0.3]
    )
    summary = json.loads((local_run / "summary.json").read_text())
    assert summary["grasps"] == 17 and summary["chunks"] == 2 + 2 + 2 + 2
    assert summary["feasible"] + summary["infeasible"] == 17 and summary["files_refused"] == 0
    assert sum(summary["failures_by_reason"].values()) == summary["infeasible"]


def test_rows_carry_every_posture_count(dataset: Dataset) -> None:
    """The posture counts reach the rows as the record has them (the dataset's 2 restarts
    stop no posture, so the stopped counts are set here)."""
    report = rank_scenario(load_scenario(dataset.root / "scenarios/d.yaml"))
    postures = tuple(
        replace(p, postures_stopped=k + 1) for k, p in enumerate(report.ranking.postures)
    )
    columns = report_columns(replace(report, ranking=replace(report.ranking, postures=postures)))
    for name in ("postures_tried", "postures_feasible", "postures_stopped"):
        assert columns[name] == [getattr(p, name) for p in postures], name
    assert columns["postures_stopped"] == list(range(1, len(postures) + 1))


def test_local_cluster_and_serial_give_identical_parts(
    dataset: Dataset, local_run: Path, tmp_path: Path
) -> None:
    from distributed import Client, LocalCluster

    from grasp_safety_ros.dataset import batch

    serial = tmp_path / "serial"
    run_batch(dataset.spec_path, serial, workers=1)
    assert _parts(serial) == _parts(local_run)
    batch._EVALUATORS.clear()
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        summary = run_batch(dataset.spec_path, tmp_path / "dask", client=client)
    assert summary["chunks_computed"] == 8
    assert _parts(tmp_path / "dask") == _parts(local_run)
    # the Dask workers (threads of this process here) ran the package pool with one worker
    workers = [e.config.workers for e in batch._EVALUATORS.values()]
    assert workers and set(workers) == {1}


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_real_dask_scheduler_and_two_workers_give_identical_parts(
    dataset: Dataset, local_run: Path, tmp_path: Path
) -> None:
    dask = Path(sys.executable).with_name("dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    common = ["--no-dashboard"]
    processes = [
        subprocess.Popen(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), *common],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    try:
        for _ in range(2):
            processes.append(
                subprocess.Popen(
                    [dask, "worker", address, "--nthreads", "1", "--host", "127.0.0.1", *common],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
            )
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=30)
            pids = client.run(lambda: __import__("os").getpid())
            assert len(set(pids.values())) == 2
        out = tmp_path / "cluster"
        assert (
            main(["batch", str(dataset.spec_path), "--out", str(out), "--scheduler", address]) == 0
        )
        assert _parts(out) == _parts(local_run)
        summary = json.loads((out / "summary.json").read_text())
        assert len(summary["throughput"]["peak_memory_per_worker_mib"]) == 2
    finally:
        for process in reversed(processes):
            process.terminate()
        for process in processes:
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()


def test_resume_recomputes_only_missing_or_stale_parts(
    dataset: Dataset, local_run: Path, tmp_path: Path
) -> None:
    out = tmp_path / "resumed"
    shutil.copytree(local_run, out)
    parts = sorted((out / PARTS).glob("part-*.parquet"))
    parts[1].unlink()  # killed before this chunk was written
    parts[5].unlink()
    (out / PARTS / ".part-00006.parquet.tmp-123").write_bytes(b"half a file")  # mid-write
    stale = pa.table({"x": [1]})  # a part from other inputs (no or another hash)
    import pyarrow.parquet as pq

    pq.write_table(stale, parts[2])
    summary = run_batch(dataset.spec_path, out, workers=1, resume=True)
    assert summary["chunks_computed"] == 3 and summary["chunks_resumed"] == 5
    assert _parts(out) == _parts(local_run)
    assert not list((out / PARTS).glob(".*tmp*"))
    # a changed SPEC changes every chunk's hash: nothing is kept
    changed = dict(dataset.spec, metric="max")
    summary = run_batch(dataset.write_spec("max.yaml", changed), out, workers=1, resume=True)
    assert summary["chunks_computed"] == 8
    metrics = {(r["format"], r["metric"]) for r in read_batch(out).to_pylist()}
    assert metrics == {("acronym", "max"), ("graspgen", "max"), ("scenarios", "mean")}


def test_bad_files_are_reported_with_file_and_key(dataset: Dataset, tmp_path: Path) -> None:
    root = dataset.root
    (root / "bad").mkdir(exist_ok=True)
    (root / "bad" / "corrupt.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00garbage" * 50)
    shutil.copy(root / "acronym" / "b.h5", root / "bad" / "nomass.h5")
    with h5py.File(root / "bad" / "rotated.h5", "w") as h5:
        transforms = np.tile(np.eye(4), (2, 1, 1))
        transforms[1, :3, :3] *= 1.1  # not a rotation
        h5["grasps/transforms"] = transforms
        h5["object/mass"], h5["object/com"], h5["object/inertia"] = INERTIA_A
    text = (root / "graspgen" / "c.yaml").read_text()
    data = yaml.safe_load(text)
    data["grasps"]["grasp_2"]["orientation"]["w"] = 3.0
    (root / "bad" / "quat.yaml").write_text(yaml.safe_dump(data))
    spec = {k: v for k, v in dataset.spec.items() if k != "object"}
    spec["sources"] = [
        {"format": "acronym", "path": "bad/*.h5"},
        {"format": "acronym", "path": "acronym/a.h5"},
        {"format": "acronym", "path": "nothing/*.h5"},
    ]
    out = tmp_path / "bad"
    summary = run_batch(dataset.write_spec("bad.yaml", spec), out, workers=1)
    failures = {(f["file"], f["key"]): f["reason"] for f in summary["failures"]}
    assert "not a readable HDF5 file" in failures[("bad/corrupt.h5", "/")]
    assert "no object defaults" in failures[("bad/nomass.h5", "object/mass")]
    assert "rigid transform" in failures[("bad/rotated.h5", "grasps/transforms[1]")]
    assert failures[("nothing/*.h5", "sources[2].path")] == "matches no file"
    assert summary["files_refused"] == 3 and summary["unreadable_grasps"] == 1
    assert summary["grasps"] == 2 + 5  # rotated.h5 (one good grasp) and a.h5 still ran
    # GraspGen: a non-unit quaternion, with the SPEC's object defaults
    spec = dict(dataset.spec, sources=[{"format": "graspgen", "path": "bad/quat.yaml"}])
    summary = run_batch(dataset.write_spec("quat.yaml", spec), tmp_path / "quat", workers=1)
    (failure,) = summary["failures"]
    assert (failure["file"], failure["key"]) == ("bad/quat.yaml", "grasps.grasp_2.orientation")
    assert "unit quaternion" in failure["reason"] and summary["grasps"] == 4


class _FieldlessError(GraspSafetyError):
    """An error about no one field (as RobotModelError): it has no ``field`` or ``reason``."""


def test_errors_naming_no_field_are_rows_and_refusals_of_the_whole(
    dataset: Dataset, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A GraspSafetyError other than InvalidInputError / FrameNotFoundError, raised while a
    file is checked, read or ranked, is reported under the key "/" with its message (it
    crashed the batch with an AttributeError on ``.field`` before)."""
    from grasp_safety_ros.dataset import batch, sources

    def raising(*args: Any, **kwargs: Any) -> Any:
        raise _FieldlessError("not for this chain")

    spec = dict(dataset.spec, sources=[{"format": "acronym", "path": "acronym/a.h5"}])
    path = dataset.write_spec("fieldless.yaml", spec)  # 5 grasps: chunks of 3 and 2
    for stage, module, name in (
        ("ranked", batch, "run_pipeline"),
        ("read", batch, "load_block"),
    ):
        with monkeypatch.context() as patch:
            patch.setattr(module, name, raising)
            summary = run_batch(path, tmp_path / stage, workers=1)
        rows = read_batch(tmp_path / stage).to_pylist()
        assert [(r["error_key"], r["error"], r["feasible"]) for r in rows] == [
            ("/", "not for this chain", False)
        ] * 5, stage
        assert summary["unreadable_grasps"] == 5 and summary["files_refused"] == 0, stage
    monkeypatch.setattr(sources, "_count_grasps", raising)  # checking the file
    summary = run_batch(path, tmp_path / "checked", workers=1)
    assert summary["refused_files"] == [
        {"file": "acronym/a.h5", "key": "/", "reason": "not for this chain"}
    ]
    assert summary["grasps"] == 0


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            {
                "motion": {
                    "waypoints": [
                        {"time_s": 0.1, "position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]},
                        {"time_s": 0.5, "position_m": [0, 0, 0.1], "quat_xyzw": [0, 0, 0, 1]},
                    ],
                    "dt_s": 0.1,
                }
            },
            r"motion\.waypoints\[0\]: must be the identity at time_s 0",
        ),
        ({"sources": [{"format": "npz", "path": "x"}]}, r"sources\[0\]\.format: must be one of"),
        ({"uncertainty": {"mass_fraction": 0.1}}, r"uncertainty: depends on the whole"),
        ({"chunk_grasps": 0}, r"chunk_grasps: must be an integer in \[1, "),
        (
            {"gripper_to_tip": {"position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 2]}},
            r"gripper_to_tip\.quat_xyzw: must be a unit quaternion",
        ),
        ({"robot": None}, r"robot: must be a mapping"),
    ],
)
def test_spec_errors_name_the_field(dataset: Dataset, change: dict, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        parse_spec({**dataset.spec, **change}, dataset.root)


def test_cli_bad_spec_exits_2_with_one_line(
    dataset: Dataset, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = dataset.write_spec(
        "nosources.yaml", {k: v for k, v in dataset.spec.items() if k != "sources"}
    )
    assert main(["batch", str(path), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "grasp-safety: error: sources: is required"


def test_kernels_warm_once_per_process_and_plain_progress_lines(
    dataset: Dataset,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from grasp_safety_ros.dataset import batch

    calls = []
    monkeypatch.setattr(batch, "warm_up", lambda: calls.append(1) or 0.0)
    monkeypatch.setattr(batch, "_WARMED", False)
    run_batch(dataset.spec_path, tmp_path / "a", workers=1)
    run_batch(dataset.spec_path, tmp_path / "b", workers=1)
    assert calls == [1]  # 16 chunks, one warm-up
    lines = capsys.readouterr().err.splitlines()  # stderr is not a terminal: plain lines
    assert lines[-1].startswith("batch: 8/8 chunks") and len(lines) == 16


def test_per_sample_series_equal_rank(dataset: Dataset, tmp_path: Path) -> None:
    spec = dict(dataset.spec, sources=[{"format": "acronym", "path": "acronym/a.h5"}])
    out = tmp_path / "series"
    assert (
        main(
            [
                "batch",
                str(dataset.write_spec("series.yaml", spec)),
                "--out",
                str(out),
                "--per-sample",
                "--workers",
                "1",
            ]
        )
        == 0
    )
    rows = read_batch(out).to_pylist()
    path = dataset.write_spec(
        "equivalent_series.yaml", dataset.equivalent_scenario("acronym/a.h5")
    )
    report = rank_scenario(load_scenario(path))
    for row, e in zip(rows, report.ranking.evaluations, strict=True):
        if not e.feasible:
            assert row["time_s"] is None and row["effective_mass_kg"] is None
            continue
        assert row["time_s"] == e.times_s.tolist()
        assert np.allclose(row["effective_mass_kg"], e.effective_mass_kg, rtol=1e-12, atol=0)
        assert np.allclose(row["tip_speed_m_s"], e.tip_speed_m_s, rtol=1e-12, atol=1e-15)
    assert sum(len(r["time_s"] or []) for r in rows) == 4 * 6  # 4 feasible x 6 samples


def test_killed_run_resumed_equals_uninterrupted(dataset: Dataset, tmp_path: Path) -> None:
    import os
    import signal

    spec = dict(dataset.spec, chunk_grasps=1, posture={"restarts": 12})
    spec_path = dataset.write_spec("kill.yaml", spec)
    whole, killed = tmp_path / "whole", tmp_path / "killed"
    run_batch(spec_path, whole, workers=1)
    command = [sys.executable, "-m", "grasp_safety_ros.cli", "batch", str(spec_path)]
    process = subprocess.Popen(
        [*command, "--out", str(killed), "--workers", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while len(list((killed / PARTS).glob("part-*.parquet"))) < 3:
            assert process.poll() is None and time.monotonic() < deadline
            time.sleep(0.002)
        os.kill(process.pid, signal.SIGKILL)
    finally:
        process.wait(timeout=30)
    written = len(list((killed / PARTS).glob("part-*.parquet")))
    if written == 17:
        pytest.skip("the run finished before it was killed")
    summary = run_batch(spec_path, killed, workers=1, resume=True)
    assert summary["chunks_resumed"] == written and summary["chunks_computed"] == 17 - written
    assert _parts(killed) == _parts(whole)


def test_missing_dependency_is_one_line(dataset: Dataset, tmp_path: Path) -> None:
    code = (
        "import sys; sys.modules['h5py'] = None\n"
        "from grasp_safety_ros.cli.main import main\n"
        f"sys.exit(main(['batch', {str(dataset.spec_path)!r}, '--out', {str(tmp_path)!r}]))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "grasp-safety: error: batch: needs the package 'h5py': pip install -r requirements.txt"
    )


def test_no_scheduler_is_a_one_line_error(
    dataset: Dataset, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import dask

    address = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        code = main(
            ["batch", str(dataset.spec_path), "--out", str(tmp_path), "--scheduler", address]
        )
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"grasp-safety: error: --scheduler: cannot connect to '{address}'")
    assert len(err.splitlines()) == 1


def test_progress_bar_on_a_terminal(
    dataset: Dataset, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import io

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    run_batch(dataset.spec_path, tmp_path, workers=1)
    shown = terminal.getvalue()
    assert "8/8" in shown and "chunk" in shown and "\r" in shown  # tqdm's bar, redrawn
    assert "batch: " not in shown  # not the plain lines


def test_the_docs_spec_example_is_valid(tmp_path: Path) -> None:
    import re

    docs = Path(__file__).resolve().parents[1] / "docs" / "batch.md"
    example = re.search(r"## The SPEC file\n\n.*?```yaml\n(.*?)```", docs.read_text(), re.S)
    assert example is not None
    spec = parse_spec(yaml.safe_load(example.group(1)), tmp_path)
    assert [s.format for s in spec.sources] == ["acronym", "graspgen", "scenarios"]
    assert spec.trajectory is not None and spec.trajectory.num_samples == 51


def _heavier(urdf: str) -> str:
    """The URDF with every link of mass 2 kg."""
    import re

    return re.sub(r'<mass value="[^"]*"/>', '<mass value="2.0"/>', urdf)


def test_evaluator_cache_keys_on_armature_and_description_bytes(
    dataset: Dataset, tmp_path: Path
) -> None:
    from dataclasses import replace

    from grasp_safety_ros.dataset import batch

    scenario = load_scenario(dataset.root / "scenarios" / "d.yaml")
    plain = batch._evaluator(scenario, 1)
    geared = batch._evaluator(
        replace(scenario, robot=replace(scenario.robot, armature_kgm2=[0.05] * 6)), 1
    )
    assert not plain.robot.armature_given and geared.robot.armature_given
    assert np.allclose(geared.robot.armature_kgm2, 0.05, rtol=0, atol=0)
    # the same file name with other content (a long-lived worker re-running): another model
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(serial_arm_urdf(ARM6_AXES))
    moved = replace(scenario, robot=replace(scenario.robot, urdf=str(urdf)))
    before = batch._evaluator(moved, 1)
    urdf.write_text(_heavier(serial_arm_urdf(ARM6_AXES)))
    after = batch._evaluator(moved, 1)
    assert after is not before


def test_dask_task_keys_differ_between_batches(dataset: Dataset, tmp_path: Path) -> None:
    """Two batches sharing a scheduler must not share task keys (they would get each other's
    results): the keys are the chunks' content hashes."""
    from distributed import Client, LocalCluster

    keys: list[set[str]] = []
    with (
        LocalCluster(
            n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        compute = client.compute

        def recording(tasks: list[Any], **kwargs: Any) -> Any:
            keys.append({str(t.key) for t in tasks})
            return compute(tasks, **kwargs)

        client.compute = recording  # type: ignore[method-assign]
        spec = dict(dataset.spec, sources=[dataset.spec["sources"][0]])
        for metric in ("mean", "max"):
            path = dataset.write_spec(f"keys_{metric}.yaml", dict(spec, metric=metric))
            run_batch(path, tmp_path / metric, client=client)
    assert len(keys) == 2 and len(keys[0]) == 4 and not keys[0] & keys[1]


def test_failed_rerun_leaves_no_manifest_and_foreign_parts_are_refused(
    dataset: Dataset, local_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from grasp_safety_ros.dataset import batch

    out = tmp_path / "rerun"
    shutil.copytree(local_run, out)
    calls = 0
    evaluate = batch.evaluate_chunk

    def failing(*args: Any) -> Any:
        nonlocal calls
        calls += 1
        if calls > 2:
            raise RuntimeError("worker lost")
        return evaluate(*args)

    monkeypatch.setattr(batch, "evaluate_chunk", failing)
    changed = dict(dataset.spec, metric="max")
    with pytest.raises(RuntimeError):
        run_batch(dataset.write_spec("rerun.yaml", changed), out, workers=1)
    # two new parts beside six old ones: no manifest to trust
    assert not (out / "manifest.json").exists()
    with pytest.raises(InvalidInputError, match=r"manifest\.json.*did not finish"):
        read_batch(out)
    # an old manifest with a part another run wrote: refused by its stored hash
    shutil.copy(local_run / "manifest.json", out / "manifest.json")
    with pytest.raises(InvalidInputError, match=r"parts/part-00000\.parquet.*another chunk"):
        read_batch(out)


def test_resume_recomputes_when_code_or_a_scenarios_urdf_changes(
    dataset: Dataset, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from grasp_safety_ros.dataset import batch

    root = tmp_path / "data"
    (root / "scenarios").mkdir(parents=True)
    shutil.copy(dataset.root / "arm.urdf", root / "arm.urdf")
    shutil.copy(dataset.root / "scenarios" / "d.yaml", root / "scenarios" / "d.yaml")
    spec = {"chunk_grasps": 3, "sources": [{"format": "scenarios", "path": "scenarios/*.yaml"}]}
    spec_path = root / "spec.yaml"
    spec_path.write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    assert run_batch(spec_path, out, workers=1)["chunks_computed"] == 2
    assert run_batch(spec_path, out, workers=1, resume=True)["chunks_computed"] == 0
    urdf = root / "arm.urdf"
    urdf.write_text(_heavier(urdf.read_text()))
    assert run_batch(spec_path, out, workers=1, resume=True)["chunks_computed"] == 2
    monkeypatch.setattr(batch, "code_sha256", lambda: "other package sources")
    assert run_batch(spec_path, out, workers=1, resume=True)["chunks_computed"] == 2
