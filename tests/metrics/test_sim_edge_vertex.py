"""Off-road at a sharp road-edge corner: the side of a point whose nearest edge point is a vertex.

Road edges run with the road on their left. At a vertex V shared by segments A (into V) and B (out
of V) a point P whose closest point is V lies on the road iff (P - V) . (n_A + n_B) > 0 (the left
normals' sum, the pseudo-normal). Past a convex corner of the road (the edge turns left) the point
is off the road if it is outside either segment, past a reflex one (the edge turns right, the road
wraps around the corner) only if it is outside both. Taking the side of whichever segment wins the
distance tie (the old rule) judged a car passing the tip of an island off-road.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax.schema import RG_ROAD_EDGE_BOUNDARY
from vmax_sim.map_index import build_map_index, signed_edge_distance
from vmax_sim.metrics import offroad

ROTATIONS = tuple(range(0, 360, 30))
WORLD = np.array([2950.0, -3290.0])  # world-sized coordinates, as in real WOMD scenes
OFFROAD = jax.jit(offroad)
DISTANCE = jax.jit(signed_edge_distance)


def rotation(degrees: float) -> np.ndarray:
    a = np.deg2rad(degrees)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def corner_map(turn_deg: float, rotate_deg: float = 0.0, leg: float = 60.0):
    """One road edge: `leg` m along +x into V = (0, 0), then `leg` m turning by turn_deg (> 0 left,
    convex for the road; < 0 right, reflex), points 1 m apart; rotated, then moved to WORLD.
    -> (map index centred on V, local-to-world function)."""
    s = np.arange(-leg, 0.0, 1.0)
    out = np.array([np.cos(np.deg2rad(turn_deg)), np.sin(np.deg2rad(turn_deg))])
    local = np.concatenate([np.stack([s, np.zeros_like(s)], 1), np.arange(0.0, leg + 0.5, 1.0)[:, None] * out])
    rot = rotation(rotate_deg)

    def to_world(xy):
        return np.asarray(xy, np.float64) @ rot.T + WORLD

    xy = to_world(local)
    n = len(xy)
    direction = np.zeros((n, 3), np.float32)
    direction[:-1, :2] = np.diff(xy, axis=0) / np.linalg.norm(np.diff(xy, axis=0), axis=1, keepdims=True)
    direction[-1] = direction[-2]
    xyz = np.concatenate([xy, np.zeros((n, 1))], 1).astype(np.float32)
    index = build_map_index(xyz, direction, np.full(n, RG_ROAD_EDGE_BOUNDARY), np.full(n, 7), np.ones(n, bool),
                            center_xy=WORLD)
    return index, to_world


def box(to_world, rotate_deg, centre, yaw=0.0, length=4.0, width=2.0):
    x, y = to_world(np.asarray(centre, np.float64)[None])[0]
    return jnp.asarray([x, y, length, width, yaw + np.deg2rad(rotate_deg)], jnp.float32)


@pytest.mark.parametrize("rotate_deg", ROTATIONS)
def test_reflex_corner_car_passing_the_tip_is_on_the_road(rotate_deg):
    # The edge turns right by 150 deg: an island (the thin wedge left behind) with the road all around
    # its tip. The car's rear-right corner (0.3, 1.0) is 1.04 m from the tip V, ahead of segment A's
    # end and behind segment B's start; it is left of A's line (road) and right of B's (outside B):
    # on the road, since a reflex corner needs outside both. The old rule said off-road whenever B
    # won the tie.
    index, to_world = corner_map(-150.0, rotate_deg)
    is_offroad, worst = OFFROAD(index, box(to_world, rotate_deg, (2.3, 2.0)))
    assert not bool(is_offroad)
    assert float(worst) == pytest.approx(-np.hypot(0.3, 1.0), abs=2e-3)


@pytest.mark.parametrize("rotate_deg", ROTATIONS)
def test_reflex_corner_car_inside_the_island_is_off_road(rotate_deg):
    index, to_world = corner_map(-150.0, rotate_deg)
    # a corner 0.12 m inside the tip of the island (outside both segments) ...
    is_offroad, worst = OFFROAD(index, box(to_world, rotate_deg, (1.5, 0.85)))
    assert bool(is_offroad) and float(worst) > 0.1
    # ... and a car parked well inside the island, where it is 6.9 m wide
    is_offroad, worst = OFFROAD(index, box(to_world, rotate_deg, (-14.0, -3.6)))
    assert bool(is_offroad) and float(worst) > 0.5


@pytest.mark.parametrize("rotate_deg", ROTATIONS)
def test_convex_corner_points_past_the_tip_are_off_road(rotate_deg):
    # The edge turns left by 135 deg: the road is the 45 deg wedge between A and B (too narrow for a
    # car at its tip, so points). (1, 0.5) and (0.2, 0.1) past the tip are left of A's line but right
    # of B's: off the road (convex: outside either); the old rule said on the road when A won the tie.
    # (-3, 1) is inside the wedge, 1 m from A.
    index, to_world = corner_map(135.0, rotate_deg)
    points = to_world(np.array([[1.0, 0.5], [0.2, 0.1], [-3.0, 1.0]]))
    got = np.asarray(DISTANCE(index, jnp.asarray(points, jnp.float32), jnp.asarray(WORLD, jnp.float32)))
    np.testing.assert_allclose(got, [np.hypot(1.0, 0.5), np.hypot(0.2, 0.1), -1.0], atol=2e-3)


@pytest.mark.parametrize("rotate_deg", ROTATIONS)
def test_convex_corner_car_inside_the_wedge_is_on_the_road(rotate_deg):
    index, to_world = corner_map(135.0, rotate_deg)
    is_offroad, worst = OFFROAD(index, box(to_world, rotate_deg, (-8.0, 1.5)))
    assert not bool(is_offroad) and float(worst) < -0.4


@pytest.mark.parametrize("rotate_deg", ROTATIONS[::3])
def test_far_field_takes_the_vertex_side_too(rotate_deg):
    # 40 m from the tip (no edge in the query window): the host-computed cell distances use the same
    # rule. Cell centres are sampled, so query at a cell centre near the wanted direction.
    index, to_world = corner_map(-150.0, rotate_deg, leg=200.0)
    target = to_world(np.array([[0.2, 1.0]]) / np.hypot(0.2, 1.0) * 40.0)[0]
    cell = np.floor((target - np.asarray(index.origin_xy)) / index.cell_size)
    centre = np.asarray(index.origin_xy) + (cell + 0.5) * index.cell_size
    local = (centre - WORLD) @ rotation(rotate_deg)
    # past A's end, before B's start (V is the nearest edge point), left of A's line, right of B's
    assert local[0] > 0.0 and local @ [np.cos(np.deg2rad(30.0)), 0.5] > 0.0
    assert local[1] > 0.0 and local @ [0.5, -np.cos(np.deg2rad(30.0))] < 0.0
    got = float(DISTANCE(index, jnp.asarray(centre[None], jnp.float32), jnp.asarray(centre, jnp.float32))[0])
    assert got == pytest.approx(-np.linalg.norm(local), abs=1e-2)  # on the road, |P - V| away


def pseudo_normal_reference(start, end, points):
    """Independent float64 reference: nearest segment; at a vertex, the sum of the left normals of
    every segment meeting there decides the side. (S, 2), (S, 2), (P, 2) -> (P,) signed distance."""
    d = end - start
    length_sq = np.sum(d * d, 1)
    normal = np.stack([-d[:, 1], d[:, 0]], 1) / np.sqrt(length_sq)[:, None]
    out = np.zeros(len(points))
    for i, p in enumerate(points):
        t = np.clip(np.sum((p - start) * d, 1) / length_sq, 0.0, 1.0)
        dist = np.linalg.norm(p - start - t[:, None] * d, axis=1)
        k = int(np.argmin(dist))
        if 1e-9 < t[k] < 1.0 - 1e-9:
            side = (p - start[k]) @ normal[k]
        else:
            v = start[k] if t[k] <= 1e-9 else end[k]
            meeting = (np.abs(start - v).max(1) < 1e-6) | (np.abs(end - v).max(1) < 1e-6)
            side = (p - v) @ normal[meeting].sum(0)
        out[i] = dist[k] if side < 0 else -dist[k]
    return out


def test_zigzag_edge_matches_the_pseudo_normal_reference():
    # a zigzag of 6 m legs turning by 120 deg, left (convex, at the bottom) and right (reflex, at the
    # top) in turn, points sampled around its vertices; every sign must match the reference wherever
    # the window surely holds the nearest edge
    teeth = 16
    top = np.arange(teeth + 1) % 2 == 1
    corners = np.stack([np.arange(teeth + 1) * 3.0 - 24.0, np.where(top, 3.0 * np.sqrt(3.0), 0.0)], 1)
    rng = np.random.default_rng(0)
    for rotate_deg in (0.0, 17.0, 245.0):
        rot = rotation(rotate_deg)
        pts = []
        for a, b in zip(corners[:-1], corners[1:]):
            pts += [a + (b - a) * f for f in np.arange(0.0, 1.0, 1.0 / 6.0)]
        xy = np.concatenate([np.asarray(pts), corners[-1:]]) @ rot.T + WORLD
        n = len(xy)
        index = build_map_index(np.concatenate([xy, np.zeros((n, 1))], 1).astype(np.float32), np.zeros((n, 3)),
                                np.full(n, RG_ROAD_EDGE_BOUNDARY), np.full(n, 3), np.ones(n, bool), center_xy=WORLD)
        vertices = corners[1:-1] @ rot.T + WORLD
        queries = vertices[rng.integers(0, len(vertices), 300)] + rng.normal(0.0, 1.5, (300, 2))
        centres = queries + rng.uniform(-1.0, 1.0, (300, 2))
        got = np.asarray(jax.jit(jax.vmap(signed_edge_distance, in_axes=(None, 0, 0)))(
            index, jnp.asarray(queries[:, None], jnp.float32), jnp.asarray(centres, jnp.float32)))[:, 0]
        edge = np.asarray(index.seg_valid)
        assert int(index.num_dropped) == 0 and edge.sum() == teeth
        expected = pseudo_normal_reference(np.asarray(index.seg_start, np.float64)[edge],
                                           np.asarray(index.seg_end, np.float64)[edge],
                                           queries.astype(np.float32).astype(np.float64))
        checked = (np.abs(expected) + np.abs(queries - centres).max(1) < 8.0) & (np.abs(expected) > 1e-3)
        assert checked.sum() > 250
        np.testing.assert_allclose(got[checked], expected[checked], atol=2e-3)


def test_vertex_aware_side_by_hand():
    from vmax_sim.map_index import vertex_aware_side

    inf = np.inf
    # one nearest segment: its own side
    assert vertex_aware_side(np.array([1.0, 4.0]), np.array(1.0), np.array([-1.0, 4.0])) == -1.0
    # a vertex tie: the segment whose line is farther from the point decides (here off the road)
    assert vertex_aware_side(np.array([4.0, 4.0, inf]), np.array(4.0), np.array([0.5, -3.0, 9.0])) == -3.0
    assert vertex_aware_side(np.array([4.0, 4.0 + 1e-6]), np.array(4.0), np.array([3.9, -2.0])) == 3.9
    # a segment a millimetre farther is not a tie
    assert vertex_aware_side(np.array([4.0, 4.004]), np.array(4.0), np.array([0.5, -3.9])) == 0.5
    # jax and numpy agree, batched
    d, b, s = np.array([[4.0, 4.0], [1.0, 2.0]]), np.array([4.0, 1.0]), np.array([[1.0, -2.0], [0.5, 2.0]])
    np.testing.assert_allclose(jax.jit(vertex_aware_side)(jnp.asarray(d), jnp.asarray(b), jnp.asarray(s)),
                               vertex_aware_side(d, b, s))
