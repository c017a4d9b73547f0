"""IK of the tip pose, compiled: one pose (``solve_pose``) and a whole trajectory
(``solve_trajectory``), with the predictor warm start between samples (as ``IKSolver``).

``settings`` is ``method.packed.IKSettings`` (tolerances, iteration and step limits, the
velocity check), one value passed as a whole."""

import math
import threading

import numpy as np

from ._jit import _jit, _jit_inline
from .kinematics import _forward_kinematics, _integrate, _joint_difference, _local_jacobian
from .lie_group import _jlog6, _log6, _relative_pose
from .linalg import _damped_step


def workspace(n):
    """Scratch of one IK / effective-mass evaluation for a chain of n joints (plain Python:
    the kernels allocate nothing). One per thread: kernels running at once need their own."""
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
        np.empty((3, 3)),  # 19 scratch 3x3
        np.zeros(7),  # 20 predictor: its defect D (6) and the previous |xi|^2
    )


_THREAD_SCRATCH = threading.local()


def thread_workspace(n):
    """This thread's ``workspace(n)``, made once (kernels running at once in the pool's
    threads must not share scratch)."""
    workspaces = getattr(_THREAD_SCRATCH, "workspaces", None)
    if workspaces is None:
        workspaces = _THREAD_SCRATCH.workspaces = {}
    ws = workspaces.get(n)
    if ws is None:
        ws = workspaces[n] = workspace(n)
    return ws


@_jit_inline
def _predict(chain, twist, settings, q_previous, guess, ws):
    """IKSolver._predict, compiled: guess = q_previous (+) J^+ (xi + c), xi = ``twist`` =
    log6(T_{i-1}^-1 T_i) (tip frame), c = r D (``method.ik``'s docstring); ws[20] holds D
    (overwritten with c) and the previous |xi|^2 (overwritten with this one).

    ws must hold the joint and tip poses at q_previous (as the solve that returned it leaves
    them), so the tip-frame Jacobian there costs no forward kinematics.
    """
    jac, error, step = ws[9], ws[8], ws[14]
    _local_jacobian(chain, ws, jac)
    defect = ws[20]
    xi2 = 0.0
    for j in range(6):
        error[j] = twist[j]
        xi2 += twist[j] * twist[j]
    previous_xi2 = defect[6]
    ratio = min(xi2 / previous_xi2, settings.predictor_max_ratio) if previous_xi2 > 0.0 else 0.0
    for j in range(6):
        defect[j] *= ratio
        error[j] += defect[j]
    defect[6] = xi2
    _damped_step(jac, error, settings.max_iteration_step, ws[12], ws[13], step)
    _integrate(chain, q_previous, step, guess, False)


@_jit_inline
def _relative_twists(rotations, translations, twists, ws):
    """twists[i] = log6(P_{i-1}^-1 P_i) of consecutive poses P (in the frame of P_{i-1}), for
    i >= 1; ws: scratch (ws[4], ws[5])."""
    er, et = ws[4], ws[5]
    for i in range(1, rotations.shape[0]):
        _relative_pose(
            rotations[i - 1], translations[i - 1], rotations[i], translations[i], er, et
        )
        _log6(er, et, twists[i])


@_jit_inline
def _solve_pose_into(chain, settings, target_rotation, target_translation, q_init, q, ws):
    """IKSolver._solve_python, compiled: q is overwritten; returns (converged, iterations).

    The error at q_init is added to the predictor's D (ws[20]); on return, ws holds the joint
    and tip poses at the returned q.
    """
    fr, ft = ws[2], ws[3]
    er, et, ir, it, error, jac, jlog, jk = ws[4], ws[5], ws[6], ws[7], ws[8], ws[9], ws[10], ws[11]
    step = ws[14]
    n = chain.axes.shape[0]
    lower_q, upper_q = chain.lower_q, chain.upper_q
    for k in range(q.shape[0]):
        q[k] = min(max(q_init[k], lower_q[k]), upper_q[k])
    max_iterations, stall = settings.max_iterations, settings.stall_iterations
    checkpoint = math.inf
    for iteration in range(max_iterations + 1):
        _forward_kinematics(chain, q, ws)
        _relative_pose(fr, ft, target_rotation, target_translation, er, et)  # current^-1 target
        _log6(er, et, error)
        position_error = math.sqrt(et[0] * et[0] + et[1] * et[1] + et[2] * et[2])
        angle_error = math.sqrt(error[3] * error[3] + error[4] * error[4] + error[5] * error[5])
        if iteration == 0:
            for j in range(6):
                ws[20][j] += error[j]
        if (
            position_error <= settings.position_tolerance
            and angle_error <= settings.orientation_tolerance
        ):
            return True, iteration
        if iteration == max_iterations:
            break
        if stall > 0 and iteration > 0 and iteration % stall == 0:
            norm = 0.0
            for j in range(6):
                norm += error[j] * error[j]
            norm = math.sqrt(norm)
            if norm > settings.stall_ratio * checkpoint:
                return False, iteration
            checkpoint = norm
        _local_jacobian(chain, ws, jac)
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
        _damped_step(jk, error, settings.max_iteration_step, ws[12], ws[13], step)
        _integrate(chain, q, step, q, True)
    return False, max_iterations


@_jit
def solve_pose(chain, settings, target_rotation, target_translation, q_init, q, ws):
    """One tip pose (world frame) from q_init into q (nq,): (converged, iterations); ws:
    ``workspace(n)``."""
    return _solve_pose_into(chain, settings, target_rotation, target_translation, q_init, q, ws)


@_jit
def solve_poses(chain, settings, target_rotations, target_translations, seeds_q, q, converged, ws):
    """``solve_pose`` of each tip pose g (world frame: rotations (G, 3, 3), translations (G, 3)
    [m]) from each seed r (seeds_q (R, nq)) into q[g, r] (G, R, nq); converged (G, R) bool."""
    for g in range(target_rotations.shape[0]):
        for r in range(seeds_q.shape[0]):
            converged[g, r], _ = _solve_pose_into(
                chain,
                settings,
                target_rotations[g],
                target_translations[g],
                seeds_q[r],
                q[g, r],
                ws,
            )


@_jit_inline
def _reset_predictor(ws):
    """No defect to extrapolate into sample 1 (ws[20], see ``_predict``)."""
    for j in range(7):
        ws[20][j] = 0.0


@_jit_inline
def _trajectory_step(chain, settings, target_rotations, target_translations, times, i, out, g, ws):
    """Sample i >= 1 of IKSolver._trajectory_python: (status, joint, value); status 0 is OK.

    Grasp g's rows of ``out`` (``method.packed.GraspBuffers``): q_all, iterations, q_fail
    (the iterate, kept when it fails), guess (scratch) and tip_twists (the predictor's xi of
    each sample, filled by the caller). ws must hold the joint and tip
    poses at q_all[i - 1] (for the predictor); on return it holds those at q_all[i] (or at
    q_fail).
    """
    q_all, iterations, q, guess = out.q_all[g], out.iterations[g], out.q_fail[g], out.guess[g]
    q_index, continuous = chain.q_index, chain.continuous
    check_velocity, velocity_limits = settings.check_velocity, settings.velocity_limits
    _predict(chain, out.tip_twists[g, i], settings, q_all[i - 1], guess, ws)
    converged, iterations[i] = _solve_pose_into(
        chain, settings, target_rotations[i], target_translations[i], guess, q, ws
    )
    if not converged:
        return 1, 0, 0.0
    for k in range(q.shape[0]):
        q_all[i, k] = q[k]
    n = chain.axes.shape[0]
    deltas = ws[14]  # the step is scratch again
    worst = 0
    largest = -1.0
    for k in range(n):
        delta = abs(_joint_difference(q_index, continuous, q_all[i - 1], q, k))
        deltas[k] = delta
        if delta > largest:
            largest = delta
            worst = k
    if largest > settings.max_joint_step:
        return 2, worst, largest
    elapsed = times[i] - times[i - 1]
    if settings.any_velocity_check and elapsed > 0:
        for k in range(n):
            speed = deltas[k] / elapsed
            if check_velocity[k] and speed > velocity_limits[k] * (1 + 1e-9):
                return 3, k, speed
    return 0, 0, 0.0


@_jit
def solve_trajectory(chain, settings, target_rotations, target_translations, times, out, ws):
    """IKSolver._trajectory_python, compiled: samples 1.. from the solution out.q_all[0, 0] of
    sample 0 (world-frame targets).

    Fills out.q_all[0] and out.iterations[0] (``GraspBuffers`` of one grasp); returns
    (status, sample, joint, value) as the Python path; on failure out.q_fail[0] holds the last
    iterate. ws: ``workspace(n)``.
    """
    count = target_rotations.shape[0]
    _relative_twists(target_rotations, target_translations, out.tip_twists[0], ws)
    _forward_kinematics(chain, out.q_all[0, 0], ws)  # the predictor of sample 1 needs these
    _reset_predictor(ws)
    for i in range(1, count):
        status, joint, value = _trajectory_step(
            chain, settings, target_rotations, target_translations, times, i, out, 0, ws
        )
        if status != 0:
            return status, i, joint, value
    return 0, count, 0, 0.0
