"""A worker pool that spreads the grasps of a large ``rank`` request over threads or processes.

Threads when the compiled kernels are in use (they run without the GIL), else processes; the
results come back in input order and each grasp is computed by the same code as in the serial
path, so they equal the serial ones bit for bit. The pool knows the evaluator only by its
type PooledEvaluator (``config``, ``robot``, ``backend``: what GraspSafetyEvaluator has,
which imports this module; a process worker rebuilds it as ``type(evaluator)(robot, config)``)
and runs the callable it is given on each job. ``split_grasps`` shares one kernel call's grasps
out over a thread pool's threads and the caller (the analyses' kernels on the shared terms).
"""

from __future__ import annotations

import math
import multiprocessing
import os
import threading
import weakref
from collections import deque
from collections.abc import Callable, Generator, Iterator, Sequence
from concurrent.futures import (
    Executor,
    Future,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
    wait,
)
from dataclasses import replace
from functools import partial
from itertools import islice, pairwise
from typing import Any, ClassVar, Protocol, TypeVar

from ..model.robot import RobotModel

Job = tuple[Any, ...]
"""Arguments of one call of the ``evaluate`` callable given to ``evaluate_jobs``."""

Result = TypeVar("Result")


class PoolConfig(Protocol):
    """What the pool reads of an evaluator's configuration (a frozen dataclass:
    ranking.EvaluationConfig)."""

    __dataclass_fields__: ClassVar[dict[str, Any]]

    @property
    def workers(self) -> int: ...

    @property
    def parallel_min_samples(self) -> int: ...


class PoolBackend(Protocol):
    """What the pool reads of an evaluator's backend (backend.Backend)."""

    @property
    def compiled(self) -> bool: ...


class PooledEvaluator(Protocol):
    """What the pool needs of an evaluator (ranking.GraspSafetyEvaluator)."""

    @property
    def config(self) -> PoolConfig: ...

    @property
    def robot(self) -> RobotModel: ...

    @property
    def backend(self) -> PoolBackend: ...


def default_workers() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def executor_for(evaluator: PooledEvaluator, total_samples: int) -> Executor | None:
    """The evaluator's worker pool when a request of ``total_samples`` (grasps x samples) is
    large enough to share out, else None (serial).

    The pool is made on first use and kept on the evaluator for later requests: threads when
    the compiled kernels are in use (they run without the GIL), else processes, each with its
    own copy of the evaluator ("fork" from a single-threaded process; "forkserver" otherwise,
    as forking a process that runs other threads is unsafe: then, as with "spawn", the main
    module must be importable without side effects, i.e. guarded by ``if __name__ ==
    "__main__":``).
    """
    config = evaluator.config
    workers = config.workers or default_workers()
    if workers <= 1 or total_samples < max(config.parallel_min_samples, 1):
        return None
    pool: Executor | None = getattr(evaluator, "_grasp_pool", None)
    if pool is None:
        if evaluator.backend.compiled:
            pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="grasp_safety")
        else:
            pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=multiprocessing.get_context(
                    "fork" if threading.active_count() == 1 else "forkserver"
                ),
                initializer=_init_worker,
                initargs=(type(evaluator), evaluator.robot, replace(config, workers=1)),
            )
        setattr(evaluator, "_grasp_pool", pool)  # noqa: B010 - a cache, not of its type
        weakref.finalize(evaluator, pool.shutdown, False)
    return pool


def _workers(executor: Executor) -> int:
    """The threads or processes of ``executor`` (the standard pools' ``_max_workers``; 2 for
    another executor)."""
    return max(1, getattr(executor, "_max_workers", 2))


def job_ranges(executor: Executor | None, grasps: int, largest: int) -> list[tuple[int, int]]:
    """Consecutive ``(start, stop)`` ranges that cover ``range(grasps)``, one per job of a
    request of ``grasps``: serial (None), batches of ``largest`` (one kernel call's).

    On a pool, a multiple of its workers in number (every worker gets a job), of at most
    ``largest`` grasps, sizes differing by at most one; when that is more than one job per
    worker, the last job of each worker is cut in two: the workers take the jobs in order as
    they free up, so short jobs at the end let them finish close together however the
    grasps' costs vary (posture selection on the node's 2 workers, 100 grasps: 10 jobs of
    12-13 and 6-7 grasps, docs/performance_pipeline.md)."""
    if executor is None:
        return [(start, min(start + largest, grasps)) for start in range(0, grasps, largest)]
    workers = _workers(executor)
    jobs = min(grasps, workers * math.ceil(grasps / (largest * workers)))
    bounds = {grasps * k // jobs for k in range(jobs + 1)} if jobs else set()
    if jobs > workers:
        ends = sorted(bounds)[jobs - workers :]
        bounds |= {start + (stop - start + 1) // 2 for start, stop in pairwise(ends)}
    return list(pairwise(sorted(bounds)))


def split_grasps(executor: Executor | None, grasps: int, run: Callable[[int, int], None]) -> None:
    """``run(start, stop)`` on consecutive ranges of ``range(grasps)`` that cover it: one per
    worker of a thread pool (``executor_for``), the first on the calling thread and each other
    on the pool, unless it has not started when the caller's is done (the caller then runs it:
    a pool busy with other work, or whose threads are the callers, does not keep it waiting);
    else (None: serial; a process pool) ``run(0, grasps)`` on the calling thread.

    ``run`` must write only its range's part of its outputs, with scratch of its own (e.g. its
    thread's ``kernels.ik.thread_workspace``), so that every grasp's numbers are the serial
    ones bit for bit. Returns when no range runs any longer; the first exception is raised.
    """
    workers = 1 if executor is None else _workers(executor)
    if not isinstance(executor, ThreadPoolExecutor) or workers == 1 or grasps < 2:
        run(0, grasps)
        return
    size = math.ceil(grasps / min(workers, grasps))
    ranges = [(start, min(start + size, grasps)) for start in range(0, grasps, size)]
    # a range not started is taken back with its slot emptied: the pool's queue, which keeps
    # a cancelled task until a thread takes it, then holds no reference to the outputs
    slots: list[list[Any]] = [[run, *bounds] for bounds in ranges[1:]]
    futures: list[Future[None]] = []
    try:
        futures.extend(executor.submit(_run_slot, slot) for slot in slots)
    except RuntimeError:  # the pool is shut down (the interpreter exits): the caller runs the rest
        pass
    try:
        run(*ranges[0])
        for bounds in ranges[1 + len(futures) :]:
            run(*bounds)
        submitted = zip(futures, slots, ranges[1:], strict=False)  # (all, unless shut down)
        for future, slot, bounds in submitted:  # first what has not started
            if future.cancel():
                slot.clear()
                run(*bounds)
        for future in futures:  # then wait for what runs
            if not future.cancelled():
                future.result()
    finally:  # on an exception too: no range still writes once this returns
        for future, slot in zip(futures, slots, strict=False):
            if future.cancel():
                slot.clear()
        wait([future for future in futures if not future.cancelled()])


def _run_slot(slot: list[Any]) -> None:
    run, start, stop = slot
    run(start, stop)


def evaluate_jobs(
    evaluator: PooledEvaluator,
    executor: Executor,
    jobs: Sequence[Job],
    evaluate: Callable[..., Result],
) -> Generator[Result, None, None]:
    """``evaluate(evaluator, *job)`` of each job on the pool, yielded in job order.

    ``evaluate`` must be picklable for a process pool (a module-level function or a method
    of a module-level class, e.g. ``GraspSafetyEvaluator.evaluate_batch``); the workers
    call it on their own copy of the evaluator. On processes, jobs go out in contiguous chunks
    (about four per worker), which keeps the pool's per-task overhead small and the load
    balanced; on threads one job is one task (the overhead is small), so the caller sees each
    result, and can stop, as soon as it is ready, and at most two per worker are submitted
    ahead of the caller: a caller that pauses between results (a ranking handing the node's
    compute lock to another request) leaves the workers to other work. Closing the returned
    generator early (an abandoned ranking) cancels the tasks not started yet; a running
    thread task finishes its one job.
    """
    if isinstance(executor, ThreadPoolExecutor):
        ahead = 2 * _workers(executor)
        return _ahead(executor, partial(_evaluate_job, evaluate, evaluator), jobs, ahead)
    size = max(1, math.ceil(len(jobs) / (4 * _workers(executor))))
    chunks = [jobs[k : k + size] for k in range(0, len(jobs), size)]
    return _close_early(executor.map(partial(_evaluate_chunk_in_worker, evaluate), chunks))


def _evaluate_job(evaluate: Callable[..., Result], evaluator: PooledEvaluator, job: Job) -> Result:
    return evaluate(evaluator, *job)


def _ahead(
    executor: Executor, run: Callable[[Job], Result], jobs: Sequence[Job], ahead: int
) -> Generator[Result, None, None]:
    """``run(job)`` of each job on ``executor``, yielded in job order, with at most ``ahead``
    jobs submitted and not yet taken by the caller; closing cancels those not started."""
    pending: deque[Future[Result]] = deque()
    remaining = iter(jobs)
    try:
        for job in islice(remaining, ahead):
            pending.append(executor.submit(run, job))
        while pending:
            result = pending.popleft().result()
            for job in islice(remaining, 1):
                pending.append(executor.submit(run, job))
            yield result
    finally:
        for future in pending:
            future.cancel()


def _close_early(results: Iterator[list[Result]]) -> Generator[Result, None, None]:
    """The results of Executor.map's chunks; closing it closes the map (cancels the rest)."""
    try:
        for chunk in results:
            yield from chunk
    finally:
        close = getattr(results, "close", None)
        if close is not None:
            close()


_WORKER_EVALUATOR: PooledEvaluator | None = None


def _init_worker(
    evaluator_class: Callable[[RobotModel, PoolConfig], PooledEvaluator],
    robot: RobotModel,
    config: PoolConfig,
) -> None:
    global _WORKER_EVALUATOR
    _WORKER_EVALUATOR = evaluator_class(robot, config)


def _evaluate_chunk_in_worker(
    evaluate: Callable[..., Result], jobs: Sequence[Job]
) -> list[Result]:
    assert _WORKER_EVALUATOR is not None
    return [evaluate(_WORKER_EVALUATOR, *job) for job in jobs]
