"""SafetyReport -> columns of the grasp table (no Dask, no Arrow): one value per grasp, read
from the core's result objects, named as in the JSON of ``grasp-safety rank``."""

from __future__ import annotations

from typing import Any

from ..core.analyses.iso15066 import PowerForceLimitAssessment
from ..core.analyses.retime import most_binding
from ..core.analyses.safety_report import SafetyReport
from .schema import grasp_schema
from .sources import LABELS, GraspBlock


def _worst_ratio(assessment: PowerForceLimitAssessment | None) -> float | None:
    """Worst F/F_max over the permitted regions (that of the limiting region); None if none."""
    if assessment is None or not assessment.limiting_region:
        return None
    return assessment.region(assessment.limiting_region).worst_force_ratio


def report_columns(report: SafetyReport, per_sample: bool = False) -> dict[str, list[Any]]:
    """The result columns of each grasp of ``report``, in candidate order (NaN: null)."""
    ranking = report.ranking
    iso = {a.index: a for a in report.iso}
    postures = ranking.postures or (None,) * len(ranking.evaluations)
    columns: dict[str, list[Any]] = {}

    def put(name: str, value: Any) -> None:
        columns.setdefault(name, []).append(value)

    for k, (e, p) in enumerate(zip(ranking.evaluations, postures, strict=True)):
        a = iso.get(e.index)
        put("feasible", e.feasible)
        put("reason", e.reason)
        put("metric", ranking.metric)
        put("score", e.score)
        put("mean_effective_mass_kg", e.mean_effective_mass_kg)
        put("peak_effective_mass_kg", e.peak_effective_mass_kg)
        put("safety_score", float(report.scores[k]))
        put("restarts", None if p is None else p.restarts)
        put("score_single_ik", None if p is None else p.score_single_ik)
        put("score_range_low", None if p is None else p.score_range[0])
        put("score_range_high", None if p is None else p.score_range[1])
        starts = None if p is None else p.start_positions
        put("start_positions", starts.tolist() if starts is not None and len(starts) else None)
        put("postures_tried", None if p is None else p.postures_tried)
        put("postures_feasible", None if p is None else p.postures_feasible)
        put("postures_stopped", None if p is None else p.postures_stopped)
        put("iso_ts_15066_worst_force_ratio", _worst_ratio(a))
        put("iso_ts_15066_min_duration_s", None if a is None else a.min_duration_s)
        put("iso_ts_15066_limiting_region", (a.limiting_region or None) if a else None)
        put("iso_ts_15066_admissible_where_permitted", a.admissible_where_permitted if a else None)
        motion = report.retimed[k] if report.retimed else None
        put("safe_duration_s", None if motion is None else motion.safe_duration_s)
        put("retime_binding", None if motion is None else most_binding(motion))
        put(
            "retime_reason",
            report.retime_reasons[k] if report.retimed and motion is None else None,
        )
        put("backend", ranking.backend)
        if per_sample:
            for name in ("times_s", "effective_mass_kg", "tip_speed_m_s"):
                series = getattr(e, name)
                put(name.replace("times_s", "time_s"), series.tolist() if e.feasible else None)
    return columns


def block_columns(
    block: GraspBlock, report: SafetyReport | None, metric: str, per_sample: bool = False
) -> dict[str, list[Any]]:
    """Every column of the grasp table for the grasps of ``block``, in file order: the
    report's results for the readable grasps, nulls and the error for the others
    (``metric``: the one asked for, written on every row)."""
    count = len(block.grasp_ids)
    fmt = block.source.format
    scenario = block.scenario
    mass = None if scenario is None else scenario.object_inertia.mass_kg
    results = report_columns(report, per_sample) if report is not None else {}
    columns: dict[str, list[Any]] = {f.name: [] for f in grasp_schema(per_sample)}
    valid = 0
    for k in range(count):
        error = block.errors[k]
        row: dict[str, Any] = {
            "source": block.source.name,
            "format": fmt,
            "grasp_index": block.start + k,
            "grasp_id": block.grasp_ids[k],
            "object_file": block.object_file,
            "object_scale": block.object_scale,
            "object_mass_kg": mass,
        }
        for label in LABELS.values():
            row[label] = block.labels[k] if label == LABELS[fmt] else None
        if error is None:
            row.update({name: values[valid] for name, values in results.items()})
            row["error_key"] = row["error"] = None
            valid += 1
        else:
            row.update({"error_key": error[0], "error": error[1]})
            row.update({"feasible": False, "reason": f"unreadable: {error[1]}", "metric": metric})
        for name, values in columns.items():
            values.append(row.get(name))
    return columns
