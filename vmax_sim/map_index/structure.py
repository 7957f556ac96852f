"""The map index's fixed-shape structure and its sizes, shared by the host-side build and the device-side queries."""

from __future__ import annotations

import dataclasses

import flax.struct
import jax.numpy as jnp
import numpy as np

from scenariomax.schema import LANE_TYPES, ROAD_EDGE_TYPES, ROAD_LINE_TYPES

FAR_DISTANCE = 1e4  # metres, stands for "no feature in reach"

# Observation points are stored as int16 columns (see MapIndex.obs_points); these are their units.
OBS_XY_STEPS = 65534  # steps per observation cell side: x, y are offsets from the cell centre
OBS_DIR_STEPS = 32767  # steps per unit: roadgraph directions are unit vectors
OBS_SPEED_STEP = 0.01  # m/s per step of the speed limit
MAX_TYPE = 127  # roadgraph types are stored as int8 (the schema's types are 0..20)


@dataclasses.dataclass(frozen=True)
class MapIndexConfig:
    """Sizes of the map index. Region covered = cell_size * grid_size metres per side."""

    cell_size: float = 8.0  # metres per segment-grid cell; also the longest merged segment
    grid_size: int = 64  # cells per side (64 x 8 m = 512 m)
    slots_per_cell: int = 16  # lane segments per cell; overflow keeps those nearest the cell centre
    edge_slots_per_cell: int = 8  # road-edge segments per cell (edges are sparser than lanes)
    max_segments: int = 4096  # S: segments kept, nearest the grid centre first
    query_window: int = 3  # cells per side looked at around a query point (odd: 3 -> 3x3)
    simplify_tolerance: float = 0.1  # metres a merged segment may stray from the points it skips
    edge_types: tuple[int, ...] = ROAD_EDGE_TYPES  # offroad queries
    lane_types: tuple[int, ...] = LANE_TYPES  # lane / route queries
    obs_types: tuple[int, ...] = ROAD_EDGE_TYPES + LANE_TYPES + ROAD_LINE_TYPES  # observation points
    obs_cell_size: float = 16.0  # metres per observation-grid cell
    obs_grid_size: int = 32  # cells per side (32 x 16 m = 512 m)
    obs_slots_per_cell: int = 8  # thinned points per observation cell
    obs_spacing: float = 2.0  # metres between observation points along a polyline
    max_link_gap: float = 5.0  # consecutive points further apart are not joined into a segment

    def __post_init__(self):
        if self.query_window % 2 != 1:
            raise ValueError(f"MapIndexConfig.query_window must be odd, got {self.query_window}")
        types = tuple(self.edge_types) + tuple(self.lane_types) + tuple(self.obs_types)
        if any(not 0 <= int(t) <= MAX_TYPE for t in types):
            raise ValueError(f"MapIndexConfig roadgraph types must be in 0..{MAX_TYPE}, got {sorted(set(types))}")


def index_dtype(largest: int):
    """The smallest signed integer dtype that holds -1..largest (int16 for the default sizes)."""
    return np.int16 if largest <= np.iinfo(np.int16).max else np.int32


@flax.struct.dataclass
class MapIndex:
    """Fixed-shape map acceleration structure of one scenario (batch it with leading dims).

    Layout (issue 12, ~0.45 MB per scene at the default sizes, was ~3 MB): each segment's endpoints,
    id and speed limit are stored once, in the seg_* table; a grid cell lists the int16 indices of its
    segments, so a query slices one contiguous window of cells and gathers those segments' rows.
    Observation points are quantised to int16 (positions within 0.2 mm).
    """

    seg_points: jnp.ndarray  # (S, 4) float32, [start x, start y, end x, end y] per segment
    seg_type: jnp.ndarray  # (S,) int8, roadgraph type, -1 pads
    seg_id: jnp.ndarray  # (S,) int32, polyline (lane) id, -1 pads
    seg_speed_limit: jnp.ndarray  # (S,) float32, m/s, -1 unknown
    origin_xy: jnp.ndarray  # (2,) float32, lower-left corner of both grids
    edge_cells: jnp.ndarray  # (G, G, Ce) int16 (int32 when S > 32767), road-edge segment indices, -1 pads
    lane_cells: jnp.ndarray  # (G, G, C) int16 (int32 when S > 32767), lane-centre segment indices, -1 pads
    cell_edge_distance: jnp.ndarray  # (G, G) float32, signed distance of cell centres to the nearest
    # edge, only for cells whose query window holds no edge (0 elsewhere: never read)
    # Observation points (Go, Go, Co, 8) int16, the features of `observation_points` quantised: [x, y
    # offsets from the cell centre (obs_cell_size / OBS_XY_STEPS m), dir x, dir y (1 / OBS_DIR_STEPS),
    # speed limit (OBS_SPEED_STEP m/s, 0 unknown), is edge, is lane, is line]; 0 in empty slots. One
    # block slice and one multiply-add per step decode it (the three 0/1 columns cost 48 kB, and save
    # the bit twiddling that made the decode ~2x slower).
    obs_points: jnp.ndarray
    obs_type: jnp.ndarray  # (Go, Go, Co) int8, roadgraph type, -1 in empty slots
    num_dropped: jnp.ndarray  # () int32, segments lost to the S cap or full cells (diagnostics)
    cell_size: float = flax.struct.field(pytree_node=False, default=8.0)  # static, metres
    obs_cell_size: float = flax.struct.field(pytree_node=False, default=16.0)  # static, metres
    query_window: int = flax.struct.field(pytree_node=False, default=3)  # static, cells per side

    @property
    def seg_start(self) -> jnp.ndarray:
        """(S, 2) float32 segment start points."""
        return self.seg_points[..., :2]

    @property
    def seg_end(self) -> jnp.ndarray:
        """(S, 2) float32 segment end points."""
        return self.seg_points[..., 2:]

    @property
    def seg_valid(self) -> jnp.ndarray:
        """(S,) bool, False for padding."""
        return self.seg_type >= 0

    @property
    def obs_valid(self) -> jnp.ndarray:
        """(Go, Go, Co) bool, the filled observation slots."""
        return self.obs_type >= 0
