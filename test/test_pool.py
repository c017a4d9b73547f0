"""The worker pool (core/method/pool.py) gives the serial results bit for bit, stays out of
small requests, stops per job when abandoned; the warm-up runs with or without an evaluator."""

from __future__ import annotations

import threading

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
