"""Free impacts with rotor inertia (armature) in MuJoCo: the impulse follows the effective mass
with armature, and the links-only prediction is visibly wrong.

The bundled Panda with the FR3 armature of data/armature_published.yaml (``dof_armature`` of
the MuJoCo scene set from the same values, validation.scene.base_spec), a box in the hand, at
configurations drawn within the joint limits and random directions: each free impact
(simulation.ImpulseChecker) measures the normal impulse P and the restitution e, and compares
P with (1 + e)·M_eff·v for M_eff with armature and for the links only. MuJoCo's soft contact
is mass-normalised (its stiffness and damping scale with the contact's effective mass, which
includes ``dof_armature``), so the peak force per M_eff·v is one constant across impacts for the
M_eff that acts: its spread (max / min over the impacts) is reported for both masses.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from ..core.method.effective_mass import effective_masses_along, translational_mobilities_in_base
from ..core.model.armature import published_armatures, published_values
from ..core.model.inertia import solid_box
from ..core.model.robot import RobotModel
from .simulation import ImpulseChecker, ImpulseSetup

ROBOT = ("example-robot-data:panda", "panda_link0", "panda_hand")
ENTRY = "franka_fr3"
LIMIT_MARGIN = 0.15
"""Fraction of each joint range left out at both ends (no joint limit during an impact)."""


def armature_impulse_check(
    cases: int, setup: ImpulseSetup, seed: int = 0, log: Callable[[str], None] | None = None
) -> dict[str, Any]:
    """``cases`` free impacts on the geared Panda; the impulse_check_armature results."""
    links = RobotModel.from_urdf(*ROBOT)
    geared = links.with_armature(published_values(published_armatures()[ENTRY], links.joint_names))
    box = solid_box(0.5, [0.06, 0.06, 0.1])
    grasp = pin.SE3.Identity()
    checker = ImpulseChecker(geared, ROBOT[0], box, grasp, setup)
    rng = np.random.default_rng(seed)
    span = links.upper_limits - links.lower_limits
    per_case = []
    for _ in range(cases):
        positions = rng.uniform(
            links.lower_limits + LIMIT_MARGIN * span, links.upper_limits - LIMIT_MARGIN * span
        )
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        q = links.q_from_positions(positions)[None]
        masses = [
            float(
                effective_masses_along(
                    translational_mobilities_in_base(robot, box, grasp, q), direction[None]
                )[0]
            )
            for robot in (geared, links)
        ]
        case = checker.run(positions, direction, masses[0])
        scale = (1.0 + case.restitution) * case.speed_before_m_s
        links_prediction = scale * masses[1]
        per_case.append(
            {
                "effective_mass_kg": masses[0],
                "links_only_effective_mass_kg": masses[1],
                "engine_effective_mass_kg": case.engine_effective_mass_kg,
                "impulse_n_s": case.impulse_n_s,
                "predicted_impulse_n_s": case.predicted_impulse_n_s,
                "links_only_predicted_impulse_n_s": links_prediction,
                "rel_error": case.rel_error,
                "links_only_rel_error": abs(case.impulse_n_s - links_prediction)
                / links_prediction,
                "restitution": case.restitution,
                "joint_limit_active": case.limit_active,
                "peak_force_n": case.peak_force_n,
            }
        )
        if log is not None:
            log(
                f"  armature impact: M_eff {masses[0]:.3f} kg (links only {masses[1]:.3f} kg), "
                f"impulse error {case.rel_error:.1e} (links only "
                f"{per_case[-1]['links_only_rel_error']:.1%})"
            )
    valid = [c for c in per_case if not c["joint_limit_active"] and np.isfinite(c["rel_error"])]
    with_errors = [c["rel_error"] for c in valid]
    links_errors = [c["links_only_rel_error"] for c in valid]
    speed = setup.speed_m_s
    per_mass = {  # peak force per (M_eff v): one constant when M_eff is the one that acts
        key: [c["peak_force_n"] / (c[key] * speed) for c in valid]
        for key in ("effective_mass_kg", "links_only_effective_mass_kg")
    }
    return {
        "robot": f"{ROBOT[0]} ({ROBOT[1]} -> {ROBOT[2]}), armature '{ENTRY}'",
        "armature_kgm2": geared.armature_kgm2.tolist(),
        "cases": len(per_case),
        "valid_cases": len(valid),
        "worst_rel_error": float(max(with_errors)) if valid else None,
        "links_only_min_rel_error": float(min(links_errors)) if valid else None,
        "links_only_median_rel_error": float(np.median(links_errors)) if valid else None,
        "peak_force_per_mass_spread": _spread(per_mass["effective_mass_kg"]),
        "links_only_peak_force_per_mass_spread": _spread(per_mass["links_only_effective_mass_kg"]),
        "per_case": per_case,
    }


def _spread(values: list[float]) -> float | None:
    """max / min of positive values (1: all equal); None when there are none."""
    return float(max(values) / min(values)) if values else None
