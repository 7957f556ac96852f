"""Waymo's own SDC paths (`Scenario.sdc_paths`, WOMD 1.3.1+) -> our path fields (`path_samples/*`).

Waymo ships, per scenario, a set of routes the SDC could drive from the log's current step, each a
polyline with arc lengths, lane ids and an on-route flag. We resample them to our layout (a point
every `spacing_m`, at most `points_per_path` points, `num_paths` rows, on-route paths first) so
that a shard's paths mean the same whichever source made them. `--sdc-paths` chooses the source:
"auto" (Waymo's when the proto carries them, else our reconstruction), "waymo" (Waymo's or a
failure) or "reconstruct" (always ours, e.g. to compare the two).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.enrich.geometry import arc_lengths, point_at_arc
from scenariomax.enrich.paths import PATHS_SOURCE, Path, paths_to_arrays  # noqa: F401 (PATHS_SOURCE re-exported)

SDC_PATHS_AUTO, SDC_PATHS_WAYMO, SDC_PATHS_RECONSTRUCT = "auto", "waymo", "reconstruct"
SDC_PATHS_MODES = (SDC_PATHS_AUTO, SDC_PATHS_WAYMO, SDC_PATHS_RECONSTRUCT)
PATHS_FROM_WAYMO = "waymo"  # the value of metadata[PATHS_SOURCE] and of the manifest note


class SdcPathError(ValueError):
    """Waymo's paths in one Scenario cannot be read; the message is one line."""


@dataclasses.dataclass(frozen=True, eq=False)
class WaymoPath:
    """One of Waymo's paths, valid points only, as the proto gives them."""

    xyz: np.ndarray  # (n, 3) float64
    lane_id: np.ndarray  # (n,) int64, -1 where the proto gives none
    on_route: bool


def _column(values, n: int, name: str, index: int, default) -> np.ndarray:
    """A per-point array of a path: absent -> `default` everywhere; another length than x's is an error."""
    values = np.asarray(values)
    if values.size == 0:
        return np.full(n, default)
    if values.size != n:
        raise SdcPathError(f"sdc path {index}: {name} has {values.size} values, x has {n}")
    return values


def decode_sdc_paths(message) -> list[WaymoPath]:
    """Waymo's paths of a Scenario message, invalid points dropped; paths with < 2 valid points are skipped
    (they give no direction). Raises SdcPathError on arrays of mismatched lengths or non-finite points."""
    paths = []
    for index, path in enumerate(message.sdc_paths):
        n = len(path.x)
        xyz = np.stack([np.asarray(path.x, np.float64), _column(path.y, n, "y", index, np.nan),
                        _column(path.z, n, "z", index, 0.0)], axis=1).astype(np.float64)
        valid = _column(path.valid, n, "valid", index, True).astype(bool)
        lane_id = _column(path.ids, n, "ids", index, -1).astype(np.int64)
        _column(path.arc_length, n, "arc_length", index, 0.0)  # checked, then recomputed from the points
        if not np.isfinite(xyz[valid]).all():
            raise SdcPathError(f"sdc path {index}: non-finite or missing coordinates")
        if valid.sum() >= 2:
            paths.append(WaymoPath(xyz[valid], lane_id[valid], bool(path.on_route)))
    return paths


def resample(path: WaymoPath, spacing_m: float, points_per_path: int) -> Path:
    """A point every `spacing_m` along the path from its first point, cut to `points_per_path`; each point
    keeps the lane id of the proto segment it falls on."""
    cum = arc_lengths(path.xyz)
    keep = np.concatenate([[True], np.diff(cum) > 1e-6])  # repeated points would stall the interpolation
    xyz, lane_id, cum = path.xyz[keep], path.lane_id[keep], cum[keep]
    total = min(cum[-1], (points_per_path - 1) * spacing_m)
    targets = np.arange(0.0, total + 1e-6, spacing_m)[:points_per_path]
    points = point_at_arc(xyz, cum, targets) if len(xyz) > 1 else xyz[:1]
    segment = np.clip(np.searchsorted(cum, targets, side="right") - 1, 0, len(lane_id) - 1)
    return Path(points, lane_id[segment], targets[: len(points)], 0.0, path.on_route)


def waymo_path_arrays(paths: list[WaymoPath], num_paths: int, points_per_path: int,
                      spacing_m: float = 1.0) -> dict:
    """Fixed-size Scenario path arrays from Waymo's paths: on-route paths first, then the rest, in the
    proto's order within each group (a stable sort), cut to `num_paths`."""
    ordered = sorted(paths, key=lambda p: not p.on_route)
    return paths_to_arrays([resample(p, spacing_m, points_per_path) for p in ordered[:num_paths]],
                           num_paths, points_per_path)
