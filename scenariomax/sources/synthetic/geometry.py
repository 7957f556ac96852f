"""Small 2-D polyline helpers used to draw synthetic roads (all arrays float64, metres)."""

from __future__ import annotations

import numpy as np

from scenariomax.enrich.geometry import wrap_angle  # noqa: F401 (shared; re-exported)


def unit(angle: float) -> np.ndarray:
    """Unit vector at `angle` radians. -> (2,)"""
    return np.array([np.cos(angle), np.sin(angle)])


def left_normal(direction: np.ndarray) -> np.ndarray:
    """The direction turned 90 degrees counter-clockwise. (..., 2) -> (..., 2)"""
    return np.stack([-direction[..., 1], direction[..., 0]], axis=-1)


def segment(start: np.ndarray, end: np.ndarray, spacing: float = 1.0) -> np.ndarray:
    """Straight polyline from start to end, about `spacing` apart. -> (n, 2)"""
    num = max(int(np.ceil(np.linalg.norm(end - start) / spacing)), 1) + 1
    return np.linspace(start, end, num)


def arc(center: np.ndarray, radius: float, start_angle: float, sweep: float, spacing: float = 1.0) -> np.ndarray:
    """Circular arc (counter-clockwise when sweep > 0). -> (n, 2)"""
    num = max(int(np.ceil(abs(sweep) * radius / spacing)), 2) + 1
    angles = start_angle + np.linspace(0.0, sweep, num)
    return center + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)


def bezier(p0: np.ndarray, h0: np.ndarray, p1: np.ndarray, h1: np.ndarray, num: int = 40) -> np.ndarray:
    """Cubic Bezier leaving p0 along unit heading h0 and arriving at p1 along h1. -> (num, 2)"""
    reach = 0.45 * np.linalg.norm(p1 - p0)
    c0, c1 = p0 + reach * h0, p1 - reach * h1
    t = np.linspace(0.0, 1.0, num)[:, None]
    return ((1 - t) ** 3) * p0 + 3 * ((1 - t) ** 2) * t * c0 + 3 * (1 - t) * (t ** 2) * c1 + (t ** 3) * p1


def half_turn(start: np.ndarray, heading: np.ndarray, end: np.ndarray, spacing: float = 1.0) -> np.ndarray:
    """Half circle leaving `start` along unit `heading` and arriving at `end` the opposite way (a U-turn); `end`
    lies square to the heading beside `start`, the diameter apart. -> (n, 2)"""
    center = (start + end) / 2
    radial = start - center
    turns_left = float(np.dot(left_normal(radial), heading)) > 0  # counter-clockwise leaves start along heading
    return arc(center, float(np.linalg.norm(radial)), float(np.arctan2(radial[1], radial[0])),
               np.pi if turns_left else -np.pi, spacing)


def join(*parts: np.ndarray) -> np.ndarray:
    """Concatenates polylines, dropping the repeated joint points. -> (n, 2)"""
    out = [parts[0]]
    for part in parts[1:]:
        out.append(part[1:] if np.allclose(part[0], out[-1][-1]) else part)
    return np.concatenate(out)


def tangents(xy: np.ndarray) -> np.ndarray:
    """Unit tangent at every vertex (central differences). (n, 2) -> (n, 2)"""
    diff = np.gradient(xy, axis=0)
    return diff / np.maximum(np.linalg.norm(diff, axis=1, keepdims=True), 1e-9)


def offset(xy: np.ndarray, distance: float) -> np.ndarray:
    """Parallel polyline `distance` metres to the left (negative: right). (n, 2) -> (n, 2)"""
    return xy + distance * left_normal(tangents(xy))


def arc_length(xy: np.ndarray) -> np.ndarray:
    """Cumulative length along the polyline, starting at 0. (n, 2) -> (n,)"""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])


def resample(xy: np.ndarray, spacing: float) -> np.ndarray:
    """Points exactly `spacing` apart in arc length (the last may be closer). (n, 2) -> (m, 2)"""
    s = arc_length(xy)
    targets = np.arange(0.0, s[-1], spacing)
    if s[-1] - targets[-1] > 1e-6:
        targets = np.append(targets, s[-1])
    return np.stack([np.interp(targets, s, xy[:, 0]), np.interp(targets, s, xy[:, 1])], axis=1)


def rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])
