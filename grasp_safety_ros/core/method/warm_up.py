"""Compile the kernels (or load them from numba's disk cache) ahead of the first request, and
say which kernels a process compiles (``announce_compiles``). The modules of every kernel are
imported by ``warm_up`` only: importing this module for ``announce_compiles`` stays light."""

from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    import numpy as np
    import pinocchio as pin

    from ..model.inertia import ObjectInertia
    from ..model.robot import RobotModel
    from ..model.trajectory import ObjectTrajectory
    from .packed import ChainArrays
    from .ranking import GraspSafetyEvaluator

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
    import numpy as np

    from ..model.inertia import solid_box
    from ..model.robot import RobotModel
    from ..model.trajectory import ObjectTrajectory
    from .ranking import GraspSafetyEvaluator

    start = time.perf_counter()
    if evaluator is None:
        evaluator = GraspSafetyEvaluator(RobotModel.from_urdf(_WARM_UP_URDF, "base", "b"))
    chain = evaluator.backend.chain
    if chain is None:  # the Pinocchio backend: nothing to compile
        return 0.0
    robot = evaluator.robot
    pose = robot.transform_tip_to_base(robot.default_seed_positions())
    trajectory = ObjectTrajectory(pose, pose, 0.02, 0.01)
    with np.errstate(all="ignore"):  # the pose may be singular: only the compiling matters
        box = solid_box(1.0, (0.1, 0.1, 0.1))
        seed_q = _warm_up_evaluator(evaluator, box, pose, trajectory)
        _warm_up_analysis_kernels(robot, chain, box, seed_q)
    return time.perf_counter() - start


def _warm_up_evaluator(
    evaluator: GraspSafetyEvaluator,
    box: ObjectInertia,
    pose: pin.SE3,
    trajectory: ObjectTrajectory,
) -> np.ndarray:
    """Run the evaluator's kernels (ranking, IK, posture selection, the analyses' IK) once
    on ``box`` held still at ``pose`` (``trajectory``); the seed configuration."""
    import numpy as np
    import pinocchio as pin

    from .ranking import Grasp, sample_trajectory

    robot = evaluator.robot
    evaluator.evaluate(Grasp(pin.SE3.Identity()), box, trajectory)
    seed_q = robot.q_from_positions(robot.default_seed_positions())
    evaluator.ik.solve(pose, seed_q)
    evaluator.ik.solve_poses([pose], seed_q[None])  # posture selection's kernels
    evaluator.follow_postures(
        [0],
        [Grasp(pin.SE3.Identity())],
        box,
        sample_trajectory(trajectory),
        "mean",
        seed_q[None],
        np.array([np.inf]),
    )
    rotations = np.array([pose.rotation, pose.rotation])
    translations = np.array([pose.translation, pose.translation])
    evaluator.ik.solve_trajectory_arrays(  # the analyses' IK and mobility kernels
        rotations, translations, np.array([0.0, 0.01]), np.array([0.0, 1.0]), seed_q
    )
    return seed_q


def _warm_up_analysis_kernels(
    robot: RobotModel, chain: ChainArrays, box: ObjectInertia, seed_q: np.ndarray
) -> None:
    """Run the analyses' kernels (mobility, terms, points, the whole arm's tip twists and
    spline rates, inertia uncertainty, effort) once at ``seed_q``."""
    import numpy as np
    import pinocchio as pin

    from ..model.trajectory import ObjectMotion
    from .compiled import augmented_bodies
    from .dynamics import joint_dynamics
    from .effective_mass import translational_mobilities_in_base
    from .executable import clamped_spline_velocities
    from .perturbed import perturbed_effective_masses
    from .points import (
        arm_site_exposure,
        region_peaks,
        site_mobilities,
        tip_following_rates,
        tip_point_masses,
        tip_twists_into,
    )
    from .terms import configurations, grasps_terms

    translational_mobilities_in_base(robot, box, pin.SE3.Identity(), np.array([seed_q]), chain)
    positions = np.array([robot.default_seed_positions()])
    terms, counts = grasps_terms(robot, chain, box, [pin.SE3.Identity()], [positions])
    still = np.ones((1, 1, 1), dtype=bool)  # the point kernels of the analyses
    tip_point_masses(
        terms,
        counts,
        np.eye(3),
        np.zeros((1, 1, 3)),
        np.zeros((1, 1, 1, 3)),
        still,
        np.zeros(1, np.int64),
    )
    n = robot.model.nv
    support, rates = np.ones((1, n), dtype=bool), np.zeros((1, 1, n))
    site = (np.zeros(1, np.int64), np.zeros((1, 3)), support)
    arm_site_exposure(terms, counts, (np.eye(3), np.zeros(3)), *site, rates, 1e-9)
    site_mobilities(terms, *site, np.zeros((1, 3), np.int64))
    region_peaks(np.ones((1, 1, 1)), np.ones((1, 1, 1)), np.ones(1), np.ones(1))
    still_motion = np.zeros((1, 3))
    motion = ObjectMotion(np.eye(3)[None], still_motion, still_motion, still_motion, np.zeros(1))
    tip_twists_into(motion, np.zeros((1, 3)), np.eye(3), [0], np.zeros((1, 1, 6)))
    clamped_spline_velocities(np.array([0.0, 1.0]), np.zeros((2, 1)))
    tip_following_rates(terms.jacobians_tip_in_world, counts, np.zeros((1, 1, 6)), rates)
    perturbed_effective_masses(  # the inertia-uncertainty kernel
        robot,
        chain,
        [box],
        [pin.SE3.Identity()],
        [positions],
        [np.array([[1.0, 0.0, 0.0]])],
        [np.array([False])],
    )
    bodies = augmented_bodies(robot, box, np.eye(3)[None], np.zeros((1, 3)))
    joint_dynamics(  # the effort analysis's kernel
        chain,
        bodies,
        positions[None],
        configurations(robot, positions)[None],
        np.ones(1, dtype=np.int64),
        np.zeros(1, dtype=np.int64),
        np.zeros((1, 3, 1)),
        np.eye(3)[None, None],
        np.zeros((1, 2, 1, 6)),
        np.zeros((1, 3)),
        np.zeros(3),
    )


def announce_compiles(stream: TextIO | None = None) -> None:
    """From now on, write a line to ``stream`` for each kernel this process compiles (its
    first use on a machine), with its time; nothing for kernels loaded from numba's cache.
    None: the ``sys.stderr`` of the moment of each line (a test's capture replaced or closed
    in between is not written to); a stream that cannot be written is skipped."""
    from ..kernels._jit import announce_compiles as announce

    announce(_Announcements(stream))


class _Announcements:
    """The stream of ``announce_compiles``: writes that fail are dropped, so that a closed
    stream never fails a compilation."""

    def __init__(self, stream: TextIO | None) -> None:
        self._stream = stream

    def write(self, text: str) -> None:
        try:
            (self._stream or sys.stderr).write(text)
        except (OSError, ValueError):  # closed or broken
            pass

    def flush(self) -> None:
        try:
            (self._stream or sys.stderr).flush()
        except (OSError, ValueError):
            pass
