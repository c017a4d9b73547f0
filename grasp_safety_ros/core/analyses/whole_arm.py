"""Whole-arm exposure: effective mass and speed at points on the robot's links, per sample.

A *site* is a point fixed on one link: a chain joint id j (the body it rides on) and the point
in joint j's frame. Sites are resolved once per robot (``resolve_arm_sites``): by default the
origin of every chain joint frame from the third joint on (elbow, wrist) and the tip; the user
adds points per link (``robot.exposed_points_m: {link: [[x, y, z], ...]}``, link frame [m]).
Sites on links welded to the base never move and are dropped.

Per sample, with the world-frame joint Jacobian columns (v_O, ω)_i of the augmented model (the
object merged into the tip body, the armature in M), a site at world position p on body j has
the translational Jacobian J_p[:, i] = v_O,i + ω_i × p for the joints i that move body j (0 for
the others), velocity v = J_p q̇, mobility A = J_p M⁻¹ J_pᵀ [1/kg] and, along its own unit
velocity u = v/|v|, the effective mass M_eff = 1 / (uᵀ A u) [kg] (mink's collision-avoidance
pattern: fixed rows per site, each row's Jacobian at its point on its own body). Where a site
does not move (|v| < STATIONARY_SPEED_M_S) it has no direction: it is flagged ``stationary``,
its speed is 0 and its effective mass is the largest over the directions it can move in (the
smallest non-zero eigenvalue of A; inf where A = 0).

Joint velocities q̇ follow the tip's twist ξ exactly, q̇ = J⁺ξ + (I − J⁺J) q̇_s, with q̇_s the
derivative of the clamped cubic spline through the samples (core.method.executable) for the
self-motion of a redundant arm; at the trajectory's rest ends every site is stationary.

ISO/TS 15066 (core.analyses.iso15066, Annex A): for each body region, the force ratio
F/F_tr = v·sqrt(μ k)/F_tr at every (sample, site); the worst over both, the worst site and
its link, admissibility over the whole arm, and T_min = T · max ratio over the permitted
regions (a uniform re-timing scales every site speed alike). Energy: ½ M_eff v² [J].
The sites themselves are resolved in ``arm_sites``, the regions assessed in ``arm_regions``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import read_only
from ..method.effective_mass import augmented_model
from ..method.executable import joint_path_velocities
from ..method.points import (
    PSEUDO_INVERSE_RCOND,
    arm_site_exposure,
    site_mobilities,
    tip_following_rates,
    tip_twists_into,
)
from ..method.ranking import Grasp, GraspEvaluation
from ..method.terms import SampleTerms
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import ObjectPath, Trajectory
from .arm_regions import WholeArmRegion as WholeArmRegion
from .arm_regions import assess_sites as assess_sites
from .arm_regions import assess_sites_batch
from .arm_sites import MAX_SITES as MAX_SITES
from .arm_sites import ArmSites as ArmSites
from .arm_sites import check_exposed_points_m as check_exposed_points_m
from .arm_sites import resolve_arm_sites as resolve_arm_sites
from .body_regions import BodyRegion, select_regions

STATIONARY_SPEED_M_S = 1e-9
"""Below this speed [m/s] a site does not move: flagged, no direction of its own."""

WHOLE_ARM_TERMS = ("mass_matrix_inverses",)
"""The optional fields of the shared terms (``method.terms.OPTIONAL_TERMS``) the whole arm
reads: M⁻¹, for its sites' mobilities J M⁻¹ Jᵀ."""

EIGENVALUE_RELATIVE_TOLERANCE = 1e-12
"""A mobility eigenvalue below this times the largest counts as zero (a direction the site
cannot move in)."""

DEFAULT_RANK_REGION = "chest"
"""Body region whose worst predicted force ``rank_by: whole_arm`` uses unless told."""


class ArmTerms(NamedTuple):
    """Per-sample terms of a chain (N samples, n = nv joints, world frame of the model).

    The shared per-(grasp, sample) computation can fill these directly.
    """

    rotations_joint_to_world: np.ndarray  # (N, n, 3, 3) joint frames in the world frame
    translations_joint_in_world: np.ndarray  # (N, n, 3) [m] joint origins in the world frame
    jacobians_in_world: np.ndarray  # (N, 6, n) columns (v_O [m/s], ω [rad/s]) per unit rate
    minv: np.ndarray  # (N, n, n) M⁻¹ of the augmented model, armature included [1/(kg m²)]
    joint_velocities: np.ndarray  # (N, n) q̇ [rad/s or m/s]


def pinocchio_kinematic_terms(
    model: pin.Model, q_all: np.ndarray, data: pin.Data | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Joint placements, world Jacobian columns and M⁻¹ (ArmTerms' first four fields) per
    configuration of ``q_all`` (N, nq), with Pinocchio on ``model`` (the augmented model);
    ``data``: its Pinocchio data to reuse (None: a new one)."""
    data = model.createData() if data is None else data
    count, n = len(q_all), model.nv
    rotations = np.empty((count, n, 3, 3))
    translations = np.empty((count, n, 3))
    jacobians = np.empty((count, 6, n))
    minv = np.empty((count, n, n))
    upper = np.triu(np.ones((n, n), dtype=bool))
    for i, q in enumerate(q_all):
        pin.computeJointJacobians(model, data, q)
        jacobians[i] = data.J.reshape(6, n)  # a 1-DOF chain: eigenpy gives (6,)
        for j in range(1, model.njoints):
            rotations[i, j - 1] = data.oMi[j].rotation
            translations[i, j - 1] = data.oMi[j].translation
        pin.computeMinverse(model, data, q)
        minv[i] = np.where(upper, data.Minv, data.Minv.T).reshape(n, n)
    return rotations, translations, jacobians, minv


def site_jacobians(sites: ArmSites, terms: ArmTerms) -> tuple[np.ndarray, np.ndarray]:
    """World positions (N, K, 3) [m] and translational Jacobians (N, K, 3, n) of the sites."""
    index = sites.joint_ids - 1
    positions = (
        np.einsum(
            "nkab,kb->nka", terms.rotations_joint_to_world[:, index], sites.points_in_joint_m
        )
        + terms.translations_joint_in_world[:, index]
    )
    linear, angular = terms.jacobians_in_world[:, :3], terms.jacobians_in_world[:, 3:]
    # ω_i × p for every column i: (N, 1, n, 3) x (N, K, 1, 3)
    cross = np.cross(np.swapaxes(angular, 1, 2)[:, None], positions[:, :, None])
    jacobians = (linear[:, None] + np.swapaxes(cross, 2, 3)) * sites.support[None, :, None, :]
    return positions, jacobians


class SiteExposure(NamedTuple):
    """Per (sample, site) results; arrays (N, K), directions and positions (N, K, 3)."""

    positions_in_base_m: np.ndarray
    directions_in_base: np.ndarray
    stationary: np.ndarray
    speed_m_s: np.ndarray
    effective_mass_kg: np.ndarray


def _largest_mass_directions(mobilities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per mobility (S, 3, 3) [1/kg] of a site at rest: the unit direction (S, 3) of largest
    effective mass it can move in and that mass (S,) [kg] (the smallest eigenvalue above
    EIGENVALUE_RELATIVE_TOLERANCE times the largest; inf where A = 0)."""
    eigenvalues, eigenvectors = np.linalg.eigh(mobilities)
    threshold = EIGENVALUE_RELATIVE_TOLERANCE * eigenvalues[:, -1:]
    movable = eigenvalues > np.maximum(threshold, 0.0)
    first = np.where(movable.any(axis=1), np.argmax(movable, axis=1), 0)
    rows = np.arange(len(first))
    smallest = eigenvalues[rows, first]
    can_move = movable.any(axis=1)
    masses = np.where(can_move, 1.0 / np.where(can_move, smallest, 1.0), np.inf)
    return eigenvectors[rows, :, first], masses


def site_exposure(
    sites: ArmSites, terms: ArmTerms, transform_base_to_world: pin.SE3
) -> SiteExposure:
    """Effective mass along each site's own velocity, and its speed, for every sample."""
    positions, jacobians = site_jacobians(sites, terms)
    velocities = (jacobians @ terms.joint_velocities[:, None, :, None])[..., 0]
    mobilities = jacobians @ terms.minv[:, None] @ np.swapaxes(jacobians, 2, 3)
    speeds = np.sqrt(np.einsum("nka,nka->nk", velocities, velocities))
    stationary = speeds < STATIONARY_SPEED_M_S
    directions = velocities / np.where(stationary, 1.0, speeds)[..., None]
    with np.errstate(divide="ignore"):  # stationary rows (0 direction) are replaced below
        masses = 1.0 / np.einsum("nka,nkab,nkb->nk", directions, mobilities, directions)
    if stationary.any():
        directions[stationary], masses[stationary] = _largest_mass_directions(
            mobilities[stationary]
        )
    speeds = np.where(stationary, 0.0, speeds)
    rotation = transform_base_to_world.rotation
    return SiteExposure(
        positions_in_base_m=(positions - transform_base_to_world.translation) @ rotation,
        directions_in_base=directions @ rotation,
        stationary=stationary,
        speed_m_s=speeds,
        effective_mass_kg=masses,
    )


def tip_twists_in_base(
    trajectory: Trajectory,
    transform_tip_to_object: pin.SE3,
    times_s: np.ndarray,
) -> np.ndarray:
    """Tip twists (N, 6) (linear [m/s], angular [rad/s]), base axes: from the object motion
    sampled once (ObjectMotion: tangent times speed per tangent) for an object path, else the
    trajectory's ``tip_twists``."""
    if not isinstance(trajectory, ObjectPath):
        return trajectory.tip_twists(transform_tip_to_object, times_s)[0]
    motion = trajectory.object_motion(times_s)
    rate = motion.speed_per_tangent[:, None]
    tangents = motion.tip_tangents(transform_tip_to_object)
    return np.concatenate([tangents * rate, motion.angular_tangents * rate], axis=1)


def jacobians_tip_in_world(
    robot: RobotModel, terms_kinematics: tuple[np.ndarray, ...]
) -> np.ndarray:
    """(N, 6, n) Jacobians of the tip frame, world axes at the tip origin (LOCAL_WORLD_ALIGNED),
    from ``pinocchio_kinematic_terms``' placements and world columns."""
    rotations, translations, jacobians = terms_kinematics[:3]
    tip = robot.model.frames[robot.tip_frame_id]
    support = np.zeros(robot.model.nv, dtype=bool)
    for i in robot.model.supports[tip.parentJoint][1:]:
        support[robot.model.joints[i].idx_v] = True
    origin = (
        rotations[:, tip.parentJoint - 1] @ tip.placement.translation
        + translations[:, tip.parentJoint - 1]
    )
    linear, angular = jacobians[:, :3], jacobians[:, 3:]
    cross = np.cross(np.swapaxes(angular, 1, 2), origin[:, None])  # (N, n, 3): ω_i × p
    return np.concatenate([linear + np.swapaxes(cross, 1, 2), angular], axis=1) * support


def tip_following_joint_velocities(
    robot: RobotModel,
    tip_jacobians: np.ndarray,
    tip_twists_in_world: np.ndarray,
    times_s: np.ndarray,
    joint_positions: np.ndarray,
) -> np.ndarray:
    """q̇ (N, n) = J⁺ξ + (I − J⁺J) q̇_s (module docstring) [rad/s or m/s].

    Args:
        tip_jacobians: (N, 6, n) from ``jacobians_tip_in_world``.
        tip_twists_in_world: (N, 6) tip twists (linear [m/s], angular [rad/s]), world axes.
        times_s, joint_positions: The samples (N,), (N, n); continuous joints are unwrapped.
    """
    continuous = ~np.isfinite(robot.lower_limits)
    spline_rates = joint_path_velocities(times_s, [joint_positions], continuous)[0]
    pseudo_inverse = np.linalg.pinv(tip_jacobians, rcond=PSEUDO_INVERSE_RCOND)  # (N, n, 6)
    residual = tip_twists_in_world - (tip_jacobians @ spline_rates[..., None])[..., 0]
    return np.asarray(spline_rates + (pseudo_inverse @ residual[..., None])[..., 0])


@dataclass(frozen=True)
class WholeArmEvaluation:
    """Exposure of every site of the arm along one grasp's trajectory (N samples, K sites).

    Attributes:
        index, name, feasible: As in the grasp's GraspEvaluation (infeasible: empty arrays).
        site_names, site_links: The sites (ArmSites.names, .links), the column order.
        times_s: (N,) sample times [s].
        positions_in_base_m: (N, K, 3) site positions [m], base frame.
        directions_in_base: (N, K, 3) unit directions of motion (or of largest effective mass
            where stationary), base axes.
        stationary: (N, K) True where the site does not move.
        speed_m_s: (N, K) site speeds [m/s] (0 where stationary).
        effective_mass_kg: (N, K) effective mass along the direction [kg].
        energy_j: (N, K) ½ M_eff v² [J].
        regions: One WholeArmRegion per assessed body region.
        admissible: Every assessed region admissible at every site.
        admissible_where_permitted: Every region that permits transient contact admissible.
        min_duration_s: T · the largest worst ratio over the permitted regions [s] (NaN if
            none is assessed or infeasible).
        limiting_region: The permitted region with the largest worst ratio ("" if none).
    """

    index: int
    name: str
    feasible: bool
    site_names: tuple[str, ...]
    site_links: tuple[str, ...]
    times_s: np.ndarray
    positions_in_base_m: np.ndarray
    directions_in_base: np.ndarray
    stationary: np.ndarray
    speed_m_s: np.ndarray
    effective_mass_kg: np.ndarray
    energy_j: np.ndarray
    regions: tuple[WholeArmRegion, ...]
    admissible: bool
    admissible_where_permitted: bool
    min_duration_s: float
    limiting_region: str

    def region(self, name: str) -> WholeArmRegion:
        """The assessment of the region called ``name``."""
        for assessed in self.regions:
            if assessed.region == name:
                return assessed
        raise InvalidInputError(
            "whole_arm.region",
            f"region {name!r} was not assessed; assessed: "
            f"{', '.join(a.region for a in self.regions)}",
        )

    @property
    def worst_energy(self) -> tuple[float, int, int]:
        """(largest ½ M_eff v² [J], its site, its sample); (0, 0, 0) when empty."""
        if not self.energy_j.size:
            return 0.0, 0, 0
        sample, site = np.unravel_index(int(np.argmax(self.energy_j)), self.energy_j.shape)
        return float(self.energy_j[sample, site]), int(site), int(sample)


def _whole_arm_result(
    evaluation: GraspEvaluation,
    sites: ArmSites,
    times: np.ndarray,
    exposure: SiteExposure,
    regions: tuple[BodyRegion, ...],
    duration_s: float,
    assessed: tuple[WholeArmRegion, ...] | None = None,
    energy_j: np.ndarray | None = None,
) -> WholeArmEvaluation:
    """The evaluation from a grasp's exposure; ``assessed``: its ``assess_sites`` and
    ``energy_j`` its ½ M_eff v² (0 where stationary) when already computed (with the grasp's
    fellows in a batch)."""
    speeds, masses = exposure.speed_m_s, exposure.effective_mass_kg
    if assessed is None:
        assessed = assess_sites(speeds, masses, duration_s, regions)
    permitted = [a for a in assessed if a.transient_contact_permitted]
    limiting = max(permitted, key=lambda a: a.worst_force_ratio) if permitted else None
    feasible = evaluation.feasible
    energy = energy_j
    if energy is None:
        energy = np.where(exposure.stationary, 0.0, 0.5 * masses * speeds**2)
    return WholeArmEvaluation(
        index=evaluation.index,
        name=evaluation.name,
        feasible=feasible,
        site_names=sites.names,
        site_links=sites.links,
        times_s=read_only(times, copy=True),
        positions_in_base_m=read_only(exposure.positions_in_base_m),
        directions_in_base=read_only(exposure.directions_in_base),
        stationary=read_only(exposure.stationary),
        speed_m_s=read_only(exposure.speed_m_s),
        effective_mass_kg=read_only(exposure.effective_mass_kg),
        energy_j=read_only(energy),
        regions=assessed if feasible else (),
        admissible=feasible and all(a.admissible for a in assessed),
        admissible_where_permitted=feasible and all(a.admissible for a in permitted),
        min_duration_s=limiting.min_duration_s if feasible and limiting else math.nan,
        limiting_region=limiting.region if feasible and limiting else "",
    )


def evaluate_whole_arm(
    robot: RobotModel,
    evaluation: GraspEvaluation,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    trajectory: Trajectory,
    sites: ArmSites,
    regions: Sequence[str | BodyRegion] | None = None,
    model: pin.Model | None = None,
    joint_positions: np.ndarray | None = None,
) -> WholeArmEvaluation:
    """Effective mass, speed, energy and ISO/TS 15066 ratios at every site, per sample.

    Reuses the evaluation's joint positions (no IK), or ``joint_positions`` (N, n) with the
    same samples and tip poses (e.g. RedundancyResolution.joint_positions). ``grasp`` and
    ``trajectory`` must be the ones the evaluation was computed with; ``model``: their
    ``augmented_model`` when already built (its ``armature`` is used, as everywhere M
    appears); ``regions``: None for all. Pinocchio per sample: the reference of the compiled
    path, ``evaluate_whole_arm_on_terms`` (equal to rounding, test_terms).
    """
    selected = select_regions(None if regions is None else list(regions))
    count_sites = len(sites)
    if not evaluation.feasible:
        empty = np.empty((0, count_sites))
        exposure = SiteExposure(
            np.empty((0, count_sites, 3)),
            np.empty((0, count_sites, 3)),
            empty.astype(bool),
            empty,
            empty,
        )
        return _whole_arm_result(evaluation, sites, np.empty(0), exposure, selected, math.nan)
    times = np.asarray(evaluation.times_s, dtype=float)
    positions = np.asarray(
        evaluation.joint_positions if joint_positions is None else joint_positions, dtype=float
    )
    if positions.shape != (len(times), robot.num_joints):
        raise InvalidInputError("evaluation.joint_positions", "must have one row per sample")
    if model is None:
        model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    q_all = np.array([robot.q_from_positions(p) for p in positions]).reshape(len(times), -1)
    kinematics = pinocchio_kinematic_terms(model, q_all)
    velocities = tip_following_joint_velocities(
        robot,
        jacobians_tip_in_world(robot, kinematics),
        _tip_twists_in_world(robot, trajectory, grasp, times),
        times,
        positions,
    )
    exposure = site_exposure(
        sites, ArmTerms(*kinematics, velocities), robot.transform_base_to_world
    )
    return _whole_arm_result(
        evaluation, sites, times, exposure, selected, float(trajectory.duration_s)
    )


def _tip_twists_in_world(
    robot: RobotModel,
    trajectory: Trajectory,
    grasp: Grasp,
    times: np.ndarray,
) -> np.ndarray:
    """(N, 6) the tip's twists (linear [m/s], angular [rad/s]), world axes."""
    transform = grasp.transform_tip_to_object
    twists_in_base = tip_twists_in_base(trajectory, transform, times)
    rotation = robot.transform_base_to_world.rotation
    return np.concatenate(
        [twists_in_base[:, :3] @ rotation.T, twists_in_base[:, 3:] @ rotation.T], axis=1
    )


def evaluate_whole_arm_on_terms(
    robot: RobotModel,
    evaluations: Sequence[GraspEvaluation],
    trajectories: Sequence[Trajectory],
    grasps: Sequence[Grasp],
    sites: ArmSites,
    regions: tuple[BodyRegion, ...],
    terms: SampleTerms,
    counts: np.ndarray,
    joint_positions: Sequence[np.ndarray] | None = None,
) -> list[WholeArmEvaluation]:
    """``evaluate_whole_arm`` of G feasible grasps at once, on their shared terms
    (``method.terms.grasps_terms`` along ``joint_positions``, default the evaluations' own:
    axis 0 the grasp, ``counts`` samples each): q̇ from the terms' tip Jacobians (compiled,
    ``method.points.tip_following_rates``), the sites' positions, directions, speeds and
    masses by one compiled call over (grasp, sample, site) (``method.points.arm_site_exposure``:
    the sites on one body share its mobility), the mobilities of the sites at rest by another,
    ISO/TS 15066's peaks compiled (``method.points.region_peaks``, numpy's bits).
    Equal to the Pinocchio path to rounding; each grasp's result is the one it gets alone.
    It reads the joints' frames and motion subspaces, the tip Jacobians and M⁻¹: the terms
    must carry the optional ``WHOLE_ARM_TERMS``; the tip's 6 x 6 mobility is not read."""
    grasp_count, samples = len(evaluations), terms.jacobians_tip_in_world.shape[1]
    paths = (
        [e.joint_positions for e in evaluations] if joint_positions is None else joint_positions
    )
    twists = np.zeros((grasp_count, samples, 6))
    spline_rates = np.zeros((grasp_count, samples, robot.num_joints))
    by_times: dict[bytes, list[int]] = {}
    by_motion: dict[tuple[int, bytes], list[int]] = {}  # each object path sampled once
    as_path: dict[int, ObjectPath | None] = {}  # a runtime Protocol's isinstance: ~10 µs
    for g, (evaluation, trajectory, grasp) in enumerate(
        zip(evaluations, trajectories, grasps, strict=True)
    ):
        times = np.asarray(evaluation.times_s, dtype=float)
        key = (id(trajectory), times.tobytes())
        if key[0] not in as_path:
            as_path[key[0]] = trajectory if isinstance(trajectory, ObjectPath) else None
        if as_path[key[0]] is None:
            twists[g, : counts[g]] = _tip_twists_in_world(robot, trajectory, grasp, times)
        else:
            by_motion.setdefault(key, []).append(g)
        by_times.setdefault(key[1], []).append(g)
    for (trajectory_id, _), group in by_motion.items():
        times = np.asarray(evaluations[group[0]].times_s, dtype=float)
        motion = as_path[trajectory_id].object_motion(times)  # type: ignore[union-attr]
        tips = np.array([grasps[g].transform_tip_to_object.translation for g in group])
        tip_twists_into(motion, tips, robot.transform_base_to_world.rotation, group, twists)
    for group in by_times.values():
        times, count = np.asarray(evaluations[group[0]].times_s, dtype=float), counts[group[0]]
        spline_rates[group, :count] = joint_path_velocities(
            times, [paths[g] for g in group], ~np.isfinite(robot.lower_limits), compiled=True
        )
    rates = tip_following_rates(terms.jacobians_tip_in_world, counts, twists, spline_rates)
    base = robot.transform_base_to_world
    positions, directions, speeds, masses, energies, stationary = arm_site_exposure(
        terms,
        counts,
        (base.rotation, base.translation),
        sites.joint_ids - 1,
        sites.points_in_joint_m,
        sites.support,
        rates,
        STATIONARY_SPEED_M_S,
    )
    if stationary.any():  # the rest ends: A's eigenvectors, world axes, then base axes
        at = np.nonzero(stationary)
        mobilities = site_mobilities(
            terms, sites.joint_ids - 1, sites.points_in_joint_m, sites.support, np.stack(at, 1)
        )
        at_rest, masses[at] = _largest_mass_directions(mobilities)
        directions[at] = at_rest @ base.rotation
    durations = [float(t.duration_s) for t in trajectories]
    assessed = assess_sites_batch(speeds, masses, durations, regions, compiled=True)
    results = []
    arrays = (positions, directions, stationary, speeds, masses, energies)  # SiteExposure's
    for g, evaluation in enumerate(evaluations):
        *exposure, energy = (array[g, : int(counts[g])] for array in arrays)
        times = np.asarray(evaluation.times_s, dtype=float)
        assessment = (regions, durations[g], assessed[g], energy)
        results.append(
            _whole_arm_result(evaluation, sites, times, SiteExposure(*exposure), *assessment)
        )
    return results


def whole_arm_score(whole_arm: WholeArmEvaluation, region: str) -> float:
    """Worst predicted transient force [N] over sites and samples for ``region``; NaN if
    infeasible (``rank_by: whole_arm``: lower is safer)."""
    if not whole_arm.feasible:
        return math.nan
    return whole_arm.region(region).peak_contact_force_n


def order_by_whole_arm(whole_arm: Sequence[WholeArmEvaluation], region: str) -> tuple[int, ...]:
    """Feasible grasps by ``whole_arm_score``, lowest first (ties: input order; a NaN score
    last, so the order is total)."""
    scored = []
    for k, w in enumerate(whole_arm):
        if w.feasible:
            score = whole_arm_score(w, region)
            scored.append((math.isnan(score), 0.0 if math.isnan(score) else score, k))
    return tuple(whole_arm[k].index for *_, k in sorted(scored))


@dataclass(frozen=True)
class WholeArmPostureCriterion:
    """Posture selection by the whole arm (a core.method.posture.PostureCriterion): each
    candidate posture's worst predicted transient force [N] over ``sites`` and the samples
    for ``region`` (``whole_arm_score``), the criterion ``rank_by: whole_arm`` ranks by.

    Attributes:
        sites: The sites assessed (``resolve_arm_sites``).
        region: Body region name.
    """

    sites: ArmSites
    region: str = DEFAULT_RANK_REGION

    def __post_init__(self) -> None:
        select_regions([self.region])  # raises on an unknown name

    @property
    def name(self) -> str:
        """``whole_arm:<region>``."""
        return f"whole_arm:{self.region}"

    def __call__(
        self,
        evaluator: Any,
        grasp: Grasp,
        object_inertia: ObjectInertia,
        trajectory: Trajectory,
        evaluations: Sequence[GraspEvaluation],
    ) -> np.ndarray:
        """The force [N] of each feasible evaluation of ``grasp``: on their terms, in one
        kernel call, with a compiled evaluator; else by Pinocchio (one augmented model)."""
        robot, count, region = evaluator.robot, len(evaluations), [self.region]
        backend = evaluator.backend
        if backend.compiled and evaluations:
            paths = [evaluation.joint_positions for evaluation in evaluations]
            transforms = [grasp.transform_tip_to_object] * count
            terms = backend.grasps_terms(
                robot, object_inertia, transforms, paths, optional=WHOLE_ARM_TERMS
            )
            assessed = evaluate_whole_arm_on_terms(
                robot,
                evaluations,
                [trajectory] * count,
                [grasp] * count,
                self.sites,
                select_regions(region),
                *terms,
            )
        else:
            model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
            assessed = [
                evaluate_whole_arm(
                    robot, e, object_inertia, grasp, trajectory, self.sites, region, model
                )
                for e in evaluations
            ]
        return np.array([whole_arm_score(result, self.region) for result in assessed])
