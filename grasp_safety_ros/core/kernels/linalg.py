"""Small dense solves of the IK, compiled: LU with partial pivoting and the damped step."""

from ._jit import _jit


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
