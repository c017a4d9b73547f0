"""Forward kinematics of a serial chain and its tip-frame (LOCAL) Jacobian, compiled."""

import math

from ._jit import _jit

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
