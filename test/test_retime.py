"""Safe retiming (core.analyses.retime): a 1-DOF arm against the closed-form time-optimal
profile, a 2-link planar arm re-evaluated sample by sample by an independent computation, the
uniform T_min as an upper bound, and refused input."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_site_speeds import IndependentSites, admissible_speed, one_link

from grasp_safety_ros.core import ObjectInertia, RobotModel
from grasp_safety_ros.core.analyses.arm_sites import resolve_arm_sites
from grasp_safety_ros.core.analyses.body_regions import BODY_REGIONS
from grasp_safety_ros.core.analyses.retime import AT_REST, RetimeLimits, retime_path
from grasp_safety_ros.core.analyses.site_speeds import SiteSpeedModel
from grasp_safety_ros.core.exceptions import InvalidInputError

LIMIT_TOLERANCE = 1e-6
"""Relative excess over a limit allowed at the grid points: TOPP-RA's LP solver (seidel)
works to about 1e-8 on x = ṡ² (toppra.constants.TINY); the issue asks for 1e-6."""


def quintic(t: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rest-to-rest quintic 0 -> 1 and its first two time derivatives."""
    x = t / duration
    return (
        10 * x**3 - 15 * x**4 + 6 * x**5,
        (30 * x**2 - 60 * x**3 + 30 * x**4) / duration,
        (60 * x - 180 * x**2 + 120 * x**3) / duration**2,
    )


def bang_coast_bang_duration(distance: float, speed: float, acceleration: float) -> float:
    """Time-optimal rest-to-rest duration over ``distance`` with |θ̇| <= speed, |θ̈| <=
    acceleration: accelerate at the limit, coast at the speed cap if it is reached, brake."""
    if distance >= speed**2 / acceleration:
        return distance / speed + speed / acceleration
    return 2.0 * np.sqrt(distance / acceleration)


ONE_DOF = {"length": 0.5, "mass": 3.0, "reach": 0.6, "armature": 0.1}
OBJECT_MASS, OBJECT_INERTIA = 1.0, 1e-3


def one_dof_case(velocity_limit: float, factor: float = 0.8):
    """The 1-DOF arm carrying a point-like object at the tip, one object point 0.1 m beyond,
    rotating 2 rad on a quintic in 1 s (401 samples): the retimed motion and the joint speed
    cap each site imposes (ω_k = f v_max(I/ρ_k²) / ρ_k, I the inertia about the axis)."""
    robot = one_link(**ONE_DOF)
    inertia = ObjectInertia(OBJECT_MASS, np.zeros(3), OBJECT_INERTIA * np.eye(3))
    model = SiteSpeedModel.build(
        robot,
        inertia,
        pin.SE3.Identity(),
        resolve_arm_sites(robot),
        np.array([[0.1, 0.0, 0.0]]),
        ["chest"],
    )
    moment = (
        ONE_DOF["mass"] * ONE_DOF["length"] ** 2
        + ONE_DOF["armature"]
        + OBJECT_MASS * ONE_DOF["reach"] ** 2
        + OBJECT_INERTIA
    )
    radii = np.array([ONE_DOF["reach"], ONE_DOF["reach"] + 0.1])
    caps = factor * admissible_speed(moment / radii**2, "chest") / radii
    times = np.linspace(0.0, 1.0, 401)
    angle = 2.0 * quintic(times, 1.0)[0]
    limits = RetimeLimits.from_input(robot, [20.0], [velocity_limit], factor)
    return retime_path(robot, model, limits, times, angle[:, None]), caps


@pytest.mark.parametrize("binds", ["site", "joint"])
def test_one_dof_matches_the_closed_form_time_optimal_profile(binds: str) -> None:
    """Bang-coast-bang in θ with the cap min(v_lim, ω_sites): the duration within the time of
    four grid intervals of the retimed motion (the profile is exact at grid points except in
    the intervals holding the two switches and the two rest ends, each at most one interval's
    time), the coasting speed and the binding constraint exactly (to the LP tolerance)."""
    _, caps = one_dof_case(10.0)
    site_cap = float(caps.min())
    velocity_limit = 10.0 if binds == "site" else 0.5 * site_cap
    retimed, _ = one_dof_case(velocity_limit)
    cap = min(velocity_limit, site_cap)
    expected = bang_coast_bang_duration(2.0, cap, 20.0)
    tolerance = 4.0 * np.diff(retimed.grid_times_s).max()
    assert abs(retimed.safe_duration_s - expected) <= tolerance
    assert tolerance < 0.05 * expected  # the check means something
    peak = np.abs(retimed.velocities).max()
    assert peak == pytest.approx(cap, rel=LIMIT_TOLERANCE)
    coasting = retimed.binding[len(retimed.times_s) // 2]
    if binds == "site":
        site = ("hand", "object[0]")[int(np.argmin(caps))]
        assert coasting == f"site {site} (chest)"
    else:
        assert coasting == "joint shoulder velocity"
    assert retimed.binding[0] == retimed.binding[-1] == AT_REST
    assert retimed.binding_ratio.max() <= 1.0 + LIMIT_TOLERANCE


PLANAR = """<robot name="planar">
<link name="base"/>
<link name="upper"><inertial><origin xyz="0.2 0 0"/><mass value="2.5"/>
<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
<link name="fore"><inertial><origin xyz="0.15 0 0"/><mass value="1.5"/>
<inertia ixx="0.005" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
<link name="hand"/>
<joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="{v1}"/></joint>
<joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
<origin xyz="0.4 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="{v2}"/>
</joint>
<joint name="wrist" type="fixed"><parent link="fore"/><child link="hand"/>
<origin xyz="0.3 0 0"/></joint>
</robot>"""

PLANAR_INERTIA = ObjectInertia(1.2, np.array([0.05, 0.0, 0.02]), np.diag([0.004, 0.006, 0.005]))
PLANAR_GRASP = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.4), np.array([-0.05, 0.02, 0.0]))
PLANAR_POINTS = np.array([[0.1, 0.05, 0.0], [0.1, -0.05, 0.0], [-0.1, 0.05, 0.03]])


def planar(v1: float = 4.0, v2: float = 5.0) -> RobotModel:
    urdf = PLANAR.format(v1=v1, v2=v2)
    return RobotModel.from_urdf(urdf, "base", "hand", armature_kgm2=[0.2, 0.05])


def planar_case(start, end, duration, accelerations, factor, samples=101):
    """Retime the planar arm's quintic joint path (output on the grid); the oracle too."""
    robot = planar()
    sites = resolve_arm_sites(robot, {"upper": [[0.4, 0.0, 0.0]], "fore": [[0.15, 0.03, 0.0]]})
    model = SiteSpeedModel.build(robot, PLANAR_INERTIA, PLANAR_GRASP, sites, PLANAR_POINTS)
    times = np.linspace(0.0, duration, samples)
    shape = quintic(times, duration)[0]
    path = np.asarray(start) + np.outer(shape, np.subtract(end, start))
    limits = RetimeLimits.from_input(robot, accelerations, None, factor)
    oracle = IndependentSites(robot, sites, PLANAR_INERTIA, PLANAR_GRASP, PLANAR_POINTS)
    return retime_path(robot, model, limits, times, path), limits, oracle, robot


def permitted_limit(mass: np.ndarray) -> np.ndarray:
    """min over the regions that permit transient contact of v_max [m/s], from the table."""
    names = [n for n, r in BODY_REGIONS.items() if r.transient_contact_permitted]
    return np.min([admissible_speed(mass, n) for n in names], axis=0)


def check_within_limits(retimed, limits, oracle) -> float:
    """Every site and joint within its limit at every output sample, by the oracle; returns
    the largest site ratio seen."""
    worst = 0.0
    for q, qd, qdd in zip(
        retimed.positions, retimed.velocities, retimed.accelerations, strict=True
    ):
        assert np.all(np.abs(qd) <= limits.joint_velocity_limits * (1 + LIMIT_TOLERANCE))
        assert np.all(np.abs(qdd) <= limits.joint_acceleration_limits * (1 + LIMIT_TOLERANCE))
        speeds, masses = oracle.speeds_and_masses(q, qd)
        moving = speeds > 1e-9
        allowed = limits.safety_factor * permitted_limit(masses[moving])
        assert np.all(speeds[moving] <= allowed * (1 + LIMIT_TOLERANCE))
        worst = max(worst, float(np.max(speeds[moving] / allowed, initial=0.0)))
    return worst


def test_planar_arm_within_every_limit_by_independent_reevaluation() -> None:
    """A fast planned motion (its worst site ratio > 1): the retimed one, evaluated on the
    grid (where TOPP-RA enforces the limits; between grid points see the module docstring),
    has every site under f v_max of its region and every joint within its limits; a site
    limit binds somewhere (worst site ratio 1), and it is no slower than uniform scaling."""
    retimed, limits, oracle, _ = planar_case([0.2, 1.4], [1.9, -0.2], 0.6, [30.0, 40.0], 0.9)
    assert retimed.planned_worst_ratio > 1.2
    assert check_within_limits(retimed, limits, oracle) == pytest.approx(1.0, abs=1e-6)
    assert any(label.startswith("site ") for label in retimed.binding)
    assert retimed.safe_duration_s < retimed.uniform_min_duration_s
    # the planner's worst ratio by the oracle, at ṡ = 1 (analytic q' of the quintic; the
    # retiming uses the spline through 101 samples: equal to ~1e-6)
    times = np.linspace(0.0, 0.6, 101)
    shape, rate, _ = quintic(times, 0.6)
    worst = 0.0
    for x, r in zip(shape[1:-1], rate[1:-1], strict=True):
        q = np.array([0.2, 1.4]) + x * np.array([1.7, -1.6])
        speeds, masses = oracle.speeds_and_masses(q, r * np.array([1.7, -1.6]))
        worst = max(worst, float(np.max(speeds / (0.9 * permitted_limit(masses)))))
    assert retimed.planned_worst_ratio == pytest.approx(worst, rel=1e-4)
    assert retimed.uniform_min_duration_s == pytest.approx(0.6 * worst, rel=1e-4)


def test_planar_arm_joint_limit_binds_for_a_slow_arm() -> None:
    """Low acceleration limits: the joints bind, no site comes near its limit."""
    retimed, limits, oracle, _ = planar_case([0.2, 1.4], [1.9, -0.2], 0.6, [0.2, 0.2], 1.0)
    assert check_within_limits(retimed, limits, oracle) < 0.99
    moving = [label for label in retimed.binding if label != AT_REST]
    assert moving and all(label.startswith("joint ") for label in moving)
    assert retimed.binding_ratio.max() == pytest.approx(1.0, abs=1e-6)


@given(
    start=st.lists(st.floats(-2.0, 2.0), min_size=2, max_size=2),
    end=st.lists(st.floats(-2.0, 2.0), min_size=2, max_size=2),
    duration=st.floats(0.3, 3.0),
    factor=st.floats(0.3, 1.0),
)
def test_retimed_no_slower_than_uniform_scaling_when_that_is_feasible(
    start, end, duration, factor
) -> None:
    """Where the uniformly slowed timing (T -> T_min) is within the joint limits (checked on
    the analytic quintic, with a 10 % margin on accelerations for the spline and the grid), it
    is a feasible timing; TOPP-RA's profile is the largest feasible one at every grid point,
    so its duration is at most that of the uniform one with the rest ends forced (ṡ = 0 at
    s = 0, T: two end intervals take twice as long): T_min (1 + 2 Δs / T)."""
    distance = np.subtract(end, start)
    if np.abs(distance).max() < 0.1:
        return
    samples = 101
    retimed, limits, _, robot = planar_case(start, end, duration, [8.0, 10.0], factor, samples)
    t_min = retimed.uniform_min_duration_s
    scale = duration / t_min
    _, rate, acceleration = quintic(np.linspace(0.0, duration, 2001), duration)
    velocity_ok = np.all(np.abs(np.outer(rate, distance)).max(0) * scale <= robot.velocity_limits)
    acceleration_ok = np.all(
        np.abs(np.outer(acceleration, distance)).max(0) * scale**2
        <= 0.9 * limits.joint_acceleration_limits
    )
    if not (velocity_ok and acceleration_ok):
        return
    assert retimed.uniform_feasible_duration_s == pytest.approx(t_min, rel=1e-3)  # spline
    step = duration / (samples - 1)
    assert retimed.safe_duration_s <= t_min * (1 + 2 * step / duration) * (1 + 1e-9)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"joint_acceleration_limits": None}, "retime.joint_acceleration_limits"),
        ({"joint_acceleration_limits": [1.0]}, "retime.joint_acceleration_limits"),
        (
            {"joint_acceleration_limits": [1.0, float("nan")]},
            "retime.joint_acceleration_limits[1]",
        ),
        ({"joint_acceleration_limits": [1.0, -2.0]}, "retime.joint_acceleration_limits[1]"),
        ({"joint_acceleration_limits": {"shoulder": 1.0}}, "retime.joint_acceleration_limits"),
        (
            {"joint_acceleration_limits": {"shoulder": 1.0, "knee": 1.0}},
            "retime.joint_acceleration_limits",
        ),
        ({"joint_velocity_limits": [0.0, 1.0]}, "retime.joint_velocity_limits[0]"),
        ({"joint_velocity_limits": {"elbow": float("inf")}}, "retime.joint_velocity_limits.elbow"),
        ({"safety_factor": 0.0}, "retime.safety_factor"),
        ({"safety_factor": 1.5}, "retime.safety_factor"),
        ({"safety_factor": float("nan")}, "retime.safety_factor"),
    ],
)
def test_bad_limits_are_refused_naming_the_field(kwargs: dict, field: str) -> None:
    arguments = {"joint_acceleration_limits": [1.0, 2.0]} | kwargs
    with pytest.raises(InvalidInputError) as error:
        RetimeLimits.from_input(planar(), **arguments)
    assert error.value.field.startswith(field)  # list entries add "(joint ...)"
    assert "\n" not in str(error.value)


def test_urdf_without_velocity_limits_needs_them_given() -> None:
    robot = planar(v1=0.0)
    with pytest.raises(InvalidInputError) as error:
        RetimeLimits.from_input(robot, [1.0, 1.0])
    assert error.value.field == "retime.joint_velocity_limits"
    assert "shoulder" in str(error.value)
    given_limits = RetimeLimits.from_input(robot, [1.0, 1.0], {"shoulder": 2.0})
    np.testing.assert_array_equal(given_limits.joint_velocity_limits, [2.0, 5.0])


def test_bad_paths_are_refused() -> None:
    robot = planar()
    limits = RetimeLimits.from_input(robot, [1.0, 1.0])
    times = np.linspace(0.0, 1.0, 5)
    for positions, t in [
        (np.zeros((5, 3)), times),
        (np.zeros((2, 2)), times[:2]),
        (np.full((5, 2), np.nan), times),
        (np.zeros((5, 2)), times[::-1]),
    ]:
        with pytest.raises(InvalidInputError, match=r"retime\.path"):
            retime_path(robot, None, limits, t, positions)
