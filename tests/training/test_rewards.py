"""Reward presets and weighted terms against hand-worked values; batched == unbatched."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.metrics import MetricsConfig
from vmax_sim.rewards import RewardConfig, compute_reward, register_term, reward_terms

ZERO = {"overlap": 0.0, "offroad": 0.0, "red_light": 0.0, "off_route": 0.0, "ego_progress": 10.0, "accel": 0.0,
        "yaw_rate": 0.0, "speed_violation": 0.0, "speed": 8.0, "log_divergence": 1.5, "wrong_way": 0.0,
        "at_fault_collision": 0.0, "ttc_violation": 0.0, "kinematic_infeasibility": 0.0, "multiple_lanes": 0.0}


def metrics(**changes) -> dict:
    values = dict(ZERO)
    values.update(changes)
    return {k: jnp.float32(v) for k, v in values.items()}


BEFORE = metrics(ego_progress=9.0)


@pytest.mark.parametrize(("preset", "changes", "expected"), [
    ("safety", {}, 0.0),
    ("safety", {"overlap": 1.0, "offroad": 1.0}, -2.0),
    ("safety", {"red_light": 1.0, "off_route": 1.0}, -1.0),  # off-route is not a safety term
    ("navigation", {}, 0.2),  # progressed 9 -> 10 m
    ("navigation", {"ego_progress": 9.0}, 0.0),  # no progress this step
    ("navigation", {"off_route": 1.0, "overlap": 1.0}, -1.0 - 0.2 + 0.2),
    ("behavior", {}, 0.2 + 0.2),  # progress + comfortable
    ("behavior", {"accel": -5.0}, 0.2),  # harder braking than nuPlan's -4.05 m/s^2 is not comfortable
    ("behavior", {"yaw_rate": 1.2, "speed_violation": 0.5}, 0.2 - 0.1),
])
def test_presets_hand_worked(preset, changes, expected):
    reward = compute_reward(metrics(**changes), BEFORE, RewardConfig(preset=preset), MetricsConfig())
    assert float(reward) == pytest.approx(expected, abs=1e-6)


def test_weighted_terms_override_and_extend_the_preset():
    config = RewardConfig(preset="navigation", weights=(("collision", -5.0), ("speed", 0.01)))
    reward = compute_reward(metrics(overlap=1.0), BEFORE, config)
    assert float(reward) == pytest.approx(-5.0 + 0.2 + 0.08, abs=1e-6)
    only = RewardConfig(preset="none", weights=(("log_divergence", -1.0),))
    assert float(compute_reward(metrics(), BEFORE, only)) == pytest.approx(-1.5)


def test_batched_equals_unbatched():
    rng = np.random.default_rng(0)
    batch = {k: jnp.asarray(rng.integers(0, 2, 7).astype(np.float32)) for k in ZERO}
    batch["ego_progress"] = jnp.asarray(rng.normal(size=7).astype(np.float32))
    batch["accel"] = jnp.asarray(rng.normal(scale=4, size=7).astype(np.float32))
    before = {k: v[::-1] for k, v in batch.items()}
    config = RewardConfig(preset="behavior")
    batched = compute_reward(batch, before, config)
    single = jax.vmap(lambda m, p: compute_reward(m, p, config))(batch, before)
    loop = [float(compute_reward({k: v[i] for k, v in batch.items()}, {k: v[i] for k, v in before.items()}, config))
            for i in range(7)]
    np.testing.assert_allclose(batched, single, atol=1e-6)
    np.testing.assert_allclose(batched, loop, atol=1e-6)


def test_terms_are_reported_unweighted():
    terms = reward_terms(metrics(overlap=1.0), BEFORE, RewardConfig(preset="behavior"))
    assert {k: float(v) for k, v in terms.items()} == {
        "collision": 1.0, "offroad": 0.0, "red_light": 0.0, "off_route": 0.0, "progress": 1.0,
        "comfortable": 1.0, "overspeed": 0.0}


def test_bad_configs_fail_in_one_line():
    with pytest.raises(ValueError, match="preset must be one of"):
        RewardConfig(preset="speedy")
    with pytest.raises(ValueError, match="unknown reward term 'colision'"):
        compute_reward(metrics(), BEFORE, RewardConfig(weights=(("colision", -1.0),)))
    with pytest.raises(ValueError, match="needs at least one"):
        RewardConfig(preset="none")


def test_registered_term_is_usable_without_touching_the_step():
    register_term("test_slow", lambda m, p, c: (m["speed"] < 9.0).astype(jnp.float32))
    config = RewardConfig(preset="none", weights=(("test_slow", 2.0),))
    assert float(compute_reward(metrics(speed=3.0), BEFORE, config)) == 2.0
    with pytest.raises(ValueError, match="exists already"):
        register_term("test_slow", lambda m, p, c: 0.0)
