"""The generated blocks of the docs: Markdown rendered from the code (the node's parameters,
the command line's input bounds) or from committed measurements (``bench/results*.json``, the
MuJoCo validation run ``docs/validation/results.json``; the benchmark tables are
``scripts/bench_tables.py``'s), one renderer per block name (GENERATORS;
``scripts/render_docs.py`` finds the blocks and calls them)."""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from bench_tables import (
    render_bench_arms,
    render_bench_batch,
    render_bench_monitor,
    render_bench_postures,
    render_bench_service,
    render_bench_start_up,
    render_bench_targets,
    render_bench_whole_arm,
)

ROOT = Path(__file__).resolve().parents[1]
VALIDATION = ROOT / "docs" / "validation" / "results.json"
"""The committed full run of ``grasp-safety reproduce --out docs/validation``."""


# --- the parameter reference ------------------------------------------------------------------

_UNIT_SUFFIXES = {"_kgm2": "kg m²", "_kg": "kg", "_m": "m", "_s": "s"}
_TYPE_NAMES = {bool: "bool", int: "integer", float: "double", str: "string"}


def parameter_type(spec: Any) -> str:
    """The declared ROS type of a ParameterSpec in words (as ``ros2 param describe`` says)."""
    if isinstance(spec.default, (list, tuple)):
        item = spec.item_type or type(spec.default[0])
        return f"{_TYPE_NAMES[item]} array"
    return _TYPE_NAMES[type(spec.default)]


def parameter_unit(name: str, description: str) -> str:
    """The unit: from the name's suffix (``_s``, ``_m``, ``_kg``, ``_kgm2``), else the first
    bracketed unit of the description (``[rad or m]``); empty for plain numbers."""
    for suffix, unit in _UNIT_SUFFIXES.items():
        if name.endswith(suffix):
            return unit
    match = re.search(r"\[([a-zA-Z][^\]]*)\]", description)
    return match.group(1).replace("^2", "²") if match else ""


def _default(value: Any) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_default(item) for item in value) + "]"
    return repr(value)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("<", "&lt;")


def _number(value: float) -> str:
    return f"{int(value):,}" if float(value).is_integer() else f"{value:g}"


def render_parameters() -> str:
    """The node's parameters as a Markdown table: type, default, constraints, unit, meaning."""
    sys.path.insert(0, str(ROOT))
    from grasp_safety_ros.ros.parameters import PARAMETERS, parameter_constraints

    rows = [
        "| Parameter | Type | Default | Constraints | Unit | Description |",
        "|---|---|---|---|---|---|",
    ]
    for name, spec in PARAMETERS.items():
        constraints = parameter_constraints(name)
        limits = [constraints.text] if constraints.text else []
        if constraints.value_range is not None:
            low, high = constraints.value_range
            limits.insert(0, f"in [{_number(low)}, {_number(high)}]")
        if spec.read_only:
            limits.append("read-only (start-up only)")
        cells = [
            f"`{name}`",
            parameter_type(spec),
            f"`{_default(spec.default)}`",
            _cell("; ".join(limits)),
            parameter_unit(name, spec.description),
            _cell(spec.description),
        ]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def render_options() -> str:
    """The one table of options (core.options) as Markdown: the scenario key, the node
    parameter, type, default (every interface's), bounds, unit, meaning; then the limits."""
    sys.path.insert(0, str(ROOT))
    from grasp_safety_ros.core.options import LIMITS, OPTIONS

    rows = [
        "| Scenario key | Node parameter | Type | Default | Bounds | Unit | Meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for key, option in OPTIONS.items():
        bounds = option.bounds
        cells = [
            f"`{option.scenario_key}`",
            f"`{key}`",
            option.type.__name__,
            f"`{_default(option.default)}`",
            "" if bounds is None else f"[{_number(bounds[0])}, {_number(bounds[1])}]",
            option.unit,
            _cell(option.help),
        ]
        rows.append("| " + " | ".join(cells) + " |")
    rows += ["", "| Limit | Scenario (and top of the node parameter) | Node parameter: default |"]
    rows.append("|---|---|---|")
    for limit in LIMITS.values():
        node = f"`{limit.node}`: {_number(limit.budget)}" if limit.node else ""
        unit = f" {limit.unit}" if limit.unit else ""
        rows.append(f"| {limit.name} | {_number(limit.value)}{unit} | {node} |")
    return "\n".join(rows) + "\n"


# --- limits of the command line's input -------------------------------------------------------


def _count(value: float) -> str:
    return f"{int(value):,}".replace(",", " ")


def render_cli_limits() -> str:
    """The bounds on a scenario file and its robot description, from the constants the code
    checks them with."""
    sys.path.insert(0, str(ROOT))
    from grasp_safety_ros.core.model.description import MAX_URDF_BYTES
    from grasp_safety_ros.scenario import fields, schema

    limits = SimpleNamespace(
        **vars(fields), **{k: v for k, v in vars(schema).items() if k.startswith("MAX_")}
    )

    return (
        f"A scenario file is at most {limits.MAX_SCENARIO_BYTES / 1e6:g} MB of UTF-8 text, "
        f"nested at most {limits.MAX_NESTING_DEPTH} levels, and may expand to at most "
        f"{_count(limits.MAX_EXPANDED_NODES)} YAML nodes with aliases counted at full size (so "
        'a "billion laughs" file is refused at once); at most '
        f"{_count(limits.MAX_GRASPS)} grasps, {_count(limits.MAX_GRASP_SAMPLES)} grasps × "
        f"trajectory samples, {_count(limits.MAX_POINTS)} `object.points_m` and "
        f"{_count(limits.MAX_UNCERTAINTY_SAMPLES)} `uncertainty.samples`; an object of at most "
        f"{_count(limits.MAX_OBJECT_MASS_KG)} kg and {limits.MAX_OBJECT_SIZE_M:g} m (edges, "
        "radii, CoM offset, radius of gyration); a URDF or MJCF description is at most "
        f"{MAX_URDF_BYTES / 1e6:g} MB.\n"
    )


# --- the committed MuJoCo validation run (docs/validation/results.json) -------------------------


def _validation() -> dict[str, Any]:
    return json.loads(VALIDATION.read_text())


def _force_span(grasps: list[dict[str, Any]]) -> str:
    forces = sorted(grasp["peak_force_n"] for grasp in grasps)
    return f"{forces[0]:.1f} N to {forces[-1]:.1f} N"


def render_validation_results() -> str:
    """The validation's headline figures against the paper's, from the committed full run."""
    run = _validation()
    tensor, book, path = run["tensor_object"], run["book"], run["book_waypoints"]
    impulse = run["impulse_check"]
    lines = [
        "| | this simulation (MuJoCo) | paper (Gazebo) |",
        "|---|---|---|",
        f"| tensor object: Spearman(M_eff at impact, peak force), {len(tensor['grasps'])} "
        f'configurations | **{tensor["spearman_meff_vs_peak_force"]:.3f}** | "in accordance" |',
        f"| book: peak force, safest to least safe grasp | {_force_span(book['grasps'])} | "
        "100 N to 130 N |",
        f"| book: peak force ratio worst/best | **{book['peak_force_ratio_worst_to_best']:.3f}** "
        "| 1.30 |",
        f"| impulse check: worst relative error over {impulse['cases']} cases | "
        f"**{impulse['worst_rel_error']:.1e}** | — |",
        f"| book on a 3-waypoint path: peak force, safest to least safe grasp | "
        f"{_force_span(path['grasps'])} | — |",
        "| book on a 3-waypoint path: peak force / M_eff at impact, ratio worst/best | "
        f"**{path['peak_force_ratio_worst_to_best']:.3f}** / "
        f"{path['effective_mass_ratio_worst_to_best']:.3f} | — |",
        "",
        f"Engine against core: MuJoCo's own 1/(uᵀJM⁻¹Jᵀu) equals the core's effective mass to "
        f"{impulse['engine_vs_core_effective_mass_max_rel_diff']:.0e} (relative). The committed "
        f"run took {run['timing_s']['total']:.0f} s (`timing_s` in `results.json`).",
    ]
    return "\n".join(lines) + "\n"


def render_validation_armature() -> str:
    """The free impacts of the Panda with the FR3 armature, from the committed full run."""
    check = _validation()["impulse_check_armature"]
    return (
        f"With the full run's {check['valid_cases']} impacts: the measured impulse matches "
        f"(1 + e)·M_eff·v with the effective mass *with* armature to "
        f"{check['worst_rel_error']:.1e} (worst relative error); it exceeds the links-only "
        f"prediction by {100 * check['links_only_min_rel_error']:.1f} % or more (median "
        f"{100 * check['links_only_median_rel_error']:.1f} %). The peak contact force follows "
        f"the same mass: peak / (M_eff·v) varies by ×{check['peak_force_per_mass_spread']:.3f} "
        f"over the impacts with the armature's M_eff and by "
        f"×{check['links_only_peak_force_per_mass_spread']:.3f} with the links-only one.\n"
    )


def render_validation_elbow() -> str:
    """The free impact at an elbow site, from the committed full run."""
    elbow = _validation()["elbow_impact"]
    relative = abs(elbow["engine_effective_mass_kg"] / elbow["effective_mass_kg"] - 1.0)
    return (
        f'Site `{elbow["site"]}` (link `{elbow["link"]}`), grasp "{elbow["grasp"]}", '
        f"t = {elbow['time_s']:g} s, {elbow['speed_m_s']:.2f} m/s: whole-arm M_eff "
        f"{elbow['effective_mass_kg']:.3f} kg, MuJoCo's own 1/(uᵀJM⁻¹Jᵀu) equal to "
        f"{relative:.0e} (relative); impulse error {elbow['rel_error']:.1e}; with the tip's "
        f"effective mass ({elbow['tip_effective_mass_kg']:.3f} kg) in its place the error is "
        f"{elbow['rel_error_with_tip_mass']:.2f}.\n"
    )


GENERATORS: dict[str, Callable[[], str]] = {
    "cli-limits": render_cli_limits,
    "parameters": render_parameters,
    "options": render_options,
    "bench-arms": render_bench_arms,
    "bench-postures": render_bench_postures,
    "bench-service": render_bench_service,
    "bench-batch": render_bench_batch,
    "bench-whole-arm": render_bench_whole_arm,
    "bench-targets": render_bench_targets,
    "bench-start-up": render_bench_start_up,
    "bench-monitor": render_bench_monitor,
    "validation-results": render_validation_results,
    "validation-armature": render_validation_armature,
    "validation-elbow": render_validation_elbow,
}
"""Every generated block's renderer, by the name its marker gives."""
