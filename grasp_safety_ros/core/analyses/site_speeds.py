"""Per-site speed and admissible transient-contact speed along a joint-space direction.

For N configurations q and N joint-space directions d (the path tangent q' = dq/ds for the
retiming, the joint velocities q̇ for the live monitor), every assessed site k (the whole-arm
sites of ``arm_sites``, the tip among them, plus the carried object's points, attached to the
tip's body) gets:

- its speed per unit of the direction, |J_k(q) d| ([m/s] per [rad/s]; [m] per unit s for q');
- its effective mass along its own direction of motion u = J_k d / |J_k d|,
  M_eff = 1 / (uᵀ J_k M_aug⁻¹ J_kᵀ u) [kg], with M_aug the joint-space inertia of the chain
  with the object merged into the tip body and the rotor inertia (armature) on its diagonal;
  a site that does not move along d gets its largest effective mass over the directions it
  can move in (``whole_arm.site_exposure``'s convention) and speed 0;
- the body region it is assessed against: of the regions where the TS permits transient
  contact, the one with the smallest admissible speed for that effective mass, and that speed
  v_max,k = F_tr / sqrt(μ k) (``iso15066.max_permissible_speed_m_s``).

All of it is ``whole_arm``'s math (``pinocchio_kinematic_terms``, ``site_exposure``) with the
direction in place of q̇; nothing here re-derives a Jacobian or a mass. One ``SiteSpeedModel``
per robot, object and grasp keeps the augmented model and its Pinocchio data, so a call with
N = 1 costs a few Pinocchio calls and array operations (the monitor's per-message path).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_array, read_only
from ..method.effective_mass import augmented_model
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .arm_sites import ArmSites
from .body_regions import BodyRegion, select_regions
from .iso15066 import max_permissible_speed_m_s
from .whole_arm import ArmTerms, pinocchio_kinematic_terms, site_exposure

OBJECT_SITE_PREFIX = "object"
"""Object points are sites named ``object[i]`` (i: the point's index in the input)."""


def sites_with_object_points(
    robot: RobotModel,
    sites: ArmSites,
    points_in_object_m: np.ndarray | Sequence[Sequence[float]] | None,
    transform_tip_to_object: pin.SE3,
) -> ArmSites:
    """``sites`` plus the object's points (P, 3) [m, object frame] as sites on the tip's body:
    each point in the tip's parent-joint frame, tip.placement · (transform_tip_to_object)⁻¹ · p.
    """
    if points_in_object_m is None or len(points_in_object_m) == 0:
        return sites
    points = finite_array(points_in_object_m, "object.points_m")
    if points.ndim != 2 or points.shape[1] != 3:
        raise InvalidInputError("object.points_m", f"must be (P, 3), got {list(points.shape)}")
    tip = robot.model.frames[robot.tip_frame_id]
    to_joint = tip.placement * pin.SE3(transform_tip_to_object).inverse()
    in_joint = points @ to_joint.rotation.T + to_joint.translation
    support = np.zeros(robot.model.nv, dtype=bool)
    for i in robot.model.supports[tip.parentJoint][1:]:
        support[robot.model.joints[i].idx_v] = True
    count = len(points)
    return ArmSites(
        names=sites.names + tuple(f"{OBJECT_SITE_PREFIX}[{i}]" for i in range(count)),
        links=sites.links + (robot.tip_frame,) * count,
        joint_ids=read_only(np.concatenate([sites.joint_ids, [tip.parentJoint] * count])),
        points_in_joint_m=read_only(np.concatenate([sites.points_in_joint_m, in_joint])),
        support=read_only(np.concatenate([sites.support, np.tile(support, (count, 1))])),
        dropped=sites.dropped,
    )


@dataclass(frozen=True)
class SiteSpeeds:
    """Per (configuration, site) arrays (N, K) (a dataclass, not a NamedTuple: NamedTuple
    modules key the kernel cache).

    Attributes:
        speed_per_unit: |J_k d| [m/s per unit of d]; 0 where the site does not move along d.
        effective_mass_kg: M_eff along the site's own direction of motion [kg].
        stationary: True where the site does not move along d (mass: its largest).
        region_index: Index into ``SiteSpeedModel.regions`` of the region assessed against.
        max_speed_m_s: That region's admissible transient-contact speed v_max [m/s].
        region_max_speed_m_s: (N, K, R) v_max of every region of ``SiteSpeedModel.regions``.
    """

    speed_per_unit: np.ndarray
    effective_mass_kg: np.ndarray
    stationary: np.ndarray
    region_index: np.ndarray
    max_speed_m_s: np.ndarray
    region_max_speed_m_s: np.ndarray


def permitted_regions(regions: Sequence[str | BodyRegion] | None) -> tuple[BodyRegion, ...]:
    """The selected regions (None: all) where the TS permits transient contact; refused when
    none is left (a speed limit of 0 everywhere admits no motion)."""
    selected = tuple(r for r in select_regions(regions) if r.transient_contact_permitted)
    if not selected:
        raise InvalidInputError(
            "iso_ts_15066.regions",
            "no region with transient contact permitted (F_tr) is selected; a speed limit "
            "needs at least one",
        )
    return selected


@dataclass(frozen=True)
class SiteSpeedModel:
    """What ``site_speeds`` needs for one robot, carried object and grasp, built once.

    Attributes:
        robot: The chain.
        model: The augmented model (object merged into the tip body, armature in M).
        data: Its Pinocchio data, reused by every call (not thread-safe: one per thread).
        sites: The assessed sites (arm sites, then the object points).
        regions: The regions assessed against (transient contact permitted).
    """

    robot: RobotModel
    model: pin.Model
    data: pin.Data
    sites: ArmSites
    regions: tuple[BodyRegion, ...]

    @classmethod
    def build(
        cls,
        robot: RobotModel,
        object_inertia: ObjectInertia,
        transform_tip_to_object: pin.SE3,
        sites: ArmSites,
        points_in_object_m: np.ndarray | None = None,
        regions: Sequence[str | BodyRegion] | None = None,
    ) -> SiteSpeedModel:
        """The model of ``robot`` carrying ``object_inertia`` at the grasp
        ``transform_tip_to_object`` (pose of the tip in the object frame), with ``sites``
        plus the object's points (object frame [m]), against ``regions`` (None: all
        permitted)."""
        model = augmented_model(robot, object_inertia, transform_tip_to_object)
        return cls(
            robot=robot,
            model=model,
            data=model.createData(),
            sites=sites_with_object_points(
                robot, sites, points_in_object_m, transform_tip_to_object
            ),
            regions=permitted_regions(regions),
        )


def site_speeds(
    speed_model: SiteSpeedModel, q_all: np.ndarray, directions: np.ndarray
) -> SiteSpeeds:
    """Every site's speed per unit of the direction, effective mass, region and v_max.

    Args:
        speed_model: The robot, object, grasp, sites and regions (``SiteSpeedModel.build``).
        q_all: (N, nq) configurations (Pinocchio's q; ``robot.q_from_positions``).
        directions: (N, nv) joint-space directions (q' or q̇) [rad or m per unit].
    """
    kinematics = pinocchio_kinematic_terms(speed_model.model, q_all, speed_model.data)
    exposure = site_exposure(
        speed_model.sites, ArmTerms(*kinematics, directions), pin.SE3.Identity()
    )
    masses = exposure.effective_mass_kg
    limits = np.stack(
        [max_permissible_speed_m_s(masses, region) for region in speed_model.regions], axis=-1
    )
    index = np.argmin(limits, axis=-1)
    return SiteSpeeds(
        speed_per_unit=exposure.speed_m_s,
        effective_mass_kg=masses,
        stationary=exposure.stationary,
        region_index=index,
        max_speed_m_s=np.take_along_axis(limits, index[..., None], axis=-1)[..., 0],
        region_max_speed_m_s=limits,
    )
