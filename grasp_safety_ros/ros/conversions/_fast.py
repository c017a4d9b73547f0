"""Fast message building: slot and template constructors, a paused garbage collector."""

from __future__ import annotations

import array
import copy
import gc
import threading
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np


class _CollectorPause:
    """Context manager: the cyclic garbage collector paused while a result message is built.

    A response holds a Python object per trajectory point and per region; none of them forms a
    reference cycle, but their allocation triggers the collector over and over (it walks every
    tracked object of the process): 40 % of the building time of a 1,000 x 201 response (when
    ``direction`` was a Vector3 per sample). Reference counting still frees everything; the
    collector resumes (if it was running) when the last of concurrent builds ends.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._depth = 0
        self._resume = False

    def __enter__(self) -> None:
        with self._lock:
            if self._depth == 0:
                self._resume = gc.isenabled()
                gc.disable()
            self._depth += 1

    def __exit__(self, *exc_info: object) -> None:
        with self._lock:
            self._depth -= 1
            if self._depth == 0 and self._resume:
                gc.enable()


collector_paused = _CollectorPause()
"""Pauses the garbage collector for ranking_msg and report_msg (re-entrant, thread-safe)."""


def float64_array(values: Sequence[float] | np.ndarray) -> array.array[float]:
    """``array('d')`` of ``values``: what a float64[] field holds; built from the bytes, so
    the message setter stores it as is instead of converting element by element."""
    return array.array("d", np.ascontiguousarray(values, dtype=np.float64).tobytes())


def has_slots(message_type: Any, fields: Sequence[str]) -> bool:
    """Whether a generated message class keeps exactly ``fields`` (and ``_check_fields``) in
    its slots: the classes the slot-filling constructors here were written for (Jazzy's)."""
    return set(message_type.__slots__) == {*(f"_{name}" for name in fields), "_check_fields"}


def _slot_constructor(message_type: Any, fields: tuple[str, ...]) -> Callable[..., Any]:
    """A constructor of ``message_type`` from all its ``fields``, given positionally.

    It fills the generated class's slots directly, where the keyword constructor runs a
    property setter per field (several times the cost; it counts for messages made per
    sample or per region of every grasp). The values must already have the field types
    (float, bool, str, int, ``array('d')`` for float64[], messages). A class whose slots are
    not exactly these fields gets its keyword constructor.
    """
    slots = tuple(f"_{name}" for name in fields)
    if not has_slots(message_type, fields):
        return lambda *values: message_type(**dict(zip(fields, values, strict=True)))
    check_fields = message_type()._check_fields

    def construct(*values: Any) -> Any:
        message = message_type.__new__(message_type)
        for slot, value in zip(slots, values, strict=True):
            setattr(message, slot, value)
        message._check_fields = check_fields
        return message

    return construct


def _template_constructor(template: Any) -> Callable[..., Any]:
    """A constructor of messages equal to ``template`` but for the fields given by keyword.

    Like _slot_constructor it fills the generated class's slots directly: numbers and strings
    of ``template`` are shared, every sequence and nested message is made anew (empty or the
    nested type's defaults, by its own template constructor; the template's must be so), the
    keyword fields are stored as given (they must already have
    the field types, as for _slot_constructor). A class that is not the kind this was written
    for (slots other than its fields and ``_check_fields``) gets a copy of ``template`` with
    the fields set through its setters.
    """
    message_type: Any = type(template)  # a generated message class (rosidl: untyped)
    fields = message_type.get_fields_and_field_types()
    if not has_slots(message_type, tuple(fields)):

        def set_fields(**values: Any) -> Any:
            message = copy.deepcopy(template)
            for name, value in values.items():
                setattr(message, name, value)
            return message

        return set_fields
    shared, arrays, lists, messages = [], [], [], []
    for name in fields:
        value = getattr(template, name)
        if isinstance(value, array.array):
            arrays.append((f"_{name}", value.typecode))
        elif isinstance(value, list):
            lists.append(f"_{name}")
        elif isinstance(value, bool | int | float | str):
            shared.append((f"_{name}", value))
        else:  # a nested message: made by its own template constructor (its defaults)
            messages.append((f"_{name}", _template_constructor(type(value)())))
    check_fields, new = template._check_fields, message_type.__new__
    slot_of = {name: f"_{name}" for name in fields}

    def construct(**values: Any) -> Any:
        message = new(message_type)
        for slot, value in shared:
            setattr(message, slot, value)
        for slot, typecode in arrays:
            setattr(message, slot, array.array(typecode))
        for slot in lists:
            setattr(message, slot, [])
        for slot, make in messages:
            setattr(message, slot, make())
        for name, value in values.items():
            setattr(message, slot_of[name], value)
        message._check_fields = check_fields
        return message

    return construct
