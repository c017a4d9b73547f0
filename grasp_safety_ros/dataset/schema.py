"""The Arrow schema of the batch's Parquet output: one row per (source file, grasp).

Units are in the column names (SI); field names follow the JSON of ``grasp-safety rank``
(cli/report.py) so JSON and Parquet agree. NaN results (infeasible grasps) are stored as null,
as the JSON stores them. Every part file is written with exactly this schema (``table``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import pyarrow as pa

SCHEMA_VERSION = 2
"""Bumped when a column changes (part of every chunk's content hash); 2: the columns
postures_stopped, retime_binding and retime_reason, and postures_feasible and
score_range_low/high no longer counting postures stopped early."""

_TEXT = pa.dictionary(pa.int32(), pa.string())
_FLOATS = pa.list_(pa.float64())

GRASP_SCHEMA = pa.schema(
    [
        pa.field("source", _TEXT, False),  # file path relative to the SPEC's folder
        pa.field("format", _TEXT, False),  # acronym | graspgen | scenarios
        pa.field("grasp_index", pa.int64(), False),  # position in the file
        pa.field("grasp_id", pa.string(), False),  # ACRONYM: the index; else the grasp's name
        pa.field("label_object_in_gripper", pa.float64()),  # ACRONYM flex/object_in_gripper
        pa.field("label_confidence", pa.float64()),  # GraspGen confidence
        pa.field("label_quality", pa.float64()),  # a scenario's grasp quality
        pa.field("object_file", pa.string()),  # ACRONYM object/file
        pa.field("object_scale", pa.float64()),  # ACRONYM object/scale
        pa.field("object_mass_kg", pa.float64()),  # the mass used
        pa.field("error_key", pa.string()),  # the key of an unreadable grasp; else null
        pa.field("error", pa.string()),  # why it could not be read; else null
        pa.field("feasible", pa.bool_(), False),
        pa.field("reason", pa.string(), False),  # why infeasible or unreadable; "" if feasible
        pa.field("metric", _TEXT, False),  # mean | max | integral
        pa.field("score", pa.float64()),  # kg (mean, max) or kg*s (integral)
        pa.field("mean_effective_mass_kg", pa.float64()),
        pa.field("peak_effective_mass_kg", pa.float64()),
        pa.field("safety_score", pa.float64()),  # with the metric point (and redundancy)
        pa.field("restarts", pa.int32()),  # posture selection (JSON "posture")
        pa.field("score_single_ik", pa.float64()),
        pa.field("score_range_low", pa.float64()),
        pa.field("score_range_high", pa.float64()),
        pa.field("start_positions", _FLOATS),  # rad or m, chain order
        pa.field("postures_tried", pa.int32()),
        pa.field("postures_feasible", pa.int32()),
        pa.field("postures_stopped", pa.int32()),  # stopped early: certainly scored higher
        pa.field("iso_ts_15066_worst_force_ratio", pa.float64()),  # max F/F_max, permitted
        pa.field("iso_ts_15066_min_duration_s", pa.float64()),  # T_min
        pa.field("iso_ts_15066_limiting_region", pa.string()),
        pa.field("iso_ts_15066_admissible_where_permitted", pa.bool_()),
        pa.field("safe_duration_s", pa.float64()),  # retimed to the site limits (retime:)
        pa.field("retime_binding", _TEXT),  # what sets it (JSON "retime_binding")
        pa.field("retime_reason", _TEXT),  # why a grasp has none (JSON "retime_reason")
        pa.field("backend", _TEXT),  # compiled | python (...)
    ]
)
"""One row per (source file, grasp); nullable columns are null for unreadable grasps, the
result columns also for infeasible ones (NaN in the core)."""

PER_SAMPLE_FIELDS = (
    pa.field("time_s", _FLOATS),
    pa.field("effective_mass_kg", _FLOATS),
    pa.field("tip_speed_m_s", _FLOATS),
)
"""Per-sample series appended to GRASP_SCHEMA with ``--per-sample`` (null when infeasible)."""


def grasp_schema(per_sample: bool = False) -> pa.Schema:
    """GRASP_SCHEMA, with PER_SAMPLE_FIELDS appended when ``per_sample``."""
    return pa.schema([*GRASP_SCHEMA, *PER_SAMPLE_FIELDS]) if per_sample else GRASP_SCHEMA


def table(columns: Mapping[str, Sequence[Any]], per_sample: bool = False) -> pa.Table:
    """A ``pyarrow.Table`` of ``columns`` (name -> one value per row, None or NaN for null)
    with exactly the grasp schema."""
    schema = grasp_schema(per_sample)
    arrays = [pa.array(columns[f.name], type=f.type, from_pandas=True) for f in schema]
    return pa.Table.from_arrays(arrays, schema=schema)
