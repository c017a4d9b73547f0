"""Reading YAML input field by field, shared by the scenario files (``scenario.schema``) and
the batch SPEC (``dataset.spec``): a bounded parse, and one-line errors naming the field."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pinocchio as pin
import yaml

from ..core.exceptions import InvalidInputError
from ..core.input_checks import pose_from_position_quat

MAX_SCENARIO_BYTES = 4_000_000
"""Largest scenario file read [bytes]."""

MAX_NESTING_DEPTH = 64
"""Deepest nesting of lists and mappings in a scenario file."""

MAX_EXPANDED_NODES = 1_000_000
"""Most YAML nodes a scenario may expand to, aliases (``*name``) counted at full size."""

_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when available
_PARSER_DEPTH_LIMIT = "exceeded maximum nesting depth"
"""What libyaml's scanner says when its own nesting limit (1000 flow levels) trips."""


def _check_yaml_structure(text: str) -> None:
    """Refuse YAML nested deeper than MAX_NESTING_DEPTH or expanding to more than
    MAX_EXPANDED_NODES nodes (aliases ``*name`` counted at the full size of their anchor, so a
    "billion laughs" file is refused however short); one pass over the parser's events."""
    child_sizes: list[int] = [0]
    anchor_stack: list[str | None] = []
    anchor_sizes: dict[str, int] = {}
    for event in yaml.parse(text, Loader=_SAFE_LOADER):
        if isinstance(event, yaml.CollectionStartEvent):
            if len(anchor_stack) >= MAX_NESTING_DEPTH:
                raise InvalidInputError(
                    "scenario",
                    f"nesting deeper than {MAX_NESTING_DEPTH} levels at line "
                    f"{event.start_mark.line + 1}",
                )
            anchor_stack.append(event.anchor)
            child_sizes.append(0)
            continue
        if isinstance(event, yaml.CollectionEndEvent):
            size, anchor = 1 + child_sizes.pop(), anchor_stack.pop()
        elif isinstance(event, yaml.AliasEvent):
            size, anchor = anchor_sizes.get(event.anchor, 1), None
        elif isinstance(event, yaml.ScalarEvent):
            size, anchor = 1, event.anchor
        else:  # stream and document start and end
            continue
        if anchor is not None:
            anchor_sizes[anchor] = size
        child_sizes[-1] += size
        if child_sizes[-1] > MAX_EXPANDED_NODES:
            raise InvalidInputError(
                "scenario",
                f"expands to more than {MAX_EXPANDED_NODES} YAML nodes (aliases counted at "
                f"full size), near line {event.start_mark.line + 1}",
            )


def load_yaml(text: str, where: str) -> Any:
    """Parse YAML text, bounded by _check_yaml_structure; errors as one-line
    InvalidInputError('scenario')."""
    try:
        _check_yaml_structure(text)
        return yaml.load(text, Loader=_SAFE_LOADER)  # a safe loader
    except (yaml.YAMLError, ValueError, OverflowError) as error:
        if isinstance(error, InvalidInputError):
            raise
        if isinstance(error, yaml.MarkedYAMLError) and _PARSER_DEPTH_LIMIT in str(error.problem):
            # libyaml (PyYAML >= 6.0.4) has a nesting limit of its own, which its scanner can
            # reach before our event loop sees MAX_NESTING_DEPTH levels: one message for both.
            line = error.problem_mark.line + 1 if error.problem_mark else 1
            raise InvalidInputError(
                "scenario", f"nesting deeper than {MAX_NESTING_DEPTH} levels at line {line}"
            ) from None
        reason = " ".join(str(error).split())
        raise InvalidInputError("scenario", f"{where} is not valid YAML: {reason}") from None


def read_yaml_file(path: str | Path, field: str = "scenario") -> Any:
    """Read and parse a YAML file of at most MAX_SCENARIO_BYTES (UTF-8, bounded structure);
    errors as one-line InvalidInputError(``field``)."""
    path = Path(path)
    try:
        with path.open("rb") as stream:
            raw = stream.read(MAX_SCENARIO_BYTES + 1)
    except OSError as error:
        reason = error.strerror or str(error)
        raise InvalidInputError(field, f"cannot read '{path}': {reason}") from None
    if len(raw) > MAX_SCENARIO_BYTES:
        raise InvalidInputError(
            field, f"'{path}' is larger than {MAX_SCENARIO_BYTES} bytes, the limit"
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InvalidInputError(
            field, f"'{path}' is not UTF-8 text (byte {error.start}: {error.reason})"
        ) from None
    return load_yaml(text, f"'{path}'")


def mapping(value: Any, field: str) -> Mapping[str, Any]:
    """``value`` if it is a mapping; else InvalidInputError(``field``)."""
    if not isinstance(value, Mapping):
        raise InvalidInputError(field, f"must be a mapping, got {type(value).__name__}")
    return value


def required(section: Mapping[str, Any], key: str, prefix: str) -> Any:
    """``section[key]``; InvalidInputError(``prefix.key``) when missing."""
    if key not in section:
        raise InvalidInputError(f"{prefix}.{key}" if prefix else key, "is required")
    return section[key]


def string(value: Any, field: str) -> str:
    """``value`` if it is a non-empty string; else InvalidInputError(``field``)."""
    if not isinstance(value, str) or not value:
        raise InvalidInputError(field, f"must be a non-empty string, got {value!r}")
    return value


def check_keys(section: Mapping[str, Any], allowed: set[str], prefix: str) -> None:
    """Refuse a key of ``section`` not in ``allowed``, naming it and the allowed ones."""
    unknown = sorted(
        k if isinstance(k, str) else json.dumps(k, default=str) for k in set(section) - allowed
    )
    if unknown:
        where = f"{prefix}.{unknown[0]}" if prefix else unknown[0]
        raise InvalidInputError(where, f"unknown field; allowed: {', '.join(sorted(allowed))}")


def read_pose(section: Any, field: str, allowed: frozenset[str] = frozenset()) -> pin.SE3:
    """A ``{position_m, quat_xyzw}`` mapping (plus the ``allowed`` keys) as a pose."""
    entry = mapping(section, field)
    check_keys(entry, {"position_m", "quat_xyzw"} | allowed, field)
    return pose_from_position_quat(
        required(entry, "position_m", field), required(entry, "quat_xyzw", field), field
    )


def flag(value: Any, field: str) -> bool:
    """``value`` if it is a bool; else InvalidInputError(``field``)."""
    if not isinstance(value, bool):
        raise InvalidInputError(field, f"must be true or false, got {value!r}")
    return value
