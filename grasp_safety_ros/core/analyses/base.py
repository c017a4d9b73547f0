"""The analyses of ``safety_report.analyse``: one protocol, and the values they share.

An ``Analysis`` has a ``name``, says whether the options want it (``wanted``) and how many
units of progress it reports (``units``), and ``run``s on the request's ``Shared`` values (the
grasps, their evaluations and motions, the backend, the per-sample terms chunk by chunk, the
augmented models) and the ``Parts`` earlier analyses set, returning the parts with its own
set. ``analyse`` loops over the registered tuple (``registry.ANALYSES``) in order, as mink's
``solve_ik`` loops over its tasks; it never learns an analysis's name.

An analysis per grasp combines its chunks with ``per_grasp``: its chunk call on each chunk of
feasible grasps (compiled backend: on the chunk's shared terms), its grasp call on every
other grasp (infeasible, or the Pinocchio backend), one result per grasp in candidate order.
A chunk call that needs nothing from the analyses before it can run ahead (``prepare``,
``Shared.run_ahead``): on each chunk's terms as soon as the first reader computes them, so the
chunks are computed once, into one reused buffer, instead of kept for a later reader.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Protocol, TypeVar

import numpy as np
import pinocchio as pin

from ..method.backend import Backend
from ..method.effective_mass import augmented_model
from ..method.pool import executor_for
from ..method.ranking import Grasp, GraspEvaluation, GraspSafetyEvaluator
from ..method.terms import OPTIONAL_TERMS, SampleTerms
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import Trajectory
from .analysis_options import AnalysisOptions
from .effort import EffortEvaluation
from .exposed_points import ExposedPointsEvaluation
from .iso15066 import PowerForceLimitAssessment
from .redundancy import RedundancyResolution
from .uncertainty import UncertaintyAnalysis
from .whole_arm import ArmSites, WholeArmEvaluation

TERMS_CHUNK_SAMPLES = 25_000
"""The shared terms are computed for consecutive chunks of feasible grasps of at most this
many samples in all (about 50 MB for a 7-joint arm), so that a request's progress is reported
(and it can be abandoned) chunk by chunk."""

TERMS_CACHE_SAMPLES = 250_000
"""Chunks of terms are kept for the next analysis while those kept hold at most this many
samples (about 500 MB for a 7-joint arm); beyond it the oldest is dropped (then computed
again if an analysis needs it)."""

Result = TypeVar("Result")
ChunkCall = Callable[[int, Sequence[int]], Sequence[tuple[int, Result]]]
"""``per_grasp``'s call on chunk c (its grasps' indices): (grasp, result) pairs."""


@dataclass(frozen=True)
class Parts:
    """The analyses' results so far, per grasp in candidate order; each analysis sets its
    own. ``analyse`` copies every field into ``SafetyReport``'s field of the same name, all
    but those marked ``metadata={"report": False}`` (``report_fields``).

    Attributes:
        scores: Safety score per grasp (the metric point's, with redundancy when on); NaN
            for infeasible grasps.
        series: Per feasible grasp, the metric point's (speeds [m/s], effective masses [kg])
            per sample, which the scores aggregate and ISO/TS 15066 assesses.
        safety_order: Feasible grasps by ``scores``, safest first.
    """

    exposed: tuple[ExposedPointsEvaluation, ...] = ()
    redundancy: tuple[RedundancyResolution, ...] = ()
    scores: np.ndarray = field(default_factory=lambda: np.empty(0))
    series: Mapping[int, tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict, metadata={"report": False}
    )
    safety_order: tuple[int, ...] = ()
    iso: tuple[PowerForceLimitAssessment, ...] = ()
    uncertainty: UncertaintyAnalysis | None = None
    effort: tuple[EffortEvaluation, ...] = ()
    whole_arm: tuple[WholeArmEvaluation, ...] = ()
    arm_sites: ArmSites | None = None

    def report_fields(self) -> dict[str, Any]:
        """The fields ``analyse`` copies into the ``SafetyReport``, by name."""
        return {
            f.name: getattr(self, f.name) for f in fields(self) if f.metadata.get("report", True)
        }

    def resolved_paths(self) -> list[np.ndarray | None] | None:
        """Per grasp, the redundancy resolution's joint path where it applied (else None);
        None when redundancy did not run (every analysis then reads the evaluated paths)."""
        if not self.redundancy:
            return None
        return [r.joint_positions if r.applied else None for r in self.redundancy]


class Analysis(Protocol):
    """One analysis of ``analyse``: adding one is its module in core/analyses, a class like
    those of ``registry``, its place in ``registry.ANALYSES`` and its result field in
    ``Parts`` and ``SafetyReport`` (docs/development.md, "Adding an analysis")."""

    @property
    def name(self) -> str:
        """What it computes (the ``Parts`` field it sets)."""
        ...

    @property
    def keeps_terms(self) -> bool:
        """Whether it reads the shared terms of chunks an earlier analysis read (they are
        then kept, within TERMS_CACHE_SAMPLES, unless it runs ahead on them)."""
        ...

    @property
    def optional_terms(self) -> tuple[str, ...]:
        """The optional fields of the terms it reads (``method.terms.OPTIONAL_TERMS``:
        computed only when a wanted analysis reads them)."""
        ...

    def wanted(self, options: AnalysisOptions) -> bool:
        """Whether ``options`` ask for it."""
        ...

    def units(self, grasps: int) -> int:
        """The units of progress it reports (``Shared.step``) for ``grasps`` candidates."""
        ...

    def prepare(self, shared: Shared) -> None:
        """Before any analysis runs: register the chunk call it can run ahead
        (``Shared.run_ahead``), if any."""
        ...

    def run(self, shared: Shared, parts: Parts) -> Parts:
        """``parts`` with its own result set."""
        ...


class Shared:
    """What every analysis of one request shares (computed once, on first use).

    Attributes:
        evaluator, robot, grasps, object_inertia, options: The request's.
        evaluations: The ranking's evaluations (one per grasp, candidate order).
        metric: The ranking's score aggregate.
        motions: Each grasp's motion (``GraspSafetyEvaluator.trajectory_for``).
        backend: Compiled or Pinocchio, the evaluator's.
        chunks: The feasible grasps in consecutive chunks of at most TERMS_CHUNK_SAMPLES
            samples (compiled backend; none on the Pinocchio one).
        executor: The evaluator's thread pool when the feasible samples are enough to share
            out (``pool.executor_for``, as the ranking's; compiled backend): the kernels of
            the terms, the exposed points and effort then run on a range of each call's
            grasps per thread (``pool.split_grasps``), the same bits; None: serial.

    ``keepers``: the names of the wanted analyses that read chunks an earlier one read
    (``Analysis.keeps_terms``); ``optional``: the optional fields of the terms to compute
    (those the wanted analyses read).
    """

    def __init__(
        self,
        evaluator: GraspSafetyEvaluator,
        grasps: Sequence[Grasp],
        object_inertia: ObjectInertia,
        motions: Sequence[Trajectory],
        options: AnalysisOptions,
        evaluations: Sequence[GraspEvaluation],
        metric: str,
        keepers: Collection[str],
        step: Callable[[], None],
        optional: Collection[str] = OPTIONAL_TERMS,
    ) -> None:
        self.evaluator = evaluator
        self.robot: RobotModel = evaluator.robot
        self.grasps, self.object_inertia, self.options = grasps, object_inertia, options
        self.evaluations, self.metric, self.motions = evaluations, metric, motions
        self.backend: Backend = evaluator.backend
        self.step = step
        feasible = [k for k, e in enumerate(evaluations) if e.feasible]
        samples = [len(evaluations[k].times_s) for k in feasible]
        self.chunks = chunks(feasible, samples) if self.backend.compiled else []
        self.executor = executor_for(evaluator, sum(samples)) if self.backend.compiled else None
        self._keepers, self._optional = set(keepers), tuple(optional)
        self._cached: dict[int, tuple[SampleTerms, np.ndarray]] = {}
        self._models: dict[int, pin.Model] = {}
        self._ahead: dict[str, ChunkCall[Any]] = {}  # registered, not yet taken
        self._ran_ahead: set[str] = set()  # every name registered
        self._ahead_results: dict[str, dict[int, Sequence[tuple[int, Any]]]] = {}  # by chunk

    def terms(self, c: int) -> tuple[SampleTerms, np.ndarray]:
        """The terms of the grasps of ``chunks[c]`` (axis 0 in its order) and their counts,
        kept while the kept chunks stay within TERMS_CACHE_SAMPLES samples when a later
        analysis reads them again (one of ``keepers`` that does not run ahead; else only the
        last chunk is kept, and the memory of the others is reused once no array refers to
        it, ``method.terms``). The calls registered by ``run_ahead`` run on a chunk right
        after its terms."""
        keep = not self._keepers.issubset(self._ran_ahead)
        cached, evaluations, chunk = self._cached, self.evaluations, self.chunks[c]
        if c not in cached:
            while cached and (
                not keep
                or sum(int(n.sum()) for _, n in cached.values())
                + sum(len(evaluations[k].times_s) for k in chunk)
                > TERMS_CACHE_SAMPLES
            ):
                del cached[next(iter(cached))]  # the oldest
            cached[c] = self.path_terms(chunk, [evaluations[k].joint_positions for k in chunk])
            for name, on_chunk in self._ahead.items():
                results = self._ahead_results[name]
                if c not in results:  # (a chunk computed again: its results stand)
                    results[c] = on_chunk(c, chunk)
        return cached[c]

    @property
    def can_run_ahead(self) -> bool:
        """Whether chunk calls can run ahead: on the compiled backend's shared terms along
        the evaluated paths (without redundancy, whose paths are known only once it ran)."""
        return self.backend.compiled and not self.options.redundancy

    def run_ahead(self, name: str, on_chunk: ChunkCall[Any]) -> None:
        """Run ``on_chunk(c, chunk)`` (``per_grasp``'s chunk call, reading ``terms(c)``) on
        each chunk right after its terms are computed; ``take_ahead(name)`` gives the
        results."""
        self._ahead[name] = on_chunk
        self._ran_ahead.add(name)
        self._ahead_results[name] = {}

    def take_ahead(self, name: str) -> ChunkCall[Any] | None:
        """Ends ``run_ahead(name, ...)``. If its call ran on a chunk: the chunk call of
        ``per_grasp`` that returns its results (on a chunk no analysis read, computing the
        terms first); else (no analysis read the terms, or nothing registered) None."""
        on_chunk, results = self._ahead.pop(name, None), self._ahead_results.pop(name, {})
        if on_chunk is None or not results:
            return None

        def ahead_results(c: int, chunk: Sequence[int]) -> Sequence[tuple[int, Any]]:
            return results[c] if c in results else on_chunk(c, chunk)

        return ahead_results

    def release(self) -> None:
        """Drop the chunk calls registered to run ahead (they refer to this Shared: a cycle
        that only a collection would break), their results and the kept chunks of terms, so
        that an abandoned request frees its terms' memory at once for the thread's next one
        (``analyse`` calls it last, whether the analyses returned or raised)."""
        self._ahead.clear()
        self._ahead_results.clear()
        self._cached.clear()

    def path_terms(
        self, indices: Sequence[int], paths: Sequence[np.ndarray]
    ) -> tuple[SampleTerms, np.ndarray]:
        """The terms of grasps ``indices`` along joint ``paths`` ((N, n) each), uncached
        (compiled backend)."""
        transforms = [self.grasps[k].transform_tip_to_object for k in indices]
        return self.backend.grasps_terms(
            self.robot, self.object_inertia, transforms, paths, self._optional, self.executor
        )

    def model_of(self, k: int) -> pin.Model | None:
        """Grasp k's ``augmented_model`` (built once), None when infeasible."""
        if not self.evaluations[k].feasible:
            return None
        if k not in self._models:
            transform = self.grasps[k].transform_tip_to_object
            self._models[k] = augmented_model(self.robot, self.object_inertia, transform)
        return self._models[k]


def per_grasp(
    shared: Shared,
    on_chunk: ChunkCall[Result],
    on_grasp: Callable[[int], Result],
) -> tuple[Result, ...]:
    """One result per grasp in candidate order, ``shared.step()`` after each: ``on_chunk(c,
    chunk)`` gives (grasp, result) pairs for the grasps of each chunk (compiled backend),
    ``on_grasp(k)`` the result of every grasp left (infeasible, or the Pinocchio backend)."""
    results: dict[int, Result] = {}
    for c, chunk in enumerate(shared.chunks):
        for k, result in on_chunk(c, chunk):
            results[k] = result
            shared.step()
    for k in range(len(shared.grasps)):
        if k not in results:
            results[k] = on_grasp(k)
            shared.step()
    return tuple(results[k] for k in range(len(shared.grasps)))


def chunks(grasps: Sequence[int], samples: Sequence[int]) -> list[list[int]]:
    """``grasps`` in consecutive chunks of at most TERMS_CHUNK_SAMPLES samples (``samples``
    per grasp; a longer grasp alone)."""
    out: list[list[int]] = []
    total = 0
    for k, count in zip(grasps, samples, strict=True):
        if not out or total + count > TERMS_CHUNK_SAMPLES:
            out.append([])
            total = 0
        out[-1].append(k)
        total += count
    return out
