"""Geometry on plain arrays: oriented boxes, segments and frame transforms (all jittable)."""

from vmax_sim.geometry.boxes import (
    bounding_radius,
    box_axes,
    box_corners,
    boxes_overlap,
    circle_cover,
    contact_time,
)
from vmax_sim.geometry.segments import point_segment_distance, project_on_segment, side_of_segment
from vmax_sim.geometry.transforms import rotate, to_local_points, to_local_vectors, wrap_angle

__all__ = [
    "bounding_radius",
    "box_axes",
    "box_corners",
    "boxes_overlap",
    "circle_cover",
    "contact_time",
    "point_segment_distance",
    "project_on_segment",
    "rotate",
    "side_of_segment",
    "to_local_points",
    "to_local_vectors",
    "wrap_angle",
]
