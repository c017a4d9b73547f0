"""The peer pipeline: the same grasp evaluation built on PyKDL (the library the paper used).

The KDL chain is built from the same URDF (bench/kdl_chain.py, kdl_parser's conventions).
Kinematics and the joint-space inertia come from KDL (ChainFkSolverPos_recursive,
ChainJntToJacSolver, ChainDynParam.JntToMass). The IK is the same damped Gauss-Newton loop as
the core's (error log6 of current^-1 * target in the tip frame, Jlog6, same damping, step
limit, tolerances 1e-6 m / 1e-6 rad, the same warm start q_{i-1} + J^+ (log6(T_{i-1}^-1 T_i) +
c_i) with the core's extrapolated second-order defect c_i, deterministic restarts, jump and
speed checks), with its SE(3) log written in numpy. The effective mass is computed as the
paper would have: Lambda = (J M^-1 J^T)^-1 (numpy inverses), Lambda_tot = Lambda + Lambda_obj
(Khatib's augmented object, T^T Lambda_com T), then [Lambda_tot^-1]_3x3 and 1 / (u^T A u).

Nothing here uses Pinocchio: only the URDF file location and the IK settings come from the core.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import Any

import numpy as np
from kdl_chain import KDLChain

from grasp_safety_ros.core.method.ik import PREDICTOR_MAX_RATIO

_EPS = float(np.finfo(float).eps)
_PREC2 = _EPS ** (1.0 / 3.0)
_PREC3 = _EPS ** (1.0 / 4.0)


# ----------------------------------------------------------------------------- SE(3) log
def _log3(r: np.ndarray) -> tuple[float, np.ndarray]:
    c0 = r[:, 0] / np.linalg.norm(r[:, 0])
    c1 = r[:, 1] / np.linalg.norm(r[:, 1])
    c2 = _cross(c0, c1)
    c0 = _cross(c1, c2)
    rn = np.column_stack([c0, c1, c2])
    tr = rn[0, 0] + rn[1, 1] + rn[2, 2]
    cos_value = (tr - 1.0) / 2.0
    axis = 0.5 * np.array([rn[2, 1] - rn[1, 2], rn[0, 2] - rn[2, 0], rn[1, 0] - rn[0, 1]])
    if cos_value >= -1.0 + _PREC2:
        theta = math.acos(cos_value) if tr <= 3.0 - _PREC2 else math.sqrt(2.0 * (1.0 - cos_value))
        if theta >= _PREC2:
            return theta, theta / math.sin(theta) * axis
        nrm2 = float(axis @ axis)
        return theta, (1.0 + nrm2 / 6.0 + nrm2 * nrm2 * 3.0 / 40.0) * axis
    # Near pi: axis from the largest diagonal entry (as Pinocchio).
    diagonal = 2.0 * np.diag(rn) - tr + 1.0
    i0 = int(np.argmax(diagonal))
    i1, i2 = (i0 + 1) % 3, (i0 + 2) % 3
    s = math.sqrt(diagonal[i0] + _EPS) * (1.0 if rn[i2, i1] >= rn[i1, i2] else -1.0)
    unit = np.empty(3)
    unit[i0] = s / 2.0
    unit[i1] = (rn[i1, i0] + rn[i0, i1]) / (2.0 * s)
    unit[i2] = (rn[i2, i0] + rn[i0, i2]) / (2.0 * s)
    w = (rn[i2, i1] - rn[i1, i2]) / (2.0 * s)
    norm = float(np.linalg.norm(unit))
    theta = 2.0 * math.atan2(norm, w)
    return theta, theta * unit / norm


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors (np.cross has a large per-call overhead)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def log6(r: np.ndarray, p: np.ndarray) -> np.ndarray:
    """[linear; angular] twist of the SE(3) element (r, p) (Pinocchio's log6)."""
    u = 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    t2 = float(u @ u)
    theta, w = _log3(r)
    if np.trace(r) >= 3.0 - _PREC2:
        alpha, beta = 1.0 - t2 / 12.0 - t2 * t2 / 720.0, 1.0 / 12.0 + t2 / 720.0
    else:
        st, ct = math.sin(theta), math.cos(theta)
        alpha = theta * st / (2.0 * (1.0 - ct))
        beta = 1.0 / theta**2 - st / (2.0 * theta * (1.0 - ct))
    linear = alpha * p - 0.5 * _cross(w, p) + beta * float(w @ p) * w
    return np.concatenate([linear, w])


def jlog6(r: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Jacobian of log6 (Pinocchio's Jlog6)."""
    t, w = _log3(r)
    t2 = t * t
    st, ct = math.sin(t), math.cos(t)
    if t < _PREC3:
        alpha, diag = 1.0 / 12.0 + t2 / 720.0, 0.5 * (2.0 - t2 / 6.0)
        beta, beta_dot = 1.0 / 12.0 + t2 / 720.0, 1.0 / 360.0
    else:
        st_1mct = st / (1.0 - ct)
        alpha, diag = 1.0 / t2 - st_1mct / (2.0 * t), 0.5 * t * st_1mct
        inv_2_2ct = 1.0 / (2.0 * (1.0 - ct))
        beta = 1.0 / t2 - st / t * inv_2_2ct
        beta_dot = -2.0 / (t2 * t2) + (1.0 + st / t) / t2 * inv_2_2ct
    a = alpha * np.outer(w, w) + diag * np.eye(3) + _skew(0.5 * w)
    wtp = float(w @ p)
    v3 = (beta_dot * wtp) * w - (t2 * beta_dot + 2.0 * beta) * p
    c = np.outer(v3, w) + beta * np.outer(w, p) + wtp * beta * np.eye(3) + _skew(0.5 * p)
    out = np.zeros((6, 6))
    out[:3, :3] = a
    out[3:, 3:] = a
    out[:3, 3:] = c @ a
    return out


# ----------------------------------------------------------------------------- pipeline
class PyKDLPipeline:
    """Grasp evaluation (IK + effective mass per sample) on PyKDL."""

    def __init__(self, kdl: ModuleType, chain: KDLChain, ik_config: Any) -> None:
        self.kdl = kdl
        self.chain = chain
        self.config = ik_config
        self.n = chain.chain.getNrOfJoints()
        self.fk = kdl.ChainFkSolverPos_recursive(chain.chain)
        self.jac = kdl.ChainJntToJacSolver(chain.chain)
        self.dyn = kdl.ChainDynParam(chain.chain, kdl.Vector(0.0, 0.0, -9.81))
        self._q = kdl.JntArray(self.n)
        self._frame = kdl.Frame()
        self._jacobian = kdl.Jacobian(self.n)
        self._mass = kdl.JntSpaceInertiaMatrix(self.n)
        self.last_tip_rotation = np.eye(3)
        """Tip rotation (base axes) at the configuration ``solve`` last returned."""

    # --- KDL calls, converted to numpy
    def _set_q(self, q: np.ndarray) -> None:
        for k in range(self.n):
            self._q[k] = q[k]

    def forward(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._set_q(q)
        self.fk.JntToCart(self._q, self._frame)
        m, p = self._frame.M, self._frame.p
        rotation = np.array([[m[i, j] for j in range(3)] for i in range(3)])
        return rotation, np.array([p[0], p[1], p[2]])

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """6 x n, [linear; angular], base axes, reference point at the tip."""
        self._set_q(q)
        self.jac.JntToJac(self._q, self._jacobian)
        j = self._jacobian
        return np.array([[j[i, k] for k in range(self.n)] for i in range(6)])

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        self._set_q(q)
        self.dyn.JntToMass(self._q, self._mass)
        m = self._mass
        return np.array([[m[i, k] for k in range(self.n)] for i in range(self.n)])

    # --- IK
    def solve(
        self,
        target_r: np.ndarray,
        target_p: np.ndarray,
        q_init: np.ndarray,
        first_residual: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool, int]:
        """Gauss-Newton from q_init; the error at q_init is added to ``first_residual``."""
        config = self.config
        q = np.clip(np.array(q_init, dtype=float), self.chain.lower, self.chain.upper)
        for iteration in range(config.max_iterations + 1):
            rotation, position = self.forward(q)
            self.last_tip_rotation = rotation
            error_r = rotation.T @ target_r
            error_p = rotation.T @ (target_p - position)
            error = log6(error_r, error_p)
            if iteration == 0 and first_residual is not None:
                first_residual += error
            if (
                np.linalg.norm(error_p) <= config.position_tolerance_m
                and np.linalg.norm(error[3:]) <= config.orientation_tolerance_rad
            ):
                return q, True, iteration
            if iteration == config.max_iterations:
                break
            jacobian_tip_in_base = self.jacobian(q)
            local = np.vstack(
                [rotation.T @ jacobian_tip_in_base[:3], rotation.T @ jacobian_tip_in_base[3:]]
            )
            jacobian = jlog6(error_r.T, -error_r.T @ error_p) @ local
            q = np.clip(q + self._damped_step(jacobian, error), self.chain.lower, self.chain.upper)
        return q, False, config.max_iterations

    def _damped_step(self, jacobian: np.ndarray, error: np.ndarray) -> np.ndarray:
        """Damped minimum-norm solution of jacobian @ step = error, step-limited (the core's)."""
        n = self.n
        damping = 1e-12 + 1e-3 * float(error @ error)
        if n >= 6:
            step = jacobian.T @ np.linalg.solve(jacobian @ jacobian.T + damping * np.eye(6), error)
        else:
            step = np.linalg.solve(jacobian.T @ jacobian + damping * np.eye(n), jacobian.T @ error)
        largest = float(np.abs(step).max())
        if largest > self.config.max_iteration_step:
            step *= self.config.max_iteration_step / largest
        return step

    def predict(
        self,
        q_previous: np.ndarray,
        tip_rotation: np.ndarray,
        rotation_previous: np.ndarray,
        position_previous: np.ndarray,
        rotation: np.ndarray,
        position: np.ndarray,
        defect: np.ndarray,
        previous_xi2: float,
    ) -> tuple[np.ndarray, float]:
        """Warm start of the next sample (the core's predictor): q_previous + J^+ (xi + c), xi
        the tip twist from the previous target to the next (tip axes), J the tip-frame
        Jacobian at q_previous, where the tip rotation is ``tip_rotation`` (base axes; as the
        core, this reuses the solve's last forward kinematics); c = r D, D in ``defect``
        (overwritten with c), r = min(|xi|^2 / previous_xi2, PREDICTOR_MAX_RATIO). Returns the
        guess and |xi|^2."""
        jacobian_tip_in_base = self.jacobian(q_previous)
        local = np.vstack(
            [tip_rotation.T @ jacobian_tip_in_base[:3], tip_rotation.T @ jacobian_tip_in_base[3:]]
        )
        twist = log6(
            rotation_previous.T @ rotation, rotation_previous.T @ (position - position_previous)
        )
        xi2 = float(twist @ twist)
        ratio = min(xi2 / previous_xi2, PREDICTOR_MAX_RATIO) if previous_xi2 > 0.0 else 0.0
        defect *= ratio
        return q_previous + self._damped_step(local, twist + defect), xi2

    def solve_first(
        self, target_r: np.ndarray, target_p: np.ndarray, seed: np.ndarray
    ) -> tuple[np.ndarray, bool, int]:
        q, converged, iterations = self.solve(target_r, target_p, seed)
        if converged:
            return q, True, iterations
        rng = np.random.default_rng(self.config.random_seed)
        lower = np.where(np.isfinite(self.chain.lower), self.chain.lower, -np.pi)
        upper = np.where(np.isfinite(self.chain.upper), self.chain.upper, np.pi)
        total = iterations
        for _ in range(self.config.random_restarts):
            q, converged, iterations = self.solve(target_r, target_p, rng.uniform(lower, upper))
            total += iterations
            if converged:
                return q, True, total
        return q, False, total

    # --- one grasp
    def tip_path(
        self, trajectory: Any, grasp_r: np.ndarray, grasp_p: np.ndarray, s_values: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tip poses in the base frame and tangents d p_tip / ds, with KDL rotations."""
        kdl = self.kdl
        start_r = np.asarray(trajectory.transform_object_to_base_start.rotation)
        start_p = np.asarray(trajectory.transform_object_to_base_start.translation)
        goal_p = np.asarray(trajectory.transform_object_to_base_goal.translation)
        log = np.asarray(trajectory.rotation_log_in_object, dtype=float)
        angle = float(np.linalg.norm(log))
        axis = kdl.Vector(*(log / angle)) if angle > 0 else kdl.Vector(0.0, 0.0, 1.0)
        lever = _cross(log, grasp_p)
        rotations = np.empty((len(s_values), 3, 3))
        positions = np.empty((len(s_values), 3))
        tangents = np.empty((len(s_values), 3))
        for i, s in enumerate(s_values):
            rot = kdl.Rotation.Rot(axis, float(s) * angle)
            object_r = start_r @ np.array([[rot[a, b] for b in range(3)] for a in range(3)])
            object_p = (1.0 - s) * start_p + s * goal_p
            rotations[i] = object_r @ grasp_r
            positions[i] = object_r @ grasp_p + object_p
            tangents[i] = goal_p - start_p + object_r @ lever
        return rotations, positions, tangents

    def evaluate(
        self,
        trajectory: Any,
        grasp_r: np.ndarray,
        grasp_p: np.ndarray,
        object_mass: float,
        object_com: np.ndarray,
        object_inertia: np.ndarray,
        seed: np.ndarray,
    ) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
        """IK along the grasp's tip path, then the effective mass per sample.

        Returns:
            reason ("" when feasible), effective masses [kg], joint positions, IK iterations.
        """
        config = self.config
        times = trajectory.times_s()
        s_values, _, _ = trajectory.path_parameter(times)
        rotations, positions, tangents = self.tip_path(trajectory, grasp_r, grasp_p, s_values)
        count = len(times)
        q_all = np.empty((count, self.n))
        iterations = np.zeros(count, dtype=int)
        check = config.check_velocity_limits & (self.chain.velocity > 0)
        defect, xi2 = np.zeros(6), 0.0
        for i in range(count):
            if i == 0:
                q, converged, iterations[i] = self.solve_first(rotations[0], positions[0], seed)
            else:
                guess, xi2 = self.predict(
                    q_all[i - 1],
                    self.last_tip_rotation,
                    rotations[i - 1],
                    positions[i - 1],
                    rotations[i],
                    positions[i],
                    defect,
                    xi2,
                )
                q, converged, iterations[i] = self.solve(rotations[i], positions[i], guess, defect)
            if not converged:
                return f"IK did not converge at sample {i}", np.empty(0), q_all[:i], iterations
            q_all[i] = q
            if i:
                delta = np.abs(q - q_all[i - 1])
                if delta.max() > config.max_joint_step:
                    return f"joint jump at sample {i}", np.empty(0), q_all[:i], iterations
                elapsed = times[i] - times[i - 1]
                if check.any() and elapsed > 0:
                    over = check & (delta / elapsed > self.chain.velocity * (1 + 1e-9))
                    if over.any():
                        return f"joint speed at sample {i}", np.empty(0), q_all[:i], iterations
        masses = self.effective_masses(
            q_all, tangents, grasp_r, grasp_p, object_mass, object_com, object_inertia
        )
        return "", masses, q_all, iterations

    def effective_masses(
        self,
        q_all: np.ndarray,
        tangents: np.ndarray,
        grasp_r: np.ndarray,
        grasp_p: np.ndarray,
        object_mass: float,
        object_com: np.ndarray,
        object_inertia: np.ndarray,
    ) -> np.ndarray:
        """Paper form: [(Lambda_robot + Lambda_obj)^-1]_3x3 per sample, 1 / (u^T A u)."""
        object_r_in_tip = grasp_r.T  # object axes in the tip frame
        com_in_tip = grasp_r.T @ (object_com - grasp_p)
        masses = np.empty(len(q_all))
        for i, q in enumerate(q_all):
            rotation, _ = self.forward(q)
            jacobian = self.jacobian(q)
            lambda_robot = np.linalg.inv(
                jacobian @ np.linalg.inv(self.mass_matrix(q)) @ jacobian.T
            )
            object_r = rotation @ object_r_in_tip
            lever = rotation @ com_in_tip
            lambda_com = np.zeros((6, 6))
            lambda_com[:3, :3] = object_mass * np.eye(3)
            lambda_com[3:, 3:] = object_r @ object_inertia @ object_r.T
            transform = np.eye(6)
            transform[:3, 3:] = -_skew(lever)
            lambda_object = transform.T @ lambda_com @ transform
            mobility = np.linalg.inv(lambda_robot + lambda_object)[:3, :3]
            norm = np.linalg.norm(tangents[i])
            if norm < 1e-9:
                masses[i] = 1.0 / np.linalg.eigvalsh(0.5 * (mobility + mobility.T))[0]
            else:
                unit = tangents[i] / norm
                masses[i] = 1.0 / (unit @ mobility @ unit)
        return masses
