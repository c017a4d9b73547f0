"""The worker pool (core/method/pool.py) gives the serial results bit for bit, stays out of
small requests, stops per job when abandoned; the warm-up runs with or without an evaluator."""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable
from functools import partial

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_positions
from fast_paths import BOX, assert_identical_ranking, grasps_near_identity, reach_trajectory

from grasp_safety_ros.core import EvaluationConfig, Grasp, GraspSafetyEvaluator, RobotModel
from grasp_safety_ros.core.method.ik import compiled_available


@pytest.mark.parametrize("backend", ["compiled", "python"])
def test_parallel_ranking_is_identical_to_serial(backend: str, arm7: RobotModel) -> None:
    if backend == "compiled" and not compiled_available():
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(11)
    seed = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, seed, dt=0.05)
    grasps = [*grasps_near_identity(8), Grasp(pin.SE3(np.eye(3), np.array([0, 0, 5.0])), "far")]
    serial = GraspSafetyEvaluator(arm7, EvaluationConfig(backend=backend, workers=1))
    pooled = GraspSafetyEvaluator(
        arm7, EvaluationConfig(backend=backend, workers=2, parallel_min_samples=1)
    )
    expected = serial.rank(grasps, BOX, trajectory, seed_positions=seed)
    progress: list[tuple[int, int]] = []
    got = pooled.rank(
        grasps, BOX, trajectory, seed_positions=seed, progress=lambda *a: progress.append(a)
    )
    assert getattr(pooled, "_grasp_pool", None) is not None  # the pool was used
    assert progress == [(k, len(grasps)) for k in range(1, len(grasps) + 1)]
    assert_identical_ranking(got, expected)
    assert_identical_ranking(pooled.rank(grasps, BOX, trajectory, seed_positions=seed), expected)


def test_a_pooled_ranking_gives_every_worker_a_job(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Fewer grasps than two batches of BATCH_GRASPS: one job per worker (9 grasps on 2: 5
    and 4, on the workers' threads), and a single grasp stays in the calling thread (no
    hand-off); the results are the serial ones (test_parallel_ranking_is_identical_to_serial)."""
    if not compiled_available():
        pytest.skip("numba is not installed")  # threads share the patched method
    rng = np.random.default_rng(11)
    seed = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, seed, dt=0.05)
    pooled = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=2, parallel_min_samples=1))
    jobs: list[tuple[int, str]] = []
    evaluate_batch = GraspSafetyEvaluator.evaluate_batch

    def recorded(self: GraspSafetyEvaluator, indices, *rest):
        jobs.append((len(indices), threading.current_thread().name))
        return evaluate_batch(self, indices, *rest)

    monkeypatch.setattr(GraspSafetyEvaluator, "evaluate_batch", recorded)
    pooled.rank(grasps_near_identity(9), BOX, trajectory, seed_positions=seed)
    assert sorted(size for size, _ in jobs) == [4, 5]
    assert all(name != threading.current_thread().name for _, name in jobs)
    jobs.clear()
    pooled.rank(grasps_near_identity(1), BOX, trajectory, seed_positions=seed)
    assert jobs == [(1, threading.current_thread().name)]


def test_warm_up_runs_with_and_without_an_evaluator(arm6: RobotModel) -> None:
    from grasp_safety_ros.core.method.warm_up import warm_up

    assert warm_up() >= 0.0
    assert warm_up(GraspSafetyEvaluator(arm6)) >= 0.0
    assert warm_up(GraspSafetyEvaluator(arm6, EvaluationConfig(backend="python"))) == 0.0


def test_small_requests_stay_serial(arm6: RobotModel) -> None:
    evaluator = GraspSafetyEvaluator(arm6, EvaluationConfig(workers=2, parallel_min_samples=10**6))
    seed = random_positions(arm6, np.random.default_rng(12))
    evaluator.rank(grasps_near_identity(2), BOX, reach_trajectory(arm6, seed), seed_positions=seed)
    assert getattr(evaluator, "_grasp_pool", None) is None


class _AbandonError(Exception):
    pass


def test_closing_the_pool_stream_starts_no_further_job() -> None:
    """Abandoning a pooled request stops it per job, not per chunk (deterministic gates)."""
    from concurrent.futures import ThreadPoolExecutor

    from grasp_safety_ros.core.method.pool import evaluate_jobs

    gate = threading.Event()
    started: list[int] = []
    lock = threading.Lock()

    def evaluate(_: object, index: int) -> int:
        with lock:
            started.append(index)
        if index >= 3:  # every job but the first three waits until the stream is closed
            gate.wait(10.0)
        return index

    with ThreadPoolExecutor(max_workers=2) as executor:
        stream = evaluate_jobs(None, executor, [(k,) for k in range(100)], evaluate)
        assert [next(stream) for _ in range(3)] == [0, 1, 2]
        stream.close()
        gate.set()
    # 0, 1, 2, then each of the two workers finishes the one job it had started; the other
    # 95 jobs never start (with chunks of jobs, every started chunk would run to its end).
    assert len(started) <= 3 + 2, sorted(started)


def test_progress_that_raises_abandons_a_pooled_ranking(arm7: RobotModel) -> None:
    rng = np.random.default_rng(13)
    seed = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, seed, dt=0.05)
    pooled = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=2, parallel_min_samples=1))
    calls: list[int] = []

    def progress(done: int, total: int) -> None:
        calls.append(done)
        if done == 2:
            raise _AbandonError

    with pytest.raises(_AbandonError):
        pooled.rank(grasps_near_identity(40), BOX, trajectory, seed, progress=progress)
    assert calls == [1, 2]  # called per grasp, in order, with the pool
    # the pool is free again and gives the serial result
    serial = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1))
    grasps = grasps_near_identity(4)
    assert_identical_ranking(
        pooled.rank(grasps, BOX, trajectory, seed), serial.rank(grasps, BOX, trajectory, seed)
    )


def test_split_grasps_covers_the_grasps_once_and_never_waits_for_a_busy_pool() -> None:
    """One range per worker, together every grasp once, the first on the calling thread;
    with every thread of the pool busy, the caller runs the other range itself (else it
    would wait for the gate) and the pool keeps no reference to the call's outputs; without
    a thread pool, one call on the caller."""
    from concurrent.futures import Executor, ThreadPoolExecutor

    from grasp_safety_ros.core.method.pool import split_grasps

    me = threading.current_thread().name
    ran: list[tuple[int, int, str]] = []
    lock = threading.Lock()

    def run(start: int, stop: int) -> None:
        with lock:
            ran.append((start, stop, threading.current_thread().name))

    class OtherPool(Executor):  # e.g. a process pool: its workers do not share the outputs
        _max_workers = 2

    for executor in (None, OtherPool()):
        ran.clear()
        split_grasps(executor, 7, run)
        assert ran == [(0, 7, me)]
    gate = threading.Event()
    with ThreadPoolExecutor(max_workers=2) as pool:
        ran.clear()
        split_grasps(pool, 7, run)
        assert sorted(bounds for *bounds, _ in ran) == [[0, 4], [4, 7]]
        assert (0, 4, me) in ran
        ran.clear()
        split_grasps(pool, 1, run)
        assert ran == [(0, 1, me)]
        busy = [pool.submit(gate.wait, 30.0) for _ in range(2)]
        outputs = np.zeros(7)
        held = weakref.ref(outputs)
        ran.clear()
        split_grasps(pool, 7, partial(_fill, outputs, run))
        assert ran == [(0, 4, me), (4, 7, me)] and not any(f.done() for f in busy)
        assert outputs.sum() == 7.0
        del outputs
        assert held() is None  # the range taken back left no reference in the pool's queue
        gate.set()


def _fill(outputs: np.ndarray, run: Callable[[int, int], None], start: int, stop: int) -> None:
    outputs[start:stop] = 1.0
    run(start, stop)


def test_split_grasps_raises_once_no_range_runs() -> None:
    """A range that raises (the caller's) is raised only once the pool's range, started
    before, has finished writing: nothing writes to the outputs after the call."""
    from concurrent.futures import ThreadPoolExecutor

    from grasp_safety_ros.core.method.pool import split_grasps

    started, release = threading.Event(), threading.Event()
    finished: list[int] = []

    def run(start: int, stop: int) -> None:
        if start == 0:
            assert started.wait(30.0)  # the pool's range runs: it cannot be taken back
            threading.Timer(0.05, release.set).start()
            raise _AbandonError
        started.set()
        release.wait(30.0)
        finished.append(start)

    with ThreadPoolExecutor(max_workers=2) as pool:
        with pytest.raises(_AbandonError):
            split_grasps(pool, 4, run)
        assert finished == [2]


def test_split_grasps_takes_back_what_has_not_started_before_waiting() -> None:
    """Three workers, two of them busy: the range that started on the pool's free thread runs
    on, the one still queued is the caller's before the caller waits (it never waits while a
    range is queued); a pool that is shut down (the interpreter exits) leaves every range to
    the caller."""
    from concurrent.futures import ThreadPoolExecutor

    from grasp_safety_ros.core.method.pool import split_grasps

    me = threading.current_thread().name
    started, release = threading.Event(), threading.Event()
    ran: list[tuple[int, str]] = []

    def run(start: int, stop: int) -> None:
        if start == 3:  # on the pool: it holds until the caller has run the queued range
            started.set()
            release.wait(5.0)
        elif start == 0:
            assert started.wait(30.0)
        ran.append((start, threading.current_thread().name))
        if start == 6:
            release.set()

    gate = threading.Event()
    with ThreadPoolExecutor(max_workers=3) as pool:
        busy = [pool.submit(gate.wait, 30.0) for _ in range(2)]
        split_grasps(pool, 9, run)
        gate.set()
        for future in busy:
            future.result()
    assert ran == [(0, me), (6, me), (3, ran[2][1])] and ran[2][1] != me

    closed = ThreadPoolExecutor(max_workers=2)
    closed.shutdown()
    ran.clear()
    split_grasps(closed, 4, run)
    assert ran == [(0, me), (2, me)]


def test_job_ranges_cover_the_grasps_once_with_the_short_jobs_last() -> None:
    """Consecutive ranges covering every grasp once, none above ``largest``; serial: batches
    of ``largest``; on a pool, every worker a job and, past one job per worker, the last job
    of each worker cut in two (sizes within one of each other). 100 grasps on 2 workers, at
    most 16: 8 jobs of 100 k // 8 bounds (12, 13, ...), the last two (75-87, 87-100) halved
    into 6 + 6 and 7 + 6."""
    from concurrent.futures import ThreadPoolExecutor

    from grasp_safety_ros.core.method.pool import job_ranges

    assert job_ranges(None, 40, 16) == [(0, 16), (16, 32), (32, 40)]
    for workers in (1, 2, 3):
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for grasps in range(0, 80):
                for largest in (1, 4, 16):
                    ranges = job_ranges(pool, grasps, largest)
                    sizes = [stop - start for start, stop in ranges]
                    assert [start for start, _ in ranges] == list(np.cumsum([0, *sizes])[:-1])
                    assert sum(sizes) == grasps and all(1 <= s <= largest for s in sizes)
                    assert len(ranges) >= min(grasps, workers)
                    if grasps > largest * workers > workers:  # halves end the request
                        firsts, seconds = sizes[-2 * workers :: 2], sizes[1 - 2 * workers :: 2]
                        jobs = [*sizes[: -2 * workers], *np.add(firsts, seconds)]
                        assert max(jobs) - min(jobs) <= 1 and len(jobs) % workers == 0
                        assert np.abs(np.subtract(firsts, seconds)).max() <= 1
    with ThreadPoolExecutor(max_workers=2) as pool:
        sizes = [stop - start for start, stop in job_ranges(pool, 100, 16)]
    assert sizes == [12, 13, 12, 13, 12, 13, 6, 6, 7, 6]


def test_posture_jobs_of_any_size_give_the_serial_selection(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Posture selection's jobs only regroup grasps: with batches of 2 (job_ranges: 9
    grasps on 2 workers, 6 jobs of 1-2, the last one halved) every evaluation, order and
    selection record equals the serial one's (batches of BATCH_GRASPS), bit for bit."""
    import pickle

    from grasp_safety_ros.core.method import posture
    from grasp_safety_ros.core.method.pool import job_ranges

    if not compiled_available():
        pytest.skip("numba is not installed")  # threads share the patched function
    rng = np.random.default_rng(5)
    seed = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, seed, dt=0.05)
    grasps = [*grasps_near_identity(8), Grasp(pin.SE3(np.eye(3), np.array([0, 0, 5.0])), "far")]
    config = posture.PostureConfig(restarts=4)
    sizes: list[int] = []
    batch = posture.select_posture_batch

    def recorded(evaluator: GraspSafetyEvaluator, job_grasps: list[Grasp], *rest):
        sizes.append(len(job_grasps))
        return batch(evaluator, job_grasps, *rest)

    kept = []
    for workers in (1, 2):
        evaluator = GraspSafetyEvaluator(
            arm7, EvaluationConfig(workers=workers, parallel_min_samples=1)
        )
        ranking = evaluator.rank(grasps, BOX, trajectory, seed_positions=seed)
        kept.append(posture.select_postures(evaluator, grasps, BOX, trajectory, ranking, config))
        monkeypatch.setattr(posture, "BATCH_GRASPS", 2)
        monkeypatch.setattr(posture, "select_posture_batch", recorded)
    serial, shared = kept
    assert sorted(sizes) == sorted(b - a for a, b in job_ranges(evaluator._grasp_pool, 9, 2))
    assert shared.order == serial.order and not serial.evaluations[-1].feasible
    assert pickle.dumps(shared.evaluations) == pickle.dumps(serial.evaluations)
    assert pickle.dumps(shared.postures) == pickle.dumps(serial.postures)
