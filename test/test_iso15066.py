"""ISO/TS 15066 power and force limiting: table, units, closed forms, re-timing identity."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import BAXTER_SEED, book_trajectory
from hypothesis import given, settings
from hypothesis import strategies as st

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    IKConfig,
    InvalidInputError,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses import body_regions, iso15066
from grasp_safety_ros.core.analyses.body_regions import BODY_REGIONS, BodyRegion
from grasp_safety_ros.core.analyses.iso15066 import (
    assess_grasp,
    assess_motion,
    assess_motions,
    max_permissible_speed_m_s,
    transient_contact_force_n,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat

SHARED_TABLE = (
    Path(__file__).resolve().parents[1].parent
    / "shared"
    / "data"
    / ("iso_ts_15066_body_regions.yaml")
)
HEAD_REGIONS = ("skull_forehead", "face", "neck")


BOOK = solid_box(0.34, [0.15, 0.22, 0.015])
SPINE = Grasp(pose_from_position_quat([-0.075, 0.1, 0.0], [0, 0, 0, 1], "grasp"), "spine")
FAST = EvaluationConfig(ik=IKConfig(check_velocity_limits=False))


def test_package_data_file_agrees_with_the_constant_table() -> None:
    assert body_regions.load_body_regions() == dict(BODY_REGIONS)
    content = yaml.safe_load(body_regions.data_file_path().read_text(encoding="utf-8"))
    assert list(content["regions"]) == [row[0] for row in body_regions.REGION_TABLE]
    assert content["units"]["k"] == "N/mm"


@pytest.mark.skipif(not SHARED_TABLE.is_file(), reason="shared data folder not present")
def test_package_table_carries_the_shared_facts() -> None:
    shared = yaml.safe_load(SHARED_TABLE.read_text(encoding="utf-8"))["regions"]
    package = yaml.safe_load(body_regions.data_file_path().read_text(encoding="utf-8"))["regions"]
    assert package == shared


def test_units_and_head_regions() -> None:
    chest = BODY_REGIONS["chest"]
    assert chest.spring_constant_n_per_m == 25_000.0  # 25 N/mm
    assert chest.max_transient_force_n == 280.0 and chest.max_quasi_static_force_n == 140.0
    assert chest.effective_mass_kg == 40.0
    assert {r.name for r in BODY_REGIONS.values() if not r.transient_contact_permitted} == set(
        HEAD_REGIONS
    )
    for region in BODY_REGIONS.values():
        if region.transient_contact_permitted:
            assert region.max_transient_force_n == 2.0 * region.max_quasi_static_force_n


def test_force_and_speed_limit_by_hand() -> None:
    """Chest, robot 2 kg at 0.5 m/s: μ = 80/42 kg, F = 0.5·sqrt(μ · 25 N/mm · 1000 mm/m)."""
    chest = BODY_REGIONS["chest"]
    mu = 40.0 * 2.0 / 42.0
    stiffness = 25.0 * 1000.0
    assert float(transient_contact_force_n(0.5, 2.0, chest)) == pytest.approx(
        0.5 * math.sqrt(mu * stiffness), rel=1e-14
    )
    assert float(transient_contact_force_n(0.5, 2.0, chest)) == pytest.approx(109.1089451, 1e-9)
    assert float(max_permissible_speed_m_s(2.0, chest)) == pytest.approx(
        280.0 / math.sqrt(mu * stiffness), rel=1e-14
    )
    assert float(max_permissible_speed_m_s(2.0, BODY_REGIONS["face"])) == 0.0


@settings(max_examples=50, deadline=None)
@given(
    speed=st.floats(0.0, 3.0),
    robot_mass=st.floats(0.01, 100.0),
    stiffness=st.floats(1.0, 200.0),
)
def test_immovable_body_region_gives_the_robot_mass(
    speed: float, robot_mass: float, stiffness: float
) -> None:
    """m_h → ∞: μ = M_eff, so F = v·sqrt(M_eff·k)."""
    rigid = BodyRegion("rigid", 100.0, 200.0, stiffness * 1000.0, math.inf)
    expected = speed * math.sqrt(robot_mass * stiffness * 1000.0)
    assert float(transient_contact_force_n(speed, robot_mass, rigid)) == pytest.approx(
        expected, rel=1e-12, abs=1e-12
    )


@settings(max_examples=50, deadline=None)
@given(robot_mass=st.floats(0.01, 100.0), region=st.sampled_from(sorted(BODY_REGIONS)))
def test_force_at_the_speed_limit_is_the_force_limit(robot_mass: float, region: str) -> None:
    body = BODY_REGIONS[region]
    v_max = float(max_permissible_speed_m_s(robot_mass, body))
    force = float(transient_contact_force_n(v_max, robot_mass, body))
    assert force == pytest.approx(body.max_transient_force_n or 0.0, rel=1e-12)


def test_synthetic_motion_ratios_admissibility_and_min_duration() -> None:
    speed = np.array([0.0, 0.2, 0.5, 0.2, 0.0])
    mass = np.array([3.0, 2.0, 2.0, 1.0, 1.0])
    assessment = assess_motion(speed, mass, 2.0, ["chest", "hand_fingers", "face"])
    chest = assessment.region("chest")
    expected = speed * np.sqrt(40.0 * mass / (40.0 + mass) * 25_000.0) / 280.0
    np.testing.assert_allclose(chest.force_ratio, expected, rtol=1e-14)
    assert chest.worst_sample == 2
    assert chest.min_duration_s == pytest.approx(2.0 * expected.max(), rel=1e-14)
    face = assessment.region("face")
    assert not face.transient_contact_permitted and not face.admissible
    np.testing.assert_array_equal(face.force_ratio, [0.0, np.inf, np.inf, np.inf, 0.0])
    assert face.min_duration_s == math.inf
    assert assessment.regions_not_permitted == ("face",)
    assert not assessment.admissible
    hand = assessment.region("hand_fingers")
    assert (
        assessment.limiting_region
        == max((chest, hand), key=lambda a: a.worst_force_ratio).region.name
    )
    assert assessment.admissible_where_permitted == (
        max(chest.worst_force_ratio, hand.worst_force_ratio) <= 1.0
    )
    assert assessment.min_duration_s == pytest.approx(
        2.0 * max(chest.worst_force_ratio, hand.worst_force_ratio), rel=1e-14
    )


def test_motionless_tip_is_admissible_even_for_the_head() -> None:
    assessment = assess_motion(np.zeros(4), np.ones(4), 1.0, list(HEAD_REGIONS))
    assert assessment.admissible
    assert all(a.worst_force_ratio == 0.0 and a.min_duration_s == 0.0 for a in assessment.regions)
    assert math.isnan(assessment.min_duration_s) and assessment.limiting_region == ""


def test_minimum_duration_makes_the_retimed_trajectory_exactly_admissible(
    baxter: RobotModel,
) -> None:
    """Re-timing to T_min (same τ samples) scales every ratio by T/T_min: the worst becomes 1."""
    evaluator = GraspSafetyEvaluator(baxter, FAST)
    duration, dt = 0.5, 0.0125
    fast = evaluator.evaluate(
        SPINE, BOOK, book_trajectory(dt, duration), seed_positions=BAXTER_SEED
    )
    assert fast.feasible, fast.reason
    assessment = assess_grasp(fast)
    assert not assessment.admissible_where_permitted
    t_min = assessment.min_duration_s
    assert t_min > duration
    retimed = evaluator.evaluate(
        SPINE, BOOK, book_trajectory(dt * t_min / duration, t_min), seed_positions=BAXTER_SEED
    )
    np.testing.assert_allclose(retimed.times_s, fast.times_s * t_min / duration, rtol=1e-12)
    again = assess_grasp(retimed)
    assert again.region(assessment.limiting_region).worst_force_ratio == pytest.approx(
        1.0, rel=1e-6
    )
    for before, after in zip(assessment.regions, again.regions, strict=True):
        if before.transient_contact_permitted:
            np.testing.assert_allclose(
                after.force_ratio, before.force_ratio * duration / t_min, rtol=1e-6, atol=1e-12
            )
            assert after.min_duration_s == pytest.approx(before.min_duration_s, rel=1e-6)
    slower = evaluator.evaluate(
        SPINE, BOOK, book_trajectory(dt, 1.001 * t_min), seed_positions=BAXTER_SEED
    )
    assert assess_grasp(slower).admissible_where_permitted
    assert not assess_grasp(slower).admissible  # head regions: never with a moving tip


def test_assess_grasp_uses_tip_speed_and_effective_mass(baxter: RobotModel) -> None:
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        SPINE, BOOK, book_trajectory(0.05, 2.0), seed_positions=BAXTER_SEED
    )
    assessment = assess_grasp(evaluation, ["pelvis"])
    assert assessment.duration_s == 2.0 and assessment.index == evaluation.index
    pelvis = assessment.region("pelvis")
    np.testing.assert_allclose(
        pelvis.contact_force_n,
        evaluation.tip_speed_m_s
        * np.sqrt(
            40.0 * evaluation.effective_mass_kg / (40.0 + evaluation.effective_mass_kg) * 25_000.0
        ),
        rtol=1e-13,
    )


def test_infeasible_grasp_is_not_assessed(baxter: RobotModel) -> None:
    far = Grasp(pose_from_position_quat([0.0, 0.0, 3.0], [0, 0, 0, 1], "grasp"), "far")
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        far, BOOK, book_trajectory(0.1, 2.0), seed_positions=BAXTER_SEED
    )
    assessment = assess_grasp(evaluation)
    assert not assessment.feasible and not assessment.admissible and assessment.regions == ()
    assert math.isnan(assessment.min_duration_s)


def _motions(rng: np.random.Generator, count: int, samples: int) -> tuple[np.ndarray, ...]:
    """Speeds [m/s] with rests, repeated peaks (ties) and masses [kg] over four decades."""
    speeds = rng.uniform(0.0, 1.5, (count, samples))
    speeds[:, :3] = 0.0
    speeds[:, -5:] = speeds[:, [-5]]  # equal speeds (and masses): equal forces
    masses = 10.0 ** rng.uniform(-1.0, 3.0, (count, samples))
    masses[:, -5:] = masses[:, [-5]]
    speeds[0] = 0.0  # a motionless one
    return speeds, masses


def test_batch_summaries_and_lazy_arrays_are_the_formulas_bit_for_bit() -> None:
    """assess_motions: per-sample arrays are the elementwise functions' bits, every summary
    is read off them (argmax, min, all, first largest), the same as motion by motion, and
    as for motions of differing lengths (assessed one by one)."""
    rng = np.random.default_rng(7)
    rigid = BodyRegion("rigid", 100.0, 150.0, 80_000.0, math.inf)
    twin = dataclasses.replace(rigid, name="rigid_twin")  # ties with rigid: never limits
    regions = [*BODY_REGIONS.values(), rigid, twin]
    speeds, masses = _motions(rng, 6, 40)
    duration = 1.7
    batch = assess_motions(list(speeds), list(masses), duration, regions, range(6), "abcdef")
    ragged = assess_motions([speeds[0], speeds[1, :25]], [masses[0], masses[1, :25]], 1.7)
    for m, assessment in enumerate(batch):
        alone = assess_motion(speeds[m], masses[m], duration, regions, m, "abcdef"[m])
        for a, b in zip(assessment.regions, alone.regions, strict=True):
            assert a == b  # the summaries
            for name in ("contact_force_n", "max_permissible_speed_m_s", "force_ratio"):
                np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert assessment == alone  # (the arrays are not compared)
        for a in assessment.regions:
            region = a.region
            force = transient_contact_force_n(speeds[m], masses[m], region)
            v_max = max_permissible_speed_m_s(masses[m], region)
            limit = region.max_transient_force_n
            ratio = force / limit if limit else np.where(speeds[m] > 0.0, np.inf, 0.0)
            np.testing.assert_array_equal(a.contact_force_n, force)
            np.testing.assert_array_equal(a.max_permissible_speed_m_s, v_max)
            np.testing.assert_array_equal(a.force_ratio, ratio)
            assert a.worst_sample == int(np.argmax(force))
            assert a.peak_contact_force_n == force.max()
            assert a.worst_force_ratio == ratio[a.worst_sample]
            assert a.min_max_permissible_speed_m_s == v_max.min()
            assert a.min_duration_s == (duration * ratio.max() if ratio.max() > 0 else 0.0)
            assert a.admissible == (ratio.max() <= 1.0 + iso15066.ADMISSIBLE_RATIO_TOLERANCE)
        permitted = [a for a in assessment.regions if a.transient_contact_permitted]
        limiting = max(permitted, key=lambda a: a.worst_force_ratio)
        assert assessment.limiting_region == limiting.region.name  # the first on ties
        assert assessment.min_duration_s == limiting.min_duration_s
        assert assessment.admissible == all(a.admissible for a in assessment.regions)
        assert assessment.admissible_where_permitted == all(a.admissible for a in permitted)
    assert batch[0].limiting_region == "back_shoulders"  # motionless: all 0, the first
    assert {a.limiting_region for a in batch[1:]} == {"rigid"}
    for motion, count in zip(ragged, (40, 25), strict=True):
        k = motion.index
        alone = assess_motion(speeds[k, :count], masses[k, :count], 1.7, None, k)
        assert motion == alone
        for a, b in zip(motion.regions, alone.regions, strict=True):
            np.testing.assert_array_equal(a.force_ratio, b.force_ratio)


def test_an_empty_motion_has_empty_arrays_and_nan_min_speed() -> None:
    """No samples: each region's arrays are (0,), its summaries 0 (ratio, force, duration)
    and its smallest v_max NaN (the minimum of nothing)."""
    assessment = assess_motion([], [], 1.0)
    for region in assessment.regions:
        for name in ("contact_force_n", "max_permissible_speed_m_s", "force_ratio"):
            assert getattr(region, name).shape == (0,), name
        assert (region.worst_force_ratio, region.peak_contact_force_n) == (0.0, 0.0)
        assert math.isnan(region.min_max_permissible_speed_m_s)


def test_a_pickled_or_copied_assessment_carries_its_own_motion_only() -> None:
    """Pickled or deep-copied, one region of one motion of a batch of 50 x 201 samples carries
    that motion's inputs (2 x 201 float64, 3.2 kB, and the 12 regions), not the batch's (50
    times as much) nor its arrays (3 x 12 x 50 x 201 float64, 2.9 MB): bound 20 kB. The
    whole batch pickles to about its inputs (161 kB) and summaries, arrays read or not:
    bound 600 kB. Equal fields and the same array bits after each round trip."""
    import copy
    import pickle

    speeds, masses = _motions(np.random.default_rng(3), 50, 201)
    batch = assess_motions(list(speeds), list(masses), 2.0)
    for read in (False, True):
        if read:
            _ = batch[0].regions[0].force_ratio  # the batch's arrays now computed
        one = batch[7].regions[4]
        assert len(pickle.dumps(one)) < 20_000
        assert len(pickle.dumps(batch)) < 600_000
        for restored in (pickle.loads(pickle.dumps(one)), copy.deepcopy(one), copy.copy(one)):
            assert restored == one
            for name in ("contact_force_n", "max_permissible_speed_m_s", "force_ratio"):
                np.testing.assert_array_equal(getattr(restored, name), getattr(one, name))
                assert not getattr(restored, name).flags.writeable
    restored_batch = pickle.loads(pickle.dumps(batch))
    assert restored_batch == batch
    for motion, again in zip(batch, restored_batch, strict=True):
        for a, b in zip(motion.regions, again.regions, strict=True):
            np.testing.assert_array_equal(a.force_ratio, b.force_ratio)


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: assess_motion([-0.1, 0.2], [1.0, 1.0], 1.0), "iso15066.speed_m_s"),
        (lambda: assess_motion([0.1, 0.2], [1.0], 1.0), "iso15066.effective_mass_kg"),
        (lambda: assess_motion([0.1, 0.2], [1.0, 0.0], 1.0), "iso15066.effective_mass_kg"),
        (lambda: assess_motion([0.1], [1.0], 0.0), "iso15066.duration_s"),
        (lambda: assess_motion([0.1], [1.0], 1.0, ["elbow"]), "iso15066.regions"),
        (lambda: assess_motion([0.1], [1.0], 1.0, ["chest", "chest"]), "iso15066.regions"),
        (lambda: BodyRegion("x", 10.0, -1.0, 1.0, 1.0), r"region 'x'\.F_tr"),
        (lambda: BodyRegion("x", 10.0, None, 1.0, 0.0), r"region 'x'\.m_h"),
        (lambda: body_regions.body_regions_from_mapping({"a": {"F_qs": 1}}), r"regions\.a"),
        (lambda: BodyRegion("x", 10.0, 20.0, 1e101, 1.0), r"region 'x'\.k.*1e\+100\]"),
        (lambda: BodyRegion("x", 1e-101, None, 1.0, 1.0), r"region 'x'\.F_qs.*\[1e-100"),
        (lambda: BodyRegion("x", 10.0, 20.0, 1.0, 1e101), r"region 'x'\.m_h.*1e\+100\] or inf"),
        (lambda: BodyRegion.from_table_units("x", 1, 2, 1e98, 1), r"region 'x'\.k.*1e\+97\]"),
        (lambda: assess_motion([1e101], [1.0], 1.0), r"iso15066\.speed_m_s.*\[0, 1e\+100\]"),
    ],
)
def test_bad_input_is_refused(call: object, field: str) -> None:
    with pytest.raises(InvalidInputError, match=field):
        call()  # type: ignore[operator]


def test_unphysical_magnitudes_are_refused_and_the_extremes_stay_finite() -> None:
    """A region of m_h = inf and a mass of 1e305 kg at rest made μ·k overflow and F = 0·inf
    NaN, which np.argmax took for the worst ratio (and the limiting region): such a mass is
    refused, naming the field and its range. At the ends of the ranges (a region's numbers,
    speeds and masses: body_regions.MIN_VALUE and MAX_VALUE) every force, speed limit, ratio
    and summary is finite, and every speed limit > 0."""
    wall = BodyRegion("wall", 100.0, 200.0, 50_000.0, math.inf)
    with pytest.raises(
        InvalidInputError, match=r"iso15066\.effective_mass_kg: must be in \[1e-100, 1e\+100\]"
    ):
        assess_motion([0.0, 0.1], [1e305, 1.0], 1.0, [wall, "chest"])
    low, high = body_regions.MIN_VALUE, body_regions.MAX_VALUE
    regions = [
        BodyRegion("stiff", high, low, high, math.inf),  # F/F_tr up to 1e200 / 1e-100
        BodyRegion("soft", low, high, low, low),  # v_max up to 1e100 / sqrt(5e-201)
        BodyRegion("forbidden", low, None, high, high),
    ]
    speeds, masses = [0.0, high, low, high, 1.0], [high, high, low, low, 1.0]
    assessment = assess_motion(speeds, masses, 1.0, regions)
    for a in assessment.regions:
        for name in ("contact_force_n", "max_permissible_speed_m_s"):
            assert np.isfinite(getattr(a, name)).all(), (a.region.name, name)
        if a.transient_contact_permitted:
            assert np.isfinite(a.force_ratio).all() and math.isfinite(a.min_duration_s)
            assert (a.max_permissible_speed_m_s > 0.0).all()
        assert math.isfinite(a.peak_contact_force_n)
    assert assessment.limiting_region == "stiff" and math.isfinite(assessment.min_duration_s)


NEW_MODULES = (
    "body_regions",
    "iso15066",
    "exposed_points",
    "uncertainty",
    "multi_objective",
    "redundancy",
    "effort",
)


def test_new_core_modules_import_without_yaml_or_ros() -> None:
    code = (
        "import sys\n"
        "for name in ('rclpy', 'yaml', 'matplotlib', 'scipy'):\n"
        "    sys.modules[name] = None\n"
        + "".join(f"import grasp_safety_ros.core.analyses.{m}\n" for m in NEW_MODULES)
        + "from grasp_safety_ros.core.analyses.body_regions import BODY_REGIONS\n"
        "print(len(BODY_REGIONS))\n"
    )
    completed = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False
    )
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.strip() == "12"
