"""The vectorised helpers give the same bits as the one-polyline numpy code they replace (issue 24 item 6:
conversion speed without changing a single output value)."""

from __future__ import annotations

import numpy as np
import pytest

from scenariomax.enrich.geometry import (
    arc_lengths,
    polyline_segments,
    project_to_polyline,
    run_cumsum,
    run_interp,
)
from scenariomax.enrich.roadgraph import (
    MapPolyline,
    direction_vectors,
    polylines_to_roadgraph,
    resample_polyline,
)


def _reference_projection(points, polyline):
    """The former (m, n-1, 2) formulation."""
    pts, line = np.asarray(points, np.float64)[:, :2], np.asarray(polyline, np.float64)[:, :2]
    a, b = line[:-1], line[1:]
    seg = b - a
    seg_len2 = np.maximum((seg ** 2).sum(-1), 1e-12)
    frac = np.clip(((pts[:, None, :] - a[None]) * seg[None]).sum(-1) / seg_len2[None], 0.0, 1.0)
    feet = a[None] + frac[..., None] * seg[None]
    dist2 = ((pts[:, None, :] - feet) ** 2).sum(-1)
    best = dist2.argmin(axis=1)
    rows = np.arange(len(pts))
    arc = arc_lengths(line)[best] + frac[rows, best] * np.sqrt(seg_len2[best])
    return np.sqrt(dist2[rows, best]), arc, feet[rows, best]


@pytest.mark.parametrize("seed", range(5))
def test_projection_matches_the_reference_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    for _ in range(40):
        n, m = int(rng.integers(2, 60)), int(rng.integers(1, 30))
        line = np.cumsum(rng.normal(size=(n, 3)), 0) * 10 ** rng.uniform(-1, 3) + rng.uniform(-1e4, 1e4, 3)
        line[int(rng.integers(0, n))] = line[0]  # a repeated point: a zero-length segment
        points = line[rng.integers(0, n, m), :2] + rng.normal(size=(m, 2)) * 5
        for got, want in zip(project_to_polyline(points, line), _reference_projection(points, line)):
            np.testing.assert_array_equal(got, want)
        dist, arc, foot = project_to_polyline(points, line, polyline_segments(line), with_foot=False)
        want_dist, want_arc, _ = _reference_projection(points, line)
        np.testing.assert_array_equal(dist, want_dist)
        np.testing.assert_array_equal(arc, want_arc)
        assert foot is None


@pytest.mark.parametrize("repeat", [1, 4, 9])  # 8 runs: one np.cumsum per run; 32, 72 runs: the tables
def test_run_cumsum_is_numpy_cumsum_per_run(repeat):
    rng = np.random.default_rng(0)
    counts = np.tile([3, 0, 1, 17, 200, 5, 64, 65], repeat)
    if repeat == 9:  # the size classes in no order, some empty
        counts = rng.permutation(counts)
    runs = [rng.uniform(0, 1, c) * 10 ** rng.uniform(-3, 3) for c in counts]
    np.testing.assert_array_equal(run_cumsum(np.concatenate(runs), counts),
                                  np.concatenate([np.cumsum(r) for r in runs]))


def test_run_interp_is_numpy_interp_per_run():
    rng = np.random.default_rng(1)
    xps = [np.concatenate([[0.0], np.cumsum(rng.uniform(1e-3, 3, c))]) + rng.uniform(-5, 5) for c in (0, 4, 30)]
    fps = [rng.normal(size=(len(xp), 3)) * 100 for xp in xps]
    xs = [np.concatenate([rng.uniform(xp[0] - 1, xp[-1] + 1, 25), xp, np.linspace(xp[0], xp[-1], 9)]) for xp in xps]
    got = run_interp(np.concatenate(xs), np.repeat(np.arange(3), [len(x) for x in xs]), np.concatenate(xps),
                     np.concatenate(fps), np.array([len(xp) for xp in xps]))
    want = np.concatenate([np.stack([np.interp(x, xp, fp[:, k]) for k in range(3)], 1)
                           for x, xp, fp in zip(xs, xps, fps)])
    np.testing.assert_array_equal(got, want)


def test_run_interp_is_numpy_interp_with_flat_stretches_and_infinities():
    # Repeated xp, infinite and NaN fp: the cases where numpy's formula retries from the right end.
    xps = [np.array([0.0, 1.0, 1.0, 2.0, 3.0, 3.0]), np.array([-1.0, 0.5, 2.0, 4.0]), np.array([5.0])]
    fps = [np.array([0.0, np.inf, np.inf, 1.0, -np.inf, 2.0]), np.array([np.nan, 1.0, np.inf, np.inf]),
           np.array([7.0])]
    xs = [np.array([-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0]),
          np.array([-2.0, -1.0, 0.0, 0.5, 1.0, 3.0, 4.0, 9.0]), np.array([4.0, 5.0, 6.0])]
    got = run_interp(np.concatenate(xs), np.repeat(np.arange(3), [len(x) for x in xs]), np.concatenate(xps),
                     np.concatenate(fps), np.array([len(xp) for xp in xps]))
    want = np.concatenate([np.interp(x, xp, fp) for x, xp, fp in zip(xs, xps, fps)])
    np.testing.assert_array_equal(got, want)


def _one_by_one(polylines, spacing=1.0, origin=None):
    """The former per-polyline loop."""
    xyz, dirs = [], []
    for line in polylines:
        points = resample_polyline(line.xyz, spacing, line.closed, origin)
        if len(points):
            xyz.append(points)
            dirs.append(direction_vectors(points))
    return np.concatenate(xyz), np.concatenate(dirs)


@pytest.mark.parametrize("seed", range(4))
def test_roadgraph_matches_the_per_polyline_resampling(seed):
    rng = np.random.default_rng(seed)
    lines = []
    for k in range(30):
        n = int(rng.integers(0, 25))
        xyz = np.cumsum(rng.normal(size=(n, 3)) * 10 ** rng.uniform(-7, 1.5), 0) + rng.uniform(-5e3, 5e3, 3)
        if n > 2 and k % 5 == 0:
            xyz[:] = xyz[0]  # every point repeated: one point remains
        lines.append(MapPolyline(k, 1 + k % 19, xyz, closed=k % 3 == 0))
    origin = rng.normal(size=3) * 100
    for spacing, at in ((1.0, None), (0.5, origin)):
        road = polylines_to_roadgraph(lines, spacing, at)
        xyz, dirs = _one_by_one(lines, spacing, at)
        np.testing.assert_array_equal(road["roadgraph_xyz"], xyz)
        np.testing.assert_array_equal(road["roadgraph_dir"], dirs)
        assert road["roadgraph_xyz"].dtype == np.float32 and len(road["roadgraph_id"]) == len(xyz)


def test_lane_arcs_and_tangents_match_the_per_lane_helpers():
    from scenariomax.enrich.geometry import tangents
    from scenariomax.enrich.lanes import Lanes

    rng = np.random.default_rng(2)
    counts = np.array([1, 2, 17, 5, 64, 3])
    points = np.concatenate([np.cumsum(rng.normal(size=(c, 3)), 0) * 30 + rng.uniform(-1e4, 1e4, 3) for c in counts])
    lanes = Lanes(np.arange(6), np.zeros(6, np.int64), np.concatenate([[0], np.cumsum(counts)]), points)
    for k in range(6):
        line = lanes.polyline(k)
        steps = np.linalg.norm(np.diff(line[:, :2], axis=0), axis=1)
        np.testing.assert_array_equal(lanes.cumulative[k], np.concatenate([[0.0], np.cumsum(steps)]))
        np.testing.assert_array_equal(arc_lengths(line), lanes.cumulative[k])
    np.testing.assert_array_equal(lanes.point_tangent, np.vstack([tangents(lanes.polyline(k)) for k in range(6)]))


def test_nanmedian_of_the_sanity_checks_matches_numpy():
    import warnings

    from scenariomax.sources.sanity import nanmedian_last

    rng = np.random.default_rng(3)
    values = np.round(rng.normal(size=(30, 40, 7)) * 3, 1)  # ties included
    values[rng.random(values.shape) < 0.4] = np.nan
    values[0, 0] = np.nan  # a window with nothing present
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        want = np.nanmedian(values, axis=-1)
    np.testing.assert_array_equal(nanmedian_last(values), want)


def test_densify_all_matches_densify_per_polyline():
    from scenariomax.enrich.orientation import _densify, densify_all

    rng = np.random.default_rng(4)
    lines = [np.cumsum(rng.normal(size=(n, 2)), 0) * scale for n, scale in ((0, 1), (1, 1), (2, 0.1), (9, 3), (30, 1))]
    lines[3][4] = lines[3][3]  # a repeated vertex
    for spacing in (1.0, 0.7):
        np.testing.assert_array_equal(densify_all(lines, spacing), np.vstack([_densify(xy, spacing) for xy in lines]))


def test_box_pairs_are_the_pairs_of_a_shapely_strtree():
    import shapely

    from scenariomax.enrich.orientation import box_pairs

    rng = np.random.default_rng(5)
    for scale in (3.0, 40.0, 2000.0):  # short segments, long ones, a few kilometre-long ones (coarser grid)
        a0, b0 = rng.uniform(-500, 500, (300, 2)), rng.uniform(-500, 500, (400, 2))
        a1, b1 = a0 + rng.normal(size=(300, 2)) * scale, b0 + rng.normal(size=(400, 2)) * scale
        a1[:20] = a0[:20]  # points
        b0[:10, 0], b1[:10, 0] = a1[:10, 0], a1[:10, 0] + 5.0  # boxes that only touch
        tree = shapely.STRtree(shapely.linestrings(np.stack([b0, b1], axis=1)))
        want = tree.query(shapely.linestrings(np.stack([a0, a1], axis=1)))
        got = box_pairs(np.minimum(a0, a1), np.maximum(a0, a1), np.minimum(b0, b1), np.maximum(b0, b1))
        assert set(zip(*got)) == set(zip(*want))


@pytest.mark.parametrize("seed", range(3))
def test_pruned_projection_matches_the_reference_on_long_paths(seed):
    rng = np.random.default_rng(seed)
    forward = np.cumsum(rng.normal(size=(150, 3)) * [1.0, 1.0, 0.1] + [1.0, 0.0, 0.0], 0) + rng.uniform(-1e4, 1e4, 3)
    loop = np.vstack([forward, forward[::-1][1:]])  # runs back over itself: every foot has a tie
    track = forward[::2, :2] + rng.normal(size=(75, 2)) * 2.0
    for line in (forward, loop):
        for got, want in zip(project_to_polyline(track, line), _reference_projection(track, line)):
            np.testing.assert_array_equal(got, want)


def test_lane_samples_match_the_per_lane_search():
    from scenariomax.enrich.lane_graph import _lane_samples
    from scenariomax.enrich.lanes import Lanes

    rng = np.random.default_rng(6)
    counts = np.array([2, 5, 40, 3, 17])
    points = np.concatenate([np.cumsum(rng.normal(size=(c, 3)) * 2.0, 0) for c in counts])
    lanes = Lanes(np.arange(5), np.zeros(5, np.int64), np.concatenate([[0], np.cumsum(counts)]), points)
    for spacing in (2.0, 0.7):
        want = []
        for k in range(5):
            cum = lanes.cumulative[k]
            marks = np.searchsorted(cum, np.arange(0.0, cum[-1] + 1e-9, spacing))
            want.append(lanes.offsets[k] + np.unique(np.minimum(marks, len(cum) - 1)))
        samples, per_lane = _lane_samples(lanes, spacing)
        np.testing.assert_array_equal(samples, np.concatenate(want))
        np.testing.assert_array_equal(per_lane, [len(w) for w in want])


def test_projection_onto_many_polylines_matches_one_by_one():
    from scenariomax.enrich.geometry import project_to_polylines

    rng = np.random.default_rng(7)
    base = np.cumsum(rng.normal(size=(300, 3)) + [1.0, 0.0, 0.0], 0) + rng.uniform(-1e4, 1e4, 3)
    lines = [base[:1], base[:2], base[10:250], base[40:120], np.vstack([base[:60], base[:60][::-1][1:]])]
    lines[2][5] = lines[2][4]  # a zero-length segment
    track = base[::4, :2] + rng.normal(size=(75, 2)) * 2.0
    for (dist, arc), line in zip(project_to_polylines(track, lines), lines):
        want_dist, want_arc, _ = project_to_polyline(track, line)
        np.testing.assert_array_equal(dist, want_dist)
        np.testing.assert_array_equal(arc, want_arc)
    assert project_to_polylines(track, []) == []


def test_sanity_prefilters_change_nothing():
    """z_outliers and fix_yaw_flips skip the tracks that cannot need a repair: the result is the one of
    repairing every track."""
    from scenariomax.sources import sanity

    rng = np.random.default_rng(8)
    z = rng.normal(size=(40, 91)) * 0.2 + rng.uniform(-50, 50, (40, 1))
    z[3, 40] += 30.0  # a spike
    z[5, 10] = np.inf  # a present non-finite z
    z[6, :] = np.nan
    present = rng.random(z.shape) < 0.9
    present[3, 40] = present[5, 10] = True
    reference = sanity.local_median(z, present)  # every track
    with np.errstate(invalid="ignore"):
        replaced = present & np.isfinite(reference) & (np.abs(z - reference) > sanity.Z_OUTLIER_M)
    got, got_replaced = sanity.z_outliers(z, present)
    np.testing.assert_array_equal(got_replaced, replaced)
    np.testing.assert_array_equal(got, np.where(replaced, reference, z))
    assert replaced[3, 40] and replaced[5, 10]

    yaw = np.cumsum(rng.normal(size=(30, 91)) * 0.02, axis=1)
    yaw[2, 30:32] += np.pi  # a two-step flip
    yaw[4, 50] += np.pi
    usable = rng.random(yaw.shape) < 0.95
    types = np.full(30, sanity.FLIP_CHECKED_TYPES[0])
    want = np.stack([sanity.flipped_steps(yaw[row], usable[row]) for row in range(30)])
    fixed, count = sanity.fix_yaw_flips(yaw, usable, types)
    np.testing.assert_array_equal(fixed, np.where(want, sanity.wrap_angle(yaw + np.pi), yaw))
    assert count == want.sum() > 0


def test_distance_to_points_matches_the_three_axis_formula():
    from scenariomax.crop import distance_to_points

    rng = np.random.default_rng(9)
    points, anchors = rng.normal(size=(5000, 2)) * 300 + 1e4, rng.normal(size=(91, 2)) * 100 + 1e4
    want = np.sqrt(((points[:, None, :] - anchors[None, :, :]) ** 2).sum(-1).min(axis=1))
    np.testing.assert_array_equal(distance_to_points(points, anchors, chunk=1000), want)
    np.testing.assert_array_equal(distance_to_points(points, anchors[:0]), np.zeros(5000))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_row_norm_is_numpy_norm(dtype):
    from scenariomax.enrich.geometry import row_norm

    rng = np.random.default_rng(10)
    for width in (2, 3):
        vectors = (rng.normal(size=(20, 500, width)) * 10 ** rng.uniform(-3, 3, (20, 500, 1))).astype(dtype)
        np.testing.assert_array_equal(row_norm(vectors), np.linalg.norm(vectors, axis=-1))


def test_point_at_arc_and_slice_match_the_stacked_formulation():
    """point_at_arc writes np.interp's columns into one array and slice_polyline interpolates both ends in one
    call: the same bits as np.stack of the per-column interps and the vstack of two one-point calls."""
    from scenariomax.enrich.geometry import point_at_arc, slice_polyline

    rng = np.random.default_rng(8)
    for _ in range(50):
        line = np.cumsum(rng.normal(size=(int(rng.integers(2, 40)), 3)), 0) + rng.uniform(-1e4, 1e4, 3)
        line[int(rng.integers(0, len(line)))] = line[0]  # a repeated point
        cum = arc_lengths(line)
        arcs = rng.uniform(-2.0, cum[-1] + 2.0, int(rng.integers(1, 20)))
        want = np.stack([np.interp(arcs, cum, line[:, k]) for k in range(3)], axis=1)
        np.testing.assert_array_equal(point_at_arc(line, cum, arcs), want)
        start, stop = sorted(rng.uniform(0.0, cum[-1], 2))
        if stop <= start:  # a polyline of one repeated point: the one-point branch, unchanged
            continue
        inner = (cum > start) & (cum < stop)
        ends = [np.stack([np.interp([a], cum, line[:, k]) for k in range(3)], axis=1) for a in (start, stop)]
        want = np.vstack([ends[0], line[inner], ends[1]])
        np.testing.assert_array_equal(slice_polyline(line, cum, start, stop), want)


@pytest.mark.parametrize("num_points", [1, 31, 400])
def test_a_point_projects_alone_as_among_others(num_points):
    """The path search decides a lane change from its end point alone before projecting the whole blend:
    that relies on each point's projection not depending on the points projected with it (all-pairs and
    pruned searches alike)."""
    rng = np.random.default_rng(num_points)
    line = np.cumsum(rng.normal(size=(200, 3)) + [1.0, 0.0, 0.0], 0) + rng.uniform(-1e4, 1e4, 3)
    line = np.vstack([line, line[::-1][1:60]])  # back over itself: ties
    points = line[rng.integers(0, len(line), num_points), :2] + rng.normal(size=(num_points, 2)) * 3.0
    together = project_to_polyline(points, line)
    for j in rng.choice(num_points, min(num_points, 25), replace=False):
        alone = project_to_polyline(points[j:j + 1], line)
        for got, want in zip(alone, together):
            np.testing.assert_array_equal(got[0], want[j])


def test_pair_keys_order_as_the_rows_do():
    """The lane graph's np.unique on a * K + b keys gives np.unique(axis=0)'s order, first occurrences,
    inverse and counts for pairs of ints in [0, K)."""
    rng = np.random.default_rng(9)
    for num in (1, 7, 300):
        a, b = rng.integers(0, num, 500), rng.integers(0, num, 500)
        rows, first, inverse, counts = np.unique(np.stack([a, b], 1), axis=0, return_index=True,
                                                 return_inverse=True, return_counts=True)
        keys, key_first, key_inverse, key_counts = np.unique(a * num + b, return_index=True, return_inverse=True,
                                                             return_counts=True)
        np.testing.assert_array_equal(np.stack([keys // num, keys % num], 1), rows)
        np.testing.assert_array_equal(key_first, first)
        np.testing.assert_array_equal(key_inverse.reshape(-1), inverse.reshape(-1))
        np.testing.assert_array_equal(key_counts, counts)


def test_run_search_is_exact_where_offset_keys_round_together():
    # Values 1e-14 apart near 1, in the later of 200 runs: shifted by their run's offset (a multiple of 8), they
    # round to the same float, and the queries between them must be searched exactly.
    from scenariomax.enrich.geometry import _last_at_or_below, run_starts

    rng = np.random.default_rng(2)
    counts = rng.integers(1, 6, 200)
    xps = [1.0 + np.cumsum(rng.integers(0, 3, c)) * 1e-14 for c in counts]
    xp = np.concatenate(xps)
    x_run = np.concatenate([np.full(3 * c, r) for r, c in enumerate(counts)])
    x = np.concatenate([np.concatenate([v, v - 5e-15, v + 5e-15]) for v in xps])
    starts = run_starts(counts)
    xp_run = np.repeat(np.arange(len(counts)), counts)
    got = _last_at_or_below(x, x_run, xp, xp_run, starts)
    want = [starts[r] + int(np.searchsorted(xps[r], value, side="right")) - 1 for value, r in zip(x, x_run)]
    np.testing.assert_array_equal(got, want)
    span = 2.0 ** (np.ceil(np.log2(max(np.abs(xp).max(), np.abs(x).max(), 1.0))) + 2)  # as _last_at_or_below
    offset = span * np.arange(len(counts))
    keys, queries = xp + offset[xp_run], x + offset[x_run]
    merged = np.searchsorted(keys, queries, side="right") - 1 != got
    assert merged.any()  # the case the exact search is for did occur
    fp = rng.normal(size=len(xp))
    np.testing.assert_array_equal(run_interp(x, x_run, xp, fp, counts),
                                  [np.interp(value, xps[r], fp[starts[r]:starts[r] + counts[r]])
                                   for value, r in zip(x, x_run)])


def test_light_evidence_gaps_and_windows_match_the_step_loops():
    from scenariomax.enrich.traffic_lights import _dilate, _fill_gaps

    def fill_reference(evidence, max_gap):  # the former loop over consecutive True steps
        out = evidence.copy()
        idx = np.flatnonzero(evidence)
        for a, b in zip(idx[:-1], idx[1:]):
            if 1 < b - a <= max_gap + 1:
                out[a:b] = True
        return out

    def dilate_reference(marks, reach):  # the former window written around each crossing step
        out = np.zeros_like(marks)
        for step in np.flatnonzero(marks):
            out[max(step - reach, 0):step + reach + 1] = True
        return out

    rng = np.random.default_rng(0)
    for _ in range(500):
        rows = rng.random((4, int(rng.integers(1, 40)))) < rng.random()
        reach = int(rng.integers(0, 6))
        np.testing.assert_array_equal(_fill_gaps(rows, reach), [fill_reference(r, reach) for r in rows])
        np.testing.assert_array_equal(_dilate(rows, reach), [dilate_reference(r, reach) for r in rows])
        np.testing.assert_array_equal(_fill_gaps(rows[0], reach), fill_reference(rows[0], reach))
