"""The whole-arm exposure in the CLI's JSON and text (core.analyses.whole_arm)."""

from __future__ import annotations

from typing import Any

from ..core.analyses.safety_report import SafetyReport
from ..core.analyses.whole_arm import ArmSites, WholeArmEvaluation
from .report_values import force_ratio_text, name_width, number, numbers


def whole_arm_sites_to_dict(sites: ArmSites, rank_region: str) -> dict[str, Any]:
    """The whole-arm sites (the column order of every grasp's ``whole_arm`` arrays)."""
    return {
        "sites": list(sites.names),
        "links": list(sites.links),
        "points_in_joint_m": sites.points_in_joint_m.tolist(),
        "dropped_welded_to_base": list(sites.dropped),
        "rank_region": rank_region,
    }


def whole_arm_to_dict(whole: WholeArmEvaluation, per_sample: bool = True) -> dict[str, Any]:
    """One grasp's whole-arm exposure: worst site per body region and by energy, the
    admissibility over the arm, T_min, and (with ``per_sample``) the (N, K) per-sample arrays
    (sites as columns)."""
    if not whole.feasible:
        return {"feasible": False}
    times = whole.times_s

    def where(site: int, sample: int) -> dict[str, Any]:
        return {
            "site": whole.site_names[site],
            "link": whole.site_links[site],
            "time_s": float(times[sample]),
            "effective_mass_kg": number(whole.effective_mass_kg[sample, site]),
            "speed_m_s": float(whole.speed_m_s[sample, site]),
        }

    energy, site, sample = whole.worst_energy
    result = {
        "feasible": True,
        "regions": {
            r.region: {
                "worst_force_ratio": number(r.worst_force_ratio),
                "peak_contact_force_n": r.peak_contact_force_n,
                "admissible": r.admissible,
                "min_duration_s": number(r.min_duration_s),
                **where(r.worst_site, r.worst_sample),
            }
            for r in whole.regions
        },
        "worst_energy": {"energy_j": energy, **where(site, sample)},
        "admissible": whole.admissible,
        "admissible_where_permitted": whole.admissible_where_permitted,
        "min_duration_s": number(whole.min_duration_s),
        "limiting_region": whole.limiting_region,
    }
    if per_sample:
        result["effective_mass_kg"] = numbers(whole.effective_mass_kg)
        result["speed_m_s"] = numbers(whole.speed_m_s)
        result["stationary"] = numbers(whole.stationary)
    return result


def whole_arm_lines(report: SafetyReport) -> list[str]:
    """One line per feasible grasp (final order): the worst site of the limiting region, of the
    ranking region, and by energy, with their links, and T_min over the whole arm."""
    sites = report.arm_sites
    region = report.options.whole_arm_region
    names = ", ".join(sites.names) if sites is not None else ""
    lines = [
        "",
        f"whole arm (sites: {names}; worst over sites and samples; grasps in the final order, "
        f"rank_by={report.options.rank_by}):",
    ]
    by_index = {w.index: w for w in report.whole_arm if w.feasible}
    width = name_width([w.name for w in report.whole_arm])
    for k in report.order:
        w = by_index.get(k)
        if w is None:
            continue
        energy, e_site, _ = w.worst_energy
        ranked = w.region(region) if any(r.region == region for r in w.regions) else None
        text = f"  {w.name:<{width}}"
        if w.limiting_region:
            limiting = w.region(w.limiting_region)
            text += (
                f" {w.limiting_region} F/F_max {force_ratio_text(limiting.worst_force_ratio)} at "
                f"{w.site_names[limiting.worst_site]} ({w.site_links[limiting.worst_site]}),"
            )
        if ranked is not None:
            text += f" {region} peak {ranked.peak_contact_force_n:.1f} N,"
        text += (
            f" energy {energy:.3f} J at {w.site_names[e_site]} ({w.site_links[e_site]}),"
            f" T_min {w.min_duration_s:.3f} s,"
            f" ok where allowed {'yes' if w.admissible_where_permitted else 'no'}"
        )
        lines.append(text)
    return lines
