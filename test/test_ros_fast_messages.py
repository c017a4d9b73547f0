"""conversions._fast: slot and template constructors equal the keyword constructor's messages;
the collector pause nests and restores the collector's state."""

from __future__ import annotations

import array
import gc

from geometry_msgs.msg import Point, PoseArray
from grasp_safety_msgs.msg import GraspEvaluation

from grasp_safety_ros.ros.conversions._fast import (
    _CollectorPause,
    _slot_constructor,
    _template_constructor,
)


def test_slot_constructor_equals_the_keyword_constructor() -> None:
    new_point = _slot_constructor(Point, ("x", "y", "z"))
    assert new_point(1.0, -2.0, 3.5) == Point(x=1.0, y=-2.0, z=3.5)


def test_slot_constructor_of_other_fields_falls_back_to_keywords() -> None:
    new_point = _slot_constructor(Point, ("x", "y"))  # not all the slots: keyword constructor
    assert new_point(1.0, 2.0) == Point(x=1.0, y=2.0, z=0.0)


def test_template_constructor_sets_fields_and_makes_fresh_sequences() -> None:
    template = GraspEvaluation(effort_score=float("nan"), name="")
    new = _template_constructor(template)
    first = new(name="g0", effective_mass_kg=array.array("d", [1.0, 2.0]))
    second = new(name="g1")
    assert first.name == "g0" and list(first.effective_mass_kg) == [1.0, 2.0]
    assert second.name == "g1" and len(second.effective_mass_kg) == 0
    assert first.time_from_start_s is not second.time_from_start_s
    first.iso_ts_15066.append(None)  # a list made anew per message, not the template's
    assert second.iso_ts_15066 == [] and template.iso_ts_15066 == []
    assert first.effort_score != first.effort_score  # NaN taken from the template


def test_template_constructor_of_a_nested_message() -> None:
    new = _template_constructor(PoseArray())
    one, two = new(), new()
    assert one.header is not two.header and one == PoseArray()


def test_collector_pause_nests_and_keeps_a_disabled_collector_disabled() -> None:
    pause = _CollectorPause()
    assert gc.isenabled()
    with pause:
        with pause:
            assert not gc.isenabled()
        assert not gc.isenabled()
    assert gc.isenabled()
    gc.disable()
    try:
        with pause:
            assert not gc.isenabled()
        assert not gc.isenabled()
    finally:
        gc.enable()
