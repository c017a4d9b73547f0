"""Simulated impacts in MuJoCo: a tracked post-grasp motion into a force sensor, and a free
impact of the unactuated arm that measures the effective mass directly."""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline

from ..core.exceptions import InvalidInputError
from ..core.method.ranking import GraspEvaluation
from ..core.model.inertia import ObjectInertia
from ..core.model.robot import RobotModel
from .scene import (
    ContactConfig,
    ObjectShape,
    Scene,
    SensorConfig,
    add_object,
    add_obstacle,
    add_tip_sphere,
    base_spec,
    compile_scene,
    engine_effective_mass,
    rotation_z_onto,
    tip_translational_jacobian,
)


@dataclass(frozen=True)
class ControllerGains:
    """Joint-space computed-torque tracking: τ = M(q)(q̈_d + K_d ė + K_p e) + c(q, q̇) + g(q).

    M, c and g come from the engine's model of robot + object (inertia and gravity
    compensation), torques are clipped to the URDF effort limits.

    Attributes:
        kp_per_s2: Position gain [1/s²] (natural frequency² of the error dynamics).
        kd_per_s: Velocity gain [1/s].
        period_s: Control period [s] with a zero-order hold in between; None updates the
            torque at every physics step (an idealised continuous-time controller).
        clip_to_effort_limits: Clip torques to the URDF effort limits (as the real robot).
    """

    kp_per_s2: float = 400.0
    kd_per_s: float = 40.0
    period_s: float | None = None
    clip_to_effort_limits: bool = True

    def __post_init__(self) -> None:
        for name in ("kp_per_s2", "kd_per_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise InvalidInputError(f"controller.{name}", f"must be > 0, got {value!r}")
        if self.period_s is not None and not (np.isfinite(self.period_s) and self.period_s > 0):
            raise InvalidInputError(
                "controller.period_s", f"must be > 0 or None, got {self.period_s!r}"
            )


@dataclass(frozen=True)
class CollisionSetup:
    """Settings of the pillar experiment.

    Attributes:
        impact_time_s: When the tip sphere would reach the sensor face on the reference [s].
        start_time_s: Simulation start on the reference (the arm starts on it, at its
            velocity).
        end_time_s: Simulation end [s].
        timestep_s: Physics timestep away from the impact [s].
        impact_timestep_s: Physics timestep from ``fine_before_s`` before the planned impact
            to ``fine_after_s`` after it [s] (the stiff contact needs it).
        fine_before_s, fine_after_s: That window [s].
        tip_sphere_radius_m: Radius of the colliding sphere at the tip [m].
        peak_window_s: The impact peak is the maximum in this window after first contact [s].
        contact, sensor, gains: See ContactConfig, SensorConfig, ControllerGains.
    """

    impact_time_s: float = 1.5
    start_time_s: float = 0.0
    end_time_s: float = 3.0
    timestep_s: float = 1e-4
    impact_timestep_s: float = 1e-5
    fine_before_s: float = 0.01
    fine_after_s: float = 0.06
    tip_sphere_radius_m: float = 0.02
    peak_window_s: float = 0.05
    contact: ContactConfig = field(default_factory=ContactConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    gains: ControllerGains = field(default_factory=ControllerGains)

    def __post_init__(self) -> None:
        if not (0.0 <= self.start_time_s < self.impact_time_s < self.end_time_s):
            raise InvalidInputError(
                "collision.times",
                "need 0 <= start_time_s < impact_time_s < end_time_s, got "
                f"{self.start_time_s}, {self.impact_time_s}, {self.end_time_s}",
            )
        for name in ("timestep_s", "impact_timestep_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise InvalidInputError(f"collision.{name}", f"must be > 0, got {value!r}")

    def timesteps(self) -> np.ndarray:
        """The physics timestep of every step from start to end [s]."""
        fine_start = max(self.start_time_s, self.impact_time_s - self.fine_before_s)
        fine_end = min(self.end_time_s, self.impact_time_s + self.fine_after_s)
        pieces = (
            (fine_start - self.start_time_s, self.timestep_s),
            (fine_end - fine_start, self.impact_timestep_s),
            (self.end_time_s - fine_end, self.timestep_s),
        )
        return np.concatenate([np.full(round(span / dt), dt) for span, dt in pieces if span > 0.0])


@dataclass(frozen=True)
class CollisionResult:
    """Force record of one tracked motion into the sensor.

    Attributes:
        times_s: Physics step times (end of each step) [s].
        sensor_force_n: Load-cell force (spring + damper; contact force if rigid) [N].
        contact_force_n: Normal force between tip sphere and sensor face [N].
        contact_time_s: First contact [s] (NaN if none).
        peak_force_n: Largest sensor force within the peak window after first contact [N].
        peak_time_s: When it occurs [s].
        peak_contact_force_n: Largest contact normal force in that window [N].
        impulse_n_s: Contact normal impulse of the first impact episode (first contact until
            the sensor force first returns to 0) [N s].
        approach_speed_m_s: Tip velocity along the sensor normal just before contact [m/s].
        effective_mass_at_impact_kg: The core's effective mass at the contact time [kg].
        tracking_error_rad: Largest joint tracking error before contact [rad].
        first_saturation_time_s: When a joint torque first hit its URDF effort limit [s]
            (NaN if never).
        first_saturation_joint: The joint that hit it (empty if none).
    """

    times_s: np.ndarray
    sensor_force_n: np.ndarray
    contact_force_n: np.ndarray
    contact_time_s: float
    peak_force_n: float
    peak_time_s: float
    peak_contact_force_n: float
    impulse_n_s: float
    approach_speed_m_s: float
    effective_mass_at_impact_kg: float
    tracking_error_rad: float
    first_saturation_time_s: float
    first_saturation_joint: str = ""


def joint_reference(evaluation: GraspEvaluation) -> CubicSpline:
    """C² joint reference q(t) through the core's IK samples, at rest at both ends."""
    if not evaluation.feasible:
        raise InvalidInputError("grasp", f"'{evaluation.name}' is infeasible: {evaluation.reason}")
    return CubicSpline(evaluation.times_s, evaluation.joint_positions, bc_type="clamped")


def _reference_state(
    spline: CubicSpline, end_s: float, time_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = min(max(time_s, 0.0), end_s)
    q = spline(t)
    if time_s >= end_s or time_s <= 0.0:
        return q, np.zeros_like(q), np.zeros_like(q)
    return q, spline(t, 1), spline(t, 2)


def _direction_at(evaluation: GraspEvaluation, time_s: float) -> np.ndarray:
    direction = np.array(
        [
            np.interp(time_s, evaluation.times_s, evaluation.directions_in_base[:, k])
            for k in range(3)
        ]
    )
    unit: np.ndarray = direction / np.linalg.norm(direction)
    return unit


def _contact_normal_force(scene: Scene) -> float:
    """Sum of the normal forces of the contacts between tip sphere and sensor face [N]."""
    data = scene.data
    total = 0.0
    wrench = np.zeros(6)
    pair = {scene.sphere_geom, scene.face_geom}
    for index in range(data.ncon):
        contact = data.contact[index]
        if {int(contact.geom1), int(contact.geom2)} == pair:
            mujoco.mj_contactForce(scene.model, data, index, wrench)
            total += wrench[0]
    return total


def collision_scene(
    robot: RobotModel,
    urdf_source: str,
    object_inertia: ObjectInertia,
    transform_tip_to_object: pin.SE3,
    face_centre_in_world_m: np.ndarray,
    direction_in_world: np.ndarray,
    setup: CollisionSetup,
    gravity: bool = True,
    object_shape: ObjectShape | None = None,
) -> Scene:
    """Robot + object + tip sphere + sensor plate facing the approach direction."""
    spec = base_spec(robot, urdf_source, setup.timestep_s, gravity=gravity)
    add_object(spec, robot.tip_frame, object_inertia, transform_tip_to_object, object_shape)
    add_tip_sphere(spec, robot.tip_frame, setup.tip_sphere_radius_m, setup.contact)
    add_obstacle(spec, face_centre_in_world_m, direction_in_world, setup.contact, setup.sensor)
    return compile_scene(spec, robot)


def simulate_collision(
    robot: RobotModel,
    urdf_source: str,
    object_inertia: ObjectInertia,
    transform_tip_to_object: pin.SE3,
    evaluation: GraspEvaluation,
    setup: CollisionSetup | None = None,
    object_shape: ObjectShape | None = None,
) -> CollisionResult:
    """Track the core's joint trajectory into a force sensor placed on the tip's path.

    The sensor face is perpendicular to the tip's direction of motion at
    ``setup.impact_time_s`` and placed where the tip sphere's leading point is then on the
    reference. The arm starts on the reference at ``setup.start_time_s`` with the reference
    velocity, and is driven by computed torque (ControllerGains).
    """
    setup = setup or CollisionSetup()
    spline = joint_reference(evaluation)
    duration = float(evaluation.times_s[-1])
    transform_base_to_world = pin.SE3(robot.transform_base_to_world)
    direction = transform_base_to_world.rotation @ _direction_at(evaluation, setup.impact_time_s)
    tip_at_impact = transform_base_to_world.act(
        robot.transform_tip_to_base(spline(setup.impact_time_s))
    ).translation
    face_centre = tip_at_impact + setup.tip_sphere_radius_m * direction
    scene = collision_scene(
        robot,
        urdf_source,
        object_inertia,
        transform_tip_to_object,
        face_centre,
        direction,
        setup,
        object_shape=object_shape,
    )
    q0, v0, _ = _reference_state(spline, duration, setup.start_time_s)
    scene.data.qpos[scene.arm_qpos] = q0
    scene.data.qvel[scene.arm_dof] = v0
    scene.data.time = setup.start_time_s
    mujoco.mj_forward(scene.model, scene.data)
    return _track_into_sensor(robot, scene, evaluation, spline, direction, setup)


def _effort_limits(robot: RobotModel) -> np.ndarray:
    """The URDF effort limits [N·m or N], inf where a joint has none (or a non-positive one)."""
    effort = np.asarray(robot.model.effortLimit, dtype=float)
    return np.where(np.isfinite(effort) & (effort > 0), effort, np.inf)


def _step_references(
    spline: CubicSpline, duration: float, starts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference position, velocity and acceleration at every step start, evaluated at
    once (held, at rest, outside the trajectory)."""
    moving = (starts > 0.0) & (starts < duration)
    clipped = np.clip(starts, 0.0, duration)
    q_refs = spline(clipped)
    v_refs = np.where(moving[:, None], spline(clipped, 1), 0.0)
    a_refs = np.where(moving[:, None], spline(clipped, 2), 0.0)
    return q_refs, v_refs, a_refs


def _arm_block(dof: np.ndarray) -> tuple[slice, ...] | tuple[np.ndarray, ...]:
    """The index of the arm's block in the engine's mass matrix (slices when contiguous)."""
    if np.array_equal(dof, np.arange(dof[0], dof[0] + len(dof))):
        return (slice(dof[0], dof[-1] + 1),) * 2
    return np.ix_(dof, dof)


def _track_into_sensor(
    robot: RobotModel,
    scene: Scene,
    evaluation: GraspEvaluation,
    spline: CubicSpline,
    direction: np.ndarray,
    setup: CollisionSetup,
) -> CollisionResult:
    """Steps the scene from its start state under computed torque, recording the sensor, the
    contact force and the tip's approach speed along ``direction`` before the first touch."""
    model, data = scene.model, scene.data
    dof = scene.arm_dof
    effort = _effort_limits(robot)
    timesteps = setup.timesteps()
    steps = len(timesteps)
    times = setup.start_time_s + np.cumsum(timesteps)
    starts = times - timesteps
    q_refs, v_refs, a_refs = _step_references(spline, float(evaluation.times_s[-1]), starts)
    sensor = np.zeros(steps)
    contact_force = np.zeros(steps)
    approach = np.full(steps, np.nan)
    watch_from = setup.impact_time_s - setup.fine_before_s
    stiffness = setup.sensor.stiffness_n_m
    full_inertia = np.zeros((model.nv, model.nv))
    jacobian = np.zeros((3, model.nv))
    arm_block = _arm_block(dof)
    torque = np.zeros(len(dof))
    tracking_error = 0.0
    saturation_time = float("nan")
    saturation_joint = ""
    touched = False
    period = setup.gains.period_s
    kp, kd = setup.gains.kp_per_s2, setup.gains.kd_per_s
    clip = setup.gains.clip_to_effort_limits
    next_update = setup.start_time_s
    for step in range(steps):
        model.opt.timestep = timesteps[step]
        mujoco.mj_step1(model, data)
        if period is None or starts[step] >= next_update - 1e-12:
            next_update += period or 0.0
            position = data.qpos[scene.arm_qpos]
            velocity = data.qvel[dof]
            error = q_refs[step] - position
            if not touched:
                tracking_error = max(tracking_error, float(np.abs(error).max()))
            mujoco.mj_fullM(model, data, full_inertia)
            command = a_refs[step] + kd * (v_refs[step] - velocity) + kp * error
            torque = full_inertia[arm_block] @ command + data.qfrc_bias[dof]
            if np.any(np.abs(torque) > effort):
                if np.isnan(saturation_time):
                    saturation_time = float(starts[step])
                    saturation_joint = robot.joint_names[int(np.argmax(np.abs(torque) / effort))]
                if clip:
                    torque = np.clip(torque, -effort, effort)
        data.qfrc_applied[dof] = torque
        if not touched and starts[step] >= watch_from:
            mujoco.mj_jacBody(model, data, jacobian, None, scene.tip_body)
            approach[step] = float(direction @ (jacobian @ data.qvel))
        mujoco.mj_step2(model, data)
        if data.ncon:
            contact_force[step] = _contact_normal_force(scene)
            touched = touched or contact_force[step] > 0.0
        if stiffness is None:
            sensor[step] = contact_force[step]
        else:
            sensor[step] = stiffness * data.qpos[scene.sensor_qpos] + (
                setup.sensor.damping_n_s_m * data.qvel[scene.sensor_dof]
            )
    return _summarise(
        evaluation,
        times,
        timesteps,
        sensor,
        contact_force,
        approach,
        setup,
        tracking_error,
        saturation_time,
        saturation_joint,
    )


def _summarise(
    evaluation: GraspEvaluation,
    times: np.ndarray,
    timesteps: np.ndarray,
    sensor: np.ndarray,
    contact_force: np.ndarray,
    approach: np.ndarray,
    setup: CollisionSetup,
    tracking_error: float,
    saturation_time: float,
    saturation_joint: str = "",
) -> CollisionResult:
    hits = np.flatnonzero(contact_force > 0.0)
    if len(hits) == 0:
        nan = float("nan")
        return CollisionResult(
            times,
            sensor,
            contact_force,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            tracking_error,
            saturation_time,
            saturation_joint,
        )
    first = int(hits[0])
    contact_time = float(times[first] - timesteps[first])  # the force acted during that step
    window = (times >= times[first]) & (times <= times[first] + setup.peak_window_s)
    peak = int(np.argmax(np.where(window, sensor, -np.inf)))
    # First impact episode: from first contact until the sensor force first falls back to 0.
    released = np.flatnonzero(sensor[first + 1 :] <= 0.0)
    last = first + 1 + (int(released[0]) if len(released) else len(sensor) - first - 1)
    return CollisionResult(
        times_s=times,
        sensor_force_n=sensor,
        contact_force_n=contact_force,
        contact_time_s=contact_time,
        peak_force_n=float(sensor[peak]),
        peak_time_s=float(times[peak]),
        peak_contact_force_n=float(contact_force[window].max()),
        impulse_n_s=float(np.sum(contact_force[first:last] * timesteps[first:last])),
        approach_speed_m_s=float(approach[first]),
        effective_mass_at_impact_kg=float(
            np.interp(contact_time, evaluation.times_s, evaluation.effective_mass_kg)
        ),
        tracking_error_rad=tracking_error,
        first_saturation_time_s=saturation_time,
        first_saturation_joint=saturation_joint,
    )


@dataclass(frozen=True)
class ImpulseSetup:
    """Settings of the free-impact check of the effective mass.

    Attributes:
        speed_m_s: Tip speed along u before the impact [m/s].
        timestep_s: Physics timestep [s].
        contact: Contact of tip sphere and wall; must be frictionless (friction 0).
        tip_sphere_radius_m: Radius of the tip sphere [m].
        max_duration_s: Longest simulated impact [s].
    """

    speed_m_s: float = 0.25
    timestep_s: float = 1e-5
    contact: ContactConfig = field(
        default_factory=lambda: ContactConfig(friction=0.0, timeconst_s=5e-4, dampratio=1.0)
    )
    tip_sphere_radius_m: float = 0.02
    max_duration_s: float = 0.02

    def __post_init__(self) -> None:
        if self.contact.friction != 0.0:
            raise InvalidInputError(
                "impulse.contact.friction",
                f"the impulse check needs a frictionless contact, got {self.contact.friction}",
            )


@dataclass(frozen=True)
class ImpulseCase:
    """One free impact: the arm at q, tip moving at speed v along u, joints unactuated.

    Attributes:
        effective_mass_kg: The core's M_eff along u at q [kg].
        engine_effective_mass_kg: 1/(uᵀ J M⁻¹ Jᵀ u) from MuJoCo's own M and J [kg].
        impulse_n_s: ∫ contact normal force dt over the impact [N s].
        speed_before_m_s: Tip velocity along u before [m/s].
        speed_after_m_s: Tip velocity along u when the contact ends [m/s].
        restitution: e = -after / before (measured).
        predicted_impulse_n_s: (1 + e)·M_eff·v [N s].
        rel_error: |impulse - predicted| / predicted (inf if the tip never separated).
        duration_s: Contact duration [s].
        limit_active: Whether a joint-limit constraint acted (would spoil the check).
        peak_force_n: Largest contact normal force during the impact [N].
    """

    effective_mass_kg: float
    engine_effective_mass_kg: float
    impulse_n_s: float
    speed_before_m_s: float
    speed_after_m_s: float
    restitution: float
    predicted_impulse_n_s: float
    rel_error: float
    duration_s: float
    limit_active: bool
    peak_force_n: float = 0.0


class ImpulseChecker:
    """Free impacts of robot + object against a frictionless wall perpendicular to u.

    Gravity, actuators and joint damping are off; the tip sphere touches the wall at the
    start, moving at v along u (minimum-norm joint velocities). For a frictionless contact
    with normal u and a short impact, Δ(uᵀ ṗ_tip) = P / M_eff whatever the tangential
    velocity, so the normal impulse is P = (1 + e)·M_eff·v with e measured from the rebound.
    """

    def __init__(
        self,
        robot: RobotModel,
        urdf_source: str,
        object_inertia: ObjectInertia,
        transform_tip_to_object: pin.SE3,
        setup: ImpulseSetup | None = None,
        body_name: str | None = None,
    ) -> None:
        """``body_name``: the link whose origin carries the colliding sphere (default: the
        tip frame's), e.g. an elbow link for a whole-arm site at its joint's origin."""
        self.robot = robot
        self.setup = setup or ImpulseSetup()
        body_name = body_name or robot.tip_frame
        rigid = SensorConfig(stiffness_n_m=None)
        spec = base_spec(robot, urdf_source, self.setup.timestep_s, gravity=False)
        add_object(spec, robot.tip_frame, object_inertia, transform_tip_to_object)
        add_tip_sphere(spec, body_name, self.setup.tip_sphere_radius_m, self.setup.contact)
        add_obstacle(
            spec, np.array([10.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), self.setup.contact, rigid
        )
        self.scene = compile_scene(spec, robot)
        self.scene.tip_body = int(
            mujoco.mj_name2id(self.scene.model, mujoco.mjtObj.mjOBJ_BODY, body_name)
        )
        self.pillar = int(mujoco.mj_name2id(self.scene.model, mujoco.mjtObj.mjOBJ_BODY, "pillar"))

    def run(
        self, positions: np.ndarray, direction_in_base: np.ndarray, effective_mass_kg: float
    ) -> ImpulseCase:
        """One impact at chain positions, along a direction in base axes."""
        scene, setup = self.scene, self.setup
        model, data = scene.model, scene.data
        transform_base_to_world = pin.SE3(self.robot.transform_base_to_world)
        unit = transform_base_to_world.rotation @ (
            direction_in_base / np.linalg.norm(direction_in_base)
        )
        mujoco.mj_resetData(model, data)
        data.qpos[scene.arm_qpos] = positions
        mujoco.mj_forward(model, data)
        tip = data.xpos[scene.tip_body].copy()
        # Wall face exactly at the sphere's leading point: in contact from the first step.
        model.body_pos[self.pillar] = tip + setup.tip_sphere_radius_m * unit
        quat = pin.Quaternion(rotation_z_onto(unit))
        model.body_quat[self.pillar] = [quat.w, quat.x, quat.y, quat.z]
        jacobian = tip_translational_jacobian(scene)[:, scene.arm_dof]
        data.qvel[scene.arm_dof] = np.linalg.pinv(jacobian) @ (setup.speed_m_s * unit)
        mujoco.mj_forward(model, data)
        engine_mass = engine_effective_mass(scene, unit)
        speed_before = float(unit @ (tip_translational_jacobian(scene) @ data.qvel))
        steps = round(setup.max_duration_s / setup.timestep_s)
        impulse = peak_force = 0.0
        started = False
        limit_active = False
        duration = 0.0
        speed_after = float("nan")
        for _ in range(steps):
            mujoco.mj_step(model, data)
            force = _contact_normal_force(scene)
            limit_active = limit_active or bool(
                np.any(data.efc_type[: data.nefc] == mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
            )
            if force > 0.0:
                started = True
                peak_force = max(peak_force, force)
                impulse += force * setup.timestep_s
                duration += setup.timestep_s
            elif started and not _touching(scene):
                speed_after = float(unit @ (tip_translational_jacobian(scene) @ data.qvel))
                break
        # No separation within max_duration_s: the check cannot be made (error = inf).
        restitution = -speed_after / speed_before
        predicted = (1.0 + restitution) * effective_mass_kg * speed_before
        error = abs(impulse - predicted) / predicted if np.isfinite(predicted) else np.inf
        return ImpulseCase(
            effective_mass_kg=float(effective_mass_kg),
            engine_effective_mass_kg=engine_mass,
            impulse_n_s=impulse,
            speed_before_m_s=speed_before,
            speed_after_m_s=speed_after,
            restitution=float(restitution),
            predicted_impulse_n_s=float(predicted),
            rel_error=float(error),
            duration_s=duration,
            limit_active=limit_active,
            peak_force_n=peak_force,
        )


def _touching(scene: Scene) -> bool:
    pair = {scene.sphere_geom, scene.face_geom}
    data = scene.data
    return any(
        {int(data.contact[i].geom1), int(data.contact[i].geom2)} == pair
        and data.contact[i].dist < 0.0
        for i in range(data.ncon)
    )
