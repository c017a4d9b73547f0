"""The analyses' protocol (core.analyses.base, registry) and the backend decision
(core.method.backend): an analysis added to the registered tuple runs in ``analyse`` on the
shared terms, its progress counted, the other parts unchanged; the backend is decided once."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_positions
from fast_paths import BOX, grasps_near_identity, needs_numba, reach_trajectory

from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator, RobotModel
from grasp_safety_ros.core.analyses import safety_report
from grasp_safety_ros.core.analyses.analysis_options import AnalysisOptions
from grasp_safety_ros.core.analyses.base import Parts, Shared, per_grasp
from grasp_safety_ros.core.analyses.registry import ANALYSES
from grasp_safety_ros.core.method.backend import Backend
from grasp_safety_ros.core.method.ranking import Grasp


@dataclass(frozen=True)
class SampleCounts:
    """A new analysis as docs/development.md describes it: per grasp, the samples it was
    given (the terms' count on a chunk, the evaluation's times on the grasp path), recorded
    in ``seen`` with the path that gave it and whether the scores before it scored it."""

    seen: dict[int, tuple[str, int, bool]] = field(default_factory=dict)
    name: str = "sample_counts"
    keeps_terms: bool = False

    def wanted(self, options: AnalysisOptions) -> bool:
        return True

    def units(self, grasps: int) -> int:
        return grasps

    def run(self, shared: Shared, parts: Parts) -> Parts:
        def on_chunk(c: int, chunk: Sequence[int]) -> list[tuple[int, int]]:
            _, counts = shared.terms(c)
            for k, count in zip(chunk, counts, strict=True):
                self.seen[k] = ("chunk", int(count), bool(np.isfinite(parts.scores[k])))
            return [(k, int(count)) for k, count in zip(chunk, counts, strict=True)]

        def on_grasp(k: int) -> int:
            count = len(shared.evaluations[k].times_s)
            self.seen[k] = ("grasp", count, bool(np.isfinite(parts.scores[k])))
            return count

        per_grasp(shared, on_chunk, on_grasp)
        return parts


@pytest.mark.parametrize("backend", ["auto", "python"])
def test_a_registered_analysis_runs_on_the_shared_terms_with_its_progress(
    arm7: RobotModel, backend: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Registered after the others, the new analysis gets every grasp once, in candidate
    order of results: the feasible ones from their chunk's terms on the compiled backend
    (as many samples as their evaluation), every grasp by itself on the Pinocchio one and
    for the infeasible grasp; the scores before it are set; the progress total grows by its
    units and the rest of the report is unchanged bit for bit."""
    if backend == "auto" and not Backend.for_robot(arm7).compiled:
        pytest.skip("numba is not installed")
    seed = random_positions(arm7, np.random.default_rng(18))
    trajectory = reach_trajectory(arm7, seed)
    far = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 5.0])), "unreachable")
    grasps = [*grasps_near_identity(3, 19), far]
    evaluator = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1, backend=backend))
    ranking = evaluator.rank(grasps, BOX, trajectory, seed_positions=seed)
    options = AnalysisOptions(effort=True)
    calls: list[tuple[int, int]] = []
    plain = safety_report.analyse(
        evaluator,
        grasps,
        BOX,
        trajectory,
        options,
        ranking=ranking,
        progress=lambda *a: calls.append(a),
    )
    counting = SampleCounts()
    monkeypatch.setattr(safety_report, "ANALYSES", (*ANALYSES, counting))
    extended: list[tuple[int, int]] = []
    report = safety_report.analyse(
        evaluator,
        grasps,
        BOX,
        trajectory,
        options,
        ranking=ranking,
        progress=lambda *a: extended.append(a),
    )
    feasible = [e.feasible for e in ranking.evaluations]
    assert sum(feasible) >= 2 and not feasible[-1]
    compiled = evaluator.backend.compiled
    assert counting.seen == {
        k: (
            "chunk" if compiled and feasible[k] else "grasp",
            len(e.times_s),
            feasible[k],  # scored before it
        )
        for k, e in enumerate(ranking.evaluations)
    }
    total = len(calls) + len(grasps)
    assert extended == [(k, total) for k in range(1, total + 1)]
    np.testing.assert_array_equal(report.scores, plain.scores)
    for ours, theirs in zip(report.effort, plain.effort, strict=True):
        np.testing.assert_array_equal(ours.joint_torques, theirs.joint_torques)


def test_the_backend_is_decided_once_per_evaluator(arm7: RobotModel) -> None:
    """The Pinocchio backend (asked for) has no chain and no shared terms; the evaluator's
    backend is its IK's decision, which the analyses read."""
    python = GraspSafetyEvaluator(arm7, EvaluationConfig(backend="python"))
    assert python.backend == Backend(None) and not python.backend.compiled
    with pytest.raises(ValueError, match="no shared terms"):
        python.backend.grasps_terms(arm7, BOX, [pin.SE3.Identity()], [np.zeros((1, 7))])
    auto = GraspSafetyEvaluator(arm7)
    assert auto.backend.compiled == auto.ik.compiled
    assert auto.backend.chain is (auto.ik.chain if auto.ik.compiled else None)


@needs_numba
def test_the_compiled_backend_gives_the_terms_of_its_chain(arm7: RobotModel) -> None:
    """Backend.grasps_terms are terms.grasps_terms on the backend's chain, bit for bit."""
    from grasp_safety_ros.core.method.terms import grasps_terms

    backend = Backend.for_robot(arm7)
    assert backend.chain is not None
    path = np.array([random_positions(arm7, np.random.default_rng(k)) for k in range(3)])
    ours, counts = backend.grasps_terms(arm7, BOX, [pin.SE3.Identity()], [path])
    theirs, _ = grasps_terms(arm7, backend.chain, BOX, [pin.SE3.Identity()], [path])
    assert list(counts) == [3]
    for a, b in zip(ours, theirs, strict=True):
        np.testing.assert_array_equal(a, b)
