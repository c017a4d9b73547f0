"""results.md: the headline figures, tables and a reading of the validation run.

Every number and every claim in the text is computed from the results dict, so that the
report stays true when the run changes.
"""

from __future__ import annotations

from typing import Any

from .reading import number, reading_markdown


def _grasp_table(summary: dict[str, Any], parameter_columns: list[tuple[str, str, int]]) -> str:
    variants = list(summary.get("variants", {}))
    header = [
        "grasp",
        *(title for _, title, _ in parameter_columns),
        "mean M_eff [kg]",
        "M_eff at impact [kg]",
        "arm alone at impact [kg]",
        "peak force [N]",
        "impulse [N s]",
        "max, whole record [N]",
        *(f"peak, {key.replace('_', ' ')} [N]" for key in variants),
    ]
    rows = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for grasp in summary["grasps"]:
        cells = [grasp["name"]]
        cells += [number(grasp.get(key), digits) for key, _, digits in parameter_columns]
        cells += [
            number(grasp["mean_effective_mass_kg"], 4),
            number(grasp["effective_mass_at_impact_kg"], 4),
            number(grasp.get("robot_only_effective_mass_at_impact_kg"), 4),
            number(grasp["peak_force_n"], 2),
            number(grasp["impulse_n_s"], 4),
            number(grasp["max_force_whole_record_n"], 1),
        ]
        cells += [number(grasp["variants"][key]["peak_force_n"], 2) for key in variants]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def _variant_table(results: dict[str, Any]) -> str:
    tensor, book = results["tensor_object"], results["book"]
    if not tensor.get("variants"):
        return "_No ablations in the quick run._"
    rows = [
        "| run | tensor: Spearman | tensor: peak worst/best | book: peak [N] "
        "| book: peak worst/best | book: order by peak force, safest first |",
        "|---|---|---|---|---|---|",
        f"| main, from {results['setup']['pillar']['simulated_from_s']:g} s "
        f"| {number(tensor['spearman_meff_vs_peak_force'])} "
        f"| {number(tensor['peak_force_ratio_worst_to_best'], 4)} "
        f"| {min(g['peak_force_n'] for g in book['grasps']):.1f} to "
        f"{max(g['peak_force_n'] for g in book['grasps']):.1f} "
        f"| {number(book['peak_force_ratio_worst_to_best'], 4)} "
        f"| {', '.join(book['order_by_peak_force'])} |",
    ]
    for key, variant in tensor["variants"].items():
        book_variant = book["variants"][key]
        rows.append(
            f"| {key.replace('_', ' ')}: {variant['description']} "
            f"| {number(variant['spearman_meff_vs_peak_force'])} "
            f"| {number(variant['peak_force_ratio_worst_to_best'], 4)} "
            f"| {book_variant['peak_force_min_n']:.1f} to {book_variant['peak_force_max_n']:.1f} "
            f"| {number(book_variant['peak_force_ratio_worst_to_best'], 4)} "
            f"| {', '.join(book_variant['order_by_peak_force'])} |"
        )
    return "\n".join(rows)


def _headline_table(results: dict[str, Any]) -> str:
    tensor, book, impulse = results["tensor_object"], results["book"], results["impulse_check"]
    paper = book["paper_gazebo"]
    peaks = [g["peak_force_n"] for g in book["grasps"]]
    rows = [
        ("", "this simulation (MuJoCo)", "paper (Gazebo)"),
        (
            f"tensor object: Spearman(M_eff at impact, peak force), {len(tensor['grasps'])} "
            "grasps",
            f"**{number(tensor['spearman_meff_vs_peak_force'])}**",
            '"in accordance" (no number)',
        ),
        (
            "book: peak force, safest to least safe grasp",
            f"{min(peaks):.1f} N to {max(peaks):.1f} N",
            f"{paper['peak_force_safest_n']:.0f} N to {paper['peak_force_least_safe_n']:.0f} N",
        ),
        (
            "book: peak force ratio worst/best",
            f"**{number(book['peak_force_ratio_worst_to_best'], 4)}**",
            f"{paper['peak_force_ratio_worst_to_best']:.2f}",
        ),
        (
            "book: force order = effective-mass order at impact",
            "yes" if book["ordering_holds"] else "**no**",
            "yes",
        ),
        (
            "book: safest grasp by simulated peak force / by the core's mean M_eff",
            f"{book['order_by_peak_force'][0]} / {book['order_by_mean_effective_mass'][0]}",
            "grasp 3 / grasp 3",
        ),
        (
            "impulse check: worst relative error, cases",
            f"**{impulse['worst_rel_error']:.1e}**, {impulse['cases']}",
            "-",
        ),
    ]
    lines = ["| " + " | ".join(row) + " |" for row in rows]
    lines.insert(1, "|---|---|---|")
    return "\n".join(lines)


def _signed_percent(change: float | None, digits: int = 1) -> str:
    return "n/a" if change is None else f"{100.0 * change:+.{digits}f} %"


def _posture_section(results: dict[str, Any]) -> str:
    """Single-IK posture against the selected posture (core.method.posture) for the same grasps."""
    postures = results.get("posture_selection")
    if not postures:
        return ""
    rows = [
        "| grasp | postures feasible/tried | mean M_eff [kg] | M_eff at impact [kg] | "
        "peak force [N] | ΔM_eff at impact | Δ peak force | √ prediction |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for g in postures["grasps"]:
        rows.append(
            f"| {g['name']} | {g['postures_feasible']}/{g['postures_tried']} | "
            f"{number(g['mean_effective_mass_single_ik_kg'], 4)} → "
            f"{number(g['mean_effective_mass_selected_kg'], 4)} | "
            f"{number(g['effective_mass_at_impact_single_ik_kg'], 4)} → "
            f"{number(g['effective_mass_at_impact_selected_kg'], 4)} | "
            f"{number(g['peak_force_single_ik_n'], 2)} → "
            f"{number(g['peak_force_selected_n'], 2)} | "
            f"{_signed_percent(g['effective_mass_at_impact_change'])} | "
            f"{_signed_percent(g['peak_force_change'])} | "
            f"{_signed_percent(g['predicted_peak_force_change_sqrt'])} |"
        )
    table = "\n".join(rows)
    return f"""
## Posture selection: single IK against the selected posture

Book, same grasps, same object path and pillar as above; the single-IK rows are the book's
runs above, the selected posture is core.method.posture's with {postures["restarts"]} IK restarts
(the lowest mean tip effective mass among the feasible start postures found, each followed
along the path). The controller tracks the selected posture's joint trajectory from its own
start configuration. "√ prediction" is the change of the peak force a spring sensor predicts
from the change of the effective mass at impact, √(M_sel / M_single) − 1.

{table}
"""


def _waypoint_section(results: dict[str, Any]) -> str:
    """The book along the timed waypoint path, and its change from the straight path."""
    waypoints = results.get("book_waypoints")
    if waypoints is None:
        return ""
    rows = [
        "| grasp | M_eff at impact | √M_eff | approach speed | peak force "
        "| peak force / approach speed |",
        "|---|---|---|---|---|---|",
    ]
    for change in waypoints["change_from_straight_path"]:
        rows.append(
            f"| {change['name']} | {_signed(change['effective_mass_at_impact_change'])} "
            f"| {_signed(change['sqrt_effective_mass_change'])} "
            f"| {_signed(change['approach_speed_change'])} "
            f"| {_signed(change['peak_force_change'])} "
            f"| {_signed(change['peak_force_per_speed_change'])} |"
        )
    order = "holds" if waypoints["ordering_holds"] else "does not hold"
    return f"""## Book along a timed waypoint path

{waypoints["description"]}

{_grasp_table(waypoints, [])}

Peak force worst/best {number(waypoints["peak_force_ratio_worst_to_best"], 4)} for effective
masses at impact worst/best {number(waypoints["effective_mass_ratio_worst_to_best"], 4)};
the order by effective mass at impact {order} for the peak force (safest first by peak force:
{", ".join(waypoints["order_by_peak_force"])}).

Change from the straight path, same grasp, impact planned at the same time:

{chr(10).join(rows)}

"""


def _armature_section(results: dict[str, Any]) -> str:
    """Free impacts with rotor inertia: the impulse against both predictions."""
    geared = results.get("impulse_check_armature")
    if not geared or not geared["valid_cases"]:
        return ""
    return f"""## Free impacts with rotor inertia (armature)

{geared["robot"]}, armature {geared["armature_kgm2"]} kg m^2 per joint in MuJoCo
(`dof_armature`) and in the core: over {geared["valid_cases"]} free impacts at random
configurations and directions, the measured impulse matches (1 + e)·M_eff·v with the effective
mass *with* armature to {geared["worst_rel_error"]:.1e} (worst relative error), and exceeds the
prediction from the links-only effective mass by at least
{100 * geared["links_only_min_rel_error"]:.1f} % (median
{100 * geared["links_only_median_rel_error"]:.1f} %). The peak contact force follows the same
effective mass (MuJoCo's soft contact scales with it): peak force / (M_eff·v) varies by a factor
{geared["peak_force_per_mass_spread"]:.3f} over the impacts with armature, by
{geared["links_only_peak_force_per_mass_spread"]:.3f} with the links-only mass.

"""


def _signed(value: float) -> str:
    return f"{100.0 * value:+.2f} %"


def _elbow_markdown(result: dict[str, Any] | None) -> str:
    """The results.md bullet of the elbow impact ("" when it was not run)."""
    if not result:
        return ""
    return (
        f"- Elbow impact: a free impact at the whole-arm site {result['site']} (link "
        f"{result['link']}), grasp {result['grasp']}, t = {result['time_s']:g} s, "
        f"{result['speed_m_s']:.2f} m/s along the site's own direction of motion: impulse vs "
        f"(1 + e)·M_eff·v with the whole-arm M_eff {result['effective_mass_kg']:.3f} kg off by "
        f"{result['rel_error']:.1e} (MuJoCo's own: {result['engine_effective_mass_kg']:.3f} kg); "
        f"with the tip's {result['tip_effective_mass_kg']:.3f} kg in its place, by "
        f"{result['rel_error_with_tip_mass']:.2f}.\n"
    )


def _simulated_section(results: dict[str, Any]) -> str:
    """results.md's "What is simulated": the models, the sensor, the controller, the check."""
    setup = results["setup"]
    pillar, impulse = setup["pillar"], results["impulse_check"]
    sensor, contact, gains = pillar["sensor"], pillar["contact"], pillar["controller"]
    control = (
        "updated at every physics step"
        if gains["period_s"] is None
        else f"updated every {1e3 * gains['period_s']:g} ms (zero-order hold)"
    )
    samples = ", ".join(f"{t:g}" for t in setup["impulse_sample_times_s"])
    return f"""## What is simulated

- **Robot**: the Baxter URDF of example-robot-data loaded by MuJoCo with its meshes stripped;
  every joint except `right_s0..right_w2` fixed at 0 (as the core locks them); no joint
  damping, friction or armature. MuJoCo's joint-space inertia equals `pinocchio.crba` of the
  core's model (with the object merged) to ~1e-15 (`test/test_validation.py`).
- **Object**: a body fixed to `right_gripper` at the grasp with the exact mass, centre of mass
  and inertia tensor the core uses; its shapes do not collide.
- **Contact**: a sphere of radius {pillar["tip_sphere_radius_m"]:g} m centred on the tip frame
  is the only colliding robot geometry (the paper's impacts are end-effector on sensor). The
  sensor face is perpendicular to the tip's direction of motion u at
  t = {pillar["planned_impact_time_s"]:g} s and placed where the sphere reaches it on the
  reference. As the sphere is centred on the tip, the normal velocity of the contact point is
  the tip's velocity along u: the contact sees the effective mass the core computes. Friction
  {contact["friction"]:g}, elliptic cone, solref ({contact["timeconst_s"]:g} s,
  {contact["dampratio"]:g}), solimp {contact["impedance"]:g}.
- **Force sensor**: a {sensor["plate_mass_kg"]:g} kg plate on a spring of
  {sensor["stiffness_n_m"]:.3g} N/m and a damper of {sensor["damping_n_s_m"]:g} N s/m along its
  normal, i.e. a load cell on a rigid pillar; the force is the spring + damper force. A
  physical stiffness matters: MuJoCo's contact forces alone scale with the contact's effective
  mass by construction (ablation "rigid plate"), while a sensor of stiffness k gives the
  textbook peak F ≈ v·sqrt(k·M_eff).
- **Controller**: joint-space computed torque with MuJoCo's M(q) and bias forces of robot +
  object (inertia and gravity compensation), K_p = {gains["kp_per_s2"]:g} 1/s²,
  K_d = {gains["kd_per_s"]:g} 1/s, {control}, torques clipped to the URDF effort limits,
  tracking the core's IK joint trajectory (cubic spline through its
  {setup["tip_or_object_trajectory"]["dt_s"]:g} s samples). The reference goes on past the
  sensor, so the arm keeps pushing after the impact, as in the paper. Simulated from
  {pillar["simulated_from_s"]:g} s to {pillar["simulated_to_s"]:g} s with a
  {pillar["timestep_s"]:g} s step, {pillar["impact_timestep_s"]:g} s around the impact.
- **Peak impact force**: the largest sensor force within {1e3 * pillar["peak_window_s"]:g} ms
  of first contact. **Impulse**: the contact normal impulse from first contact until the
  sensor force first returns to zero.
- **Impulse check**: for each grasp at t = {samples} s of its trajectory, the arm is put at the
  core's q with the tip moving at {impulse["speed_m_s"]:g} m/s along u (minimum-norm joint
  velocities); gravity, actuators and damping off; a frictionless rigid wall perpendicular to
  u touches the tip sphere; step {impulse["timestep_s"]:g} s, contact solref
  {impulse["contact_solref"]}. The impulse is the integral of the contact force; e is measured
  from the tip's velocity along u when the contact ends.
"""


def results_markdown(results: dict[str, Any]) -> str:
    """The markdown report of a validation run."""
    setup = results["setup"]
    tensor, book, impulse = results["tensor_object"], results["book"], results["impulse_check"]
    tensor_peaks = [g["peak_force_n"] for g in tensor["grasps"]]
    kind = "quick (reduced)" if setup["quick"] else "full"
    figures = "\n\n".join(f"![{name}]({name})" for name in results.get("figures", []))
    versions = ", ".join(f"{k} {v}" for k, v in setup["versions"].items())
    return f"""# Validation of the effective mass with MuJoCo (issue #4)

The {kind} run, made by

```
{results["command"]}
```

in {results["timing_s"]["total"]:.0f} s ({versions}). Everything below is generated from
`results.json` in this folder.

## Headline figures

{_headline_table(results)}

- Tensor object: peak forces {min(tensor_peaks):.2f} to {max(tensor_peaks):.2f} N (worst/best
  {number(tensor["peak_force_ratio_worst_to_best"], 4)}) for effective masses at impact with
  worst/best {number(tensor["effective_mass_ratio_worst_to_best"], 4)}; Spearman of the
  effective mass with the contact impulse {number(tensor["spearman_meff_vs_impulse"])}.
- Book: effective mass at impact worst/best
  {number(book["effective_mass_ratio_worst_to_best"], 4)}; safest first by peak force:
  {", ".join(book["order_by_peak_force"])}.
- Impulse check: transmitted impulse vs (1 + e)·M_eff·v with the core's M_eff, restitution
  e measured {impulse["restitution_min"]:.3f} to {impulse["restitution_max"]:.3f}; MuJoCo's own
  1/(uᵀ J M⁻¹ Jᵀ u) differs from the core's by at most
  {impulse["engine_vs_core_effective_mass_max_rel_diff"]:.1e} (relative).
{_elbow_markdown(results.get("elbow_impact"))}
## Reading the results

{reading_markdown(results)}

## Tensor object

{tensor["description"]}

{_grasp_table(tensor, [("x_ring_distance_m", "a [m]", 3), ("y_ring_distance_m", "b [m]", 3)])}

## Book

{book["description"]}

{_grasp_table(book, [])}
{_posture_section(results)}
{_waypoint_section(results)}{_armature_section(results)}## Ablations

Each ablation changes one setting and is simulated from
{setup["variants_simulated_from_to_s"][0]:g} s to {setup["variants_simulated_from_to_s"][1]:g} s,
starting on the reference; compare it with "main from 1.3 s".

{_variant_table(results)}

{_simulated_section(results)}
## Figures

{figures}
"""
