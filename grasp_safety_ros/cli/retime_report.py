"""The safe retiming and the standard's effective-mass estimate in the CLI's JSON and text
(core.analyses.retime, core.analyses.safe_duration; docs/safe_speed.md)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..core.analyses.retime import RetimedMotion, most_binding
from ..core.analyses.safe_duration import compare_with_standard
from ..core.analyses.safety_report import SafetyReport


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def retimed_to_dict(
    motion: RetimedMotion | None, per_sample: bool = True, reason: str = "none found"
) -> dict[str, Any]:
    """One grasp's retiming: ``safe_duration_s`` (None: infeasible or no timing found, with
    ``retime_reason`` why; else ``retime_binding``, what binds most), the planner's worst
    ratio and the uniform T_min; with ``per_sample`` the trajectory ``{t_s, q, qd, qdd}``
    (rows in ``joint_names`` order), the binding constraint per sample and its ratio, and per
    region the worst site's speed and its limit f · v_max."""
    if motion is None:
        return {"safe_duration_s": None, "retime_reason": reason}
    result: dict[str, Any] = {
        "safe_duration_s": motion.safe_duration_s,
        "retime_binding": most_binding(motion),
        "planned_duration_s": motion.planned_duration_s,
        "planned_worst_ratio": motion.planned_worst_ratio,
        "planned_worst_site": motion.planned_worst_site,
        "uniform_min_duration_s": motion.uniform_min_duration_s,
        "uniform_feasible_duration_s": motion.uniform_feasible_duration_s,
    }
    if per_sample:
        result["retimed"] = {
            "t_s": motion.times_s,
            "q": motion.positions,
            "qd": motion.velocities,
            "qdd": motion.accelerations,
            "binding": list(motion.binding),
            "binding_ratio": motion.binding_ratio,
            "regions": list(motion.regions),
            "region_speed_m_s": motion.region_speed_m_s,
            "region_limit_m_s": motion.region_limit_m_s,
        }
    return result


def standard_mass_to_dict(report: SafetyReport, k: int) -> dict[str, Any] | None:
    """ISO/TS 15066's m_R = M/2 + m_L beside the exact effective mass of grasp ``k``: the
    tip's largest along the motion and, with the whole arm, every site's; ``optimistic``
    where the estimate is smaller (None: infeasible)."""
    evaluation = report.ranking.evaluations[k]
    if not evaluation.feasible:
        return None
    estimate = report.standard_mass_estimate_kg
    tip = float(np.max(evaluation.effective_mass_kg))
    result: dict[str, Any] = {
        "estimate_kg": _number(estimate),
        "tip_exact_kg": tip,
        "tip_optimistic": bool(estimate < tip),
    }
    if report.whole_arm and report.whole_arm[k].feasible:
        whole = report.whole_arm[k]
        sites = compare_with_standard(estimate, whole.effective_mass_kg, whole.stationary)
        result["sites"] = {
            name: {"exact_kg": _number(exact), "optimistic": bool(optimistic)}
            for name, exact, optimistic in zip(
                whole.site_names, sites.exact_kg, sites.optimistic, strict=True
            )
        }
    return result


def _reason(report: SafetyReport, k: int) -> str:
    """Why grasp ``k`` has no retimed motion."""
    reasons = report.retime_reasons
    return (reasons[k] if k < len(reasons) else "") or "infeasible or none found"


def retime_lines(report: SafetyReport) -> list[str]:
    """One line per grasp in the final order: safe duration, planned and uniform T_min, what
    binds most; then the standard's estimate where it is optimistic."""
    factor = report.options.retime.safety_factor if report.options.retime else 1.0
    lines = ["", f"safe retiming (TOPP-RA, site speeds <= {factor:g} x v_max, joint limits):"]
    evaluations = report.ranking.evaluations
    for k in list(report.order) + [k for k in range(len(evaluations)) if k not in report.order]:
        motion = report.retimed[k] if report.retimed else None
        name = evaluations[k].name or f"grasp {k}"
        if motion is None:
            lines.append(f"  {name}: no safe timing ({_reason(report, k)})")
            continue
        uniform = motion.uniform_feasible_duration_s
        lines.append(
            f"  {name}: safe duration {motion.safe_duration_s:.3f} s (planned "
            f"{motion.planned_duration_s:.3f} s at worst ratio {motion.planned_worst_ratio:.2f}"
            f"; uniform T_min {motion.uniform_min_duration_s:.3f} s, {uniform:.3f} s with the "
            f"joint limits, {100 * (1.0 - motion.safe_duration_s / uniform):.0f} % saved); "
            f"binding most: {most_binding(motion)}"
        )
    return lines


def standard_mass_lines(report: SafetyReport) -> list[str]:
    """The standard's m_R = M/2 + m_L and the grasps (and sites) where it is optimistic."""
    estimate = report.standard_mass_estimate_kg
    lines = ["", f"ISO/TS 15066 estimate m_R = M/2 + m_L = {estimate:.2f} kg (exact beside it):"]
    for k in report.order:
        entry = standard_mass_to_dict(report, k)
        if entry is None:
            continue
        name = report.ranking.evaluations[k].name or f"grasp {k}"
        flagged = [s for s, v in entry.get("sites", {}).items() if v["optimistic"]]
        text = f"  {name}: tip exact {entry['tip_exact_kg']:.2f} kg"
        text += " (estimate optimistic)" if entry["tip_optimistic"] else ""
        if flagged:
            text += f"; estimate optimistic at {', '.join(flagged)}"
        lines.append(text)
    return lines


def add_retime_to_grasp(
    report: SafetyReport, k: int, grasp: dict[str, Any], per_sample: bool = True
) -> None:
    """Grasp ``k``'s retiming (when on) and the standard's estimate (with the whole arm or
    the retiming) into its JSON entry ``grasp``."""
    if report.retimed:
        grasp.update(retimed_to_dict(report.retimed[k], per_sample, _reason(report, k)))
    if report.whole_arm or report.retimed:
        grasp["standard_mass_estimate"] = standard_mass_to_dict(report, k)


def retime_sections(report: SafetyReport) -> list[str]:
    """The text report's retiming lines (when on) and the standard's estimate (with the
    whole arm or the retiming)."""
    lines = retime_lines(report) if report.retimed else []
    if report.whole_arm or report.retimed:
        lines += standard_mass_lines(report)
    return lines
