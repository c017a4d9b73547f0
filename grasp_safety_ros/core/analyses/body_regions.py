"""The ISO/TS 15066 body-region table (Annex A, Tables A.2 and A.3): ``BodyRegion`` (limits
and biomechanical model of one region, in SI units), ``BODY_REGIONS`` (the table, also shipped
as the package's data file), reading a region file, and ``select_regions`` (the regions an
assessment asks for). The assessment itself is ``iso15066``'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from ..exceptions import GraspSafetyError, InvalidInputError
from ..input_checks import finite_float

N_PER_MM_IN_N_PER_M = 1000.0
"""1 N/mm = 1000 N/m: the table gives k in N/mm, the core works in N/m."""

MIN_VALUE, MAX_VALUE = 1e-100, 1e100
"""The range of a region's F_qs [N], F_tr [N], k [N/m] and finite m_h [kg], and of the speeds
[m/s] (or 0) and effective masses [kg] assessed against it (``iso15066``): then μ·k > 0 and
μ·k, sqrt(μ·k), F = v·sqrt(μ·k), v_max = F_tr/sqrt(μ·k) and F/F_tr are at most about 1e300,
never inf or NaN (a custom region of m_h = inf and a mass of 1e305 kg at rest made μ·k inf and
F = 0·inf NaN; the shortest admissible duration T·F/F_tr may still overflow to inf there, never
NaN). Far beyond any physical value: the table's k is 1e4-1.5e5 N/m, m_h 0.6-75 kg."""

DATA_FILE_NAME = "iso_ts_15066_body_regions.yaml"
"""Name of the package's data file (in grasp_safety_ros/data/) holding the same table."""

# ISO/TS 15066:2016 Annex A, Tables A.2 and A.3, as commonly quoted; carried over from the
# project's shared data file (shared/data/iso_ts_15066_body_regions.yaml), cross-checked between
# several public transcriptions; the TS itself is the authority. The package ships the same
# table as data/iso_ts_15066_body_regions.yaml; test/test_iso15066.py checks that both agree.
# Columns: name, F_qs [N], F_tr [N] (None: transient contact not permitted), k [N/mm], m_h [kg].
REGION_TABLE: tuple[tuple[str, float, float | None, float, float], ...] = (
    ("skull_forehead", 130.0, None, 150.0, 4.4),
    ("face", 65.0, None, 75.0, 4.4),
    ("neck", 150.0, None, 50.0, 1.2),
    ("back_shoulders", 210.0, 420.0, 35.0, 40.0),
    ("chest", 140.0, 280.0, 25.0, 40.0),
    ("abdomen", 110.0, 220.0, 10.0, 40.0),
    ("pelvis", 180.0, 360.0, 25.0, 40.0),
    ("upper_arm_elbow", 150.0, 300.0, 30.0, 3.0),
    ("lower_arm_wrist", 160.0, 320.0, 40.0, 2.0),
    ("hand_fingers", 140.0, 280.0, 75.0, 0.6),
    ("thigh_knee", 220.0, 440.0, 50.0, 75.0),
    ("lower_leg", 130.0, 260.0, 60.0, 75.0),
)
"""The body-region table in the data file's own units (k in N/mm)."""


@dataclass(frozen=True)
class BodyRegion:
    """One body region's limits and biomechanical model, in SI units.

    Attributes:
        name: Region name, e.g. ``chest``.
        max_quasi_static_force_n: F_qs [N].
        max_transient_force_n: F_tr [N]; None when transient contact is not permitted.
        spring_constant_n_per_m: k [N/m] (the table's N/mm times 1000).
        effective_mass_kg: m_h [kg]; may be inf (an immovable region: μ = m_r).

    Each number is in [MIN_VALUE, MAX_VALUE] (m_h: or inf).
    """

    name: str
    max_quasi_static_force_n: float
    max_transient_force_n: float | None
    spring_constant_n_per_m: float
    effective_mass_kg: float

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InvalidInputError(
                "region.name", f"must be a non-empty string, got {self.name!r}"
            )
        where = f"region '{self.name}'"
        f_qs = finite_float(self.max_quasi_static_force_n, f"{where}.F_qs", MIN_VALUE, MAX_VALUE)
        f_tr = self.max_transient_force_n
        if f_tr is not None:
            f_tr = finite_float(f_tr, f"{where}.F_tr", MIN_VALUE, MAX_VALUE)
        k = finite_float(self.spring_constant_n_per_m, f"{where}.k", MIN_VALUE, MAX_VALUE)
        m_h = self.effective_mass_kg
        if not (isinstance(m_h, (int, float, np.floating)) and not isinstance(m_h, bool)) or not (
            MIN_VALUE <= m_h <= MAX_VALUE or m_h == math.inf
        ):
            raise InvalidInputError(
                f"{where}.m_h",
                f"must be a number in [{MIN_VALUE:g}, {MAX_VALUE:g}] or inf, got {m_h!r}",
            )
        object.__setattr__(self, "max_quasi_static_force_n", f_qs)
        object.__setattr__(self, "max_transient_force_n", f_tr)
        object.__setattr__(self, "spring_constant_n_per_m", k)
        object.__setattr__(self, "effective_mass_kg", float(m_h))

    @property
    def transient_contact_permitted(self) -> bool:
        """False for regions where the TS permits no transient contact (F_tr is None)."""
        return self.max_transient_force_n is not None

    @classmethod
    def from_table_units(
        cls, name: str, f_qs_n: float, f_tr_n: float | None, k_n_per_mm: float, m_h_kg: float
    ) -> BodyRegion:
        """Build from the table's units: forces [N], k [N/mm], m_h [kg]."""
        low, high = (bound / N_PER_MM_IN_N_PER_M for bound in (MIN_VALUE, MAX_VALUE))
        k = finite_float(k_n_per_mm, f"region '{name}'.k", low, high)
        return cls(name, f_qs_n, f_tr_n, k * N_PER_MM_IN_N_PER_M, m_h_kg)


BODY_REGIONS: Mapping[str, BodyRegion] = MappingProxyType(
    {row[0]: BodyRegion.from_table_units(*row) for row in REGION_TABLE}
)
"""Every region of REGION_TABLE by name, in table order."""


def body_regions_from_mapping(
    table: Mapping[str, Any], field: str = "regions"
) -> dict[str, BodyRegion]:
    """Regions from a mapping name -> {F_qs [N], F_tr [N] or None, k [N/mm], m_h [kg]}.

    This is the ``regions`` mapping of the YAML data file, parsed by any YAML loader.
    """
    if not isinstance(table, Mapping) or not table:
        raise InvalidInputError(field, f"must be a non-empty mapping, got {table!r}")
    regions: dict[str, BodyRegion] = {}
    for name, row in table.items():
        keys = ("F_qs", "F_tr", "k", "m_h")
        if not isinstance(row, Mapping) or set(row) != set(keys):
            raise InvalidInputError(
                f"{field}.{name}", f"must be a mapping with exactly the keys {keys}, got {row!r}"
            )
        regions[str(name)] = BodyRegion.from_table_units(
            str(name), row["F_qs"], row["F_tr"], row["k"], row["m_h"]
        )
    return regions


def data_file_path() -> Path:
    """Path of the package's copy of the table (grasp_safety_ros/data/)."""
    return Path(__file__).resolve().parents[2] / "data" / DATA_FILE_NAME


def load_body_regions(path: str | Path | None = None) -> dict[str, BodyRegion]:
    """Read a region table file (default: the package's data file). Needs PyYAML.

    The core itself does not need this: BODY_REGIONS holds the same table.
    """
    try:
        import yaml
    except ImportError:
        raise GraspSafetyError(
            "reading a body-region file needs PyYAML; use body_regions.BODY_REGIONS instead"
        ) from None
    file = Path(path) if path is not None else data_file_path()
    try:
        content = yaml.safe_load(file.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as error:
        raise InvalidInputError(
            "iso15066.regions_file", f"cannot read '{file}': {error}"
        ) from None
    if not isinstance(content, Mapping) or "regions" not in content:
        raise InvalidInputError("iso15066.regions_file", f"'{file}' has no 'regions' mapping")
    return body_regions_from_mapping(content["regions"])


def select_regions(
    regions: Sequence[str | BodyRegion] | Mapping[str, BodyRegion] | None = None,
) -> tuple[BodyRegion, ...]:
    """Regions to assess: None -> all of BODY_REGIONS; names are looked up in BODY_REGIONS."""
    if regions is None:
        return tuple(BODY_REGIONS.values())
    if isinstance(regions, Mapping):
        regions = list(regions.values())
    if isinstance(regions, str) or not isinstance(regions, Sequence) or not regions:
        raise InvalidInputError(
            "iso15066.regions", f"must be a non-empty list of region names, got {regions!r}"
        )
    selected: list[BodyRegion] = []
    for region in regions:
        if isinstance(region, BodyRegion):
            selected.append(region)
        elif region in BODY_REGIONS:
            selected.append(BODY_REGIONS[region])
        else:
            raise InvalidInputError(
                "iso15066.regions",
                f"unknown body region {region!r}; regions: {', '.join(BODY_REGIONS)}",
            )
    names = [region.name for region in selected]
    if len(set(names)) != len(names):
        raise InvalidInputError("iso15066.regions", f"regions repeat: {names}")
    return tuple(selected)
