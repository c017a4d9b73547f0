"""Fast paths of the core: compiled kernels (numba) and a worker pool for large requests.

Kernels (used by ik.py and effective_mass.py through their ``backend="compiled"`` paths) mirror
the Pinocchio-based Python loops operation for operation: the same damped Gauss-Newton steps,
Pinocchio's own log6 / Jlog6 formulas (with its Taylor branches), the same warm start and the
same checks, so per-sample results equal the Python path's to rounding. They are compiled on
first use and cached on disk by numba (``cache=True``), and release the GIL (``nogil=True``),
so grasps can be evaluated on threads.

Pool: ``executor_for`` / ``evaluate_jobs`` spread the grasps of a large ``rank`` request
over threads (compiled path: the kernels run without the GIL) or processes (Python path),
results in input order; each grasp is computed by the same code as in the serial path, so the
results are identical to the serial ones, bit for bit.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import threading
import weakref
from collections.abc import Callable, Generator, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import replace
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

try:  # optional accelerator
    import numba
except ImportError:  # pragma: no cover - exercised on machines without numba
    numba = None

if TYPE_CHECKING:
    from .ik import IKSolver
    from .inertia import ObjectInertia
    from .ranking import EvaluationConfig, GraspEvaluation, GraspSafetyEvaluator
    from .robot import RobotModel
    from .trajectory import ObjectTrajectory


def _jit(function: Callable[..., Any]) -> Callable[..., Any]:
    if numba is None:  # pragma: no cover
        return function
    return numba.njit(cache=True, nogil=True, error_model="numpy")(function)


_EPS = float(np.finfo(np.float64).eps)
_PREC2 = _EPS ** (1.0 / 3.0)  # Pinocchio's TaylorSeriesExpansion<double>::precision<2>()
_PREC3 = _EPS ** (1.0 / 4.0)  # ... precision<3>()


# ----------------------------------------------------------------------------- kinematics
# Conventions: a chain is (placement_rotations (n,3,3), placement_translations (n,3), axes (n,3),
# prismatic (n,)); poses are (rotation, translation) pairs in the world (= model root) frame.
# Inner functions allocate nothing: callers pass every buffer.


@_jit
def _forward_kinematics(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    q,
    joint_rotations,
    joint_translations,
    fr,
    ft,
):
    """World poses of every joint frame (joint_*) and of the tip frame (fr, ft) at q.

    prismatic[k] is 1.0 for a prismatic joint, 0.0 for a revolute one: the joint turns by
    q (1 - prismatic) and slides by q prismatic (exactly the identity / zero otherwise).
    """
    pr, pt, jr, jt = (
        placement_rotations,
        placement_translations,
        joint_rotations,
        joint_translations,
    )
    n = q.shape[0]
    for k in range(n):
        # fr, ft: scratch for the pose of joint k's parent frame composed with its placement.
        if k == 0:
            for i in range(3):
                ft[i] = pt[0, i]
                for j in range(3):
                    fr[i, j] = pr[0, i, j]
        else:
            for i in range(3):
                r0, r1, r2 = jr[k - 1, i, 0], jr[k - 1, i, 1], jr[k - 1, i, 2]
                ft[i] = jt[k - 1, i] + r0 * pt[k, 0] + r1 * pt[k, 1] + r2 * pt[k, 2]
                fr[i, 0] = r0 * pr[k, 0, 0] + r1 * pr[k, 1, 0] + r2 * pr[k, 2, 0]
                fr[i, 1] = r0 * pr[k, 0, 1] + r1 * pr[k, 1, 1] + r2 * pr[k, 2, 1]
                fr[i, 2] = r0 * pr[k, 0, 2] + r1 * pr[k, 1, 2] + r2 * pr[k, 2, 2]
        ax, ay, az = axes[k, 0], axes[k, 1], axes[k, 2]
        slide = q[k] * prismatic[k]
        angle = q[k] - slide
        c = math.cos(angle)
        s = math.sin(angle)
        v = 1.0 - c
        m00, m01, m02 = c + v * ax * ax, v * ax * ay - s * az, v * ax * az + s * ay
        m10, m11, m12 = v * ay * ax + s * az, c + v * ay * ay, v * ay * az - s * ax
        m20, m21, m22 = v * az * ax - s * ay, v * az * ay + s * ax, c + v * az * az
        for i in range(3):
            a0, a1, a2 = fr[i, 0], fr[i, 1], fr[i, 2]
            jt[k, i] = ft[i] + slide * (a0 * ax + a1 * ay + a2 * az)
            jr[k, i, 0] = a0 * m00 + a1 * m10 + a2 * m20
            jr[k, i, 1] = a0 * m01 + a1 * m11 + a2 * m21
            jr[k, i, 2] = a0 * m02 + a1 * m12 + a2 * m22
    for i in range(3):
        r0, r1, r2 = jr[n - 1, i, 0], jr[n - 1, i, 1], jr[n - 1, i, 2]
        ft[i] = (
            jt[n - 1, i]
            + r0 * tip_translation[0]
            + r1 * tip_translation[1]
            + r2 * tip_translation[2]
        )
        for j in range(3):
            fr[i, j] = r0 * tip_rotation[0, j] + r1 * tip_rotation[1, j] + r2 * tip_rotation[2, j]


@_jit
def _local_jacobian(axes, prismatic, joint_rotations, joint_translations, fr, ft, out):
    """Tip-frame Jacobian (6 x n, LOCAL: [linear; angular] in tip axes), as Pinocchio's."""
    jr, jt = joint_rotations, joint_translations
    n = axes.shape[0]
    for k in range(n):
        ax, ay, az = axes[k, 0], axes[k, 1], axes[k, 2]
        u0 = jr[k, 0, 0] * ax + jr[k, 0, 1] * ay + jr[k, 0, 2] * az
        u1 = jr[k, 1, 0] * ax + jr[k, 1, 1] * ay + jr[k, 1, 2] * az
        u2 = jr[k, 2, 0] * ax + jr[k, 2, 1] * ay + jr[k, 2, 2] * az
        turn = 1.0 - prismatic[k]
        w0, w1, w2 = u0 * turn, u1 * turn, u2 * turn
        slide = prismatic[k]
        dx, dy, dz = jt[k, 0] - ft[0], jt[k, 1] - ft[1], jt[k, 2] - ft[2]
        l0 = (dy * w2 - dz * w1) + slide * u0
        l1 = (dz * w0 - dx * w2) + slide * u1
        l2 = (dx * w1 - dy * w0) + slide * u2
        for i in range(3):
            out[i, k] = fr[0, i] * l0 + fr[1, i] * l1 + fr[2, i] * l2
            out[3 + i, k] = fr[0, i] * w0 + fr[1, i] * w1 + fr[2, i] * w2


# ----------------------------------------------------------------------------- SO(3) / SE(3)
@_jit
def _compute_theta_axis(i0, val, rn, axis):
    """Pinocchio's internal::compute_theta_axis (log3 near pi); returns the angle."""
    i1 = (i0 + 1) % 3
    i2 = (i0 + 2) % 3
    sign = 1.0 if rn[i2, i1] >= rn[i1, i2] else -1.0
    s = math.sqrt(val + _EPS + _EPS * _EPS) * sign
    axis[i0] = s / 2.0
    axis[i1] = 1.0 / (2.0 * s) * (rn[i1, i0] + rn[i0, i1])
    axis[i2] = 1.0 / (2.0 * s) * (rn[i2, i0] + rn[i0, i2])
    w = 1.0 / (2.0 * s) * (rn[i2, i1] - rn[i1, i2])
    norm = math.sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2])
    angle = 2.0 * math.atan2(norm, w)
    for k in range(3):
        axis[k] /= norm
    return angle


@_jit
def _log3(rot):
    """Pinocchio's log3 (renormalised input, Taylor and near-pi branches): (theta, w0, w1, w2)."""
    n0 = math.sqrt(rot[0, 0] * rot[0, 0] + rot[1, 0] * rot[1, 0] + rot[2, 0] * rot[2, 0])
    n1 = math.sqrt(rot[0, 1] * rot[0, 1] + rot[1, 1] * rot[1, 1] + rot[2, 1] * rot[2, 1])
    a00, a10, a20 = rot[0, 0] / n0, rot[1, 0] / n0, rot[2, 0] / n0
    a01, a11, a21 = rot[0, 1] / n1, rot[1, 1] / n1, rot[2, 1] / n1
    a02 = a10 * a21 - a20 * a11  # col2 = col0 x col1
    a12 = a20 * a01 - a00 * a21
    a22 = a00 * a11 - a10 * a01
    b00 = a11 * a22 - a21 * a12  # col0 = col1 x col2
    b10 = a21 * a02 - a01 * a22
    b20 = a01 * a12 - a11 * a02
    a00, a10, a20 = b00, b10, b20
    tr = a00 + a11 + a22
    cos_value = (tr - 1.0) / 2.0
    prec = _PREC2
    u0, u1, u2 = 0.5 * (a21 - a12), 0.5 * (a02 - a20), 0.5 * (a10 - a01)
    if cos_value >= -1.0 + prec:
        if tr <= 3.0 - prec:
            theta = math.acos(cos_value)
        else:
            theta = math.sqrt(2.0 * (1.0 - cos_value) + _EPS * _EPS)
        if theta >= prec:
            t = theta / math.sin(theta)
        else:
            nrm2 = u0 * u0 + u1 * u1 + u2 * u2
            t = 1.0 + nrm2 / 6.0 + nrm2 * nrm2 * 3.0 / 40.0
        return theta, t * u0, t * u1, t * u2
    # Near pi (rare: far-off IK guesses): the axis from the largest diagonal entry.
    rn = np.empty((3, 3))
    rn[0, 0], rn[0, 1], rn[0, 2] = a00, a01, a02
    rn[1, 0], rn[1, 1], rn[1, 2] = a10, a11, a12
    rn[2, 0], rn[2, 1], rn[2, 2] = a20, a21, a22
    v0 = 2.0 * a00 - tr + 1.0
    v1 = 2.0 * a11 - tr + 1.0
    v2 = 2.0 * a22 - tr + 1.0
    axis = np.empty(3)
    if v0 >= v1:
        i0, val = (0, v0) if v0 >= v2 else (2, v2)
    else:
        i0, val = (1, v1) if v1 >= v2 else (2, v2)
    theta = _compute_theta_axis(i0, val, rn, axis)
    return theta, theta * axis[0], theta * axis[1], theta * axis[2]


@_jit
def _log6(rot, p, out):
    """Pinocchio's log6 of (rot, p) into out = [linear; angular]."""
    u0, u1, u2 = (
        0.5 * (rot[2, 1] - rot[1, 2]),
        0.5 * (rot[0, 2] - rot[2, 0]),
        0.5 * (rot[1, 0] - rot[0, 1]),
    )
    t2 = u0 * u0 + u1 * u1 + u2 * u2
    tr = rot[0, 0] + rot[1, 1] + rot[2, 2]
    theta, w0, w1, w2 = _log3(rot)
    if tr >= 3.0 - _PREC2:
        alpha = 1.0 - t2 / 12.0 - t2 * t2 / 720.0
        beta = 1.0 / 12.0 + t2 / 720.0
    else:
        st = math.sin(theta)
        ct = math.cos(theta)
        alpha = theta * st / (2.0 * (1.0 - ct))
        beta = 1.0 / (theta * theta) - st / (2.0 * theta * (1.0 - ct))
    wp = w0 * p[0] + w1 * p[1] + w2 * p[2]
    out[0] = alpha * p[0] - 0.5 * (w1 * p[2] - w2 * p[1]) + beta * wp * w0
    out[1] = alpha * p[1] - 0.5 * (w2 * p[0] - w0 * p[2]) + beta * wp * w1
    out[2] = alpha * p[2] - 0.5 * (w0 * p[1] - w1 * p[0]) + beta * wp * w2
    out[3], out[4], out[5] = w0, w1, w2


@_jit
def _jlog6(rot, p, out):
    """Pinocchio's Jlog6 of (rot, p) into the 6x6 array out."""
    t, w0, w1, w2 = _log3(rot)
    t2 = t * t
    st = math.sin(t)
    ct = math.cos(t)
    if t < _PREC3:  # Jlog3's and Jlog6's Taylor branches share the threshold
        alpha = 1.0 / 12.0 + t2 / 720.0
        diag = 0.5 * (2.0 - t2 / 6.0)
        beta = 1.0 / 12.0 + t2 / 720.0
        beta_dot_over_theta = 1.0 / 360.0
    else:
        st_1mct = st / (1.0 - ct)
        alpha = 1.0 / t2 - st_1mct / (2.0 * t)
        diag = 0.5 * (t * st_1mct)
        tinv = 1.0 / t
        t2inv = tinv * tinv
        inv_2_2ct = 1.0 / (2.0 * (1.0 - ct))
        beta = t2inv - st * tinv * inv_2_2ct
        beta_dot_over_theta = -2.0 * t2inv * t2inv + (1.0 + st * tinv) * t2inv * inv_2_2ct
    # A = Jlog3 (top-left and bottom-right blocks)
    a00 = alpha * w0 * w0 + diag
    a01 = alpha * w0 * w1 - 0.5 * w2
    a02 = alpha * w0 * w2 + 0.5 * w1
    a10 = alpha * w1 * w0 + 0.5 * w2
    a11 = alpha * w1 * w1 + diag
    a12 = alpha * w1 * w2 - 0.5 * w0
    a20 = alpha * w2 * w0 - 0.5 * w1
    a21 = alpha * w2 * w1 + 0.5 * w0
    a22 = alpha * w2 * w2 + diag
    p0, p1, p2 = p[0], p[1], p[2]
    wtp = w0 * p0 + w1 * p1 + w2 * p2
    k1 = beta_dot_over_theta * wtp
    k2 = t2 * beta_dot_over_theta + 2.0 * beta
    v0, v1, v2 = k1 * w0 - k2 * p0, k1 * w1 - k2 * p1, k1 * w2 - k2 * p2
    d = wtp * beta
    c00 = v0 * w0 + beta * w0 * p0 + d
    c01 = v0 * w1 + beta * w0 * p1 - 0.5 * p2
    c02 = v0 * w2 + beta * w0 * p2 + 0.5 * p1
    c10 = v1 * w0 + beta * w1 * p0 + 0.5 * p2
    c11 = v1 * w1 + beta * w1 * p1 + d
    c12 = v1 * w2 + beta * w1 * p2 - 0.5 * p0
    c20 = v2 * w0 + beta * w2 * p0 - 0.5 * p1
    c21 = v2 * w1 + beta * w2 * p1 + 0.5 * p0
    c22 = v2 * w2 + beta * w2 * p2 + d
    out[0, 0], out[0, 1], out[0, 2] = a00, a01, a02
    out[1, 0], out[1, 1], out[1, 2] = a10, a11, a12
    out[2, 0], out[2, 1], out[2, 2] = a20, a21, a22
    out[3, 3], out[3, 4], out[3, 5] = a00, a01, a02
    out[4, 3], out[4, 4], out[4, 5] = a10, a11, a12
    out[5, 3], out[5, 4], out[5, 5] = a20, a21, a22
    out[0, 3] = c00 * a00 + c01 * a10 + c02 * a20  # B = C A
    out[0, 4] = c00 * a01 + c01 * a11 + c02 * a21
    out[0, 5] = c00 * a02 + c01 * a12 + c02 * a22
    out[1, 3] = c10 * a00 + c11 * a10 + c12 * a20
    out[1, 4] = c10 * a01 + c11 * a11 + c12 * a21
    out[1, 5] = c10 * a02 + c11 * a12 + c12 * a22
    out[2, 3] = c20 * a00 + c21 * a10 + c22 * a20
    out[2, 4] = c20 * a01 + c21 * a11 + c22 * a21
    out[2, 5] = c20 * a02 + c21 * a12 + c22 * a22
    for i in range(3):
        for j in range(3):
            out[3 + i, j] = 0.0


@_jit
def _exp3(v0, v1, v2, out):
    """Pinocchio's exp3 of the rotation vector (v0, v1, v2) into the 3x3 array out."""
    t2 = v0 * v0 + v1 * v1 + v2 * v2 + _EPS * _EPS
    t = math.sqrt(t2)
    ct = math.cos(t)
    st = math.sin(t)
    if t > _PREC3:
        a_vxvx = (1.0 - ct) / t2
        a_vx = st / t
    else:
        a_vxvx = 0.5 - t2 / 24.0
        a_vx = 1.0 - t2 / 6.0
        ct = 1.0 - t2 / 2.0
    out[0, 0] = a_vxvx * v0 * v0 + ct
    out[0, 1] = a_vxvx * v0 * v1 - a_vx * v2
    out[0, 2] = a_vxvx * v0 * v2 + a_vx * v1
    out[1, 0] = a_vxvx * v1 * v0 + a_vx * v2
    out[1, 1] = a_vxvx * v1 * v1 + ct
    out[1, 2] = a_vxvx * v1 * v2 - a_vx * v0
    out[2, 0] = a_vxvx * v2 * v0 - a_vx * v1
    out[2, 1] = a_vxvx * v2 * v1 + a_vx * v0
    out[2, 2] = a_vxvx * v2 * v2 + ct


@_jit
def _lu_solve(a, b, m):
    """Solve a[:m, :m] x = b[:m] in place (b becomes x) by LU with partial pivoting."""
    for k in range(m):
        pivot = k
        largest = abs(a[k, k])
        for i in range(k + 1, m):
            if abs(a[i, k]) > largest:
                largest = abs(a[i, k])
                pivot = i
        if pivot != k:
            for j in range(m):
                a[k, j], a[pivot, j] = a[pivot, j], a[k, j]
            b[k], b[pivot] = b[pivot], b[k]
        inverse = 1.0 / a[k, k]
        for i in range(k + 1, m):
            factor = a[i, k] * inverse
            a[i, k] = factor
            for j in range(k + 1, m):
                a[i, j] -= factor * a[k, j]
    for i in range(m):
        total = b[i]
        for j in range(i):
            total -= a[i, j] * b[j]
        b[i] = total
    for i in range(m - 1, -1, -1):
        total = b[i]
        for j in range(i + 1, m):
            total -= a[i, j] * b[j]
        b[i] = total / a[i, i]


# ----------------------------------------------------------------------------- IK
@_jit
def _relative_pose(rotation_a, translation_a, rotation_b, translation_b, out_r, out_p):
    """(rotation_a, translation_a)^-1 * (rotation_b, translation_b) into (out_r, out_p)."""
    d0 = translation_b[0] - translation_a[0]
    d1 = translation_b[1] - translation_a[1]
    d2 = translation_b[2] - translation_a[2]
    for i in range(3):
        f0, f1, f2 = rotation_a[0, i], rotation_a[1, i], rotation_a[2, i]
        out_p[i] = f0 * d0 + f1 * d1 + f2 * d2
        for j in range(3):
            out_r[i, j] = f0 * rotation_b[0, j] + f1 * rotation_b[1, j] + f2 * rotation_b[2, j]


@_jit
def _damped_step(jacobian, error, max_iteration_step, system, rhs, step):
    """IKSolver._damped_step, compiled: the step-limited damped minimum-norm solution of
    jacobian (6 x n) @ step = error, into step (system, rhs: scratch).

    n >= 6: (J J^T + damping I) y = error, symmetric positive definite, is solved by LDL^T,
    step = J^T y. Rounding could make a pivot non-positive only where the damping (>= 1e-12)
    is below eps |J|^2, i.e. at a singularity of an arm with lever arms of tens of metres:
    then LU with partial pivoting, as before.
    """
    n = step.shape[0]
    e0, e1, e2, e3, e4, e5 = error[0], error[1], error[2], error[3], error[4], error[5]
    damping = 1e-12 + 1e-3 * (e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4 + e5 * e5)
    if n < 6:
        for a in range(n):
            for b in range(n):
                total = 0.0
                for i in range(6):
                    total += jacobian[i, a] * jacobian[i, b]
                system[a, b] = total
            system[a, a] += damping
            total = 0.0
            for i in range(6):
                total += jacobian[i, a] * error[i]
            rhs[a] = total
        _lu_solve(system, rhs, n)
        for k in range(n):
            step[k] = rhs[k]
    else:
        # J J^T: lower triangle in 21 independent sums (no latency chain through memory).
        a00 = a10 = a11 = a20 = a21 = a22 = a30 = a31 = a32 = a33 = 0.0
        a40 = a41 = a42 = a43 = a44 = a50 = a51 = a52 = a53 = a54 = a55 = 0.0
        for k in range(n):
            j0, j1, j2 = jacobian[0, k], jacobian[1, k], jacobian[2, k]
            j3, j4, j5 = jacobian[3, k], jacobian[4, k], jacobian[5, k]
            a00 += j0 * j0
            a10 += j1 * j0
            a11 += j1 * j1
            a20 += j2 * j0
            a21 += j2 * j1
            a22 += j2 * j2
            a30 += j3 * j0
            a31 += j3 * j1
            a32 += j3 * j2
            a33 += j3 * j3
            a40 += j4 * j0
            a41 += j4 * j1
            a42 += j4 * j2
            a43 += j4 * j3
            a44 += j4 * j4
            a50 += j5 * j0
            a51 += j5 * j1
            a52 += j5 * j2
            a53 += j5 * j3
            a54 += j5 * j4
            a55 += j5 * j5
        a00 += damping
        a11 += damping
        a22 += damping
        a33 += damping
        a44 += damping
        a55 += damping
        s = system
        s[0, 0] = a00
        s[1, 0], s[1, 1] = a10, a11
        s[2, 0], s[2, 1], s[2, 2] = a20, a21, a22
        s[3, 0], s[3, 1], s[3, 2], s[3, 3] = a30, a31, a32, a33
        s[4, 0], s[4, 1], s[4, 2], s[4, 3], s[4, 4] = a40, a41, a42, a43, a44
        s[5, 0], s[5, 1], s[5, 2], s[5, 3], s[5, 4], s[5, 5] = a50, a51, a52, a53, a54, a55
        # LDL^T in place: L below the diagonal, 1/D on it, L D above it.
        definite = True
        for j in range(6):
            total = s[j, j]
            for k in range(j):
                total -= s[j, k] * s[k, j]
            if not total > 0.0:
                definite = False
                break
            inverse = 1.0 / total
            s[j, j] = inverse
            for i in range(j + 1, 6):
                total = s[i, j]
                for k in range(j):
                    total -= s[i, k] * s[k, j]
                s[j, i] = total
                s[i, j] = total * inverse
        if definite:
            for i in range(6):
                total = error[i]
                for k in range(i):
                    total -= s[i, k] * rhs[k]
                rhs[i] = total
            for i in range(6):
                rhs[i] *= s[i, i]
            for i in range(5, -1, -1):
                total = rhs[i]
                for k in range(i + 1, 6):
                    total -= s[k, i] * rhs[k]
                rhs[i] = total
        else:  # pragma: no cover - see the docstring
            s[0, 0], s[0, 1], s[0, 2], s[0, 3], s[0, 4], s[0, 5] = a00, a10, a20, a30, a40, a50
            s[1, 0], s[1, 1], s[1, 2], s[1, 3], s[1, 4], s[1, 5] = a10, a11, a21, a31, a41, a51
            s[2, 0], s[2, 1], s[2, 2], s[2, 3], s[2, 4], s[2, 5] = a20, a21, a22, a32, a42, a52
            s[3, 0], s[3, 1], s[3, 2], s[3, 3], s[3, 4], s[3, 5] = a30, a31, a32, a33, a43, a53
            s[4, 0], s[4, 1], s[4, 2], s[4, 3], s[4, 4], s[4, 5] = a40, a41, a42, a43, a44, a54
            s[5, 0], s[5, 1], s[5, 2], s[5, 3], s[5, 4], s[5, 5] = a50, a51, a52, a53, a54, a55
            for i in range(6):
                rhs[i] = error[i]
            _lu_solve(s, rhs, 6)
        r0, r1, r2, r3, r4, r5 = rhs[0], rhs[1], rhs[2], rhs[3], rhs[4], rhs[5]
        for k in range(n):
            step[k] = (
                jacobian[0, k] * r0
                + jacobian[1, k] * r1
                + jacobian[2, k] * r2
                + jacobian[3, k] * r3
                + jacobian[4, k] * r4
                + jacobian[5, k] * r5
            )
    largest = 0.0
    for k in range(n):
        if abs(step[k]) > largest:
            largest = abs(step[k])
    if largest > max_iteration_step:
        scale = max_iteration_step / largest
        for k in range(n):
            step[k] *= scale


@_jit
def _predict(
    axes,
    prismatic,
    joint_rotations,
    joint_translations,
    fr,
    ft,
    rotation_previous,
    translation_previous,
    rotation_next,
    translation_next,
    max_iteration_step,
    q_previous,
    guess,
    er,
    et,
    error,
    jac,
    system,
    rhs,
    step,
):
    """IKSolver._predict, compiled: guess = q_previous + J^+ log6(T_{i-1}^-1 T_i).

    joint_*, fr, ft: the joint and tip poses at q_previous (as the solve that returned it
    leaves them), so the tip-frame Jacobian there costs no forward kinematics; er, et, error,
    jac, system, rhs, step: scratch.
    """
    _local_jacobian(axes, prismatic, joint_rotations, joint_translations, fr, ft, jac)
    _relative_pose(
        rotation_previous, translation_previous, rotation_next, translation_next, er, et
    )
    _log6(er, et, error)
    _damped_step(jac, error, max_iteration_step, system, rhs, step)
    for k in range(step.shape[0]):
        guess[k] = q_previous[k] + step[k]


@_jit
def _workspace(n):
    """Buffers of one IK / effective-mass evaluation for an n-joint chain."""
    m = 6 if n >= 6 else n
    return (
        np.empty((n, 3, 3)),  # 0 joint rotations
        np.empty((n, 3)),  # 1 joint translations
        np.empty((3, 3)),  # 2 tip rotation
        np.empty(3),  # 3 tip translation
        np.empty((3, 3)),  # 4 error rotation
        np.empty(3),  # 5 error translation
        np.empty((3, 3)),  # 6 inverse error rotation
        np.empty(3),  # 7 inverse error translation
        np.empty(6),  # 8 error twist
        np.empty((6, n)),  # 9 frame Jacobian
        np.empty((6, 6)),  # 10 Jlog6
        np.empty((6, n)),  # 11 task Jacobian
        np.empty((m, m)),  # 12 normal matrix
        np.empty(m),  # 13 right-hand side
        np.empty(n),  # 14 step
        np.empty((n, n)),  # 15 mass matrix
        np.empty((n, 3)),  # 16 motion subspaces, linear (world origin)
        np.empty((n, 3)),  # 17 ... angular
        np.empty((n, 3)),  # 18 tip linear Jacobian, transposed, base axes
        np.empty((3, 3)),  # 19 composite rotational inertia about the world origin
        np.empty((3, 3)),  # 20 scratch 3x3
    )


@_jit
def _solve_pose_into(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    lower_q,
    upper_q,
    target_rotation,
    target_translation,
    q_init,
    position_tolerance,
    orientation_tolerance,
    max_iterations,
    max_iteration_step,
    q,
    ws,
):
    """IKSolver._solve_python, compiled: q is overwritten; returns (converged, iterations).

    On return, ws holds the joint and tip poses at the returned q.
    """
    joint_rotations, joint_translations, fr, ft = ws[0], ws[1], ws[2], ws[3]
    er, et, ir, it, error, jac, jlog, jk = ws[4], ws[5], ws[6], ws[7], ws[8], ws[9], ws[10], ws[11]
    system, rhs, step = ws[12], ws[13], ws[14]
    n = q.shape[0]
    for k in range(n):
        q[k] = min(max(q_init[k], lower_q[k]), upper_q[k])
    for iteration in range(max_iterations + 1):
        _forward_kinematics(
            placement_rotations,
            placement_translations,
            axes,
            prismatic,
            tip_rotation,
            tip_translation,
            q,
            joint_rotations,
            joint_translations,
            fr,
            ft,
        )
        _relative_pose(fr, ft, target_rotation, target_translation, er, et)  # current^-1 target
        _log6(er, et, error)
        position_error = math.sqrt(et[0] * et[0] + et[1] * et[1] + et[2] * et[2])
        angle_error = math.sqrt(error[3] * error[3] + error[4] * error[4] + error[5] * error[5])
        if position_error <= position_tolerance and angle_error <= orientation_tolerance:
            return True, iteration
        if iteration == max_iterations:
            break
        _local_jacobian(axes, prismatic, joint_rotations, joint_translations, fr, ft, jac)
        for i in range(3):  # inverse error transform
            it[i] = -(er[0, i] * et[0] + er[1, i] * et[1] + er[2, i] * et[2])
            for j in range(3):
                ir[i, j] = er[j, i]
        _jlog6(ir, it, jlog)
        # jk = Jlog6 jac; Jlog6 = [[A, B], [0, A]]: columns independent, no zero products.
        a00, a01, a02 = jlog[0, 0], jlog[0, 1], jlog[0, 2]
        a10, a11, a12 = jlog[1, 0], jlog[1, 1], jlog[1, 2]
        a20, a21, a22 = jlog[2, 0], jlog[2, 1], jlog[2, 2]
        b00, b01, b02 = jlog[0, 3], jlog[0, 4], jlog[0, 5]
        b10, b11, b12 = jlog[1, 3], jlog[1, 4], jlog[1, 5]
        b20, b21, b22 = jlog[2, 3], jlog[2, 4], jlog[2, 5]
        for k in range(n):
            v0, v1, v2 = jac[0, k], jac[1, k], jac[2, k]
            w0, w1, w2 = jac[3, k], jac[4, k], jac[5, k]
            jk[0, k] = a00 * v0 + a01 * v1 + a02 * v2 + b00 * w0 + b01 * w1 + b02 * w2
            jk[1, k] = a10 * v0 + a11 * v1 + a12 * v2 + b10 * w0 + b11 * w1 + b12 * w2
            jk[2, k] = a20 * v0 + a21 * v1 + a22 * v2 + b20 * w0 + b21 * w1 + b22 * w2
            jk[3, k] = a00 * w0 + a01 * w1 + a02 * w2
            jk[4, k] = a10 * w0 + a11 * w1 + a12 * w2
            jk[5, k] = a20 * w0 + a21 * w1 + a22 * w2
        _damped_step(jk, error, max_iteration_step, system, rhs, step)
        for k in range(n):
            q[k] = min(max(q[k] + step[k], lower_q[k]), upper_q[k])
    return False, max_iterations


@_jit
def solve_pose(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    base_rotation,
    lower_q,
    upper_q,
    target_rotation,
    target_translation,
    q_init,
    position_tolerance,
    orientation_tolerance,
    max_iterations,
    max_iteration_step,
):
    """One tip pose (world frame) from q_init: (q, converged, iterations)."""
    n = axes.shape[0]
    q = np.empty(n)
    converged, iterations = _solve_pose_into(
        placement_rotations,
        placement_translations,
        axes,
        prismatic,
        tip_rotation,
        tip_translation,
        lower_q,
        upper_q,
        target_rotation,
        target_translation,
        q_init,
        position_tolerance,
        orientation_tolerance,
        max_iterations,
        max_iteration_step,
        q,
        _workspace(n),
    )
    return q, converged, iterations


@_jit
def _trajectory_step(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    lower_q,
    upper_q,
    target_rotations,
    target_translations,
    times,
    i,
    position_tolerance,
    orientation_tolerance,
    max_iterations,
    max_iteration_step,
    max_joint_step,
    check_velocity,
    any_velocity_check,
    velocity_limits,
    q_all,
    iterations,
    q_fail,
    guess,
    q,
    ws,
):
    """Sample i >= 1 of IKSolver._trajectory_python: (status, joint, value); status 0 is OK.

    ws must hold the joint and tip poses at q_all[i - 1] (for the predictor); on return it
    holds those at q.
    """
    n = q.shape[0]
    _predict(
        axes,
        prismatic,
        ws[0],
        ws[1],
        ws[2],
        ws[3],
        target_rotations[i - 1],
        target_translations[i - 1],
        target_rotations[i],
        target_translations[i],
        max_iteration_step,
        q_all[i - 1],
        guess,
        ws[4],
        ws[5],
        ws[8],
        ws[9],
        ws[12],
        ws[13],
        ws[14],
    )
    converged, iterations[i] = _solve_pose_into(
        placement_rotations,
        placement_translations,
        axes,
        prismatic,
        tip_rotation,
        tip_translation,
        lower_q,
        upper_q,
        target_rotations[i],
        target_translations[i],
        guess,
        position_tolerance,
        orientation_tolerance,
        max_iterations,
        max_iteration_step,
        q,
        ws,
    )
    if not converged:
        for k in range(n):
            q_fail[k] = q[k]
        return 1, 0, 0.0
    worst = 0
    largest = -1.0
    for k in range(n):
        q_all[i, k] = q[k]
        delta = abs(q[k] - q_all[i - 1, k])
        if delta > largest:
            largest = delta
            worst = k
    if largest > max_joint_step:
        return 2, worst, largest
    elapsed = times[i] - times[i - 1]
    if any_velocity_check and elapsed > 0:
        for k in range(n):
            speed = abs(q[k] - q_all[i - 1, k]) / elapsed
            if check_velocity[k] and speed > velocity_limits[k] * (1 + 1e-9):
                return 3, k, speed
    return 0, 0, 0.0


@_jit
def solve_trajectory(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    base_rotation,
    lower_q,
    upper_q,
    target_rotations,
    target_translations,
    times,
    q0,
    position_tolerance,
    orientation_tolerance,
    max_iterations,
    max_iteration_step,
    max_joint_step,
    check_velocity,
    velocity_limits,
    q_all,
    iterations,
    q_fail,
):
    """IKSolver._trajectory_python, compiled: samples 1.. from the solution q0 of sample 0.

    Fills q_all and iterations; returns (status, sample, joint, value) as the Python path.
    """
    count = target_rotations.shape[0]
    n = axes.shape[0]
    ws = _workspace(n)
    guess = np.empty(n)
    q = np.empty(n)
    any_velocity_check = False
    for k in range(n):
        q_all[0, k] = q0[k]
        if check_velocity[k]:
            any_velocity_check = True
    _forward_kinematics(  # the predictor of sample 1 needs the poses at q0
        placement_rotations,
        placement_translations,
        axes,
        prismatic,
        tip_rotation,
        tip_translation,
        q_all[0],
        ws[0],
        ws[1],
        ws[2],
        ws[3],
    )
    for i in range(1, count):
        status, joint, value = _trajectory_step(
            placement_rotations,
            placement_translations,
            axes,
            prismatic,
            tip_rotation,
            tip_translation,
            lower_q,
            upper_q,
            target_rotations,
            target_translations,
            times,
            i,
            position_tolerance,
            orientation_tolerance,
            max_iterations,
            max_iteration_step,
            max_joint_step,
            check_velocity,
            any_velocity_check,
            velocity_limits,
            q_all,
            iterations,
            q_fail,
            guess,
            q,
            ws,
        )
        if status != 0:
            return status, i, joint, value
    return 0, count, 0, 0.0


# ----------------------------------------------------------------------------- effective mass
@_jit
def _mobility_from_frames(
    axes, prismatic, base_rotation, masses, levers, rotational_inertias, ws, out
):
    """[J M^-1 J^T]_3x3 at the tip origin, base axes [1/kg], from the joint and tip poses in ws.

    M: joint-space inertia of the chain whose body k has mass masses[k], centre of mass
    levers[k] and rotational inertia about it rotational_inertias[k] (joint-k frame), by the
    composite-rigid-body algorithm in world axes; M^-1 through its Cholesky factor.
    """
    jr, jp, ft = ws[0], ws[1], ws[3]
    mass_matrix, sv, sw, jt, io, tmp = ws[15], ws[16], ws[17], ws[18], ws[19], ws[20]
    n = axes.shape[0]
    for k in range(n):
        ax, ay, az = axes[k, 0], axes[k, 1], axes[k, 2]
        u0 = jr[k, 0, 0] * ax + jr[k, 0, 1] * ay + jr[k, 0, 2] * az
        u1 = jr[k, 1, 0] * ax + jr[k, 1, 1] * ay + jr[k, 1, 2] * az
        u2 = jr[k, 2, 0] * ax + jr[k, 2, 1] * ay + jr[k, 2, 2] * az
        turn = 1.0 - prismatic[k]
        slide = prismatic[k]
        w0, w1, w2 = u0 * turn, u1 * turn, u2 * turn
        p0, p1, p2 = jp[k, 0], jp[k, 1], jp[k, 2]
        sw[k, 0], sw[k, 1], sw[k, 2] = w0, w1, w2
        sv[k, 0] = (p1 * w2 - p2 * w1) + slide * u0
        sv[k, 1] = (p2 * w0 - p0 * w2) + slide * u1
        sv[k, 2] = (p0 * w1 - p1 * w0) + slide * u2
        dx, dy, dz = ft[0] - p0, ft[1] - p1, ft[2] - p2
        l0 = (w1 * dz - w2 * dy) + slide * u0
        l1 = (w2 * dx - w0 * dz) + slide * u1
        l2 = (w0 * dy - w1 * dx) + slide * u2
        for i in range(3):
            jt[k, i] = (
                base_rotation[0, i] * l0 + base_rotation[1, i] * l1 + base_rotation[2, i] * l2
            )
    # Composite inertia of bodies k..n-1 about the world origin: mass, first moment h, io.
    total_mass = 0.0
    h0 = h1 = h2 = 0.0
    for i in range(3):
        for j in range(3):
            io[i, j] = 0.0
    for k in range(n - 1, -1, -1):
        m = masses[k]
        lx, ly, lz = levers[k, 0], levers[k, 1], levers[k, 2]
        c0 = jp[k, 0] + jr[k, 0, 0] * lx + jr[k, 0, 1] * ly + jr[k, 0, 2] * lz
        c1 = jp[k, 1] + jr[k, 1, 0] * lx + jr[k, 1, 1] * ly + jr[k, 1, 2] * lz
        c2 = jp[k, 2] + jr[k, 2, 0] * lx + jr[k, 2, 1] * ly + jr[k, 2, 2] * lz
        for i in range(3):
            r0, r1, r2 = jr[k, i, 0], jr[k, i, 1], jr[k, i, 2]
            for j in range(3):
                tmp[i, j] = (
                    r0 * rotational_inertias[k, 0, j]
                    + r1 * rotational_inertias[k, 1, j]
                    + r2 * rotational_inertias[k, 2, j]
                )
        cc = c0 * c0 + c1 * c1 + c2 * c2
        mc0, mc1, mc2 = m * c0, m * c1, m * c2
        for i in range(3):
            t0, t1, t2 = tmp[i, 0], tmp[i, 1], tmp[i, 2]
            mci = mc0 if i == 0 else (mc1 if i == 1 else mc2)
            io[i, 0] += (t0 * jr[k, 0, 0] + t1 * jr[k, 0, 1] + t2 * jr[k, 0, 2]) - mci * c0
            io[i, 1] += (t0 * jr[k, 1, 0] + t1 * jr[k, 1, 1] + t2 * jr[k, 1, 2]) - mci * c1
            io[i, 2] += (t0 * jr[k, 2, 0] + t1 * jr[k, 2, 1] + t2 * jr[k, 2, 2]) - mci * c2
            io[i, i] += m * cc
        h0 += mc0
        h1 += mc1
        h2 += mc2
        total_mass += m
        # Force of the composite moving along joint k: f = m v - h x w, n = h x v + io w.
        v0, v1, v2 = sv[k, 0], sv[k, 1], sv[k, 2]
        w0, w1, w2 = sw[k, 0], sw[k, 1], sw[k, 2]
        f0 = total_mass * v0 - (h1 * w2 - h2 * w1)
        f1 = total_mass * v1 - (h2 * w0 - h0 * w2)
        f2 = total_mass * v2 - (h0 * w1 - h1 * w0)
        n0 = (h1 * v2 - h2 * v1) + io[0, 0] * w0 + io[0, 1] * w1 + io[0, 2] * w2
        n1 = (h2 * v0 - h0 * v2) + io[1, 0] * w0 + io[1, 1] * w1 + io[1, 2] * w2
        n2 = (h0 * v1 - h1 * v0) + io[2, 0] * w0 + io[2, 1] * w1 + io[2, 2] * w2
        for i in range(k + 1):
            value = (
                sv[i, 0] * f0
                + sv[i, 1] * f1
                + sv[i, 2] * f2
                + sw[i, 0] * n0
                + sw[i, 1] * n1
                + sw[i, 2] * n2
            )
            mass_matrix[i, k] = value
            mass_matrix[k, i] = value
    # Cholesky M = L L^T (lower triangle), X = L^-1 J^T (in jt), A = X^T X.
    for j in range(n):
        total = mass_matrix[j, j]
        for k in range(j):
            total -= mass_matrix[j, k] * mass_matrix[j, k]
        diagonal = math.sqrt(total)
        mass_matrix[j, j] = diagonal
        for i in range(j + 1, n):
            total = mass_matrix[i, j]
            for k in range(j):
                total -= mass_matrix[i, k] * mass_matrix[j, k]
            mass_matrix[i, j] = total / diagonal
    for c in range(3):
        for i in range(n):
            total = jt[i, c]
            for k in range(i):
                total -= mass_matrix[i, k] * jt[k, c]
            jt[i, c] = total / mass_matrix[i, i]
    for a in range(3):
        for b in range(a, 3):
            total = 0.0
            for i in range(n):
                total += jt[i, a] * jt[i, b]
            out[a, b] = total
            out[b, a] = total


@_jit
def translational_mobilities(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    base_rotation,
    masses,
    levers,
    rotational_inertias,
    q_all,
    out,
):
    """_mobility_from_frames for each row of q_all, into out (N, 3, 3)."""
    ws = _workspace(axes.shape[0])
    for sample in range(q_all.shape[0]):
        _forward_kinematics(
            placement_rotations,
            placement_translations,
            axes,
            prismatic,
            tip_rotation,
            tip_translation,
            q_all[sample],
            ws[0],
            ws[1],
            ws[2],
            ws[3],
        )
        _mobility_from_frames(
            axes, prismatic, base_rotation, masses, levers, rotational_inertias, ws, out[sample]
        )


# ----------------------------------------------------------------------------- fused
@_jit
def evaluate_grasp(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    base_rotation,
    lower_q,
    upper_q,
    base_translation,
    start_rotation,
    start_translation,
    goal_translation,
    rotation_log,
    grasp_rotation,
    grasp_translation,
    times,
    s_values,
    seed_q,
    q0_given,
    position_tolerance,
    orientation_tolerance,
    max_iterations,
    max_iteration_step,
    max_joint_step,
    check_velocity,
    velocity_limits,
    masses,
    levers,
    rotational_inertias,
    stationary_tangent,
    target_rotations,
    target_translations,
    tangents,
    tangent_norms,
    q_all,
    iterations,
    q_fail,
    mobilities,
    effective_masses,
    directions,
    worst,
):
    """One grasp along an object trajectory: tip path, IK, effective mass; one call.

    The same computation as ObjectTrajectory.tip_path + IKSolver.solve_trajectory +
    translational_mobility_in_base + effective_mass_along, sample by sample. The tip poses
    (world frame) and path tangents (base axes) are written first. Sample 0 is solved from
    seed_q unless q0_given (then seed_q is its solution, found by the caller's restarts).

    Returns:
        (status, sample, joint, value): status 0 OK, 1 IK not converged, 2 joint jump,
        3 joint speed over its limit, 4 sample 0 not converged from the seed (q_fail holds
        the last iterate); for worst[i] samples (tip not translating) the caller fills
        directions and effective masses from mobilities[i].
    """
    count = s_values.shape[0]
    n = axes.shape[0]
    ws = _workspace(n)
    rot = ws[20]
    linear0 = goal_translation[0] - start_translation[0]
    linear1 = goal_translation[1] - start_translation[1]
    linear2 = goal_translation[2] - start_translation[2]
    g0, g1, g2 = grasp_translation[0], grasp_translation[1], grasp_translation[2]
    lever0 = rotation_log[1] * g2 - rotation_log[2] * g1
    lever1 = rotation_log[2] * g0 - rotation_log[0] * g2
    lever2 = rotation_log[0] * g1 - rotation_log[1] * g0
    ro = np.empty((3, 3))
    rt = np.empty((3, 3))
    po = np.empty(3)
    pt = np.empty(3)
    for i in range(count):
        s = s_values[i]
        _exp3(s * rotation_log[0], s * rotation_log[1], s * rotation_log[2], rot)
        for a in range(3):
            for b in range(3):
                ro[a, b] = (
                    start_rotation[a, 0] * rot[0, b]
                    + start_rotation[a, 1] * rot[1, b]
                    + start_rotation[a, 2] * rot[2, b]
                )
            po[a] = (1.0 - s) * start_translation[a] + s * goal_translation[a]
        for a in range(3):
            for b in range(3):
                rt[a, b] = (
                    ro[a, 0] * grasp_rotation[0, b]
                    + ro[a, 1] * grasp_rotation[1, b]
                    + ro[a, 2] * grasp_rotation[2, b]
                )
            pt[a] = ro[a, 0] * g0 + ro[a, 1] * g1 + ro[a, 2] * g2 + po[a]
        tangents[i, 0] = linear0 + ro[0, 0] * lever0 + ro[0, 1] * lever1 + ro[0, 2] * lever2
        tangents[i, 1] = linear1 + ro[1, 0] * lever0 + ro[1, 1] * lever1 + ro[1, 2] * lever2
        tangents[i, 2] = linear2 + ro[2, 0] * lever0 + ro[2, 1] * lever1 + ro[2, 2] * lever2
        tangent_norms[i] = math.sqrt(
            tangents[i, 0] * tangents[i, 0]
            + tangents[i, 1] * tangents[i, 1]
            + tangents[i, 2] * tangents[i, 2]
        )
        for a in range(3):
            target_translations[i, a] = base_translation[a] + (
                base_rotation[a, 0] * pt[0]
                + base_rotation[a, 1] * pt[1]
                + base_rotation[a, 2] * pt[2]
            )
            for b in range(3):
                target_rotations[i, a, b] = (
                    base_rotation[a, 0] * rt[0, b]
                    + base_rotation[a, 1] * rt[1, b]
                    + base_rotation[a, 2] * rt[2, b]
                )
    guess = np.empty(n)
    q = np.empty(n)
    if q0_given:
        for k in range(n):
            q[k] = seed_q[k]
        _forward_kinematics(
            placement_rotations,
            placement_translations,
            axes,
            prismatic,
            tip_rotation,
            tip_translation,
            q,
            ws[0],
            ws[1],
            ws[2],
            ws[3],
        )
    else:
        converged, iterations[0] = _solve_pose_into(
            placement_rotations,
            placement_translations,
            axes,
            prismatic,
            tip_rotation,
            tip_translation,
            lower_q,
            upper_q,
            target_rotations[0],
            target_translations[0],
            seed_q,
            position_tolerance,
            orientation_tolerance,
            max_iterations,
            max_iteration_step,
            q,
            ws,
        )
        if not converged:
            for k in range(n):
                q_fail[k] = q[k]
            return 4, 0, 0, 0.0
    any_velocity_check = False
    for k in range(n):
        q_all[0, k] = q[k]
        if check_velocity[k]:
            any_velocity_check = True
    for i in range(count):
        if i > 0:
            status, joint, value = _trajectory_step(
                placement_rotations,
                placement_translations,
                axes,
                prismatic,
                tip_rotation,
                tip_translation,
                lower_q,
                upper_q,
                target_rotations,
                target_translations,
                times,
                i,
                position_tolerance,
                orientation_tolerance,
                max_iterations,
                max_iteration_step,
                max_joint_step,
                check_velocity,
                any_velocity_check,
                velocity_limits,
                q_all,
                iterations,
                q_fail,
                guess,
                q,
                ws,
            )
            if status != 0:
                return status, i, joint, value
        # ws holds the joint poses at q_all[i] (the IK's last forward kinematics).
        mobility = mobilities[i]
        _mobility_from_frames(
            axes, prismatic, base_rotation, masses, levers, rotational_inertias, ws, mobility
        )
        norm = tangent_norms[i]
        if norm < stationary_tangent:
            worst[i] = True
            continue
        worst[i] = False
        d0, d1, d2 = tangents[i, 0] / norm, tangents[i, 1] / norm, tangents[i, 2] / norm
        directions[i, 0], directions[i, 1], directions[i, 2] = d0, d1, d2
        unit_norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        u0, u1, u2 = d0 / unit_norm, d1 / unit_norm, d2 / unit_norm
        quadratic = 0.0
        for a in range(3):
            ua = u0 if a == 0 else (u1 if a == 1 else u2)
            quadratic += ua * (mobility[a, 0] * u0 + mobility[a, 1] * u1 + mobility[a, 2] * u2)
        effective_masses[i] = 1.0 / quadratic
    return 0, count, 0, 0.0


_ROBOT_INERTIAS: weakref.WeakKeyDictionary[Any, tuple[np.ndarray, ...]] = (
    weakref.WeakKeyDictionary()
)
"""robot_inertia_arrays of each RobotModel in use."""


class CompiledGraspResult(NamedTuple):
    """What ``evaluate_grasp_compiled`` returns; arrays have one row per sample if feasible."""

    reason: str
    q: np.ndarray
    iterations: np.ndarray
    mobilities: np.ndarray
    effective_masses: np.ndarray
    directions: np.ndarray
    worst: np.ndarray
    tangent_norms: np.ndarray


def evaluate_grasp_compiled(
    solver: IKSolver,
    object_inertia: ObjectInertia,
    trajectory: ObjectTrajectory,
    transform_tip_to_object: Any,
    times_s: np.ndarray,
    s_values: np.ndarray,
    seed_q: np.ndarray,
) -> CompiledGraspResult:
    """One grasp with the fused kernel ``evaluate_grasp`` (solver.compiled must be true).

    Directions and effective masses of samples where the tip does not translate (``worst``)
    are left for the caller. Random restarts of sample 0 run here, as in ``solve_first``.
    """
    from .effective_mass import augmented_inertia_arrays, robot_inertia_arrays
    from .ranking import STATIONARY_TANGENT_M

    chain, config, robot = solver.chain, solver.config, solver.robot
    assert chain is not None
    count = len(s_values)
    n = robot.model.nq
    robot_arrays = _ROBOT_INERTIAS.get(robot)
    if robot_arrays is None:
        robot_arrays = _ROBOT_INERTIAS.setdefault(robot, robot_inertia_arrays(robot))
    masses, levers, rotational = augmented_inertia_arrays(
        robot, object_inertia, transform_tip_to_object, robot_arrays
    )
    velocity_limits = np.asarray(robot.velocity_limits, dtype=float)
    check_velocity = (
        config.check_velocity_limits & np.isfinite(velocity_limits) & (velocity_limits > 0)
    )
    start = trajectory.transform_object_to_base_start
    base = robot.transform_base_to_world
    times_s = np.ascontiguousarray(times_s, dtype=float)
    s_values = np.ascontiguousarray(s_values, dtype=float)
    target_rotations = np.empty((count, 3, 3))
    target_translations = np.empty((count, 3))
    tangents = np.empty((count, 3))
    tangent_norms = np.empty(count)
    q_all = np.empty((count, n))
    iterations = np.zeros(count, dtype=np.int64)
    q_fail = np.empty(n)
    mobilities = np.empty((count, 3, 3))
    effective_masses = np.empty(count)
    directions = np.empty((count, 3))
    worst = np.zeros(count, dtype=np.bool_)
    fixed = (
        np.ascontiguousarray(base.translation),
        np.ascontiguousarray(start.rotation),
        np.ascontiguousarray(start.translation),
        np.ascontiguousarray(trajectory.transform_object_to_base_goal.translation),
        np.ascontiguousarray(trajectory.rotation_log_in_object, dtype=float),
        np.ascontiguousarray(transform_tip_to_object.rotation),
        np.ascontiguousarray(transform_tip_to_object.translation),
        times_s,
        s_values,
    )
    limits = (
        config.position_tolerance_m,
        config.orientation_tolerance_rad,
        config.max_iterations,
        config.max_iteration_step,
        config.max_joint_step,
        check_velocity,
        velocity_limits,
        masses,
        levers,
        rotational,
        STATIONARY_TANGENT_M,
        target_rotations,
        target_translations,
        tangents,
        tangent_norms,
        q_all,
        iterations,
        q_fail,
        mobilities,
        effective_masses,
        directions,
        worst,
    )
    status, index, joint, value = evaluate_grasp(
        *chain, *fixed, np.asarray(seed_q, dtype=float), False, *limits
    )
    if status == 4:  # sample 0 failed from the seed: deterministic random restarts
        total = int(iterations[0])
        converged = False
        for restart in solver.restarts():
            q0, converged, restart_iterations = solve_pose(
                *chain,
                target_rotations[0],
                target_translations[0],
                restart,
                config.position_tolerance_m,
                config.orientation_tolerance_rad,
                config.max_iterations,
                config.max_iteration_step,
            )
            total += int(restart_iterations)
            if converged:
                break
            q_fail = q0
        if not converged:
            empty = np.empty(0)
            return CompiledGraspResult(
                solver.first_sample_reason(q_fail, times_s),
                np.empty((0, n)),
                np.zeros(0, dtype=np.int64),
                np.empty((0, 3, 3)),
                empty,
                np.empty((0, 3)),
                np.zeros(0, dtype=bool),
                empty,
            )
        status, index, joint, value = evaluate_grasp(*chain, *fixed, q0, True, *limits)
        iterations[0] = total
    if status != 0:
        reason = solver.failure_reason(status, index, joint, value, q_fail, times_s)
        return CompiledGraspResult(
            reason,
            q_all[:index],
            iterations[:index],
            mobilities[:index],
            effective_masses[:index],
            directions[:index],
            worst[:index],
            tangent_norms[:index],
        )
    return CompiledGraspResult(
        "", q_all, iterations, mobilities, effective_masses, directions, worst, tangent_norms
    )


_WARM_UP_URDF = """<robot name="warm_up"><link name="base"/>
<link name="a"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
 ixy="0" ixz="0" iyz="0"/></inertial></link>
<link name="b"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
 ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
 <limit lower="-3" upper="3" effort="1" velocity="10"/></joint>
<joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0.3 0 0"/>
 <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="10"/></joint>
</robot>"""


def warm_up(evaluator: GraspSafetyEvaluator | None = None) -> float:
    """Compile the kernels (first use on a machine, ~10-20 s) or load them from numba's disk
    cache (later, < 1 s), so that the first real request does not pay for it.

    Args:
        evaluator: The evaluator to warm up; None: a small built-in arm (the compiled code
            does not depend on the robot, so this fills the cache for every robot).

    Returns:
        The time taken [s]; 0 when the compiled backend is not in use.
    """
    import time

    import pinocchio as pin

    from .inertia import solid_box
    from .ranking import Grasp, GraspSafetyEvaluator
    from .robot import RobotModel
    from .trajectory import ObjectTrajectory

    start = time.perf_counter()
    if evaluator is None:
        evaluator = GraspSafetyEvaluator(RobotModel.from_urdf(_WARM_UP_URDF, "base", "b"))
    if not evaluator.ik.compiled:
        return 0.0
    robot = evaluator.robot
    pose = robot.transform_tip_to_base(robot.default_seed_positions())
    trajectory = ObjectTrajectory(pose, pose, 0.02, 0.01)
    with np.errstate(all="ignore"):  # the pose may be singular: only the compiling matters
        box = solid_box(1.0, (0.1, 0.1, 0.1))
        evaluator.evaluate(Grasp(pin.SE3.Identity()), box, trajectory)
    evaluator.ik.solve(pose, robot.q_from_positions(robot.default_seed_positions()))
    return time.perf_counter() - start


# ----------------------------------------------------------------------------- pool
def default_workers() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def executor_for(evaluator: GraspSafetyEvaluator, total_samples: int) -> Executor | None:
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
        if evaluator.ik.compiled:
            pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="grasp_safety")
        else:
            pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=multiprocessing.get_context(
                    "fork" if threading.active_count() == 1 else "forkserver"
                ),
                initializer=_init_worker,
                initargs=(evaluator.robot, replace(config, workers=1)),
            )
        evaluator._grasp_pool = pool  # type: ignore[attr-defined]
        weakref.finalize(evaluator, pool.shutdown, False)
    return pool


Job = tuple[Any, ...]
"""Arguments of GraspSafetyEvaluator._evaluate_sampled."""


def evaluate_jobs(
    evaluator: GraspSafetyEvaluator, executor: Executor, jobs: Sequence[Job]
) -> Generator[GraspEvaluation, None, None]:
    """``evaluator.evaluate`` of each job on the pool, yielded in job order.

    On processes, jobs go out in contiguous chunks (about four per worker), which keeps the
    pool's per-task overhead small and the load balanced; on threads one job is one task (the
    overhead is small), so the caller sees each result, and can stop, as soon as it is ready.
    Closing the returned generator early (an abandoned ranking) cancels the tasks not started
    yet; a running thread task finishes its one job.
    """
    if isinstance(executor, ThreadPoolExecutor):
        return _close_early(executor.map(lambda job: [_evaluate(evaluator, job)], jobs))
    workers = max(1, getattr(executor, "_max_workers", 2))
    size = max(1, math.ceil(len(jobs) / (4 * workers)))
    chunks = [jobs[k : k + size] for k in range(0, len(jobs), size)]
    return _close_early(executor.map(_evaluate_chunk_in_worker, chunks))


def _close_early(
    results: Iterator[list[GraspEvaluation]],
) -> Generator[GraspEvaluation, None, None]:
    """The evaluations of Executor.map's chunks; closing it closes the map (cancels the rest)."""
    try:
        for chunk in results:
            yield from chunk
    finally:
        close = getattr(results, "close", None)
        if close is not None:
            close()


def _evaluate(evaluator: GraspSafetyEvaluator, job: Job) -> GraspEvaluation:
    return evaluator._evaluate_sampled(*job)


_WORKER_EVALUATOR: GraspSafetyEvaluator | None = None


def _init_worker(robot: RobotModel, config: EvaluationConfig) -> None:
    from .ranking import GraspSafetyEvaluator

    global _WORKER_EVALUATOR
    _WORKER_EVALUATOR = GraspSafetyEvaluator(robot, config)


def _evaluate_chunk_in_worker(jobs: Sequence[Job]) -> list[GraspEvaluation]:
    assert _WORKER_EVALUATOR is not None
    return [_evaluate(_WORKER_EVALUATOR, job) for job in jobs]
