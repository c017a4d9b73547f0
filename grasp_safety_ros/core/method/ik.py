"""Inverse kinematics of the tip frame along a trajectory (damped Gauss-Newton on SE(3)).

Along a trajectory each sample is warm-started by a predictor from the previous solution,
q_guess = q_{i-1} (+) J^+(q_{i-1}) (xi_i + c_i): xi_i = log6(T_{i-1}^-1 T_i) is the tip twist
between consecutive targets (tip frame) and J^+ the damped minimum-norm pseudo-inverse of the
tip-frame (LOCAL) Jacobian at q_{i-1} (the same damping and step limit as the Gauss-Newton
correction). The first-order step J^+ xi_i misses a second-order defect, which grows as
|xi_i|^2 and changes little from one sample to the next; c_i extrapolates it from the previous
sample: c_i = r_i D_{i-1}, where D_{i-1} = c_{i-1} + (the error left at sample i-1's guess,
Gauss-Newton's first residual) and r_i = min(|xi_i|^2 / |xi_{i-1}|^2, PREDICTOR_MAX_RATIO)
(c_1 = 0). Most samples then converge at the guess, without a Gauss-Newton iteration.
Neither the predictor nor the correction steps have a null-space component, so on redundant
arms the path follows the minimum-norm solution and does not drift along the self-motion
manifold (as extrapolating the previous joint step would).

Two implementations of the same algorithm (same warm start, steps, tolerances and checks):

- ``python``: a loop over Pinocchio's Python bindings; works for every chain.
- ``compiled``: the whole trajectory in one numba kernel (``pip install numba``), for serial
  chains of revolute, continuous and prismatic joints. Its per-sample results equal the Python
  loop's to rounding (the test suite checks 1e-9); it releases the GIL, so grasps can run on
  threads.

``backend="auto"`` picks ``compiled`` when numba is importable and the chain is supported.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator, Sequence
from types import ModuleType
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..model.robot import RobotModel
from .compiled import call_kernel, chain_arrays_or_reason, plain_array
from .ik_config import (
    BACKENDS,
    NUMBA_AVAILABLE,
    IKConfig,
    IKTrajectoryResult,
    check_backend,
    compiled_available,
    ik_settings,
)
from .packed import STALL_RATIO, ChainArrays, grasp_buffers

__all__ = [  # the solver, and what callers import from here (defined in ik_config)
    "BACKENDS",
    "NUMBA_AVAILABLE",
    "IKConfig",
    "IKSolver",
    "IKTrajectoryResult",
    "check_backend",
    "compiled_available",
    "ik_settings",
]


class IKSolver:
    """Tip-pose IK for a RobotModel, warm-started along trajectories."""

    def __init__(
        self, robot: RobotModel, config: IKConfig | None = None, backend: str = "auto"
    ) -> None:
        self.robot = robot
        self.config = config or IKConfig()
        self.backend = check_backend(backend, "ik.backend")
        self.data = robot.model.createData()
        model = robot.model
        lower = np.array(model.lowerPositionLimit, dtype=float)
        upper = np.array(model.upperPositionLimit, dtype=float)
        for joint in model.joints[1:]:
            if joint.nq != joint.nv:  # continuous joint: (cos, sin), no limit
                lower[joint.idx_q : joint.idx_q + joint.nq] = -np.inf
                upper[joint.idx_q : joint.idx_q + joint.nq] = np.inf
        self._lower_q, self._upper_q = lower, upper
        chain = chain_arrays_or_reason(robot) if backend != "python" else "requested"
        self.chain = chain if isinstance(chain, ChainArrays) else None
        self.settings = (
            ik_settings(self.config, robot.velocity_limits, PREDICTOR_MAX_RATIO)
            if self.chain is not None
            else None
        )
        if backend == "compiled" and self.chain is None:
            raise InvalidInputError(
                "ik.backend",
                "'compiled' supports serial chains of revolute, continuous and prismatic "
                "joints only; "
                f"joints here: {', '.join(j.shortname() for j in model.joints[1:])}",
            )
        self.compiled = NUMBA_AVAILABLE and self.chain is not None
        if self.compiled or backend == "python":
            self.backend_used = "compiled" if self.compiled else "python"
        elif not NUMBA_AVAILABLE:
            self.backend_used = "python (numba not installed)"
        else:
            self.backend_used = f"python ({chain})"
        """What runs: ``compiled`` or ``python``, with the reason when ``auto`` fell back."""
        self._dgesv: Any = None if self.compiled else _lapack_dgesv()
        self._identity6 = np.eye(6)
        self._identity_n = np.eye(model.nv)
        self._restarts: tuple[np.ndarray, ...] | None = None  # see restarts()
        self._restarts_lock = threading.Lock()

    # ----------------------------------------------------------------------------- one pose
    def solve(
        self, transform_tip_to_base: pin.SE3, q_init: np.ndarray
    ) -> tuple[np.ndarray, bool, int]:
        """Solve one tip pose from ``q_init``.

        Returns:
            The configuration, whether it converged to the tolerances, and the iterations.
        """
        transform_target_to_world = self.robot.transform_base_to_world * transform_tip_to_base
        if self.compiled:
            q = np.empty(self.robot.model.nq)
            converged, iterations = call_kernel(
                _kernels().solve_pose,
                self.chain,
                self.settings,
                plain_array(transform_target_to_world.rotation),
                plain_array(transform_target_to_world.translation),
                plain_array(q_init),
                q,
                _kernels().thread_workspace(self.robot.model.nv),
            )
            return q, bool(converged), int(iterations)
        return self._solve_python(transform_target_to_world, q_init)

    def solve_poses(
        self,
        transforms_tip_to_base: Sequence[pin.SE3],
        seeds_q: np.ndarray,
        max_iterations: int | None = None,
        stall_iterations: int = 0,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``solve`` of each tip pose g from each seed r (seeds_q (R, nq)), compiled in one
        kernel call: the configurations (G, R, nq) and whether each converged (G, R);
        ``max_iterations`` replaces the config's (None: the config's); ``stall_iterations``
        k > 0 gives a solve up when k iterations cut its error by less than
        ``packed.STALL_RATIO`` (IKSettings.stall_iterations)."""
        seeds_q = np.asarray(seeds_q, dtype=float).reshape(-1, self.robot.model.nq)
        shape = (len(transforms_tip_to_base), len(seeds_q))
        q = np.empty((*shape, self.robot.model.nq))
        converged = np.zeros(shape, dtype=np.bool_)
        targets = [self.robot.transform_base_to_world * pose for pose in transforms_tip_to_base]
        if not self.compiled:
            for g, target in enumerate(targets):
                for r, seed in enumerate(seeds_q):
                    q[g, r], converged[g, r], _ = self._solve_python(
                        target, seed, max_iterations=max_iterations, stall=stall_iterations
                    )
            return q, converged
        settings = self.settings
        if settings is not None:
            settings = settings._replace(
                max_iterations=settings.max_iterations
                if max_iterations is None
                else max_iterations,
                stall_iterations=int(stall_iterations),
            )
        call_kernel(
            _kernels().solve_poses,
            self.chain,
            settings,
            plain_array(np.array([target.rotation for target in targets]).reshape(-1, 3, 3)),
            plain_array(np.array([target.translation for target in targets]).reshape(-1, 3)),
            plain_array(seeds_q),
            q,
            converged,
            _kernels().thread_workspace(self.robot.model.nv),
        )
        return q, converged

    def _solve_python(
        self,
        transform_target_to_world: pin.SE3,
        q_init: np.ndarray,
        first_residual: np.ndarray | None = None,
        max_iterations: int | None = None,
        stall: int = 0,
    ) -> tuple[np.ndarray, bool, int]:
        """Gauss-Newton from q_init: (q, converged, iterations); the error at q_init (tip frame)
        is added to ``first_residual`` when given (the predictor's D); ``max_iterations``
        replaces the config's (None: the config's); ``stall``: IKSettings.stall_iterations."""
        model, data, config = self.robot.model, self.data, self.config
        iterations = config.max_iterations if max_iterations is None else max_iterations
        checkpoint = math.inf
        frame_id = self.robot.tip_frame_id
        lower, upper = self._lower_q, self._upper_q
        q = np.minimum(np.maximum(np.array(q_init, dtype=float), lower), upper)
        n = model.nv
        position_tolerance = config.position_tolerance_m
        orientation_tolerance = config.orientation_tolerance_rad
        for iteration in range(iterations + 1):
            pin.computeJointJacobians(model, data, q)  # forward kinematics + joint Jacobians
            current = pin.updateFramePlacement(model, data, frame_id)
            error_transform = current.actInv(transform_target_to_world)
            error = pin.log6(error_transform).vector
            translation = error_transform.translation
            if iteration == 0 and first_residual is not None:
                first_residual += error
            if (
                math.sqrt(translation.dot(translation)) <= position_tolerance
                and math.sqrt(error[3:].dot(error[3:])) <= orientation_tolerance
            ):
                return q, True, iteration
            if iteration == iterations:
                break
            if stall > 0 and iteration > 0 and iteration % stall == 0:
                norm = math.sqrt(error.dot(error))
                if norm > STALL_RATIO * checkpoint:
                    return q, False, iteration
                checkpoint = norm
            frame_jacobian = pin.getFrameJacobian(
                model, data, frame_id, pin.ReferenceFrame.LOCAL
            ).reshape(6, n)  # eigenpy returns a 6x1 matrix as a vector
            jacobian = pin.Jlog6(error_transform.inverse()) @ frame_jacobian
            q = pin.integrate(model, q, self._damped_step(jacobian, error))
            np.maximum(q, lower, out=q)
            np.minimum(q, upper, out=q)
        return q, False, iterations

    def _damped_step(self, jacobian: np.ndarray, error: np.ndarray) -> np.ndarray:
        """Damped minimum-norm solution of jacobian @ step = error (6 x n), step-limited.

        Damping 1e-12 + 1e-3 |error|^2; n >= 6: step = J^T (J J^T + damping I)^-1 error (no
        null-space component), else (J^T J + damping I)^-1 J^T error. A step whose largest
        entry exceeds ``max_iteration_step`` is scaled down to it (same direction). Solved by
        LAPACK's LU here, by LDL^T in the compiled kernel (equal to rounding).
        """
        damping = 1e-12 + 1e-3 * float(error.dot(error))
        step: np.ndarray
        if jacobian.shape[1] >= 6:
            step = (
                jacobian.T
                @ self._dgesv(jacobian @ jacobian.T + damping * self._identity6, error)[2]
            )
        else:
            step = self._dgesv(
                jacobian.T @ jacobian + damping * self._identity_n, jacobian.T @ error
            )[2]
        largest = float(np.abs(step).max())
        if largest > self.config.max_iteration_step:
            step *= self.config.max_iteration_step / largest
        return step

    def _predict(
        self, q_previous: np.ndarray, motion_tip: pin.SE3, defect: np.ndarray, previous_xi2: float
    ) -> tuple[np.ndarray, float]:
        """The warm start q_previous (+) J^+ (xi + c) of the next sample (module docstring) and
        |xi|^2, for the next call.

        ``self.data`` must hold the joint Jacobians at q_previous (computeJointJacobians, as
        left by the solve that returned it); motion_tip: previous target^-1 * next target;
        defect: D of the previous sample, overwritten with c (``_solve_python`` then adds its
        first residual); previous_xi2: |xi|^2 of the previous sample (0: no correction).
        """
        model = self.robot.model
        frame_jacobian = pin.getFrameJacobian(
            model, self.data, self.robot.tip_frame_id, pin.ReferenceFrame.LOCAL
        ).reshape(6, model.nv)
        twist_in_tip = pin.log6(motion_tip).vector
        xi2 = float(np.sum(twist_in_tip * twist_in_tip))
        ratio = min(xi2 / previous_xi2, PREDICTOR_MAX_RATIO) if previous_xi2 > 0.0 else 0.0
        defect *= ratio
        step = self._damped_step(frame_jacobian, twist_in_tip + defect)
        return pin.integrate(model, q_previous, step), xi2

    def solve_first(
        self, transform_tip_to_base: pin.SE3, seed_q: np.ndarray
    ) -> tuple[np.ndarray, bool, int]:
        """Solve from the seed, then from deterministic random restarts within the limits."""
        q, converged, iterations = self.solve(transform_tip_to_base, seed_q)
        if converged:
            return q, True, iterations
        total = iterations
        for start in self.restarts():
            q, converged, iterations = self.solve(transform_tip_to_base, start)
            total += iterations
            if converged:
                return q, True, total
        return q, False, total

    # ----------------------------------------------------------------------------- trajectory
    def solve_trajectory(
        self,
        transforms_tip_to_base: Sequence[pin.SE3],
        times_s: np.ndarray,
        s_values: np.ndarray,
        seed_q: np.ndarray,
    ) -> IKTrajectoryResult:
        """Solve every sample, each warm-started by the predictor from the previous solution
        (module docstring): the joint path has no self-motion.

        The result is infeasible (with a reason) when a sample does not converge, or joint
        positions jump by more than ``max_joint_step`` or exceed the velocity limits between
        consecutive samples.

        Args:
            transforms_tip_to_base: Tip pose of each sample.
            times_s: Sample times [s] (for the velocity check).
            s_values: Path parameters of the samples (unused by the predictor, which needs
                only the poses; kept so callers need not change).
            seed_q: Seed of sample 0 (then deterministic random restarts).
        """
        rotations = np.array([pose.rotation for pose in transforms_tip_to_base]).reshape(-1, 3, 3)
        translations = np.array([pose.translation for pose in transforms_tip_to_base])
        return self.solve_trajectory_arrays(
            rotations, translations.reshape(-1, 3), times_s, s_values, seed_q
        )

    def solve_trajectory_arrays(
        self,
        rotations_tip_to_base: np.ndarray,
        translations_tip_in_base: np.ndarray,
        times_s: np.ndarray,
        s_values: np.ndarray,
        seed_q: np.ndarray,
    ) -> IKTrajectoryResult:
        """``solve_trajectory`` with the tip poses as (N, 3, 3) rotations and (N, 3) [m]."""
        base = self.robot.transform_base_to_world
        rotations_tip_to_world = np.matmul(base.rotation, rotations_tip_to_base)
        translations_tip_in_world = (
            np.einsum("ij,nj->ni", base.rotation, translations_tip_in_base) + base.translation
        )
        count = len(rotations_tip_to_world)
        if count == 0:
            return IKTrajectoryResult(np.empty((0, self.robot.model.nq)), np.zeros(0, int), "")
        first = pin.SE3(np.array(rotations_tip_to_base[0]), np.array(translations_tip_in_base[0]))
        q0, converged, iterations0 = self.solve_first(first, seed_q)
        if not converged:
            reason = self.first_sample_reason(q0, times_s)
            return IKTrajectoryResult(
                np.empty((0, self.robot.model.nq)), np.zeros(0, dtype=int), reason
            )
        if self.compiled:
            status, index, joint, value, q_all, iterations, q_fail = self._trajectory_compiled(
                rotations_tip_to_world, translations_tip_in_world, times_s, q0
            )
        else:
            velocity_limits = self.robot.velocity_limits
            check_velocity = (
                self.config.check_velocity_limits
                & np.isfinite(velocity_limits)
                & (velocity_limits > 0)
            )
            status, index, joint, value, q_all, iterations, q_fail = self._trajectory_python(
                rotations_tip_to_world, translations_tip_in_world, times_s, q0, check_velocity
            )
        iterations[0] = iterations0
        if status == _OK:
            return IKTrajectoryResult(q_all, iterations, "")
        reason = self.failure_reason(status, index, joint, value, q_fail, times_s)
        return IKTrajectoryResult(q_all[:index], iterations[:index], reason)

    def failure_reason(
        self,
        status: int,
        index: int,
        joint: int,
        value: float,
        q_fail: np.ndarray,
        times_s: np.ndarray,
    ) -> str:
        """Why a trajectory fails, from a trajectory solve's status (not OK) and details."""
        i, k = index, joint
        names, config = self.robot.joint_names, self.config
        if status == _NOT_CONVERGED:
            return f"IK did not converge at sample {i} (t={times_s[i]:.3f} s)" + self._limit_note(
                q_fail
            )
        if status == _JUMP:
            return (
                f"joint '{names[k]}' jumps by {value:.3f} between t="
                f"{times_s[i - 1]:.3f} s and t={times_s[i]:.3f} s (max_joint_step="
                f"{config.max_joint_step:g})"
            )
        return (
            f"joint '{names[k]}' needs speed {value:.3f} > limit "
            f"{self.robot.velocity_limits[k]:g} at t={times_s[i]:.3f} s"
        )

    def first_sample_reason(self, q_fail: np.ndarray, times_s: np.ndarray) -> str:
        """Why sample 0 fails (no convergence from the seed or any restart)."""
        return (
            f"IK did not converge at sample 0 (t={times_s[0]:.3f} s)"
            + self._limit_note(q_fail)
            + " from the seed or any restart"
        )

    def restarts(self) -> Iterator[np.ndarray]:
        """The deterministic random restart configurations tried by ``solve_first`` (drawn
        once per solver, read-only)."""
        with self._restarts_lock:
            if self._restarts is None:
                rng = np.random.default_rng(self.config.random_seed)
                robot = self.robot
                lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -np.pi)
                upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, np.pi)
                restarts = tuple(
                    robot.q_from_positions(rng.uniform(lower, upper))
                    for _ in range(self.config.random_restarts)
                )
                for q in restarts:
                    q.setflags(write=False)
                self._restarts = restarts
        yield from self._restarts

    def _trajectory_compiled(
        self,
        rotations_tip_to_world: np.ndarray,
        translations_tip_in_world: np.ndarray,
        times_s: np.ndarray,
        q0: np.ndarray,
    ) -> tuple[int, int, int, float, np.ndarray, np.ndarray, np.ndarray]:
        out = grasp_buffers(1, len(rotations_tip_to_world), self.robot.model.nq)
        out.q_all[0, 0] = q0
        status, index, joint, value = call_kernel(
            _kernels().solve_trajectory,
            self.chain,
            self.settings,
            plain_array(rotations_tip_to_world),
            plain_array(translations_tip_in_world),
            plain_array(times_s),
            out,
            _kernels().thread_workspace(self.robot.model.nv),
        )
        return (
            int(status),
            int(index),
            int(joint),
            float(value),
            out.q_all[0],
            out.iterations[0],
            out.q_fail[0],
        )

    def _trajectory_python(
        self,
        rotations_tip_to_world: np.ndarray,
        translations_tip_in_world: np.ndarray,
        times_s: np.ndarray,
        q0: np.ndarray,
        check_velocity: np.ndarray,
    ) -> tuple[int, int, int, float, np.ndarray, np.ndarray, np.ndarray]:
        model, config = self.robot.model, self.config
        count = len(rotations_tip_to_world)
        q_all = np.empty((count, model.nq))
        iterations = np.zeros(count, dtype=np.int64)
        q_all[0] = q0
        velocity_limits = self.robot.velocity_limits
        any_velocity_check = bool(check_velocity.any())
        pin.computeJointJacobians(model, self.data, q0)  # _predict's Jacobian at q_all[0]
        previous = pin.SE3(rotations_tip_to_world[0], translations_tip_in_world[0])
        defect, xi2 = np.zeros(6), 0.0
        for i in range(1, count):
            target = pin.SE3(rotations_tip_to_world[i], translations_tip_in_world[i])
            guess, xi2 = self._predict(q_all[i - 1], previous.actInv(target), defect, xi2)
            previous = target
            q, converged, iterations[i] = self._solve_python(target, guess, defect)
            if not converged:
                return _NOT_CONVERGED, i, 0, 0.0, q_all, iterations, q
            q_all[i] = q
            delta = np.abs(pin.difference(model, q_all[i - 1], q))
            k = int(np.argmax(delta))
            if delta[k] > config.max_joint_step:
                return _JUMP, i, k, float(delta[k]), q_all, iterations, q
            elapsed = times_s[i] - times_s[i - 1]
            if any_velocity_check and elapsed > 0:
                speed = delta / elapsed
                over = check_velocity & (speed > velocity_limits * (1 + 1e-9))
                if over.any():
                    k = int(np.flatnonzero(over)[0])
                    return _TOO_FAST, i, k, float(speed[k]), q_all, iterations, q
        return _OK, count, 0, 0.0, q_all, iterations, q_all[-1]

    def _limit_note(self, q: np.ndarray) -> str:
        positions = self.robot.positions_from_q(q)
        at_limit = (positions <= self.robot.lower_limits + 1e-9) | (
            positions >= self.robot.upper_limits - 1e-9
        )
        if not at_limit.any():
            return " (target out of reach or singular)"
        names = ", ".join(self.robot.joint_names[k] for k in np.flatnonzero(at_limit))
        return f" (joint limits reached: {names})"


PREDICTOR_MAX_RATIO = 4.0
"""Largest growth r_i of the predictor's defect from one sample to the next (module docstring):
bounds the correction where a short step is followed by a long one (irregular sample times)."""

_OK, _NOT_CONVERGED, _JUMP, _TOO_FAST = 0, 1, 2, 3
"""Status codes of a trajectory solve."""


def _lapack_dgesv() -> Any:
    """LAPACK's dgesv (what np.linalg.solve calls, without its Python overhead)."""
    from scipy.linalg.lapack import dgesv

    return dgesv


def _kernels() -> ModuleType:
    """The IK kernels (numba compiles them, or loads them from its cache, on first use)."""
    from ..kernels import ik

    return ik
