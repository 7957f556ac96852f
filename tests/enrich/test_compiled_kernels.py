"""The compiled kernels (numba) give the same bits as the numpy code they stand in for, on random inputs with the
awkward cases (repeated points, ties, NaN, inf) and on whole real conversions: a shard converted with and without
them is the same file (issue 24 item 6: conversion speed without changing one output value)."""

from __future__ import annotations

import numpy as np
import pytest

from scenariomax import _compiled
from scenariomax.enrich import geometry
from scenariomax.enrich.paths import _TrackNearLanes
from scenariomax.io import example

pytest.importorskip("numba", reason="numba is not installed: the numpy code runs alone")
KERNELS = _compiled.kernels()


def _without_kernels(monkeypatch, run):
    """run() with the kernels switched off (as where numba is missing), then on again."""
    monkeypatch.setenv(_compiled.DISABLE_ENV, "1")
    _compiled.kernels.cache_clear()
    try:
        return run()
    finally:
        monkeypatch.delenv(_compiled.DISABLE_ENV)
        _compiled.kernels.cache_clear()


def _awkward_polyline(rng, n):
    line = np.cumsum(rng.normal(size=(n, 3)) * rng.uniform(0.01, 3.0), axis=0) + rng.uniform(-5e3, 5e3, size=3)
    if n > 2 and rng.random() < 0.3:
        line[rng.integers(1, n)] = line[rng.integers(0, n)]  # a repeated point: a zero-length segment
    return line


def _awkward_points(rng, line, m):
    pts = rng.normal(size=(m, 2)) * 5.0 + line[:, :2].mean(axis=0)
    choice = rng.integers(0, 3)
    if choice == 1:
        pts = np.round(pts)  # ties between segments
    elif choice == 2:
        pts = line[rng.integers(0, len(line), size=m), :2].copy()  # on the vertices
    return pts


def test_kernels_load_and_the_switch_turns_them_off(monkeypatch):
    assert KERNELS is not None
    assert _without_kernels(monkeypatch, _compiled.kernels) is None


@pytest.mark.parametrize("seed", range(3))
def test_projection_onto_one_polyline_is_numpys(seed):
    rng = np.random.default_rng(seed)
    for _ in range(300):
        line = _awkward_polyline(rng, int(rng.integers(2, 120)))  # pruned from 32 segments on
        pts = _awkward_points(rng, line, int(rng.integers(1, 80)))
        segments = geometry.polyline_segments(line)
        for with_foot in (True, False):
            want = geometry._project_numpy(pts, segments, with_foot)
            got = geometry.project_to_polyline(pts, line, segments, with_foot)
            for a, b in zip(want, got):
                assert (a is None and b is None) or np.array_equal(a, b)


def test_polyline_segments_are_numpys(monkeypatch):
    rng = np.random.default_rng(4)
    lines = [_awkward_polyline(rng, int(rng.integers(2, 90))) for _ in range(200)]
    lines[0][3] = np.nan
    compiled = [geometry.polyline_segments(line) for line in lines]
    plain = _without_kernels(monkeypatch, lambda: [geometry.polyline_segments(line) for line in lines])
    for got, want in zip(compiled, plain):
        assert len(got) == len(want) == 7
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a, b)


def test_projection_with_non_finite_points_is_numpys():
    rng = np.random.default_rng(7)
    line = _awkward_polyline(rng, 60)
    pts = _awkward_points(rng, line, 20)
    pts[3] = np.nan
    pts[5, 0] = np.inf
    segments = geometry.polyline_segments(line)
    want = geometry._project_numpy(pts, segments, True)
    got = geometry.project_to_polyline(pts, line, segments, True)
    for a, b in zip(want, got):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(3))
def test_projection_onto_many_polylines_is_numpys(seed):
    rng = np.random.default_rng(10 + seed)
    for _ in range(100):
        lines = [_awkward_polyline(rng, int(rng.integers(2, 300)))[:, :2] for _ in range(int(rng.integers(1, 9)))]
        pts = _awkward_points(rng, lines[0], int(rng.integers(1, 90)))
        got = geometry.project_to_polylines(pts, lines)
        vertex = np.concatenate(lines)
        want = geometry._project_many_numpy(pts, lines, list(range(len(lines))), vertex, [None] * len(lines))
        for (d1, a1), (d2, a2) in zip(want, got):
            assert np.array_equal(d1, d2) and np.array_equal(a1, a2)


def test_track_near_lanes_is_numpys(monkeypatch):
    """The box test and projection of the path search in one kernel: the same distances and arcs per lane."""
    from scenariomax.enrich.lanes import Lanes

    rng = np.random.default_rng(3)
    polylines = [np.cumsum(rng.normal(size=(int(rng.integers(2, 80)), 3)), axis=0) + rng.uniform(-25, 25, size=3)
                 for _ in range(30)]  # lanes around the track and away from it
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in polylines])])
    lanes = Lanes(ids=np.arange(30), types=np.ones(30, np.int64), offsets=offsets, points=np.concatenate(polylines))
    track = np.cumsum(rng.normal(size=(90, 2)), axis=0)
    compiled = [_TrackNearLanes(lanes, track, 6.0).of(lane) for lane in range(30)]
    plain = _without_kernels(monkeypatch, lambda: [_TrackNearLanes(lanes, track, 6.0).of(k) for k in range(30)])
    near = sum(np.isfinite(dist).any() for dist, _ in plain)
    assert 3 <= near < 30  # lanes near the track, and far ones
    for (dist, arc), (want_dist, want_arc) in zip(compiled, plain):
        np.testing.assert_array_equal(dist, want_dist)
        np.testing.assert_array_equal(arc, want_arc)


@pytest.mark.parametrize("seed", range(3))
def test_arc_lengths_run_cumsum_and_interpolation_are_numpys(seed):
    rng = np.random.default_rng(20 + seed)
    for _ in range(200):
        line = _awkward_polyline(rng, int(rng.integers(1, 100)))
        steps = np.sqrt(np.sum(np.diff(line[:, :2], axis=0) ** 2, axis=1))
        assert np.array_equal(geometry.arc_lengths(line), np.concatenate([[0.0], np.cumsum(steps)]))
        counts = rng.integers(1, 50, size=int(rng.integers(1, 40)))
        values = rng.normal(size=int(counts.sum())) * 10.0 ** rng.integers(-3, 4)
        want = np.concatenate([np.cumsum(part) for part in np.split(values, np.cumsum(counts)[:-1])])
        assert np.array_equal(geometry.run_cumsum(values, counts), want)
        cum = geometry.arc_lengths(line)
        arcs = np.concatenate([rng.uniform(-5.0, cum[-1] + 5.0, size=40), cum[rng.integers(0, len(cum), 5)],
                               [np.nan, np.inf, -np.inf]])
        want = np.stack([np.interp(arcs, cum, line[:, k]) for k in range(3)], axis=1)
        np.testing.assert_array_equal(geometry.point_at_arc(line, cum, arcs), want)


def test_interpolation_with_infinite_and_repeated_knots_is_numpys():
    rng = np.random.default_rng(5)
    for _ in range(500):
        n = int(rng.integers(1, 30))
        xp = np.sort(np.round(rng.normal(size=n) * 5))  # repeated knots
        if rng.random() < 0.2:
            xp[-1] = np.inf
        fp = rng.normal(size=(n, 2)) * 100
        if rng.random() < 0.2:
            fp[rng.integers(0, n)] = np.inf  # infinite slopes: numpy's NaN fallbacks
        x = np.concatenate([rng.normal(size=30) * 6, xp, [np.nan, np.inf, -np.inf]])
        want = np.stack([np.interp(x, xp, fp[:, k]) for k in range(2)], axis=1)
        got, computed = KERNELS.interp_columns(x, xp, fp)
        assert computed
        np.testing.assert_array_equal(got, want)
    _, computed = KERNELS.interp_columns(np.zeros(3), np.array([0.0, np.nan, 1.0]), np.zeros((3, 2)))
    assert not computed  # not ordered: left to numpy


def test_interpolation_per_run_is_numpys():
    rng = np.random.default_rng(8)
    for _ in range(300):
        counts = rng.integers(1, 20, size=int(rng.integers(1, 12)))
        xp = np.concatenate([np.sort(np.round(rng.normal(size=c) * 4)) for c in counts])  # repeated knots
        fp = rng.normal(size=(len(xp), 2)) * 50
        if rng.random() < 0.2:
            fp[rng.integers(0, len(fp))] = np.inf
        x_run = rng.integers(0, len(counts), size=60)
        x = np.where(rng.random(60) < 0.1, np.nan, rng.normal(size=60) * 6)
        parts = np.split(np.arange(len(xp)), np.cumsum(counts)[:-1])
        want = np.array([[np.interp(x[i], xp[parts[r]], fp[parts[r], k]) for k in range(2)]
                         for i, r in enumerate(x_run)])
        np.testing.assert_array_equal(geometry.run_interp(x, x_run, xp, fp, counts), want)
        np.testing.assert_array_equal(geometry.run_interp(x, x_run, xp, fp[:, 0], counts), want[:, 0])


def test_slices_and_resampled_paths_are_numpys(monkeypatch):
    from scenariomax.enrich.paths import PathSettings, _Piece, _resample

    rng = np.random.default_rng(9)
    cases = []
    for _ in range(200):
        line = _awkward_polyline(rng, int(rng.integers(1, 60)))
        cum = geometry.arc_lengths(line)
        bounds = sorted(rng.uniform(-3.0, cum[-1] + 3.0, size=2))
        pieces = []
        for lane in range(int(rng.integers(1, 4))):
            xyz = _awkward_polyline(rng, int(rng.integers(1, 40)))
            pieces.append(_Piece(xyz, np.full(len(xyz), lane)))
        settings = PathSettings(spacing_m=float(rng.choice([0.5, 1.0, 2.0])), points_per_path=int(rng.integers(2, 90)))
        cases.append((line, cum, bounds, tuple(pieces), settings))

    def run():
        return [(geometry.slice_polyline(line, cum, *bounds), _resample(pieces, settings))
                for line, cum, bounds, pieces, settings in cases]

    compiled = run()
    plain = _without_kernels(monkeypatch, run)
    for (cut, path), (want_cut, want_path) in zip(compiled, plain):
        np.testing.assert_array_equal(cut, want_cut)
        np.testing.assert_array_equal(path.xyz, want_path.xyz)
        np.testing.assert_array_equal(path.lane, want_path.lane)


def test_varints_are_numpys():
    rng = np.random.default_rng(1)
    for case in range(500):
        n = int(rng.integers(1, 300))
        values = (rng.integers(-2**63, 2**63 - 1, size=n, dtype=np.int64) if case % 3 == 0
                  else rng.integers(-3, 2 ** int(rng.integers(1, 40)), size=n))
        if case % 3 == 2:
            values[-int(rng.integers(0, n + 1)):] = -1  # padding: 10 bytes each
        assert example.varints(values) == example._varints_numpy(values.astype(np.int64).view(np.uint64))


def _records(dataset: str, relative: str) -> list[bytes]:
    """Every record a conversion worker writes for one real sample (read, sanity pass, enrichment, encoding)."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import SANITIZED_SOURCES, prepare_scenario, sanitize_scenario
    from scenariomax.schema import Sizes
    from scenariomax.sources.base import Failure
    from scenariomax.sources.registry import make_source
    from tests.conftest import realdata_file

    sizes, (transform, _) = Sizes(), make_transform(True)
    source = make_source(dataset, src=str(realdata_file(relative)), sizes=sizes, orient_edges=False)
    records = []
    for unit in source.list_units():
        for item in source.read_unit(unit):
            assert not isinstance(item, Failure), item
            item = sanitize_scenario(item) if source.name in SANITIZED_SOURCES else item
            records.append(prepare_scenario(item, sizes, transform))
    return records


@pytest.mark.parametrize("dataset, relative", [
    ("womd", "womd/motion_data_one_scenario.tfrecord"),
    ("gpudrive", "gpudrive/tfrecord-00000-of-01000_402.json"),
    ("scenarionet", "scenarionet/sd_nuscenes_v1.0-mini_scene-0553.pkl"),
])
def test_real_conversions_write_the_same_bytes_with_and_without_kernels(dataset, relative, monkeypatch):
    compiled = _records(dataset, relative)
    plain = _without_kernels(monkeypatch, lambda: _records(dataset, relative))
    assert len(compiled) == len(plain) >= 1
    assert all(a == b for a, b in zip(compiled, plain))
