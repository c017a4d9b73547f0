"""Forward kinematics of a serial chain, its tip-frame (LOCAL) Jacobian and Pinocchio's
integrate / difference of its configurations, compiled."""

import math

from ._jit import _jit_inline

# ----------------------------------------------------------------------------- kinematics
# Conventions: a chain is ``method.packed.ChainArrays`` (one value, passed as a whole): n
# joints of one degree of freedom each, joint k at q[q_index[k]]; a continuous joint holds
# (cos, sin) of its angle in q[q_index[k]], q[q_index[k] + 1] (Pinocchio's nq = 2, nv = 1).
# Poses are (rotation, translation) pairs in the world (= model root) frame. ws is the
# workspace tuple of ``ik.workspace``: ws[0], ws[1] the joint rotations and translations,
# ws[2], ws[3] the tip rotation and translation. Inner functions allocate nothing.

_PIO2_HI = 1.5707963267341256
"""pi/2 to 33 significant bits: quadrant * _PIO2_HI is exact for |quadrant| < 2**20."""
_PIO2_LO = 6.077100506506192e-11
"""pi/2 - _PIO2_HI, rounded."""
_TWO_OVER_PI = 0.6366197723675814
_SINCOS_RANGE = 1.0e5
"""Largest |angle| [rad] of ``_sincos``'s own reduction; beyond it, math.sin and math.cos."""


@_jit_inline
def _sincos(angle):
    """(sin, cos) of angle [rad], absolute error at most 2.3e-16 (vs math.sin / math.cos,
    test_kernel_kinematics), at half their cost: a Cody-Waite reduction to [-pi/4, pi/4] and
    the Taylor series there (truncated below 1e-17), evaluated by Estrin's scheme."""
    if not abs(angle) <= _SINCOS_RANGE:  # also NaN
        return math.sin(angle), math.cos(angle)
    quadrant = math.floor(angle * _TWO_OVER_PI + 0.5)
    r = (angle - quadrant * _PIO2_HI) - quadrant * _PIO2_LO
    z = r * r
    z2 = z * z
    z4 = z2 * z2
    # sin r = r + r z S(z), cos r = 1 - z / 2 + z^2 C(z): coefficients (-1)^k / (2k + 1)!, ...
    s01 = -1.0 / 6.0 + z * (1.0 / 120.0)
    s23 = -1.0 / 5040.0 + z * (1.0 / 362880.0)
    s45 = -1.0 / 39916800.0 + z * (1.0 / 6227020800.0)
    s67 = -1.0 / 1307674368000.0 + z * (1.0 / 355687428096000.0)
    sin_r = r + r * z * ((s01 + z2 * s23) + z4 * (s45 + z2 * s67))
    c01 = 1.0 / 24.0 + z * (-1.0 / 720.0)
    c23 = 1.0 / 40320.0 + z * (-1.0 / 3628800.0)
    c45 = 1.0 / 479001600.0 + z * (-1.0 / 87178291200.0)
    c6 = 1.0 / 20922789888000.0
    cos_r = 1.0 - 0.5 * z + z2 * ((c01 + z2 * c23) + z4 * (c45 + z2 * c6))
    turn = int(quadrant) & 3
    if turn == 0:
        return sin_r, cos_r
    if turn == 1:
        return cos_r, -sin_r
    if turn == 2:
        return -sin_r, -cos_r
    return -cos_r, sin_r


@_jit_inline
def _forward_kinematics(chain, q, ws):
    """World poses of every joint frame (ws[0], ws[1]) and of the tip frame (ws[2], ws[3]).

    prismatic[k] is 1.0 for a prismatic joint, 0.0 for a revolute one: the joint turns by
    q (1 - prismatic) and slides by q prismatic (exactly the identity / zero otherwise).
    """
    # Fields are read into locals once: reading them inside loops costs a reference count each.
    pr, pt, axes = chain.placement_rotations, chain.placement_translations, chain.axes
    prismatic, continuous, q_index = chain.prismatic, chain.continuous, chain.q_index
    jr, jt, fr, ft = ws[0], ws[1], ws[2], ws[3]
    n = axes.shape[0]
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
        index = q_index[k]
        if continuous[k]:  # (cos, sin) as given, as Pinocchio (no renormalisation)
            slide = 0.0
            c = q[index]
            s = q[index + 1]
        else:
            slide = q[index] * prismatic[k]
            s, c = _sincos(q[index] - slide)
        if ax == 0.0 and ay == 0.0 and az == 1.0:  # the common z axis: Pinocchio's RZ / PZ
            for i in range(3):
                a0, a1, a2 = fr[i, 0], fr[i, 1], fr[i, 2]
                jt[k, i] = ft[i] + slide * a2
                jr[k, i, 0] = a0 * c + a1 * s
                jr[k, i, 1] = a1 * c - a0 * s
                jr[k, i, 2] = a2
            continue
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
    tip_rotation, tip_translation = chain.tip_rotation, chain.tip_translation
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


@_jit_inline
def _joint_axis_in_world(axes, prismatic, joint_rotations, k):
    """Joint k's unit axis in world axes (u) and the joint's angular part w = u (revolute)
    or 0 (prismatic): (u0, u1, u2, w0, w1, w2, slide), slide = 1.0 for prismatic (the
    chain's axes and prismatic arrays)."""
    ax, ay, az = axes[k, 0], axes[k, 1], axes[k, 2]
    jr = joint_rotations
    if ax == 0.0 and ay == 0.0 and az == 1.0:  # the common z axis: the frame's third column
        u0, u1, u2 = jr[k, 0, 2], jr[k, 1, 2], jr[k, 2, 2]
    else:
        u0 = jr[k, 0, 0] * ax + jr[k, 0, 1] * ay + jr[k, 0, 2] * az
        u1 = jr[k, 1, 0] * ax + jr[k, 1, 1] * ay + jr[k, 1, 2] * az
        u2 = jr[k, 2, 0] * ax + jr[k, 2, 1] * ay + jr[k, 2, 2] * az
    slide = prismatic[k]
    turn = 1.0 - slide
    return u0, u1, u2, u0 * turn, u1 * turn, u2 * turn, slide


@_jit_inline
def _local_jacobian(chain, ws, out):
    """Tip-frame Jacobian (6 x n, LOCAL: [linear; angular] in tip axes), as Pinocchio's, at
    the poses in ws."""
    jr, jt, fr, ft = ws[0], ws[1], ws[2], ws[3]
    axes, prismatic = chain.axes, chain.prismatic
    for k in range(axes.shape[0]):
        u0, u1, u2, w0, w1, w2, slide = _joint_axis_in_world(axes, prismatic, jr, k)
        dx, dy, dz = jt[k, 0] - ft[0], jt[k, 1] - ft[1], jt[k, 2] - ft[2]
        l0 = (dy * w2 - dz * w1) + slide * u0
        l1 = (dz * w0 - dx * w2) + slide * u1
        l2 = (dx * w1 - dy * w0) + slide * u2
        for i in range(3):
            out[i, k] = fr[0, i] * l0 + fr[1, i] * l1 + fr[2, i] * l2
            out[3 + i, k] = fr[0, i] * w0 + fr[1, i] * w1 + fr[2, i] * w2


@_jit_inline
def _integrate(chain, q, step, out, clamp):
    """Pinocchio's integrate(q, step) into out (may be q); clamp: then clip to the chain's
    position limits (continuous joints have none)."""
    q_index, continuous = chain.q_index, chain.continuous
    lower_q, upper_q = chain.lower_q, chain.upper_q
    for k in range(step.shape[0]):
        index = q_index[k]
        if continuous[k]:  # SO(2): rotate (cos, sin), first-order renormalisation
            ca, sa = q[index], q[index + 1]
            co, so = math.cos(step[k]), math.sin(step[k])
            r0 = co * ca - so * sa
            r1 = so * ca + co * sa
            scale = (3.0 - (r0 * r0 + r1 * r1)) / 2.0
            out[index] = r0 * scale
            out[index + 1] = r1 * scale
        elif clamp:
            out[index] = min(max(q[index] + step[k], lower_q[index]), upper_q[index])
        else:
            out[index] = q[index] + step[k]


@_jit_inline
def _joint_difference(q_index, continuous, q_from, q_to, k):
    """Pinocchio's difference(q_from, q_to) for joint k [rad or m] (the chain's q_index and
    continuous arrays)."""
    index = q_index[k]
    if not continuous[k]:
        return q_to[index] - q_from[index]
    ca0, sa0 = q_from[index], q_from[index + 1]
    ca1, sa1 = q_to[index], q_to[index + 1]
    cos_value = ca0 * ca1 + sa0 * sa1  # SO(2) log of R0^T R1, Pinocchio's branches
    sin_value = ca0 * sa1 - sa0 * ca1
    trace = 2.0 * cos_value
    if trace > 2.0:
        return 0.0
    if trace < -2.0:
        return math.pi if sin_value >= 0.0 else -math.pi
    if trace > 2.0 - 1e-2:
        return math.asin(sin_value)
    angle = math.acos(cos_value)
    return angle if sin_value >= 0.0 else -angle
