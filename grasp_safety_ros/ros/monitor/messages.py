"""The monitor's outgoing messages: the per-state status and its /diagnostics status."""

from __future__ import annotations

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from grasp_safety_msgs.msg import RegionSpeed, SpeedScalingStatus
from std_msgs.msg import Header

from ..robot.bundle import RobotBundle
from .governor import Decision, GovernorCounters
from .parameters import MonitorSettings


def status_msg(decision: Decision, stamp: Time, base_frame: str) -> SpeedScalingStatus:
    """The SpeedScalingStatus of ``decision`` for the state stamped ``stamp``."""
    scaling = decision.scaling
    regions = [] if scaling is None else scaling.regions
    return SpeedScalingStatus(
        header=Header(stamp=stamp, frame_id=base_frame),
        factor=decision.factor,
        target_factor=decision.target,
        state_factor=scaling.factor if scaling else 0.0,
        limiting_site=scaling.limiting_site if scaling else "",
        limiting_region=scaling.limiting_region if scaling else "",
        fail_safe=decision.fail_safe,
        compute_time_s=decision.compute_time_s,
        regions=[
            RegionSpeed(
                region=r.region,
                worst_site=r.site,
                effective_mass_kg=r.effective_mass_kg,
                speed_m_s=r.speed_m_s,
                max_permissible_speed_m_s=r.max_speed_m_s,
                factor=r.factor,
            )
            for r in regions
        ],
    )


def diagnostic_status(
    node_name: str,
    last: Decision | None,
    counters: GovernorCounters,
    settings: MonitorSettings,
    bundle: RobotBundle | None,
    payload_note: str,
    last_refusal: str,
) -> DiagnosticStatus:
    """The monitor's DiagnosticStatus: ERROR with the one-line reason in a fail-safe, WARN
    while the factor is below 1, OK at 1."""
    if last is None:
        level, message = DiagnosticStatus.ERROR, "fail-safe (factor 0): no /joint_states yet"
    elif last.fail_safe:
        level, message = DiagnosticStatus.ERROR, f"fail-safe (factor 0): {last.fail_safe}"
    elif last.factor < 1.0:
        scaling = last.scaling
        where = f"{scaling.limiting_site} vs {scaling.limiting_region}" if scaling else ""
        level = DiagnosticStatus.WARN
        message = f"scaling {last.factor:.3f} (target {last.target:.3f}{', ' if where else ''}"
        message += f"{where})"
    else:
        level, message = DiagnosticStatus.OK, "factor 1"
    node = settings.node
    values = {
        "robot_source": bundle.origin if bundle else "",
        "factor": f"{last.factor:.6f}" if last else "0",
        "states": counters.states,
        "refused_states": counters.refused,
        "timeouts": counters.timeouts,
        "last_compute_time_s": f"{counters.last_compute_time_s:.6f}",
        "max_compute_time_s": f"{counters.max_compute_time_s:.6f}",
        "joint_states_timeout_s": settings.joint_states_timeout_s,
        "margin": settings.margin,
        "closed_loop": settings.closed_loop,
        "max_increase_per_s": settings.max_increase_per_s,
        "payload": payload_note,
        "last_refusal": last_refusal,
    }
    return DiagnosticStatus(
        level=level,
        name=f"{node_name}: speed scaling",
        message=message,
        hardware_id=f"{node.base_frame}->{node.tip_frame}",
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
    )
