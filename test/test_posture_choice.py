"""Posture selection's choice (core.method.posture._choose) over arbitrary candidates: the
structural half of "never worse than the single IK" and of "the early stop changes no
choice", without any IK (the kernel's half, that a stopped posture really scores above one
already found, is test_posture.py's); and which restarts' start postures are followed
(``_new_start_postures``: the duplicates of postures already found are not)."""

from __future__ import annotations

import math
import pickle
from dataclasses import replace
from functools import partial

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grasp_safety_ros.core.method.posture import PostureConfig, _choose, _new_start_postures
from grasp_safety_ros.core.method.results import FollowedPosture, GraspEvaluation

SCORES = st.one_of(
    st.sampled_from([1.0, 1.5, 2.0]),  # ties
    st.floats(0.01, 100.0, allow_nan=False),
)
OUTCOMES = st.one_of(st.none(), st.just(math.nan), SCORES)  # stopped, infeasible, a score


def _evaluation(k: int, score: float) -> GraspEvaluation:
    """Candidate k: feasible with ``score`` unless NaN; its start posture is (k, k)."""
    feasible = not math.isnan(score)
    samples = 3
    return GraspEvaluation(
        index=0,
        name="g",
        feasible=feasible,
        reason="" if feasible else f"candidate {k} infeasible",
        score=score,
        times_s=np.arange(samples, dtype=float),
        joint_positions=np.full((samples, 2), float(k)),
        directions_in_base=np.tile([1.0, 0.0, 0.0], (samples, 1)),
        effective_mass_kg=np.full(samples, score),
        direction_is_worst_case=np.zeros(samples, dtype=bool),
        tip_speed_m_s=np.ones(samples),
        ik_iterations=np.zeros(samples, dtype=np.int64),
    )


def _choice(single: float, outcomes: list[float | None]):
    followed = [
        None if s is None else FollowedPosture.of(_evaluation(k + 1, s))
        for k, s in enumerate(outcomes)
    ]
    config = PostureConfig(restarts=len(outcomes))
    return _choose(
        None,  # type: ignore[arg-type]  # used by a criterion only
        None,  # type: ignore[arg-type]
        _evaluation(0, single),
        followed,
        (config, len(outcomes) + 1, True),
        None,
    )


@settings(max_examples=400, deadline=None)
@given(st.one_of(st.just(math.nan), SCORES), st.lists(OUTCOMES, max_size=10))
def test_the_kept_posture_is_the_first_lowest_and_never_worse_than_the_single_ik(
    single: float, outcomes: list[float | None]
) -> None:
    """Whatever the restarts give, the kept score is the lowest feasible one, the first of
    equal ones (so the single IK on a tie), hence never above the single IK's when that one
    is feasible; the record counts each candidate once."""
    kept, record = _choice(single, outcomes)
    scores = [single, *(math.nan if s is None else s for s in outcomes)]
    feasible = [k for k, s in enumerate(scores) if not math.isnan(s)]
    assert record.postures_tried == len(scores)
    assert record.postures_stopped == outcomes.count(None)
    assert record.postures_feasible == len(feasible)
    if not feasible:
        assert not kept.feasible and record.selected == -1 and math.isnan(record.score)
        return
    best = min(feasible, key=lambda k: (scores[k], k))
    assert record.selected == best
    assert kept.score == record.score == scores[best]
    assert np.array_equal(record.start_positions, [best, best])
    assert record.score_range == (scores[best], max(scores[k] for k in feasible))
    if not math.isnan(single):
        assert kept.score <= single
        assert record.score_single_ik == single
        assert (record.selected == 0) == (single <= min(scores[k] for k in feasible))


@settings(max_examples=400, deadline=None)
@given(
    st.one_of(st.just(math.nan), SCORES),
    st.lists(SCORES, max_size=10),
    st.lists(st.booleans(), min_size=10, max_size=10),
)
def test_stopping_postures_that_score_above_one_found_changes_no_choice(
    single: float, scores: list[float], stop: list[bool]
) -> None:
    """The early stop's rule: a restart posture may be stopped (None) only if its score is
    strictly above a feasible posture's, i.e. above the lowest score m of all. Stopping any
    such subset keeps the same evaluation and record bit for bit, but for the counts (each
    moves from feasible to stopped) and the top of the score range."""
    lowest = min([single, *scores]) if not math.isnan(single) else min(scores, default=0.0)
    stopped = [None if cut and s > lowest else s for s, cut in zip(scores, stop, strict=False)]
    kept, record = _choice(single, list(scores))
    kept_early, record_early = _choice(single, stopped)
    assert pickle.dumps(kept_early) == pickle.dumps(kept)
    moved = stopped.count(None)
    assert record_early.postures_stopped == moved
    assert record_early.postures_feasible == record.postures_feasible - moved
    assert record_early.score_range[1] <= record.score_range[1] or not record.postures_feasible
    counts = ("postures_stopped", "postures_feasible", "score_range")
    unchanged = replace(record_early, **{name: getattr(record, name) for name in counts})
    assert pickle.dumps(unchanged) == pickle.dumps(record)


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.just(math.nan), SCORES), st.lists(OUTCOMES, max_size=10))
def test_only_the_kept_restart_posture_is_built(
    single: float, outcomes: list[float | None]
) -> None:
    """Selecting by the score, ``_choose`` reads the followed postures' feasibility and score
    and builds the GraspEvaluation of the kept one only (none when the single IK is kept or
    nothing is feasible): the others' were posture selection's largest Python cost."""
    built: list[int] = []

    def build(k: int, score: float) -> GraspEvaluation:
        built.append(k)
        return _evaluation(k, score)

    followed = [
        None if s is None else FollowedPosture(not math.isnan(s), s, partial(build, k + 1, s))
        for k, s in enumerate(outcomes)
    ]
    config = PostureConfig(restarts=len(outcomes))
    case = (config, len(outcomes) + 1, True)
    single_ik = _evaluation(0, single)
    kept, record = _choose(None, None, single_ik, followed, case, None)  # type: ignore[arg-type]
    assert built == ([record.selected] if record.selected > 0 else [])
    assert kept.score == record.score or record.selected == -1


def _followed_one_at_a_time(robot, single_iks, q, converged, tolerance):
    """The rule of ``_new_start_postures``, one posture at a time: a converged restart's
    posture is followed unless its largest joint difference to the single IK's (when
    feasible) or to a posture followed before it is below ``tolerance``."""
    starts = []
    for g, single_ik in enumerate(single_iks):
        found = [np.array(single_ik.joint_positions[0])] if single_ik.feasible else []
        new = []
        for r in range(q.shape[1]):
            if not converged[g, r]:
                continue
            positions = robot.positions_from_q(q[g, r])
            if any(np.max(np.abs(f - positions)) < tolerance for f in found):
                continue
            found.append(positions)
            new.append(positions)
        starts.append(new)
    return starts


@pytest.mark.parametrize("arm", ["arm7", "continuous_arm"])
def test_the_restarts_followed_are_those_not_within_the_tolerance_of_one_found(
    arm: str, request: pytest.FixtureRequest
) -> None:
    """Random restarts with exact and near duplicates (half the tolerance away: duplicates;
    twice: not), unconverged rows holding garbage (inf, NaN) and infeasible single IKs: the
    postures followed, bit for bit and in order, are those of the one-at-a-time rule; on an
    arm with continuous joints (q holds cos and sin) too."""
    robot = request.getfixturevalue(arm)
    rng = np.random.default_rng(7)
    tolerance = 1e-3
    n = robot.num_joints
    for _ in range(50):
        grasps, restarts = int(rng.integers(1, 6)), int(rng.integers(0, 9))
        positions = rng.uniform(-2.0, 2.0, (grasps, restarts + 1, n))
        for g in range(grasps):  # restart r repeats an earlier posture, or the single IK's
            for r in range(1, restarts + 1):
                kind = rng.integers(0, 4)
                if kind < 3:
                    step = (0.0, 0.5 * tolerance, 2.0 * tolerance)[kind]
                    positions[g, r] = positions[g, rng.integers(0, r)]
                    positions[g, r, rng.integers(0, n)] += step * rng.choice([-1.0, 1.0])
        q = np.array([[robot.q_from_positions(p) for p in row[1:]] for row in positions])
        q = q.reshape(grasps, restarts, robot.model.nq)
        converged = rng.uniform(size=(grasps, restarts)) < 0.8
        q[~converged] = rng.choice([np.inf, np.nan, 1e300])
        single_iks = [
            _evaluation(0, 1.0 if rng.uniform() < 0.7 else math.nan) for _ in range(grasps)
        ]
        single_iks = [
            replace(e, joint_positions=np.tile(positions[g, 0], (3, 1)))
            for g, e in enumerate(single_iks)
        ]
        got = _new_start_postures(robot, single_iks, q, converged, tolerance)
        expected = _followed_one_at_a_time(robot, single_iks, q, converged, tolerance)
        assert [len(s) for s in got] == [len(s) for s in expected]
        for kept, reference in zip(got, expected, strict=True):
            for a, b in zip(kept, reference, strict=True):
                assert a.tobytes() == b.tobytes()
