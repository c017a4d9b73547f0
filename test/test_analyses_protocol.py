"""The analyses' protocol (core.analyses.base, registry) and the backend decision
(core.method.backend): an analysis added to the registered tuple runs in ``analyse`` on the
shared terms, its progress counted, its result in the report, the other parts unchanged;
every analysis runs on the evaluator's backend."""

from __future__ import annotations

import gc
import inspect
import itertools
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, is_dataclass, replace
from functools import partial
from typing import Any

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
from grasp_safety_ros.core.analyses.uncertainty import InertiaUncertainty
from grasp_safety_ros.core.method.backend import Backend
from grasp_safety_ros.core.method.ranking import Grasp
from grasp_safety_ros.core.model.trajectory import ObjectTrajectory


@dataclass(frozen=True)
class CountingParts(Parts):
    """``Parts`` with the new analysis's result field."""

    sample_counts: tuple[int, ...] = ()


@dataclass(frozen=True)
class CountingReport(safety_report.SafetyReport):
    """``SafetyReport`` with the new analysis's result field."""

    sample_counts: tuple[int, ...] = ()


@dataclass(frozen=True)
class SampleCounts:
    """A new analysis as docs/development.md describes it: per grasp, the samples it was
    given (the terms' count on a chunk, the evaluation's times on the grasp path), recorded
    in ``seen`` with the path that gave it and whether the scores before it scored it, and
    set as its result (``sample_counts``)."""

    seen: dict[int, tuple[str, int, bool]] = field(default_factory=dict)
    name: str = "sample_counts"
    keeps_terms: bool = False
    optional_terms: tuple[str, ...] = ()

    def wanted(self, options: AnalysisOptions) -> bool:
        return True

    def units(self, grasps: int) -> int:
        return grasps

    def prepare(self, shared: Shared) -> None:
        """Nothing runs ahead."""

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

        return replace(parts, sample_counts=per_grasp(shared, on_chunk, on_grasp))


@pytest.mark.parametrize("backend", ["auto", "python"])
def test_a_registered_analysis_runs_on_the_shared_terms_with_its_progress(
    arm7: RobotModel, backend: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Registered after the others, the new analysis gets every grasp once, in candidate
    order of results: the feasible ones from their chunk's terms on the compiled backend
    (as many samples as their evaluation), every grasp by itself on the Pinocchio one and
    for the infeasible grasp; the scores before it are set; its result reaches the report
    through its fields alone (``analyse`` unchanged); the progress total grows by its units
    and the rest of the report is unchanged bit for bit."""
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
    monkeypatch.setattr(safety_report, "Parts", CountingParts)
    monkeypatch.setattr(safety_report, "SafetyReport", CountingReport)
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
    assert isinstance(report, CountingReport)
    assert report.sample_counts == tuple(len(e.times_s) for e in ranking.evaluations)
    total = len(calls) + len(grasps)
    assert extended == [(k, total) for k in range(1, total + 1)]
    np.testing.assert_array_equal(report.scores, plain.scores)
    for ours, theirs in zip(report.effort, plain.effort, strict=True):
        np.testing.assert_array_equal(ours.joint_torques, theirs.joint_torques)


def test_the_pinocchio_backend_has_no_shared_terms(arm7: RobotModel) -> None:
    """The Pinocchio backend (asked for) has no chain and no shared terms."""
    python = GraspSafetyEvaluator(arm7, EvaluationConfig(backend="python"))
    assert python.backend == Backend(None) and not python.backend.compiled
    with pytest.raises(ValueError, match="no shared terms"):
        python.backend.grasps_terms(arm7, BOX, [pin.SE3.Identity()], [np.zeros((1, 7))])


def _same(a: object, b: object) -> bool:
    """Whether two reports (or parts of them) are equal bit for bit, NaN equal to NaN (the
    fields a dataclass compares: not, e.g., where a RegionAssessment's arrays come from)."""
    if is_dataclass(a) and is_dataclass(b) and type(a) is type(b):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a) if f.compare)
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (np.ndarray, float)) or isinstance(b, (np.ndarray, float)):
        x, y = np.asarray(a), np.asarray(b)
        numeric = x.dtype.kind in "fc" and y.dtype.kind in "fc"
        return x.shape == y.shape and bool(np.array_equal(x, y, equal_nan=numeric))
    return bool(a == b)


@needs_numba
def test_every_analysis_runs_on_the_evaluators_backend(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The analyses take their backend from the evaluator alone: a compiled evaluator whose
    backend is set to Pinocchio's gives, on one ranking, the report of an evaluator asked
    for the python backend bit for bit, every analysis on; with its own (compiled) backend
    some result differs in its rounding, which an analysis deciding for itself would show."""
    seed = random_positions(arm7, np.random.default_rng(18))
    trajectory = reach_trajectory(arm7, seed)
    grasps = grasps_near_identity(3, 19)
    compiled = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1))
    python = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1, backend="python"))
    assert compiled.backend.compiled
    ranking = python.rank(grasps, BOX, trajectory, seed_positions=seed)
    assert any(e.feasible for e in ranking.evaluations)
    options = AnalysisOptions(
        points_in_object_m=np.array([[0.04, 0.06, 0.1], [-0.04, -0.06, -0.1]]),
        uncertainty=InertiaUncertainty(mass_fraction=0.2, num_random_samples=2),
        redundancy=True,
        effort=True,
        whole_arm=True,
    )

    def report(evaluator: GraspSafetyEvaluator) -> safety_report.SafetyReport:
        return safety_report.analyse(evaluator, grasps, BOX, trajectory, options, ranking=ranking)

    reference = report(python)
    assert not _same(report(compiled), reference)
    monkeypatch.setattr(compiled, "backend", Backend(None))
    assert _same(report(compiled), reference)


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


def _ranked(arm7: RobotModel, grasps: int) -> tuple[GraspSafetyEvaluator, list[Grasp], object]:
    """A compiled evaluator, ``grasps`` grasps near the identity (+ an unreachable one), and
    their ranking along one reach (every reachable grasp: the same samples)."""
    seed = random_positions(arm7, np.random.default_rng(18))
    trajectory = reach_trajectory(arm7, seed)
    far = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 5.0])), "unreachable")
    candidates = [*grasps_near_identity(grasps, 19), far]
    evaluator = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1))
    ranking = evaluator.rank(candidates, BOX, trajectory, seed_positions=seed)
    return evaluator, candidates, (trajectory, ranking)


@needs_numba
def test_a_later_chunk_never_overwrites_terms_still_referenced(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With a chunk per grasp and no chunk kept, the terms of chunk 1 do not land in the
    memory of chunk 0's while an analysis still holds those (the memory is reused only once
    nothing refers to it): chunk 0's arrays keep their values."""
    from grasp_safety_ros.core.analyses import base

    evaluator, grasps, (trajectory, ranking) = _ranked(arm7, 3)
    feasible = [e for e in ranking.evaluations if e.feasible]
    assert len(feasible) >= 2 and len({len(e.times_s) for e in feasible}) == 1
    monkeypatch.setattr(base, "TERMS_CHUNK_SAMPLES", len(feasible[0].times_s))
    motions = [evaluator.trajectory_for(g, trajectory) for g in grasps]
    args = (evaluator, grasps, BOX, motions, AnalysisOptions(), ranking.evaluations)
    shared = Shared(*args, ranking.metric, keepers=(), step=lambda: None)
    assert len(shared.chunks) >= 2
    held, _ = shared.terms(0)
    before = [array.copy() for array in held]
    later, _ = shared.terms(1)
    assert not any(np.shares_memory(a, b) for a, b in zip(held, later, strict=True))
    for array, copy in zip(held, before, strict=True):
        np.testing.assert_array_equal(array, copy)


@needs_numba
@pytest.mark.parametrize("chunk_samples", (None, 1))
def test_analyses_run_ahead_on_the_shared_terms_give_their_numbers_bit_for_bit(
    arm7: RobotModel, chunk_samples: int | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Run ahead on the exposed points' chunks of terms (all grasps in one chunk, or one
    grasp per chunk), effort gives the numbers of its one kernel call without terms and the
    whole arm those it gives alone (its own pass over the chunks), bit for bit; so do both
    when no analysis before them reads the terms; the progress is counted in order. With no
    chunk kept for a later reader (TERMS_CACHE_SAMPLES 0), each chunk's terms are computed
    once all the same, and effort's dynamics read them when the exposed points computed them
    (a reader that did not run ahead would compute every chunk again)."""
    from grasp_safety_ros.core.analyses import base
    from grasp_safety_ros.core.analyses import effort as effort_module
    from grasp_safety_ros.core.analyses.effort import evaluate_efforts
    from grasp_safety_ros.core.method import backend

    if chunk_samples is not None:
        monkeypatch.setattr(base, "TERMS_CHUNK_SAMPLES", chunk_samples)
    evaluator, grasps, (trajectory, ranking) = _ranked(arm7, 3)
    motions = [evaluator.trajectory_for(g, trajectory) for g in grasps]
    effort = evaluate_efforts(
        arm7, ranking.evaluations, BOX, grasps, motions, chain=evaluator.backend.chain
    )
    feasible = [k for k, e in enumerate(ranking.evaluations) if e.feasible]
    chunks = base.chunks(feasible, [len(ranking.evaluations[k].times_s) for k in feasible])
    monkeypatch.setattr(base, "TERMS_CACHE_SAMPLES", 0)
    terms_calls: list[int] = []  # the grasps of each terms call
    with_terms: list[bool] = []  # whether each dynamics call was given the terms
    computed, dynamics = backend.grasps_terms, effort_module.joint_dynamics

    def terms_spy(*args: Any, **kwargs: Any) -> Any:
        terms_calls.append(len(args[3]))  # transforms_tip_to_object
        return computed(*args, **kwargs)

    def dynamics_spy(*args: Any, **kwargs: Any) -> Any:
        given = inspect.signature(dynamics).bind(*args, **kwargs).arguments.get("terms")
        with_terms.append(given is not None)
        return dynamics(*args, **kwargs)

    monkeypatch.setattr(backend, "grasps_terms", terms_spy)
    monkeypatch.setattr(effort_module, "joint_dynamics", dynamics_spy)

    def report(options: AnalysisOptions) -> safety_report.SafetyReport:
        calls.clear()
        terms_calls.clear()
        with_terms.clear()
        return safety_report.analyse(
            evaluator,
            grasps,
            BOX,
            trajectory,
            options,
            ranking=ranking,
            progress=lambda *a: calls.append(a),
        )

    calls: list[tuple[int, int]] = []
    whole_arm = report(AnalysisOptions(effort=False, whole_arm=True)).whole_arm
    corners = np.array([[0.04, 0.06, 0.1], [-0.04, -0.06, -0.1]])
    for points in (corners, None):
        ours = report(AnalysisOptions(points_in_object_m=points, effort=True, whole_arm=True))
        assert _same(ours.effort, effort) and _same(ours.whole_arm, whole_arm)
        assert calls == [(k, len(calls)) for k in range(1, len(calls) + 1)]
        assert terms_calls == [len(chunk) for chunk in chunks]  # each chunk once
        assert with_terms and all(given == (points is not None) for given in with_terms)


@needs_numba
@pytest.mark.parametrize("chunk_samples", (None, 1))
def test_no_analysis_reads_an_optional_terms_field_it_did_not_declare(
    arm7: RobotModel, chunk_samples: int | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The analyses read only the optional fields of the terms a wanted analysis declares
    (``Analysis.optional_terms``; the others are left as the memory was, NaN here): with the
    terms' buffers filled with NaN before the kernel, each report is the one on the buffers as
    they come bit for bit, every analysis on (run ahead along the evaluated paths; with
    redundancy, terms of its own) and each reader of the terms with only its own declared
    (all grasps in one chunk, or one grasp per chunk)."""
    from grasp_safety_ros.core.analyses import base
    from grasp_safety_ros.core.method import terms as terms_module

    if chunk_samples is not None:
        monkeypatch.setattr(base, "TERMS_CHUNK_SAMPLES", chunk_samples)
    evaluator, grasps, (trajectory, ranking) = _ranked(arm7, 3)
    points = np.array([[0.04, 0.06, 0.1], [-0.04, -0.06, -0.1]])
    every = AnalysisOptions(
        points_in_object_m=points,
        uncertainty=InertiaUncertainty(mass_fraction=0.2, num_random_samples=2),
        effort=True,
        whole_arm=True,
    )
    requests = (
        every,
        replace(every, redundancy=True),
        AnalysisOptions(points_in_object_m=points, effort=False),
        AnalysisOptions(points_in_object_m=points, effort=True),
        AnalysisOptions(effort=False, whole_arm=True),
        AnalysisOptions(effort=True, whole_arm=True),
    )

    def reports() -> list[safety_report.SafetyReport]:
        return [
            safety_report.analyse(evaluator, grasps, BOX, trajectory, options, ranking=ranking)
            for options in requests
        ]

    expected = reports()
    buffers = terms_module.sample_terms_buffers

    def poisoned(grasps: int, count: int, n: int) -> terms_module.SampleTerms:
        terms = buffers(grasps, count, n)
        for array in terms:
            array.fill(np.nan)
        return terms

    monkeypatch.setattr(terms_module, "sample_terms_buffers", poisoned)
    for ours, theirs, options in zip(reports(), expected, requests, strict=True):
        assert _same(ours, theirs), options


@needs_numba
def test_analyses_on_the_pool_give_the_serial_numbers_bit_for_bit(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On an evaluator with a pool of 2 (``parallel_min_samples`` 1), the kernels of the
    terms, the exposed points and effort are each given the pool (``pool.split_grasps``: a
    range of each call's grasps per thread) and every report is the serial one bit for bit:
    every analysis on, with redundancy (terms along its own paths), effort without terms;
    along a reach and a turn about the object's origin (an exposed point there does not
    translate: its mobility comes back from the points kernel); with the pool's threshold
    above the request, no kernel is given the pool."""
    from grasp_safety_ros.core.method import dynamics, points, terms

    serial, grasps, (reach, _) = _ranked(arm7, 5)
    seed = random_positions(arm7, np.random.default_rng(18))  # _ranked's
    start = reach.transform_object_to_base_start
    turn = ObjectTrajectory(
        start,
        pin.SE3(start.rotation @ pin.exp3(np.array([0.2, -0.1, 0.3])), start.translation),
        1.0,
        0.02,
    )
    pooled = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=2, parallel_min_samples=1))
    large = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=2, parallel_min_samples=10**6))
    splits: list[tuple[str, int, bool]] = []  # module, grasps of the call, pool given
    for module in (terms, points, dynamics):
        split = module.split_grasps

        def spy(executor: Any, count: int, run: Any, split: Any = split, name: str = "") -> None:
            splits.append((name, count, executor is not None))
            split(executor, count, run)

        monkeypatch.setattr(module, "split_grasps", partial(spy, name=module.__name__))
    every = AnalysisOptions(
        points_in_object_m=np.array([[0.0, 0.0, 0.0], [0.04, 0.06, 0.1], [-0.04, -0.06, -0.1]]),
        uncertainty=InertiaUncertainty(mass_fraction=0.2, num_random_samples=2),
        effort=True,
        whole_arm=True,
    )
    requests = (every, replace(every, redundancy=True), AnalysisOptions(effort=True))
    for trajectory, options in itertools.product((reach, turn), requests):
        ranking = serial.rank(grasps, BOX, trajectory, seed_positions=seed)
        reports, given = [], []
        for evaluator in (serial, pooled, large):
            splits.clear()
            reports.append(
                safety_report.analyse(evaluator, grasps, BOX, trajectory, options, ranking=ranking)
            )
            given.append({(name, count >= 2, pool) for name, count, pool in splits})
        modules = {name for name, _, _ in given[0]}
        assert given[0] == given[2] == {(name, True, False) for name in modules}, options
        assert given[1] == {(name, True, True) for name in modules}, options
        assert _same(reports[1], reports[0]) and _same(reports[2], reports[0]), options
        if trajectory is turn and options.points_in_object_m is not None:
            still = [e.direction_is_worst_case for e in reports[0].exposed if e.feasible]
            assert len(still) >= 2 and all(s[:, 0].all() and not s[:, 1:].any() for s in still)
    assert modules == {dynamics.__name__}  # the last: effort alone, without terms


class AbandonedError(Exception):
    """Raised by a progress callback to abandon a request."""


@needs_numba
@pytest.mark.parametrize("workers", (1, 2))
def test_an_abandoned_request_frees_its_terms_at_once(arm7: RobotModel, workers: int) -> None:
    """A request abandoned mid-way (its progress raises after the first grasp, the whole arm
    and effort registered to run ahead: their chunk calls refer to the Shared) leaves no
    Shared alive and no reference to the kept terms' memory, without a garbage collection:
    the thread's next request reuses the memory at once; so does one whose kernels ran on a
    pool of 2."""
    from grasp_safety_ros.core.method import terms as terms_module

    evaluator, grasps, (trajectory, ranking) = _ranked(arm7, 3)
    if workers > 1:
        config = EvaluationConfig(workers=workers, parallel_min_samples=1)
        evaluator = GraspSafetyEvaluator(arm7, config)
    options = AnalysisOptions(
        points_in_object_m=np.array([[0.04, 0.06, 0.1]]), effort=True, whole_arm=True
    )

    def abandon(done: int, total: int) -> None:
        raise AbandonedError

    gc.collect()
    gc.disable()
    try:
        try:
            safety_report.analyse(
                evaluator, grasps, BOX, trajectory, options, ranking=ranking, progress=abandon
            )
        except AbandonedError:
            pass
        alive = [type(o) for o in gc.get_objects() if isinstance(o, Shared)]
        blocks = terms_module._BLOCKS.blocks  # unreferenced: the list's and the call's only
        referenced = [k for k in range(len(blocks)) if sys.getrefcount(blocks[k]) != 2]
    finally:
        gc.enable()
    assert alive == [] and blocks and referenced == []
