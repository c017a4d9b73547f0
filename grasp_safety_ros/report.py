"""Rankings as JSON-ready dictionaries and as a text table."""

from __future__ import annotations

import math
from typing import Any

from .core.ranking import GraspEvaluation, Ranking

SCORE_UNITS = {"mean": "kg", "max": "kg", "integral": "kg*s"}


def _number(value: float) -> float | None:
    """JSON has no NaN: infeasible scores become null."""
    return None if math.isnan(value) else float(value)


def evaluation_to_dict(evaluation: GraspEvaluation) -> dict[str, Any]:
    """One grasp in the JSON shape of the CLI (samples carry q in joint_names order)."""
    samples = [
        {
            "t_s": float(evaluation.times_s[i]),
            "q": evaluation.joint_positions[i].tolist(),
            "direction_in_base": evaluation.directions_in_base[i].tolist(),
            "effective_mass_kg": float(evaluation.effective_mass_kg[i]),
            "direction_is_worst_case": bool(evaluation.direction_is_worst_case[i]),
            "tip_speed_m_s": float(evaluation.tip_speed_m_s[i]),
            "ik_iterations": int(evaluation.ik_iterations[i]),
        }
        for i in range(len(evaluation.times_s))
    ]
    return {
        "index": evaluation.index,
        "name": evaluation.name,
        "feasible": evaluation.feasible,
        "reason": evaluation.reason,
        "score": _number(evaluation.score),
        "mean_effective_mass_kg": _number(evaluation.mean_effective_mass_kg),
        "peak_effective_mass_kg": _number(evaluation.peak_effective_mass_kg),
        "samples": samples,
    }


def ranking_to_dict(ranking: Ranking) -> dict[str, Any]:
    """The CLI's JSON output: joint names, metric, ranking (indices) and per-grasp results."""
    return {
        "joint_names": list(ranking.joint_names),
        "metric": ranking.metric,
        "score_unit": SCORE_UNITS[ranking.metric],
        "ranking": list(ranking.order),
        "grasps": [evaluation_to_dict(e) for e in ranking.evaluations],
    }


def ranking_table(ranking: Ranking) -> str:
    """Plain-text table: rank, index, name, score, mean and peak effective mass, or the reason."""
    unit = SCORE_UNITS[ranking.metric]
    score = f"score [{unit}]"
    header = (
        f"{'rank':>4}  {'index':>5}  {'name':<16} {score:>14} {'mean [kg]':>10} {'peak [kg]':>10}"
    )
    lines = [f"metric: {ranking.metric}", header, "-" * len(header)]
    for rank, index in enumerate(ranking.order, start=1):
        e = ranking.evaluations[index]
        worst = "  (worst-case direction used)" if e.direction_is_worst_case.any() else ""
        lines.append(
            f"{rank:>4}  {index:>5}  {e.name[:16]:<16} {e.score:>14.4f} "
            f"{e.mean_effective_mass_kg:>10.4f} {e.peak_effective_mass_kg:>10.4f}{worst}"
        )
    for e in ranking.evaluations:
        if not e.feasible:
            lines.append(f"{'-':>4}  {e.index:>5}  {e.name[:16]:<16} infeasible: {e.reason}")
    return "\n".join(lines)
