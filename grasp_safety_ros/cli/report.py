"""Safety reports as JSON-ready dictionaries and as text tables (no NaN or inf in JSON)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..core.analyses.iso15066 import PowerForceLimitAssessment
from ..core.analyses.safety_report import SafetyReport
from ..core.method.executable import (
    joint_velocities_accelerations,
    rates_for_execution,
    rates_for_execution_many,
)
from ..core.method.ranking import GraspEvaluation, Ranking
from ..core.method.results import SCORE_CRITERION, PostureSelection
from ..core.model.armature import ArmatureRatio, armature_ratio
from ..core.model.robot import NO_ARMATURE_NOTE
from .report_values import force_ratio_text, name_width, number, numbers
from .retime_report import add_retime_to_grasp, retime_sections
from .whole_arm_report import whole_arm_lines, whole_arm_sites_to_dict, whole_arm_to_dict

SCORE_UNITS = {"mean": "kg", "max": "kg", "integral": "kg*s"}

SCHEMA_VERSION = 2
"""Version of the JSON layout: 2 holds each grasp's ``samples`` as one array per field
(columnar; 1, before it, held one object per sample). Bumped when a key moves, changes type
or goes; keys added beside the others do not bump it (as the whole arm's, the retiming's and
``posture.postures_stopped``, whose presence says that ``postures_feasible`` and
``score_range`` leave out the postures stopped early)."""


def evaluation_to_dict(
    evaluation: GraspEvaluation, per_sample: bool = True, velocities: np.ndarray | None = None
) -> dict[str, Any]:
    """One grasp of the paper's ranking; with ``per_sample``, its ``samples``: one array per
    field, one entry per sample (q and qd rows in joint_names order; ``velocities``: its q̇ if
    already computed, e.g. by ``rates_for_execution_many`` for a whole ranking)."""
    result: dict[str, Any] = {
        "index": evaluation.index,
        "name": evaluation.name,
        "feasible": evaluation.feasible,
        "reason": evaluation.reason,
        "score": number(evaluation.score),
        "mean_effective_mass_kg": number(evaluation.mean_effective_mass_kg),
        "peak_effective_mass_kg": number(evaluation.peak_effective_mass_kg),
        **_links_only_to_dict(evaluation),
    }
    if per_sample:
        if velocities is None:
            velocities, _ = rates_for_execution(
                evaluation.times_s, evaluation.joint_positions, evaluation.planned_joint_rates
            )
        result["samples"] = {
            "t_s": numbers(evaluation.times_s),
            "q": numbers(evaluation.joint_positions),
            "qd": numbers(velocities),
            "direction_in_base": numbers(evaluation.directions_in_base),
            "effective_mass_kg": numbers(evaluation.effective_mass_kg),
            "direction_is_worst_case": numbers(evaluation.direction_is_worst_case),
            "tip_speed_m_s": numbers(evaluation.tip_speed_m_s),
            "ik_iterations": numbers(evaluation.ik_iterations),
            "links_only_effective_mass_kg": numbers(evaluation.links_only_effective_mass_kg),
        }
    return result


def posture_to_dict(posture: PostureSelection) -> dict[str, Any]:
    """How one grasp's posture was chosen (core.method.posture); scores in the ranking's unit,
    and, when a criterion other than the score chose it, its name and values."""
    result = {
        "restarts": posture.restarts,
        "score_single_ik": number(posture.score_single_ik),
        "score_range": [number(posture.score_range[0]), number(posture.score_range[1])],
        "start_positions": posture.start_positions.tolist(),
        "postures_tried": posture.postures_tried,
        "postures_feasible": posture.postures_feasible,
        "postures_stopped": posture.postures_stopped,
    }
    if posture.criterion != SCORE_CRITERION:
        result["criterion"] = posture.criterion
        result["criterion_single_ik"] = number(posture.criterion_single_ik)
        result["criterion_value"] = number(posture.criterion_value)
    return result


def ranking_to_dict(ranking: Ranking, per_sample: bool = True) -> dict[str, Any]:
    """The paper's ranking: joint names, metric, ranking (indices), per-grasp results (with
    their per-sample arrays when ``per_sample``) and the backend that ran (``compiled`` or
    ``python``, with the reason of a fallback)."""
    evaluations = ranking.evaluations
    velocities: list[np.ndarray | None] = [None] * len(evaluations)
    if per_sample:  # the splines of all grasps in one pass
        trajectories = [(e.times_s, e.joint_positions, e.planned_joint_rates) for e in evaluations]
        velocities = [v for v, _ in rates_for_execution_many(trajectories)]
    grasps = [
        evaluation_to_dict(e, per_sample, v) for e, v in zip(evaluations, velocities, strict=True)
    ]
    for grasp, posture in zip(grasps, ranking.postures, strict=False):
        grasp["posture"] = posture_to_dict(posture)
    return {
        "schema_version": SCHEMA_VERSION,
        "backend": ranking.backend,
        "joint_names": list(ranking.joint_names),
        "metric": ranking.metric,
        "score_unit": SCORE_UNITS[ranking.metric],
        "ranking": list(ranking.order),
        "armature": armature_to_dict(ranking),
        "grasps": grasps,
    }


def iso_to_dict(assessment: PowerForceLimitAssessment) -> dict[str, Any]:
    """ISO/TS 15066 power and force limiting of one grasp, per body region."""
    return {
        "admissible": assessment.admissible,
        "admissible_where_permitted": assessment.admissible_where_permitted,
        "min_duration_s": number(assessment.min_duration_s),
        "limiting_region": assessment.limiting_region,
        "regions_not_permitted": list(assessment.regions_not_permitted),
        "regions": {
            r.region.name: {
                "transient_contact_permitted": r.transient_contact_permitted,
                "worst_force_ratio": number(r.worst_force_ratio),
                "peak_contact_force_n": number(r.peak_contact_force_n),
                "max_transient_force_n": r.region.max_transient_force_n,
                "min_max_permissible_speed_m_s": number(r.min_max_permissible_speed_m_s),
                "admissible": r.admissible,
                "min_duration_s": number(r.min_duration_s),
            }
            for r in assessment.regions
        },
    }


def _report_tree(report: SafetyReport, per_sample: bool = True) -> dict[str, Any]:
    """The CLI's JSON as a tree of dicts, lists, scalars and numpy arrays: the paper's
    ranking plus every analysis the options asked for.

    ``ranking`` is the final order (safety, safety + quality, or effort); ``safety_ranking``
    orders by the safety score alone (with the chosen ``metric_point``). Without
    ``per_sample``, the grasps have no ``samples`` (per-grasp summaries only).
    """
    result = ranking_to_dict(report.ranking, per_sample)
    options = report.options
    result.update(
        {
            "ranking": list(report.order),
            "safety_ranking": list(report.safety_order),
            "paper_ranking": list(report.ranking.order),
            "metric_point": options.metric_point,
            "rank_by": options.rank_by,
            "safety_weight": options.safety_weight if options.grasp_quality is not None else None,
            "pareto_set": list(report.quality.pareto_set)
            if options.grasp_quality is not None
            else None,
        }
    )
    if report.uncertainty is not None:
        u = report.uncertainty
        result["uncertainty"] = {
            "mass_fraction": u.uncertainty.mass_fraction,
            "com_offset_m": u.uncertainty.com_offset_m,
            "inertia_fraction": u.uncertainty.inertia_fraction,
            "percentile": u.uncertainty.percentile,
            "perturbations": len(u.perturbations.inertias),
            "ranking_flips": u.ranking_flips,
            "order_stability": number(u.order_stability),
            "worst_case_ranking": list(u.worst_case_order),
            "message": u.message,
        }
    if report.armature_range is not None:
        result["armature_range"] = armature_range_to_dict(report)
    iso = {a.index: a for a in report.iso}
    for k, grasp in enumerate(result["grasps"]):
        grasp["safety_score"] = number(report.scores[k])
        if k in iso:
            grasp["iso_ts_15066"] = iso_to_dict(iso[k])
        if options.grasp_quality is not None:
            grasp["quality"] = options.grasp_quality[k]
            grasp["combined_score"] = number(report.quality.combined[k])
            grasp["pareto_optimal"] = k in report.quality.pareto_set
        if report.uncertainty is not None:
            g = report.uncertainty.grasps[k]
            grasp["uncertainty"] = {
                "worst_case_score": number(g.worst_case_score),
                "percentile_score": number(g.percentile_score),
                "probability_safest": number(g.probability_safest),
            }
        _add_per_grasp_series(report, k, grasp)
        if report.whole_arm:
            grasp["whole_arm"] = whole_arm_to_dict(report.whole_arm[k], per_sample)
        add_retime_to_grasp(report, k, grasp, per_sample)
    if report.arm_sites is not None:
        result["whole_arm"] = whole_arm_sites_to_dict(report.arm_sites, options.whole_arm_region)
    return result


def _array_as_list(value: Any) -> Any:
    """orjson's fallback for what it does not write natively (e.g. a 0-d array)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def json_bytes(tree: Any) -> bytes:
    """Compact, strict UTF-8 JSON of a tree of dicts (str keys), lists, tuples, scalars and
    numpy arrays: NaN and inf are written as null.

    Written by orjson, which takes numpy arrays as they are (no per-float Python objects);
    floats are the shortest text that reads back to the same double.
    """
    import orjson  # imported when first needed (start-up time)

    return orjson.dumps(tree, default=_array_as_list, option=orjson.OPT_SERIALIZE_NUMPY)


def report_json_bytes(report: SafetyReport, per_sample: bool = True) -> bytes:
    """The CLI's JSON file: ``json_bytes`` of ``_report_tree``."""
    return json_bytes(_report_tree(report, per_sample))


def report_json(report: SafetyReport, per_sample: bool = True) -> str:
    """``report_json_bytes`` as text."""
    return report_json_bytes(report, per_sample).decode("utf-8")


def report_to_dict(report: SafetyReport, per_sample: bool = True) -> dict[str, Any]:
    """The CLI's JSON read back: plain dicts, lists, floats and None (``report_json``)."""
    import orjson  # imported when first needed (start-up time)

    return orjson.loads(report_json_bytes(report, per_sample))


def _add_per_grasp_series(report: SafetyReport, k: int, grasp: dict[str, Any]) -> None:
    """The analyses' per-grasp results, and their per-sample arrays into ``grasp["samples"]``
    when it is there."""
    samples = grasp.get("samples")
    if report.exposed:
        exposed = report.exposed[k]
        grasp["exposed_points_in_object_m"] = numbers(exposed.points_in_object_m)
        if samples is not None:
            samples["leading_point_index"] = numbers(exposed.leading_point_index)
            samples["leading_point_effective_mass_kg"] = numbers(exposed.leading_effective_mass_kg)
            samples["worst_point_index"] = numbers(exposed.worst_point_index)
            samples["worst_point_effective_mass_kg"] = numbers(exposed.worst_effective_mass_kg)
    if report.redundancy:
        resolution = report.redundancy[k]
        grasp["redundancy"] = {
            "applied": resolution.applied,
            "reason": resolution.reason,
            "score": number(resolution.score),
            "score_without": number(resolution.original_score),
        }
        if resolution.applied and samples is not None:
            velocities, _ = joint_velocities_accelerations(
                resolution.times_s, resolution.joint_positions
            )
            samples["q_redundancy"] = numbers(resolution.joint_positions)
            samples["qd_redundancy"] = numbers(velocities)
            samples["effective_mass_redundancy_kg"] = numbers(resolution.effective_mass_kg)
    if report.effort:
        effort = report.effort[k]
        if effort.feasible:
            grasp["effort"] = {
                "peak_abs_torque": numbers(effort.peak_abs_torque),
                "rms_torque": numbers(effort.rms_torque),
                "effort_limits": numbers(effort.effort_limits),
                "peak_fraction_of_limit": numbers(effort.peak_fraction_of_limit),
                "rms_fraction_of_limit": numbers(effort.rms_fraction_of_limit),
                "score": number(effort.score(report.options.effort_criterion)),
                "criterion": report.options.effort_criterion,
            }
            if samples is not None:
                samples["joint_torques"] = numbers(effort.joint_torques)


def ranking_table(ranking: Ranking) -> str:
    """Plain-text table: rank, index, name, score, mean and peak effective mass, or the reason."""
    unit = SCORE_UNITS[ranking.metric]
    score = f"score [{unit}]"
    width = name_width([e.name for e in ranking.evaluations])
    header = (
        f"{'rank':>4}  {'index':>5}  {'name':<{width}} {score:>14} {'mean [kg]':>10} "
        f"{'peak [kg]':>10}"
    )
    if ranking.armature_given:  # with armature; the links-only mean (a lower bound) beside
        header += f" {'links [kg]':>10}"
    lines = [f"metric: {ranking.metric}", header, "-" * len(header)]
    for rank, index in enumerate(ranking.order, start=1):
        e = ranking.evaluations[index]
        worst = "  (worst-case direction used)" if e.direction_is_worst_case.any() else ""
        links = ""
        if ranking.armature_given:
            links = f" {float(np.mean(e.links_only_effective_mass_kg)):>10.4f}"
        lines.append(
            f"{rank:>4}  {index:>5}  {e.name:<{width}} {e.score:>14.4f} "
            f"{e.mean_effective_mass_kg:>10.4f} {e.peak_effective_mass_kg:>10.4f}{links}{worst}"
        )
    if ranking.armature_given:
        lines.append(armature_line(ranking))
    for e in ranking.evaluations:
        if not e.feasible:
            lines.append(f"{'-':>4}  {e.index:>5}  {e.name:<{width}} infeasible: {e.reason}")
    return "\n".join(lines)


ISO_COLUMNS = 8
"""Grasps shown in the ISO/TS 15066 table (the first ones of the final ranking)."""


def _iso_lines(report: SafetyReport) -> list[str]:
    """Worst transient F/F_max per body region (rows) for the best-ranked grasps (columns)."""
    by_index = {a.index: a for a in report.iso if a.feasible}
    shown = [by_index[k] for k in report.order if k in by_index][:ISO_COLUMNS]
    if not shown:
        return []
    region_width = name_width([r.region.name for r in shown[0].regions])
    widths = [max(15, len(a.name)) for a in shown]

    def row(label: str, cells: Sequence[str]) -> str:
        return f"{label:<{region_width}} " + " ".join(
            f"{cell:>{w}}" for cell, w in zip(cells, widths, strict=True)
        )

    lines = [
        "",
        "ISO/TS 15066 transient contact, worst F/F_max over the trajectory "
        "(n/p: transient contact not permitted; > 1: too fast)",
        row("region", [a.name for a in shown]),
    ]
    for j, region in enumerate(shown[0].regions):
        lines.append(
            row(
                region.region.name,
                [force_ratio_text(a.regions[j].worst_force_ratio) for a in shown],
            )
        )
    lines.append(
        row("ok where allowed", ["yes" if a.admissible_where_permitted else "no" for a in shown])
    )
    lines.append(row("T_min [s]", [f"{a.min_duration_s:.3f}" for a in shown]))
    if len(by_index) > len(shown):
        lines.append(f"({len(by_index) - len(shown)} more feasible grasps in the JSON output)")
    return lines


def _posture_summary(p: PostureSelection) -> str:
    """One grasp's line of the posture selection; an infeasible one counts the IK seeds as the
    evaluation's reason does (the configured seed and the restarts)."""
    if p.restarts == 0:  # select_posture keeps a planned joint trajectory's posture as given
        given = f"score {p.score:.4f}" if p.postures_feasible else "infeasible"
        return f"planned joint trajectory, posture as given: {given}"
    if not p.postures_feasible:
        followed = p.postures_tried
        return (
            f"no feasible posture from {p.restarts + 1} IK seeds ({followed} distinct start "
            f"posture{'s' if followed != 1 else ''} followed)"
        )
    by = f", {p.postures_stopped} stopped early" if p.postures_stopped else ""
    if p.criterion != SCORE_CRITERION:
        by += f", chosen by {p.criterion} {p.criterion_single_ik:.4g} -> {p.criterion_value:.4g}"
    return (
        f"single IK {p.score_single_ik:.4f} -> {p.score:.4f} "
        f"(range {p.score_range[0]:.4f}..{p.score_range[1]:.4f}, "
        f"{p.postures_feasible}/{p.postures_tried} postures feasible{by})"
    )


def report_text(report: SafetyReport) -> str:
    """The ranking table followed by one section per analysis that was run."""
    options = report.options
    lines = [ranking_table(report.ranking)]
    evaluations = report.ranking.evaluations
    width = name_width([e.name for e in evaluations])
    if options.metric_point != "tip" or report.redundancy or options.grasp_quality is not None:
        lines.append("")
        what = f"metric point: {options.metric_point}"
        if report.redundancy and options.metric_point == "tip":
            what += ", redundancy resolved"
        if options.grasp_quality is not None:
            what += f", quality weight {1 - options.safety_weight:g}"
        lines.append(f"final ranking ({what}, rank_by={options.rank_by}):")
        for rank, k in enumerate(report.order, start=1):
            extra = ""
            if options.grasp_quality is not None:
                pareto = " pareto" if k in report.quality.pareto_set else ""
                extra = f"  quality {options.grasp_quality[k]:.3f}{pareto}"
            lines.append(
                f"{rank:>4}  {k:>5}  {evaluations[k].name:<{width}} "
                f"safety score {report.scores[k]:.4f}{extra}"
            )
    postures = report.ranking.postures
    restarts = max((p.restarts for p in postures), default=0)
    if restarts > 0:
        lines += ["", f"posture selection ({restarts} IK restarts per grasp):"]
        for p in postures:
            lines.append(f"  {evaluations[p.index].name:<{width}} {_posture_summary(p)}")
    if report.iso:
        lines += _iso_lines(report)
    if report.whole_arm:
        lines += whole_arm_lines(report)
    lines += retime_sections(report)
    if report.uncertainty is not None:
        lines += ["", f"inertia uncertainty (tip effective mass): {report.uncertainty.message}"]
        for g in report.uncertainty.grasps:
            if g.feasible:
                lines.append(
                    f"  {g.name:<{width}} nominal {g.nominal_score:.4f}  worst case "
                    f"{g.worst_case_score:.4f}  p{report.uncertainty.uncertainty.percentile:g} "
                    f"{g.percentile_score:.4f}  P(safest) {g.probability_safest:.2f}"
                )
    if report.armature_range is not None:
        lines += armature_range_lines(report)
    if report.redundancy:
        lines += ["", "redundancy (null-space) resolution, tip effective mass:"]
        for r in report.redundancy:
            if r.applied:
                lines.append(f"  {r.name:<{width}} score {r.original_score:.4f} -> {r.score:.4f}")
            else:
                lines.append(f"  {r.name:<{width}} not applied: {r.reason}")
    if report.effort:
        lines += ["", f"joint effort ({options.effort_criterion} of the torque limits):"]
        for e in report.effort:
            if e.feasible:
                lines.append(
                    f"  {e.name:<{width}} peak |tau| max {np.max(e.peak_abs_torque):.2f} N m, "
                    f"{options.effort_criterion} {e.score(options.effort_criterion):.3f}"
                )
    return "\n".join(lines)


# --- Armature (reflected rotor inertia): links-only masses and their ratio -------------------


def _links_only_to_dict(evaluation: GraspEvaluation) -> dict[str, Any]:
    """Mean and peak of the links-only effective mass [kg] (NaN: None if infeasible)."""
    links = evaluation.links_only_effective_mass_kg
    feasible = evaluation.feasible and len(links) > 0
    return {
        "links_only_mean_effective_mass_kg": number(np.mean(links)) if feasible else None,
        "links_only_peak_effective_mass_kg": number(np.max(links)) if feasible else None,
    }


def _ratio_of(ranking: Ranking) -> ArmatureRatio:
    feasible = [e for e in ranking.evaluations if e.feasible]
    return armature_ratio(
        [e.effective_mass_kg for e in feasible], [e.links_only_effective_mass_kg for e in feasible]
    )


def armature_to_dict(ranking: Ranking) -> dict[str, Any]:
    """Whether armature was given, and the ratio with armature / links only over the samples."""
    ratio = _ratio_of(ranking)
    return {
        "given": ranking.armature_given,
        "note": "" if ranking.armature_given else NO_ARMATURE_NOTE,
        "ratio_median": number(ratio.median),
        "ratio_p10": number(ratio.p10),
        "ratio_p90": number(ratio.p90),
        "ratio_max": number(ratio.maximum),
    }


def armature_line(ranking: Ranking) -> str:
    """The ratio with armature / links only (under the ranking table), or the note."""
    if not ranking.armature_given:
        return NO_ARMATURE_NOTE
    ratio = _ratio_of(ranking)
    return (
        f"effective mass with rotor inertia / links only: median x{ratio.median:.2f} "
        f"(p10 x{ratio.p10:.2f}, p90 x{ratio.p90:.2f}, max x{ratio.maximum:.2f}, "
        f"{ratio.samples} samples)"
    )


def armature_range_to_dict(report: SafetyReport) -> dict[str, Any] | None:
    """Effective-mass range and scores at both ends of the armature ranges, if given."""
    spread = report.armature_range
    if spread is None:
        return None
    return {
        "lower_kgm2": spread.lower_kgm2.tolist(),
        "upper_kgm2": spread.upper_kgm2.tolist(),
        "effective_mass_range_kg": numbers(spread.effective_mass_range_kg),
        "scores_lower": numbers(spread.scores_lower),
        "scores_upper": numbers(spread.scores_upper),
        "order_lower": list(spread.order_lower),
        "order_upper": list(spread.order_upper),
        "ranking_flips": spread.ranking_flips,
        "message": spread.message,
    }


def armature_range_lines(report: SafetyReport) -> list[str]:
    """Per grasp the effective-mass range over the armature ranges, and whether it flips."""
    spread = report.armature_range
    if spread is None:
        return []
    lines = ["", f"armature ranges (tip effective mass): {spread.message}"]
    width = name_width([e.name for e in report.ranking.evaluations])
    for k, e in enumerate(report.ranking.evaluations):
        if e.feasible:
            low, high = spread.effective_mass_range_kg[k]
            scores = f"{spread.scores_lower[k]:.4f}..{spread.scores_upper[k]:.4f}"
            lines.append(
                f"  {e.name:<{width}} score {scores}  effective mass {low:.3f}..{high:.3f} kg"
            )
    return lines
