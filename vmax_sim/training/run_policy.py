"""A training run directory as an evaluation policy: its checkpoint loaded, evaluated with its own settings.

This is training's side of evaluation: it reads the run's configuration and rebuilds its learner
(`vmax_sim.training.run`), so it sits above `vmax_sim.evaluation`, which only receives `evaluate_run` (as
`compare_policies(..., run_evaluator=evaluate_run)`) and never imports training.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

from scenariomax.errors import InputError
from scenariomax.progress import Progress
from vmax_sim.evaluation.evaluate import evaluate, mark_partial
from vmax_sim.evaluation.report import expected_num_scenarios
from vmax_sim.evaluation.trained import trained_policy
from vmax_sim.map_index.structure import MapIndexConfig
from vmax_sim.observation import (
    LIGHT_FEATURES,
    ROADGRAPH_FEATURES,
    Observation,
    object_feature_count,
    sdc_feature_count,
)
from vmax_sim.policies.base import Policy
from vmax_sim.training.checkpoint import CheckpointStore
from vmax_sim.training.config import apply_overrides, brake_guard, policy_name
from vmax_sim.training.ensemble import ensemble_learner, is_ensemble, member_params
from vmax_sim.training.run import (
    components,
    data_config,
    load_run_config,
    resolve_eval_data,
    selfplay_env_and_act,
)


@dataclasses.dataclass(frozen=True)
class LoadedPolicy:
    policy: Policy
    params: object
    config: object  # the run's TrainConfig
    env_steps: int  # checkpoint step the parameters come from (an ensemble's newest member)
    learner: object  # whose act takes `params` (an ensemble's: the members' mean action, params stacked)


def load_trained_policy(run_dir: str | Path, step: int | None = None, brake_guard_ttc: float | None = None,
                        brake_guard_hold: bool = False) -> LoadedPolicy:
    """The policy of a training run directory at its latest (or the given) checkpoint; of an ensemble directory
    (RUN/ensemble, `train.ensemble`), all its members driving as one (`train.ensemble_rule`). brake_guard_ttc:
    None drives with the run's own `train.brake_guard_ttc` and `train.brake_guard_hold`; a number in its place (0: the
    student alone; no hold then) drives with that guard, holding as brake_guard_hold says, so the same weights can be
    evaluated with and without the guard."""
    run_dir = Path(run_dir)
    config = load_run_config(run_dir)
    if brake_guard_ttc is not None:
        config = apply_overrides(config, [f"train.brake_guard_ttc={brake_guard_ttc}",
                                          f"train.brake_guard_hold={brake_guard_hold}"])
    store = CheckpointStore(run_dir / "checkpoints")
    env, learner = components(config)
    name = f"{policy_name(config)}@{run_dir.name}"
    ensemble = is_ensemble(run_dir) and step is None
    step = store.latest_step() if step is None else step
    if step is None:
        raise InputError(f"{run_dir}: the {'ensemble has no member' if ensemble else 'run has no checkpoint'} yet")
    like = jax.eval_shape(learner.init, jax.random.PRNGKey(0), _example_observation(config, env))
    try:
        if ensemble:
            params, steps = member_params(store, like, learner.policy_params)
            learner, step = ensemble_learner(learner, config.train.ensemble_rule), steps[-1]
        else:
            params = learner.policy_params(store.restore_learner(step, like))
    except (ValueError, KeyError) as error:
        raise InputError(f"{run_dir}: checkpoint {step} does not match this version's {config.algo} / "
                         f"{config.network.name} networks ({str(error)[:120]})") from None
    return LoadedPolicy(policy=trained_policy(learner, name, brake_guard(config)), params=params, config=config,
                        env_steps=int(step), learner=learner)


def _example_observation(config, env):
    """A batch-of-one observation shaped as the run's (zeros; only shapes matter for init)."""
    obs = config.obs
    points = obs.num_roadgraph_points or _window_points(config)
    k, n = obs.num_history, obs.num_object_slots
    zeros = jnp.zeros
    return Observation(
        sdc=zeros((1, k, sdc_feature_count(obs))), sdc_valid=zeros((1, k), bool),
        objects=zeros((1, n, k, object_feature_count(obs))),
        objects_valid=zeros((1, n, k), bool), roadgraph=zeros((1, points, ROADGRAPH_FEATURES)),
        roadgraph_valid=zeros((1, points), bool), lights=zeros((1, obs.num_lights, LIGHT_FEATURES)),
        lights_valid=zeros((1, obs.num_lights), bool), path_targets=zeros((1, obs.num_path_targets, 2)),
        path_targets_valid=zeros((1, obs.num_path_targets), bool))


def _window_points(config) -> int:
    return config.obs.roadgraph_window ** 2 * MapIndexConfig().obs_slots_per_cell


def evaluate_run(run_dir: str | Path, data: str | None = None, mode: str = "non_reactive",
                 num_scenarios: int | None = None, batch_size: int = 8, step: int | None = None, on_batch=None,
                 progress: bool = False, stop=None, brake_guard_ttc: float | None = None,
                 brake_guard_hold: bool = False):
    """Evaluates a training run's policy on `data` (default: the run's held-out split), with the run's
    observation and environment settings. `progress`: the scenarios done of the total on stderr. `stop`: a
    flag with `requested` (vmax_sim.evaluation.evaluate): once set, the result covers the batches done.
    brake_guard_ttc, brake_guard_hold: as `load_trained_policy`'s."""
    loaded = load_trained_policy(run_dir, step, brake_guard_ttc, brake_guard_hold)
    config = loaded.config
    # notes go to stderr: stdout may be carrying `evaluate --json`
    path = data or resolve_eval_data(config, lambda line: print(line, file=sys.stderr))
    total = expected_num_scenarios(path, num_scenarios) if progress else None
    with Progress(f"evaluating {Path(run_dir).name}", total, "scenarios", enabled=progress) as shown:
        result = evaluate(loaded.policy, data_config(config, path, batch_size=batch_size), mode=mode,
                          env_config=components(config)[0].env_config,
                          obs_config=config.obs, num_scenarios=num_scenarios, policy_params=loaded.params,
                          on_batch=on_batch, progress=shown, stop=stop)
    if result.summary.get("partial"):
        return mark_partial(result, expected_num_scenarios(path, num_scenarios))
    return result


__all__ = ["LoadedPolicy", "evaluate_run", "load_trained_policy"]


def evaluate_selfplay_run(run_dir: str | Path, data: str | None = None, num_scenarios: int | None = None,
                          batch_size: int = 8, step: int | None = None, progress: bool = False, seed: int = 0):
    """One policy (a training run's, self-play or not) drives every agent of `data` (default: the run's held-out
    split): `vmax_sim.evaluation.selfplay.SelfPlayResult`."""
    from vmax_sim.evaluation.evaluate import scenario_batches
    from vmax_sim.evaluation.selfplay import evaluate_selfplay

    loaded = load_trained_policy(run_dir, step)
    config = loaded.config
    path = data or resolve_eval_data(config, lambda line: print(line, file=sys.stderr))
    env = selfplay_env_and_act(config)[0]
    act = lambda params, observation, key: loaded.learner.act(params, observation, key, True)  # noqa: E731
    data_settings = data_config(config, path, batch_size=batch_size, include_agent_paths=True)
    total = expected_num_scenarios(path, num_scenarios) if progress else None
    with Progress(f"self-play {Path(run_dir).name}", total, "scenarios", enabled=progress) as shown:
        return evaluate_selfplay(env, act, loaded.params, scenario_batches(path, data_settings, num_scenarios),
                                 seed=seed, on_batch=shown.update if progress else None)
