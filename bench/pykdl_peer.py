"""The peer pipeline: the same grasp evaluation built on PyKDL (the library the paper used).

The KDL chain is built here from the same URDF (kdl_parser's conventions, parsed with
xml.etree: joints base -> tip, origins rpy/xyz, axes, link inertials). Kinematics and the
joint-space inertia come from KDL (ChainFkSolverPos_recursive, ChainJntToJacSolver,
ChainDynParam.JntToMass). The IK is the same damped Gauss-Newton loop as the core's (error
log6 of current^-1 * target in the tip frame, Jlog6, same damping, step limit, tolerances
1e-6 m / 1e-6 rad, the same warm start q_{i-1} + J^+ (log6(T_{i-1}^-1 T_i) + c_i) with the
core's extrapolated second-order defect c_i, deterministic restarts, jump and speed checks),
with its SE(3) log written in numpy. The effective mass is computed as the paper would have:
Lambda = (J M^-1 J^T)^-1 (numpy inverses), Lambda_tot = Lambda + Lambda_obj (Khatib's augmented
object, T^T Lambda_com T), then [Lambda_tot^-1]_3x3 and 1 / (u^T A u).

Nothing here uses Pinocchio: only the URDF file location and the IK settings come from the core.
"""

from __future__ import annotations

import importlib.util
import math
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from grasp_safety_ros.core.method.ik import PREDICTOR_MAX_RATIO

DIST_PACKAGES = Path("/usr/lib/python3/dist-packages")
_EPS = float(np.finfo(float).eps)
_PREC2 = _EPS ** (1.0 / 3.0)
_PREC3 = _EPS ** (1.0 / 4.0)


def load_pykdl(install: bool = True) -> tuple[ModuleType | None, str]:
    """Import PyKDL (Debian's python3-pykdl), installing it with apt-get when root.

    Only the PyKDL extension module is loaded from the system dist-packages (by file), so
    nothing else from the system Python shadows the venv's packages.

    Returns:
        The module, or None and the reason it is unavailable.
    """
    try:
        import PyKDL  # type: ignore[import-not-found]

        return PyKDL, ""
    except ImportError:
        pass
    tag = sys.implementation.cache_tag.replace("cpython-", "cpython-")  # e.g. cpython-311
    pattern = f"PyKDL.{tag}-*.so"

    def find() -> Path | None:
        matches = sorted(DIST_PACKAGES.glob(pattern))
        return matches[0] if matches else None

    path = find()
    if path is None and install:
        if shutil.which("apt-get") is None:
            return None, "PyKDL missing and apt-get unavailable (install python3-pykdl)"
        if hasattr(__import__("os"), "geteuid") and __import__("os").geteuid() != 0:
            return None, "PyKDL missing: run 'sudo apt-get install -y python3-pykdl'"
        print("bench: installing python3-pykdl with apt-get ...", file=sys.stderr)
        for command in (
            ["apt-get", "update", "-qq"],
            ["apt-get", "install", "-y", "-qq", "python3-pykdl"],
        ):
            done = subprocess.run(command, capture_output=True, text=True, check=False)
            if done.returncode != 0:
                return None, f"'{' '.join(command)}' failed: {done.stderr.strip()[-300:]}"
        path = find()
    if path is None:
        return None, (
            f"no {pattern} in {DIST_PACKAGES} (python3-pykdl is built for the system Python "
            f"{'.'.join(map(str, sys.version_info[:2]))}?)"
        )
    spec = importlib.util.spec_from_file_location("PyKDL", path)
    if spec is None or spec.loader is None:
        return None, f"cannot load {path}"
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except ImportError as error:
        return None, f"cannot import {path}: {error}"
    sys.modules["PyKDL"] = module
    return module, ""


# ----------------------------------------------------------------------------- URDF -> KDL
def _floats(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    return tuple(float(x) for x in text.split()) if text else default


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


@dataclass
class KDLChain:
    """A KDL chain with its solvers and joint limits (chain order)."""

    chain: Any
    joint_names: list[str]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray


def build_chain(kdl: ModuleType, urdf_text: str, base_link: str, tip_link: str) -> KDLChain:
    """The chain base_link -> tip_link of a URDF, as kdl_parser builds it.

    kdl_parser's tree keeps side branches (fingers, sensors) that a chain extracted from it
    drops; here each chain link also carries the inertia of everything rigidly hanging off it
    (side branches with their joints at zero, links beyond the tip), as the Pinocchio model
    (locked joints at their neutral position) does, so both describe the same rigid bodies.
    """
    root = ET.fromstring(urdf_text)
    links = {link.get("name"): link for link in root.findall("link")}
    joints = root.findall("joint")
    joint_of_child = {joint.find("child").get("link"): joint for joint in joints}
    children: dict[str, list[ET.Element]] = {}
    for joint in joints:
        children.setdefault(joint.find("parent").get("link"), []).append(joint)
    path = []
    link = tip_link
    while link != base_link:
        if link not in joint_of_child:
            raise ValueError(f"'{base_link}' is not upstream of '{tip_link}'")
        joint = joint_of_child[link]
        path.append(joint)
        link = joint.find("parent").get("link")
    path.reverse()
    on_path = {id(joint) for joint in path}
    chain = kdl.Chain()
    names, lower, upper, velocity = [], [], [], []
    for joint in path:
        rotation, translation = _origin(joint)
        frame = kdl.Frame(kdl.Rotation(*rotation.reshape(-1)), kdl.Vector(*translation))
        kind = joint.get("type")
        name = joint.get("name")
        if kind in ("revolute", "continuous", "prismatic"):
            axis_element = joint.find("axis")
            axis = _floats(
                axis_element.get("xyz") if axis_element is not None else None, (1.0, 0.0, 0.0)
            )
            axis_in_parent = frame.M * kdl.Vector(*axis)
            joint_type = kdl.Joint.TransAxis if kind == "prismatic" else kdl.Joint.RotAxis
            kdl_joint = kdl.Joint(name, frame.p, axis_in_parent, joint_type)
            limit = joint.find("limit")
            if kind == "continuous" or limit is None:
                lo, hi = -math.inf, math.inf
            else:
                lo, hi = float(limit.get("lower", 0.0)), float(limit.get("upper", 0.0))
            names.append(name)
            lower.append(lo)
            upper.append(hi)
            velocity.append(float(limit.get("velocity", 0.0)) if limit is not None else 0.0)
        elif kind == "fixed":
            kdl_joint = kdl.Joint(name, kdl.Joint.Fixed)
        else:
            raise ValueError(f"joint '{name}' of type '{kind}' is not supported by the peer")
        child = joint.find("child").get("link")
        body = _Body()
        _add_subtree(body, child, np.eye(3), np.zeros(3), links, children, on_path)
        chain.addSegment(kdl.Segment(child, kdl_joint, frame, body.kdl(kdl)))
    return KDLChain(chain, names, np.array(lower), np.array(upper), np.array(velocity))


def _origin(element: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    origin = element.find("origin")
    xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
    rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
    return _rpy_matrix(*rpy), np.array(xyz)


class _Body:
    """Sum of rigid-body inertias in one frame: mass, first moment, inertia about the origin."""

    def __init__(self) -> None:
        self.mass = 0.0
        self.moment = np.zeros(3)
        self.inertia_origin = np.zeros((3, 3))

    def add(self, mass: float, com: np.ndarray, inertia_com: np.ndarray) -> None:
        self.mass += mass
        self.moment += mass * com
        shift = float(com @ com) * np.eye(3) - np.outer(com, com)
        self.inertia_origin += inertia_com + mass * shift

    def kdl(self, kdl: ModuleType) -> Any:
        if self.mass <= 0.0:
            return kdl.RigidBodyInertia()
        com = self.moment / self.mass
        shift = float(com @ com) * np.eye(3) - np.outer(com, com)
        about_com = self.inertia_origin - self.mass * shift
        rotational = kdl.RotationalInertia(
            about_com[0, 0],
            about_com[1, 1],
            about_com[2, 2],
            about_com[0, 1],
            about_com[0, 2],
            about_com[1, 2],
        )
        return kdl.RigidBodyInertia(self.mass, kdl.Vector(*com), rotational)


def _add_subtree(
    body: _Body,
    link: str,
    rotation: np.ndarray,
    translation: np.ndarray,
    links: dict[str, ET.Element],
    children: dict[str, list[ET.Element]],
    on_path: set[int],
) -> None:
    """Add link's inertial and every off-path subtree below it (joints at zero) to body."""
    inertial = links[link].find("inertial")
    if inertial is not None:
        frame_r, frame_p = _origin(inertial)
        element = inertial.find("inertia")
        values = {key: float(element.get(key, 0.0)) for key in element.keys()}
        tensor = np.array(
            [
                [values.get("ixx", 0.0), values.get("ixy", 0.0), values.get("ixz", 0.0)],
                [values.get("ixy", 0.0), values.get("iyy", 0.0), values.get("iyz", 0.0)],
                [values.get("ixz", 0.0), values.get("iyz", 0.0), values.get("izz", 0.0)],
            ]
        )
        r = rotation @ frame_r
        mass = float(inertial.find("mass").get("value"))
        body.add(mass, rotation @ frame_p + translation, r @ tensor @ r.T)
    for joint in children.get(link, []):
        if id(joint) in on_path:
            continue
        joint_r, joint_p = _origin(joint)
        child = joint.find("child").get("link")
        _add_subtree(
            body,
            child,
            rotation @ joint_r,
            rotation @ joint_p + translation,
            links,
            children,
            on_path,
        )


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
