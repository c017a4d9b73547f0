"""SO(3) / SE(3) maps as Pinocchio computes them (log3, log6, Jlog6, exp3), compiled;
and the relative pose of two frames."""

import math

from ._jit import _EPS, _PREC2, _PREC3, _jit


@_jit
def _compute_theta_axis(i0, val, a00, a01, a02, a10, a11, a12, a20, a21, a22):
    """Pinocchio's internal::compute_theta_axis (log3 near pi) on the rotation's entries:
    (angle, axis0, axis1, axis2)."""
    i1 = (i0 + 1) % 3
    i2 = (i0 + 2) % 3
    m = (a00, a01, a02, a10, a11, a12, a20, a21, a22)
    r21 = m[3 * i2 + i1]
    r12 = m[3 * i1 + i2]
    sign = 1.0 if r21 >= r12 else -1.0
    s = math.sqrt(val + _EPS + _EPS * _EPS) * sign
    x0 = s / 2.0
    x1 = 1.0 / (2.0 * s) * (m[3 * i1 + i0] + m[3 * i0 + i1])
    x2 = 1.0 / (2.0 * s) * (m[3 * i2 + i0] + m[3 * i0 + i2])
    w = 1.0 / (2.0 * s) * (r21 - r12)
    norm = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    angle = 2.0 * math.atan2(norm, w)
    x0, x1, x2 = x0 / norm, x1 / norm, x2 / norm
    if i0 == 0:
        return angle, x0, x1, x2
    if i0 == 1:
        return angle, x2, x0, x1
    return angle, x1, x2, x0


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
    v0 = 2.0 * a00 - tr + 1.0
    v1 = 2.0 * a11 - tr + 1.0
    v2 = 2.0 * a22 - tr + 1.0
    if v0 >= v1:
        i0, val = (0, v0) if v0 >= v2 else (2, v2)
    else:
        i0, val = (1, v1) if v1 >= v2 else (2, v2)
    theta, x0, x1, x2 = _compute_theta_axis(i0, val, a00, a01, a02, a10, a11, a12, a20, a21, a22)
    return theta, theta * x0, theta * x1, theta * x2


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
