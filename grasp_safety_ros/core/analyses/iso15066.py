"""Power and force limiting after ISO/TS 15066 (transient contact, Annex A).

For a transient contact of the moving robot + object (effective mass m_r along the direction of
motion, speed v) with a body region (effective mass m_h, spring constant k), the TS models the
collision as two masses and a spring:

    μ = (1/m_h + 1/m_r)⁻¹,   F = v·sqrt(μ·k),   v_max = F_max / sqrt(μ·k),   E = F² / (2k).

F_max is the region's maximum permissible *transient* force F_tr. Regions where transient
contact is not permitted (the head: F_tr is null in the table) get v_max = 0, a force ratio of
inf at every sample where the tip moves (0 where it is at rest), are never admissible for a
moving tip, and need an infinite duration. Here m_r is the pose-dependent effective mass of
robot + object (GraspEvaluation.effective_mass_kg), not ISO's shortcut m_r = M/2 + m_L.

Minimum duration: the effective mass along the path does not depend on the duration T (the IK
depends only on the path parameter) and the speed of a quintic scales as 1/T, so re-timing to
T' multiplies every force ratio by T/T'; the shortest admissible duration is
T_min = T · max_t F(t)/F_max (for a ratio <= 1 the motion is admissible as it is, and T_min <= T
is still reported). All maxima are over the trajectory samples. For a timed waypoint path or a
planned joint trajectory the same holds for slowing the whole timed motion uniformly
(t -> t·T'/T: the path, hence the effective mass, is unchanged and every speed scales by T/T').
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..exceptions import InvalidInputError
from ..input_checks import finite_array, finite_float, read_only
from ..method.results import GraspEvaluation
from .body_regions import MAX_VALUE, MIN_VALUE, BodyRegion, select_regions

ADMISSIBLE_RATIO_TOLERANCE = 1e-9
"""A force ratio F/F_tr up to 1 + this counts as admissible (absorbs rounding only)."""


def reduced_mass_kg(human_mass_kg: float, robot_effective_mass_kg: Any) -> np.ndarray:
    """μ = (1/m_h + 1/m_r)⁻¹ [kg], elementwise; m_h = inf gives μ = m_r."""
    robot = np.asarray(robot_effective_mass_kg, dtype=float)
    return 1.0 / (1.0 / human_mass_kg + 1.0 / robot)


def transient_contact_force_n(
    speed_m_s: Any, robot_effective_mass_kg: Any, region: BodyRegion
) -> np.ndarray:
    """Predicted peak transient contact force F = v·sqrt(μ·k) [N], elementwise."""
    mu = reduced_mass_kg(region.effective_mass_kg, robot_effective_mass_kg)
    return np.asarray(speed_m_s, dtype=float) * np.sqrt(mu * region.spring_constant_n_per_m)


def max_permissible_speed_m_s(robot_effective_mass_kg: Any, region: BodyRegion) -> np.ndarray:
    """v_max = F_tr / sqrt(μ·k) [m/s], elementwise; 0 where transient contact is not permitted."""
    mu = reduced_mass_kg(region.effective_mass_kg, robot_effective_mass_kg)
    if region.max_transient_force_n is None:
        return np.zeros_like(mu)
    return region.max_transient_force_n / np.sqrt(mu * region.spring_constant_n_per_m)


class _RegionSamples:
    """The per-sample arrays of R regions for M motions of N samples ((M, N) speeds [m/s] and
    masses [kg], validated): force [N], v_max [m/s] and force ratio (R·M, N) (region-major),
    read-only, computed for all at once on the first read (``_region_arrays``). Most
    callers read only the summaries, which ``_region_peaks`` computes without them.
    Immutable once made (copies share it); pickled as its inputs."""

    def __init__(
        self, speed_m_s: np.ndarray, effective_mass_kg: np.ndarray, regions: tuple[BodyRegion, ...]
    ) -> None:
        self._inputs = (speed_m_s, effective_mass_kg, regions)
        self._arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._motions: dict[int, _RegionSamples] = {}

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), self._inputs)

    def __copy__(self) -> _RegionSamples:
        return self

    def __deepcopy__(self, memo: dict[int, Any]) -> _RegionSamples:
        return self

    @property
    def motions(self) -> int:
        """M, the motions assessed together."""
        return int(self._inputs[0].shape[0])

    def of_motion(self, m: int) -> _RegionSamples:
        """Motion m's inputs alone (rows k of its R regions), the same object at every call:
        what a pickled assessment carries instead of the whole batch."""
        if m not in self._motions:
            speed, mass, regions = self._inputs
            self._motions[m] = _RegionSamples(
                speed[m : m + 1].copy(), mass[m : m + 1].copy(), regions
            )
        return self._motions[m]

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(force, v_max, ratio), each (R·M, N)."""
        if self._arrays is None:  # (two threads may both compute it: the same bits)
            speed, _, regions = self._inputs
            shape = (len(regions) * speed.shape[0], speed.shape[1])
            force, v_max, ratio = (a.reshape(shape) for a in _region_arrays(*self._inputs))
            self._arrays = (force, v_max, ratio)
        return self._arrays

    def row(self, which: int, at: int) -> np.ndarray:
        """Row ``at`` (N,) of array ``which`` (0 force, 1 v_max, 2 ratio) of ``arrays``."""
        array: np.ndarray = self.arrays()[which][at]
        return array


@dataclass(frozen=True)
class RegionAssessment:
    """Transient contact with one body region along one trajectory.

    Attributes:
        region: The body region.
        worst_force_ratio: max_t of force_ratio (0 for an empty or motionless trajectory).
        worst_sample: Sample index of the peak force (first one on ties), where the ratio is
            worst too (F_tr is a constant; inf wherever moving if not permitted).
        peak_contact_force_n: max_t F(t) [N].
        admissible: worst_force_ratio <= 1 (+ ADMISSIBLE_RATIO_TOLERANCE).
        min_duration_s: T · worst_force_ratio [s]: the shortest duration of the same quintic
            path for which this region is admissible (inf if not permitted and moving).
        min_max_permissible_speed_m_s: min_t of max_permissible_speed_m_s [m/s] (0 if not
            permitted, NaN without samples).

    The per-sample arrays (N,), ``contact_force_n``, ``max_permissible_speed_m_s`` and
    ``force_ratio``, are properties, computed on first read for every region and motion
    assessed with this one (``_samples``, at row ``_at``: region k of motion m at k·M + m).
    Pickled or deep-copied, an assessment carries its own motion's inputs (speeds and masses),
    not its batch's; its arrays are computed again from them, the same bits.
    """

    region: BodyRegion
    worst_force_ratio: float
    worst_sample: int
    peak_contact_force_n: float
    admissible: bool
    min_duration_s: float
    min_max_permissible_speed_m_s: float
    _samples: _RegionSamples = field(repr=False, compare=False)
    _at: int = field(repr=False, compare=False)

    def __reduce__(self) -> tuple[Any, ...]:
        """Its fields, with its own motion's samples (``_RegionSamples.of_motion``)."""
        region, m = divmod(self._at, self._samples.motions)
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values.update(_samples=self._samples.of_motion(m), _at=region)
        return (_restored_assessment, (type(self), values))

    @property
    def contact_force_n(self) -> np.ndarray:
        """(N,) predicted transient contact force F(t) [N]."""
        return self._samples.row(0, self._at)

    @property
    def max_permissible_speed_m_s(self) -> np.ndarray:
        """(N,) v_max(t) [m/s] for the effective mass at t (0 if not permitted)."""
        return self._samples.row(1, self._at)

    @property
    def force_ratio(self) -> np.ndarray:
        """(N,) F(t)/F_tr; where transient contact is not permitted: inf where the tip
        moves, 0 where it is at rest."""
        return self._samples.row(2, self._at)

    @property
    def transient_contact_permitted(self) -> bool:
        """Whether the TS permits transient contact with this region."""
        return self.region.transient_contact_permitted


def _restored_assessment(cls: type[RegionAssessment], values: dict[str, Any]) -> RegionAssessment:
    """A pickled RegionAssessment (or subclass) from its fields by name."""
    return cls(**values)


@dataclass(frozen=True)
class PowerForceLimitAssessment:
    """ISO/TS 15066 power-and-force-limiting check of one grasp's trajectory.

    Attributes:
        index, name: The grasp, as in its GraspEvaluation.
        feasible: False when the grasp's trajectory is infeasible (then nothing is assessed).
        duration_s: T of the assessed trajectory [s]; NaN if infeasible.
        regions: One RegionAssessment per assessed region, in the order asked.
        admissible: Every assessed region admissible (never, for a moving tip, when a region
            that permits no transient contact is assessed).
        admissible_where_permitted: Every assessed region that permits transient contact is
            admissible.
        min_duration_s: Shortest duration [s] admissible for every assessed region that
            permits transient contact (NaN if none is assessed or infeasible).
        limiting_region: The permitted region with the largest worst ratio ("" if none).
        regions_not_permitted: Names of assessed regions that permit no transient contact.
    """

    index: int
    name: str
    feasible: bool
    duration_s: float
    regions: tuple[RegionAssessment, ...]
    admissible: bool
    admissible_where_permitted: bool
    min_duration_s: float
    limiting_region: str
    regions_not_permitted: tuple[str, ...]

    def region(self, name: str) -> RegionAssessment:
        """The assessment of the region called ``name``."""
        for assessment in self.regions:
            if assessment.region.name == name:
                return assessment
        raise InvalidInputError(
            "iso15066.region",
            f"region {name!r} was not assessed; assessed: "
            f"{', '.join(a.region.name for a in self.regions)}",
        )


@functools.lru_cache(maxsize=64)
def _region_columns(
    regions: tuple[BodyRegion, ...],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(R, 1) columns of the regions: permitted, m_h [kg], k [N/m], F_tr [N] (NaN: none)."""
    columns = (
        np.array([r.transient_contact_permitted for r in regions], dtype=bool),
        np.array([r.effective_mass_kg for r in regions], dtype=float),
        np.array([r.spring_constant_n_per_m for r in regions], dtype=float),
        np.array([r.max_transient_force_n or np.nan for r in regions], dtype=float),
    )
    return tuple(read_only(column[:, None]) for column in columns)  # type: ignore[return-value]


def _assess_batch(
    speed_m_s: np.ndarray,
    effective_mass_kg: np.ndarray,
    duration_s: float,
    regions: tuple[BodyRegion, ...],
    indices: Sequence[int],
    names: Sequence[str],
) -> list[PowerForceLimitAssessment]:
    """The assessments of M motions ((M, N) speeds and masses, validated): regions x motions
    in array passes (``_region_peaks``), the per-sample arrays on first read
    (``_RegionSamples``); the same numbers as one region and one motion at a time."""
    worst, worst_sample, peak, min_speed = _region_peaks(speed_m_s, effective_mass_kg, regions)
    admissible = worst <= 1.0 + ADMISSIBLE_RATIO_TOLERANCE
    min_duration = np.where(worst > 0.0, duration_s * worst, 0.0)
    samples = _RegionSamples(speed_m_s, effective_mass_kg, regions)
    columns = (worst, worst_sample, peak, admissible, min_duration, min_speed)
    count, permitted = len(speed_m_s), _region_columns(regions)[0][:, 0]
    assessed = [  # positional (R per motion): the fields in order
        tuple(
            [
                RegionAssessment(region, w, s, p, a, d, v, samples, k * count + m)
                for k, (region, w, s, p, a, d, v) in enumerate(zip(regions, *rows, strict=True))
            ]
        )
        for m, rows in enumerate(zip(*(column.T.tolist() for column in columns), strict=True))
    ]
    if permitted.any():  # the limiting region: the first of the largest worst ratio
        limiting = np.flatnonzero(permitted)[np.argmax(worst[permitted], axis=0)]
        durations = min_duration[limiting, np.arange(count)].tolist()
        limiting_names = [regions[k].name for k in limiting.tolist()]
    else:
        durations, limiting_names = [math.nan] * count, [""] * count
    not_permitted = tuple(
        region.name for region in regions if not region.transient_contact_permitted
    )
    all_admissible = np.logical_and.reduce(admissible, axis=0)
    admissible_where_permitted = np.logical_and.reduce(admissible[permitted], axis=0)
    return [
        PowerForceLimitAssessment(
            index=index,
            name=name,
            feasible=True,
            duration_s=duration_s,
            regions=regions_m,
            admissible=every,
            admissible_where_permitted=where_permitted,
            min_duration_s=min_duration_s,
            limiting_region=limiting_region,
            regions_not_permitted=not_permitted,
        )
        for index, name, regions_m, every, where_permitted, min_duration_s, limiting_region in zip(
            indices,
            names,
            assessed,
            all_admissible.tolist(),
            admissible_where_permitted.tolist(),
            durations,
            limiting_names,
            strict=True,
        )
    ]


def _region_peaks(
    speed_m_s: np.ndarray, effective_mass_kg: np.ndarray, regions: tuple[BodyRegion, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per (region, motion) (R, M) of M motions of N samples ((M, N) speeds and masses,
    validated): the worst force ratio, its sample (that of the first peak force), the peak
    force [N] and the smallest v_max [m/s]: ``_region_arrays``' numbers there, region by
    region in (M, N) buffers, without its (R, M, N) arrays.

    v_max is smallest where the mass is largest (every operation of the formula is
    monotonic, rounding included), so it is computed at that mass only.
    """
    permitted, human_mass, stiffness, limit = _region_columns(regions)
    count, samples = speed_m_s.shape
    if not samples:
        zeros = np.zeros((len(regions), count))
        return zeros, zeros.astype(int), zeros, np.full_like(zeros, np.nan)
    inverse_mass = 1.0 / effective_mass_kg
    root, force = np.empty_like(speed_m_s), np.empty_like(speed_m_s)
    worst_sample = np.empty((len(regions), count), dtype=int)
    peak = np.empty((len(regions), count))
    for k, region in enumerate(regions):  # transient_contact_force_n's operations
        np.add(1.0 / region.effective_mass_kg, inverse_mass, out=root)
        np.divide(1.0, root, out=root)
        np.multiply(root, region.spring_constant_n_per_m, out=root)
        np.sqrt(root, out=root)
        np.multiply(speed_m_s, root, out=force)
        worst_sample[k] = np.argmax(force, axis=1)
        peak[k] = np.take_along_axis(force, worst_sample[k, :, None], axis=1)[:, 0]
    moving = np.take_along_axis(speed_m_s, worst_sample.T, axis=1).T > 0.0
    worst = np.where(permitted, peak / limit, np.where(moving, np.inf, 0.0))
    heaviest = effective_mass_kg.max(axis=1)  # max_permissible_speed_m_s's operations
    root_max = np.sqrt(1.0 / (1.0 / human_mass + 1.0 / heaviest) * stiffness)
    min_speed = np.where(permitted, limit / root_max, 0.0)
    return worst, worst_sample, peak, min_speed


def _region_arrays(
    speed_m_s: np.ndarray, effective_mass_kg: np.ndarray, regions: tuple[BodyRegion, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force [N], v_max [m/s] and force ratio (R, M, N) (read-only) of R regions for M motions
    of N samples ((M, N) speeds and masses, validated).

    The elementwise formulas of transient_contact_force_n and max_permissible_speed_m_s, in
    the same operation order (so the same bits), written in place: one (R, M, N) buffer per
    output, no temporaries of that size.
    """
    permitted, human_mass, stiffness, limit = (c[:, :, None] for c in _region_columns(regions))
    shape = (len(regions), *speed_m_s.shape)
    root = np.add(1.0 / human_mass, 1.0 / effective_mass_kg, out=np.empty(shape))
    np.divide(1.0, root, out=root)  # μ = (1/m_h + 1/m_r)⁻¹
    np.multiply(root, stiffness, out=root)
    np.sqrt(root, out=root)  # sqrt(μ·k)
    force = np.multiply(speed_m_s, root)  # (R, M, N)
    v_max = np.divide(limit, root, out=root)
    ratio = np.divide(force, limit)
    not_permitted = ~permitted[:, 0, 0]
    if not_permitted.any():
        v_max[not_permitted] = 0.0
        ratio[not_permitted] = np.where(speed_m_s > 0.0, np.inf, 0.0)
    return read_only(force), read_only(v_max), read_only(ratio)


def _checked_motion(speed_m_s: Any, effective_mass_kg: Any) -> tuple[np.ndarray, np.ndarray]:
    """One motion's speeds [m/s] in [0, MAX_VALUE] and masses [kg] in [MIN_VALUE, MAX_VALUE]
    (``body_regions.MIN_VALUE``: no force, speed limit or ratio overflows)."""
    speed = finite_array(speed_m_s, "iso15066.speed_m_s")
    if speed.ndim != 1 or not _within(speed, 0.0):
        raise InvalidInputError(
            "iso15066.speed_m_s", f"must be a 1-D array of speeds in [0, {MAX_VALUE:g}]"
        )
    mass = finite_array(effective_mass_kg, "iso15066.effective_mass_kg", speed.shape)
    if not _within(mass, MIN_VALUE):
        raise InvalidInputError(
            "iso15066.effective_mass_kg",
            f"must be in [{MIN_VALUE:g}, {MAX_VALUE:g}] at every sample",
        )
    return speed, mass


def _within(values: np.ndarray, low: float) -> bool:
    """Every value in [low, MAX_VALUE] (NaN is not)."""
    return bool(((values >= low) & (values <= MAX_VALUE)).all())


def assess_motion(
    speed_m_s: Any,
    effective_mass_kg: Any,
    duration_s: float,
    regions: Sequence[str | BodyRegion] | Mapping[str, BodyRegion] | None = None,
    index: int = 0,
    name: str = "",
) -> PowerForceLimitAssessment:
    """Assess per-sample speeds [m/s] and effective masses [kg] of a quintic of duration T [s]
    (speeds in [0, 1e100], masses in [1e-100, 1e100]: ``body_regions.MIN_VALUE``).

    Use this for any point of the moving body (e.g. an exposed point of the object); for the
    tip of an evaluated grasp use ``assess_grasp``.
    """
    return assess_motions([speed_m_s], [effective_mass_kg], duration_s, regions, [index], [name])[
        0
    ]


def assess_motions(
    speeds_m_s: Sequence[Any],
    effective_masses_kg: Sequence[Any],
    duration_s: float,
    regions: Sequence[str | BodyRegion] | Mapping[str, BodyRegion] | None = None,
    indices: Sequence[int] | None = None,
    names: Sequence[str] | None = None,
) -> list[PowerForceLimitAssessment]:
    """``assess_motion`` of several motions of the same duration (e.g. the grasps of a ranking).

    Motions with the same number of samples are assessed in one array pass; the results are
    those of assess_motion one by one.
    """
    count = len(speeds_m_s)
    if len(effective_masses_kg) != count:
        raise InvalidInputError(
            "iso15066.effective_mass_kg", f"must have one series per motion ({count})"
        )
    indices = list(range(count)) if indices is None else list(indices)
    names = [""] * count if names is None else list(names)
    duration = finite_float(duration_s, "iso15066.duration_s", 0.0, None, True)
    selected = select_regions(regions)
    batch = _checked_batch(speeds_m_s, effective_masses_kg)
    if batch is not None:
        return _assess_batch(*batch, duration, selected, indices, names)
    checked = [_checked_motion(v, m) for v, m in zip(speeds_m_s, effective_masses_kg, strict=True)]
    return [
        _assess_batch(speed[None], mass[None], duration, selected, [index], [name])[0]
        for (speed, mass), index, name in zip(checked, indices, names, strict=True)
    ]


def _checked_batch(
    speeds_m_s: Sequence[Any], effective_masses_kg: Sequence[Any]
) -> tuple[np.ndarray, np.ndarray] | None:
    """The motions as (M, N) speeds and masses when they are M >= 1 valid series of one
    length N (checked in one pass); None otherwise (then each is checked, and a bad one is
    named, by ``_checked_motion``)."""
    try:
        speeds = np.array(speeds_m_s, dtype=float)
        masses = np.array(effective_masses_kg, dtype=float)
    except (TypeError, ValueError):  # ragged or not numeric
        return None
    valid = (
        speeds.ndim == 2
        and len(speeds) > 0
        and masses.shape == speeds.shape
        and _within(speeds, 0.0)
        and _within(masses, MIN_VALUE)
    )
    return (speeds, masses) if valid else None


def assess_grasp(
    evaluation: GraspEvaluation,
    regions: Sequence[str | BodyRegion] | Mapping[str, BodyRegion] | None = None,
) -> PowerForceLimitAssessment:
    """Assess a grasp's tip motion: tip speed and effective mass along the direction of motion.

    The duration T is the evaluation's last sample time (trajectories always sample t = T).
    An infeasible evaluation gives an assessment with ``feasible`` False, no regions, NaN
    duration and ``admissible`` False.
    """
    if not evaluation.feasible:
        selected = select_regions(regions)
        return PowerForceLimitAssessment(
            index=evaluation.index,
            name=evaluation.name,
            feasible=False,
            duration_s=math.nan,
            regions=(),
            admissible=False,
            admissible_where_permitted=False,
            min_duration_s=math.nan,
            limiting_region="",
            regions_not_permitted=tuple(
                r.name for r in selected if not r.transient_contact_permitted
            ),
        )
    return assess_motion(
        evaluation.tip_speed_m_s,
        evaluation.effective_mass_kg,
        float(evaluation.times_s[-1]),
        regions,
        evaluation.index,
        evaluation.name,
    )
