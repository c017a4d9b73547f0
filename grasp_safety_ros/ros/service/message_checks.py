"""Checks of whole messages at the node's boundary: no subnormal floats in (an integer sent
as a float), no non-finite score out.

Needs message classes, not rclpy. Each check raises a GraspSafetyError naming the field.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from operator import attrgetter
from typing import Any, ClassVar, Protocol

import numpy as np

from ...core.exceptions import GraspSafetyError, InvalidInputError

MIN_NORMAL = sys.float_info.min
"""Nonzero magnitudes below this (2.2e-308) are subnormal."""
INT_AS_FLOAT_HINT = (
    "an integer where a float is expected? set ROS_PYTHON_CHECK_FIELDS=1 in the client"
)
"""Why a float field holds a subnormal: Jazzy's rclpy, with its field checks off (the
default), serialises the int 1 of ``Point(x=1)`` as 5e-324 (and -1 as NaN)."""


class _Message(Protocol):
    """A rosidl-generated message, as far as these checks read its class (rosidl's Python
    classes carry no type information)."""

    __slots__: ClassVar[tuple[str, ...]]
    SLOT_TYPES: ClassVar[tuple[Any, ...]]

    @classmethod
    def get_fields_and_field_types(cls) -> dict[str, str]: ...


_FLOATS = ("double", "float")
_Plan = tuple[tuple[str, bool, type[_Message] | None], ...]
_PLANS: dict[type[_Message], _Plan] = {}
_FLAT: dict[type[_Message], tuple[str, ...] | None] = {}


class NonFiniteResultError(GraspSafetyError):
    """A ranking gave a NaN or infinite score to a grasp it ordered: refused, not answered."""


def _plan(message_type: type[_Message]) -> _Plan:
    """(field, is a sequence, nested message type or None for floats) of every field of
    ``message_type`` that holds floats or messages."""
    plan = _PLANS.get(message_type)
    if plan is None:
        example = message_type()
        entries: list[tuple[str, bool, type[_Message] | None]] = []
        for name, kind in message_type.get_fields_and_field_types().items():
            is_sequence = kind.startswith("sequence<") or kind.endswith("]")
            base = kind.removeprefix("sequence<").split(",")[0].split("[")[0].rstrip(">")
            if base in _FLOATS:
                entries.append((name, is_sequence, None))
            elif "/" in base:
                value = getattr(example, name)
                nested = type(value) if not is_sequence else _item_type(message_type, name)
                entries.append((name, is_sequence, nested))
        plan = _PLANS[message_type] = tuple(entries)
    return plan


def _item_type(message_type: type[_Message], name: str) -> type[_Message]:
    """The message type of the items of sequence field ``name`` (from the generated class's
    slot types)."""
    slot_types = dict(zip(message_type.__slots__, message_type.SLOT_TYPES, strict=False))
    item = slot_types[f"_{name}"].value_type
    module = sys.modules.get(".".join(item.namespaces)) or __import__(
        ".".join(item.namespaces), fromlist=[item.name]
    )
    item_type: type[_Message] = getattr(module, item.name)
    return item_type


def _flat_paths(message_type: type[_Message]) -> tuple[str, ...] | None:
    """Dotted paths of every float of a message type without sequences (Pose: 7), else None."""
    if message_type not in _FLAT:
        _FLAT[message_type] = _float_paths(message_type)
    return _FLAT[message_type]


def _float_paths(message_type: type[_Message]) -> tuple[str, ...] | None:
    paths: list[str] = []
    for name, is_sequence, nested in _plan(message_type):
        if is_sequence:
            return None
        if nested is None:
            paths.append(name)
            continue
        inner = _flat_paths(nested)
        if inner is None:
            return None
        paths.extend(f"{name}.{path}" for path in inner)
    return tuple(paths)


def _first_subnormal_index(values: np.ndarray) -> int | None:
    bad = np.flatnonzero((values != 0.0) & (np.abs(values) < MIN_NORMAL))
    return int(bad[0]) if len(bad) else None


def first_subnormal(message: Any) -> tuple[str, float] | None:
    """(field path, value) of the first subnormal float of ``message`` (recursively), or None.

    Sequences of messages without sequences (poses, points of a Path) are read in one array.
    """
    for name, is_sequence, nested in _plan(type(message)):
        value = getattr(message, name)
        if nested is None:
            if is_sequence:
                if len(value) == 0:
                    continue
                array = np.asarray(value, dtype=float).ravel()
                k = _first_subnormal_index(array)
                if k is not None:
                    return f"{name}[{k}]", float(array[k])
            elif value != 0.0 and abs(value) < MIN_NORMAL:
                return name, float(value)
        elif not is_sequence:
            found = first_subnormal(value)
            if found is not None:
                return f"{name}.{found[0]}", found[1]
        elif len(value):
            paths = _flat_paths(nested)
            if paths is None:
                for i, item in enumerate(value):
                    found = first_subnormal(item)
                    if found is not None:
                        return f"{name}[{i}].{found[0]}", found[1]
            elif paths:
                getter: Callable[[Any], Any] = attrgetter(*paths)
                table = np.array([getter(item) for item in value], dtype=float)
                table = table.reshape(len(value), len(paths))
                k = _first_subnormal_index(table.ravel())
                if k is not None:
                    i, j = divmod(k, len(paths))
                    return f"{name}[{i}].{paths[j]}", float(table[i, j])
    return None


def check_no_subnormals(message: Any, field: str = "") -> None:
    """Refuse a message holding a subnormal float anywhere (what an int sent into a float
    field becomes), naming the field (``field`` prefixes the path) and the likely cause.

    Raises:
        InvalidInputError: ``<field>.<path>: holds the subnormal number 5e-324: an integer
            where a float is expected? set ROS_PYTHON_CHECK_FIELDS=1 in the client``.
    """
    found = first_subnormal(message)
    if found is not None:
        path, value = found
        raise InvalidInputError(
            f"{field}.{path}" if field else path,
            f"holds the subnormal number {value!r}: {INT_AS_FLOAT_HINT}",
        )


_SCORES = ("score", "safety_score", "peak_effective_mass_kg", "mean_effective_mass_kg")
"""Scores every ordered grasp has (a feasible evaluation)."""


def check_finite_result(ranking: Any) -> None:
    """Refuse a grasp_safety_msgs/GraspRanking in which a grasp of an order (``order``,
    ``safety_order``, ``paper_order``, ``worst_case_order``) has a NaN or infinite score, or
    any evaluation an infinite one: no success answer ranks a grasp by a non-finite number.

    Scores of analyses that ran are checked too: ``combined_score`` and ``grasp_quality``
    when a quality was given (``safety_weight`` finite), ``effort_score`` when it orders,
    ``worst_case_score`` and ``percentile_score`` when the uncertainty analysis ran, the
    scores at both ends of the armature ranges when those ran (``armature_order_*`` ordered).

    Raises:
        NonFiniteResultError: naming the grasp and the score.
    """
    names = list(_SCORES)
    if math.isfinite(ranking.safety_weight):
        names += ["combined_score", "grasp_quality"]
    if ranking.rank_by == "effort":  # else NaN is an answer: no effort limit known
        names.append("effort_score")
    if math.isfinite(ranking.order_stability):
        names += ["worst_case_score", "percentile_score"]
    if ranking.armature_range_message:
        names += ["score_armature_lower", "score_armature_upper"]
    ordered = {
        *ranking.order,
        *ranking.safety_order,
        *ranking.paper_order,
        *ranking.worst_case_order,
        *ranking.armature_order_lower,
        *ranking.armature_order_upper,
    }
    evaluations = ranking.evaluations
    for index in sorted(ordered):
        if not 0 <= index < len(evaluations):
            raise NonFiniteResultError(
                f"result: grasp {index} is ordered but has no evaluation ({len(evaluations)})"
            )
        for name in names:
            value = getattr(evaluations[index], name)
            if not math.isfinite(value):
                raise NonFiniteResultError(
                    f"result: grasp {index} ({evaluations[index].name}) would be ranked with "
                    f"{name} = {value}; refused rather than answered (an input at the edge of "
                    "its range, or a bug: please report it with the request)"
                )
    for evaluation in evaluations:
        for name in (*_SCORES, "combined_score"):
            if math.isinf(getattr(evaluation, name)):
                raise NonFiniteResultError(
                    f"result: grasp {evaluation.index} ({evaluation.name}) has {name} = "
                    f"{getattr(evaluation, name)}; refused rather than answered"
                )
