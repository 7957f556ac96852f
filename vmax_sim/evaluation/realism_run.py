"""`evaluate_realism`: a rollout function over scenes, scored by the realism meta-metric, and its table."""

from __future__ import annotations

import dataclasses
import math
import zlib

import jax
import numpy as np

from scenariomax import read_shards
from scenariomax.errors import InputError
from vmax_sim.data import DataConfig, scenario_to_numpy_state
from vmax_sim.evaluation.realism import BUCKETS, FEATURE_NAMES, RealismConfig, scene_realism
from vmax_sim.evaluation.realism_rollouts import RolloutFn, evaluated_objects

DEFAULT_MAX_AGENTS = 32  # evaluated agents besides the SDC, nearest first


@dataclasses.dataclass(frozen=True)
class RealismResult:
    summary: dict  # JSON-serialisable: policy, settings, dataset means (features, meta-metric, buckets, rates)
    per_scene: dict  # name -> (S,) float64 numpy, one entry per scene
    scenario_ids: tuple[str, ...]  # (S,)


def scene_key(seed: int, scenario_id: str) -> jax.Array:
    """The rollouts' key of a scene: the same for any order or subset of scenes. -> (2,)"""
    return jax.random.fold_in(jax.random.PRNGKey(seed), zlib.crc32(scenario_id.encode()) & 0x7FFFFFFF)


def _states(data_config: DataConfig, num_scenes: int | None):
    try:
        for count, scenario in enumerate(read_shards(data_config.path)):
            if num_scenes is not None and count >= num_scenes:
                return
            yield scenario.scenario_id, scenario_to_numpy_state(scenario, data_config)
    except FileNotFoundError as error:
        raise InputError(str(error)) from None


def evaluate_realism(rollout_fn: RolloutFn, data_config: DataConfig, *, policy: str = "custom",
                     num_rollouts: int = 32, num_scenes: int | None = None, max_agents: int = DEFAULT_MAX_AGENTS,
                     config: RealismConfig | None = None, seed: int = 0, progress=None,
                     settings: dict | None = None) -> RealismResult:
    """Runs `rollout_fn` on every scene of data_config.path (the first num_scenes) and scores it.

    The data must carry the map index and the agents' paths (they are switched on here). progress: anything
    with `update(n)`, told the scenes done. settings: extra JSON entries for the summary."""
    config = config or RealismConfig()
    data_config = dataclasses.replace(data_config, include_map_index=True, include_agent_paths=True)

    @jax.jit
    def score(state, sim):
        slots, valid = evaluated_objects(state, max_agents, config.current_timestep)
        out = scene_realism(state, sim, slots, valid, config)
        out["num_evaluated"] = valid.sum().astype(np.float32)
        return out

    collected: dict[str, list[float]] = {}
    ids: list[str] = []
    for scenario_id, host_state in _states(data_config, num_scenes):
        state = jax.device_put(host_state)
        sim = rollout_fn(state, scene_key(seed, scenario_id))
        if sim.num_rollouts != num_rollouts:
            raise ValueError(f"the rollout function returned {sim.num_rollouts} rollouts, expected {num_rollouts}")
        for name, value in jax.device_get(score(state, sim)).items():
            collected.setdefault(name, []).append(float(value))
        ids.append(scenario_id)
        if progress is not None:
            progress.update(1)
    if not ids:
        raise InputError(f"{data_config.path}: no scenes to score")
    per_scene = {name: np.asarray(values, np.float64) for name, values in collected.items()}
    summary = {"policy": policy, "num_scenes": len(ids), "num_rollouts": num_rollouts, "max_agents": max_agents,
               "seed": seed, **(settings or {}), **summarise(per_scene, config)}
    return RealismResult(summary=summary, per_scene=per_scene, scenario_ids=tuple(ids))


def summarise(per_scene: dict, config: RealismConfig) -> dict:
    """Dataset means (`realism.aggregate_scenes`), None where nothing could be scored (JSON has no NaN)."""
    from vmax_sim.evaluation.realism import aggregate_scenes

    means = aggregate_scenes(per_scene, config)
    clean = {k: (v if math.isfinite(v) else None) for k, v in means.items()}
    return {"metametric": clean.pop("metametric"),
            "buckets": {name: clean.pop(name) for name in BUCKETS},
            "likelihoods": {name: clean.pop(name) for name in FEATURE_NAMES},
            "weights": {name: feature.weight for name, feature in config.features},
            **{name: clean[name] for name in ("collision_rate", "offroad_rate", "ade", "min_ade",
                                              "num_evaluated")}}


@dataclasses.dataclass(frozen=True)
class TrainedRun:
    """What realism needs of a training run; training builds it (the CLI wires `vmax_sim.training` in), so this
    floor never imports training."""

    name: str
    learner: object  # the run's Learner (its `act` samples the policy)
    params: object  # the checkpoint's policy parameters
    env_config: object  # the run's EnvConfig (normalised actions)
    obs_config: object  # the run's ObservationConfig
    data_config: DataConfig  # the run's data sizes, with the shards to score


def realism_for_policy(policy: str, data_config: DataConfig | None = None, *, trained: TrainedRun | None = None,
                       num_rollouts: int = 32, num_scenes: int | None = None, max_agents: int = DEFAULT_MAX_AGENTS,
                       action_noise: float = 0.0, deterministic: bool = False, seed: int = 0,
                       config: RealismConfig | None = None, progress=None) -> RealismResult:
    """`evaluate_realism` of a named policy ("log", "constant", "idm", on `data_config`) or of a trained run
    (`trained`, on its own data config)."""
    from vmax_sim.env.config import EnvConfig
    from vmax_sim.env.factory import make_environment
    from vmax_sim.evaluation.realism_rollouts import named_rollout_fn, trained_rollout_fn
    from vmax_sim.metrics import MetricsConfig

    if num_rollouts < 1 or max_agents < 1 or action_noise < 0:
        raise ValueError("rollouts and max agents must be at least 1 and the action noise not negative")
    settings = {"action_noise": action_noise}
    if trained is not None:
        data_config = trained.data_config
        env = make_environment(trained.env_config, MetricsConfig())
        rollout_fn = trained_rollout_fn(trained.learner, trained.params, env, trained.obs_config, num_rollouts,
                                        max_agents, deterministic=deterministic, action_noise=action_noise,
                                        name=trained.name)
        policy, settings["sampled"] = trained.name, not deterministic
    else:
        env = make_environment(EnvConfig(max_num_objects=data_config.num_objects), MetricsConfig())
        rollout_fn = named_rollout_fn(policy, env, num_rollouts, max_agents, action_noise)
    return evaluate_realism(rollout_fn, data_config, policy=policy, num_rollouts=num_rollouts, num_scenes=num_scenes,
                            max_agents=max_agents, config=config, seed=seed, progress=progress, settings=settings)


def _cell(value, fmt: str = ".4f") -> str:
    return "n/a" if value is None else format(value, fmt)


def format_realism(summaries: list[dict]) -> str:
    """One column per policy: the nine likelihoods with their weights, the buckets, the meta-metric, then the
    simulated collision / off-road rates and displacement errors (not part of the meta-metric)."""
    header = "| feature | weight | " + " | ".join(s["policy"] for s in summaries) + " |"
    lines = [header, "|---|---|" + "---|" * len(summaries)]
    weights = summaries[0]["weights"]
    for name in FEATURE_NAMES:
        lines.append(f"| {name} | {weights[name]:.2f} | "
                     + " | ".join(_cell(s["likelihoods"][name]) for s in summaries) + " |")
    for bucket in BUCKETS:
        lines.append(f"| *{bucket}* | | " + " | ".join(_cell(s["buckets"][bucket]) for s in summaries) + " |")
    lines.append("| **meta-metric** | 1.00 | " + " | ".join(f"**{_cell(s['metametric'])}**" for s in summaries)
                 + " |")
    for name, fmt in (("collision_rate", ".4f"), ("offroad_rate", ".4f"), ("ade", ".2f"), ("min_ade", ".2f")):
        lines.append(f"| {name} | | " + " | ".join(_cell(s[name], fmt) for s in summaries) + " |")
    first = summaries[0]
    lines.append(f"\n{first['num_scenes']} scene(s), {first['num_rollouts']} rollouts each, "
                 f"{_cell(first['num_evaluated'], '.1f')} evaluated objects per scene (SDC + up to "
                 f"{first['max_agents']} controllable agents)")
    return "\n".join(lines)


__all__ = ["DEFAULT_MAX_AGENTS", "RealismResult", "TrainedRun", "evaluate_realism", "format_realism",
           "realism_for_policy", "scene_key", "summarise"]
