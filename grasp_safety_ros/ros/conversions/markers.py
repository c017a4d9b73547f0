"""RViz markers of a ranking: grasp arrows coloured by rank, with labels."""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from ...core.method.ranking import Grasp, Ranking
from ...core.model.trajectory import ObjectTrajectory
from ...core.model.waypoint_trajectory import WaypointTrajectory

SCORE_UNITS = {"mean": "kg", "max": "kg", "integral": "kg*s"}
ARROW_LENGTH_M = 0.08
"""Length of the grasp arrows in RViz; they end at the grasp point along the tip z axis."""
INFEASIBLE_RGBA = (0.5, 0.5, 0.5, 0.6)
"""Grasps outside the final order (infeasible, or without an effort score) are grey."""
LABEL_OFFSET_M = np.array([0.0, 0.0, 0.03])
"""Labels float this far above the grasp point (base axes)."""


def rank_color(rank: int, count: int) -> tuple[float, float, float, float]:
    """RGBA from green (rank 0, safest) to red (rank count-1, least safe)."""
    fraction = rank / (count - 1) if count > 1 else 0.0
    return (fraction, 1.0 - fraction, 0.0, 1.0)


def markers_msg(
    ranking: Ranking,
    grasps: Sequence[Grasp],
    trajectory: ObjectTrajectory | WaypointTrajectory,
    base_frame: str,
    stamp: Time,
    *,
    order: Sequence[int] | None = None,
    scores: Sequence[float] | np.ndarray | None = None,
    not_admissible: Collection[int] = (),
) -> MarkerArray:
    """RViz markers of a ranking: per grasp an arrow and a label, in the base frame.

    The first marker deletes the previous ranking's markers. Each grasp is drawn with the
    object at its start pose: an ARROW of ARROW_LENGTH_M along the tip z axis ending at the
    tip (namespace ``grasps``) and a TEXT_VIEW_FACING label with rank and score (namespace
    ``labels``); ids are the candidate indices. Grasps in ``order`` (default: the ranking's)
    go from green (first) to red (last), the others are grey. The label shows ``scores``
    (default: each evaluation's score) and, for the indices in ``not_admissible``, that
    ISO/TS 15066 does not admit the motion.
    """
    header = Header(stamp=stamp, frame_id=base_frame)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    order = ranking.order if order is None else order
    rank_of = {index: rank for rank, index in enumerate(order)}
    unit = SCORE_UNITS.get(ranking.metric, "")
    start = trajectory.transform_object_to_base_start
    for evaluation, grasp in zip(ranking.evaluations, grasps, strict=True):
        tip_in_base = start * grasp.transform_tip_to_object
        tip = tip_in_base.translation
        tail = tip - ARROW_LENGTH_M * tip_in_base.rotation[:, 2]
        index = evaluation.index
        score = evaluation.score if scores is None else scores[index]
        if index in rank_of:
            rgba = rank_color(rank_of[index], len(order))
            text = f"#{rank_of[index] + 1} {evaluation.name}: {score:.3f} {unit}"
        elif evaluation.feasible:
            rgba = INFEASIBLE_RGBA
            text = f"{evaluation.name}: {score:.3f} {unit}, not ranked"
        else:
            rgba = INFEASIBLE_RGBA
            text = f"{evaluation.name}: infeasible"
        if index in not_admissible:
            text += ", ISO/TS 15066: not admissible"
        color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
        identity = Pose(orientation=Quaternion(w=1.0))
        markers.append(
            Marker(
                header=header,
                ns="grasps",
                id=index,
                type=Marker.ARROW,
                action=Marker.ADD,
                pose=identity,
                points=[_point(tail), _point(tip)],
                scale=Vector3(x=0.008, y=0.016, z=0.02),
                color=color,
            )
        )
        label_pose = Pose(position=_point(tip + LABEL_OFFSET_M), orientation=Quaternion(w=1.0))
        markers.append(
            Marker(
                header=header,
                ns="labels",
                id=index,
                type=Marker.TEXT_VIEW_FACING,
                action=Marker.ADD,
                pose=label_pose,
                scale=Vector3(z=0.02),
                color=color,
                text=text,
            )
        )
    return MarkerArray(markers=markers)


def _point(vector: np.ndarray) -> Point:
    x, y, z = (float(v) for v in vector)
    return Point(x=x, y=y, z=z)
