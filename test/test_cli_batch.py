"""``grasp-safety batch`` on the example dataset (examples/dataset): every refused input is
printed with its reason and fails the command unless ``--allow-refused``; an ACRONYM file's
object is its mass and inertia together or the SPEC's."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

h5py = pytest.importorskip("h5py")
pytest.importorskip("pyarrow")

from grasp_safety_ros.cli.main import main  # noqa: E402
from grasp_safety_ros.dataset.batch import read_batch  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "dataset"
REFUSED = [  # (file, key, reason) of spec_refused.yaml's refused inputs
    ("refused/mass_only.h5", "object/inertia", "is required when object/mass is given"),
    ("missing/*.yaml", "sources[3].path", "matches no file"),
]


@pytest.fixture
def dataset(tmp_path: Path) -> Path:
    """A copy of the example dataset (the tests add files to it)."""
    shutil.copytree(EXAMPLE, tmp_path / "dataset")
    return tmp_path / "dataset"


def _batch(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, list[str]]:
    """Exit code, stdout, and the stderr lines other than the progress lines."""
    code = main(["batch", *args])
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if not line.startswith("batch: ")]
    return code, captured.out, errors


def test_refused_inputs_are_listed_and_fail_the_command(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "labels"
    code, stdout, errors = _batch(capsys, str(dataset / "spec_refused.yaml"), "--out", str(out))
    assert code == 2
    listed = [f"grasp-safety: refused {file}: {key}: {reason}" for file, key, reason in REFUSED]
    assert errors == [
        *listed,
        "grasp-safety: error: sources: 2 requested inputs refused (listed above); "
        "--allow-refused accepts a partial run",
    ]
    assert "10 grasps (10 feasible" in stdout and "2 files refused" in stdout
    summary = json.loads((out / "summary.json").read_text())  # the run is written anyway
    assert [(f["file"], f["key"], f["reason"]) for f in summary["refused_files"]] == REFUSED
    assert read_batch(out).num_rows == 10  # box.h5's 6 grasps and box.yaml's 4


def test_allow_refused_accepts_a_partial_run(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = str(dataset / "spec_refused.yaml")
    code, _, errors = _batch(capsys, spec, "--out", str(tmp_path / "x"), "--allow-refused")
    assert code == 0
    assert errors == [f"grasp-safety: refused {f}: {k}: {r}" for f, k, r in REFUSED]


def test_nothing_refused_exits_0_and_prints_no_refusal(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, stdout, errors = _batch(capsys, str(dataset / "spec.yaml"), "--out", str(tmp_path / "x"))
    assert (code, errors) == (0, [])
    assert "0 files refused" in stdout


def _write_object(path: Path, keys: dict[str, object]) -> None:
    with h5py.File(EXAMPLE / "acronym" / "box.h5", "r") as source, h5py.File(path, "w") as h5:
        h5["grasps/transforms"] = source["grasps/transforms"][()]
        for key, value in keys.items():
            h5[key] = value


@pytest.mark.parametrize(
    ("keys", "refusal"),
    [
        ({"object/mass": 0.3}, ("object/inertia", "is required when object/mass is given")),
        ({"object/inertia": np.eye(3) * 1e-3}, ("object/mass", "is required when")),
        ({"object/com": np.zeros(3)}, ("object/mass", "is required when object/com is given")),
    ],
)
def test_an_acronym_object_is_mass_and_inertia_together(
    dataset: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    keys: dict[str, object],
    refusal: tuple[str, str],
) -> None:
    """A mass without its inertia (or an inertia or CoM without the mass) would mix the
    file's object with the SPEC's shape: refused naming the missing key."""
    _write_object(dataset / "acronym" / "partial.h5", keys)
    code, _, errors = _batch(capsys, str(dataset / "spec.yaml"), "--out", str(tmp_path / "x"))
    key, reason = refusal
    assert code == 2
    assert errors[0].startswith(f"grasp-safety: refused acronym/partial.h5: {key}: {reason}")


def test_an_acronym_object_without_com_has_it_at_the_origin(
    dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """object/mass and object/inertia without object/com: the file's object, CoM at the
    origin (the mass column is the file's, not the SPEC's 0.3 kg)."""
    inertia = np.diag([2e-3, 3e-3, 1e-3])
    _write_object(dataset / "acronym" / "box.h5", {"object/mass": 0.7, "object/inertia": inertia})
    spec = yaml.safe_load((dataset / "spec.yaml").read_text())
    spec["sources"] = [{"format": "acronym", "path": "acronym/box.h5"}]
    (dataset / "one.yaml").write_text(yaml.safe_dump(spec))
    out = tmp_path / "x"
    code, _, errors = _batch(capsys, str(dataset / "one.yaml"), "--out", str(out))
    assert (code, errors) == (0, [])
    assert set(read_batch(out, ["object_mass_kg"]).column(0).to_pylist()) == {0.7}
