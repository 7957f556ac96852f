"""`evaluate`: closed-loop episodes of a policy over scenarios, reduced to episode metrics and scores.

Scores are computed per episode and then averaged (docs/metrics.md). The result holds a
JSON-serialisable summary and the per-episode arrays.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Iterable, Iterator

import jax
import numpy as np

from scenariomax import Scenario, read_shards
from scenariomax.errors import InputError
from vmax_sim.data import DataConfig, scenario_to_numpy_state, stack_states
from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.config import EnvConfig
from vmax_sim.env.factory import make_environment
from vmax_sim.evaluation.mode_rollout import make_batch_runner
from vmax_sim.evaluation.modes import MODE_NAMES, PLANNED_MODES, EvalMode, parse_mode  # noqa: F401
from vmax_sim.evaluation.policies import Policy, make_policy
from vmax_sim.metrics import MetricsConfig
from vmax_sim.observation import ObservationConfig

# Modes: how the world around the SDC behaves (vmax_sim.evaluation.modes; adversarial is planned).
MODES = MODE_NAMES
SCORE_KEYS = ("accuracy", "accuracy_at_fault", "nuplan_score", "vmax_score")


@dataclasses.dataclass(frozen=True)
class EvaluationResult:
    summary: dict  # JSON-serialisable: policy, mode, num_episodes, scores, mean of every episode metric
    episodes: dict  # metric name -> (E,) float32 numpy, one entry per episode (scores included)
    scenario_ids: tuple[str, ...]  # (E,) the scenario of each episode


@functools.lru_cache(maxsize=8)
def _environment(env_config: EnvConfig, metrics_config: MetricsConfig):
    return make_environment(env_config, metrics_config)


@functools.lru_cache(maxsize=16)
def _named_policy(name: str, env) -> Policy:
    return make_policy(name, env)


def _check_mode(mode: str | EvalMode, seed: int = 0) -> EvalMode:
    """The EvalMode of a mode name (or EvalMode); one-line ValueError for an unknown or planned one."""
    return parse_mode(mode, seed=seed)


def _scenarios(data, num_scenarios: int | None) -> Iterator[Scenario]:
    if isinstance(data, (DataConfig, str)):
        path = data.path if isinstance(data, DataConfig) else data
        if not path:
            raise InputError("no data given: pass a shard directory, file or glob")
        stream: Iterable[Scenario] = read_shards(path)
    else:
        stream = data
    try:
        for count, scenario in enumerate(stream):
            if num_scenarios is not None and count >= num_scenarios:
                return
            yield scenario
    except FileNotFoundError as error:
        raise InputError(str(error)) from None


def scenario_batches(data, config: DataConfig, num_scenarios: int | None
                     ) -> Iterator[tuple[list[str], SimulatorState, int]]:
    """(scenario ids, host batch padded to batch_size by repeating its last state, number of real ones)."""
    ids: list[str] = []
    states: list[SimulatorState] = []
    for scenario in _scenarios(data, num_scenarios):
        ids.append(scenario.scenario_id)
        states.append(scenario_to_numpy_state(scenario, config))
        if len(states) == config.batch_size:
            yield ids, stack_states(states), len(states)
            ids, states = [], []
    if states:
        real = len(states)
        states += [states[-1]] * (config.batch_size - real)  # same shapes: no recompile for the last batch
        yield ids, stack_states(states), real


@dataclasses.dataclass(frozen=True)
class PreparedBatches:
    """Host batches converted once (map indices built), to evaluate many times without converting again."""

    batches: tuple  # (scenario ids, numpy SimulatorState (batch_size, ...), number of real ones) per batch
    data_config: DataConfig


def prepare_batches(data, num_scenarios: int | None = None) -> PreparedBatches:
    """Converts `data` (a DataConfig with its path and batch_size) once for repeated evaluations."""
    return PreparedBatches(batches=tuple(scenario_batches(data, data, num_scenarios)), data_config=data)


def _summary(episodes: dict[str, np.ndarray], policy: str, mode: str | EvalMode) -> dict:
    """Means over the judged episodes: one whose SDC log ends at the start step has no scored step, would
    score as perfect and is left out (counted in "num_unjudged"; its row stays in the per-episode table)."""
    total = int(len(next(iter(episodes.values()))))
    judged = episodes["judged_steps"] > 0 if "judged_steps" in episodes else np.ones(total, bool)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # every episode unjudged: NaN means
        means = {k: float(np.mean(v[judged])) for k, v in episodes.items()}
    summary = {"policy": policy, "mode": getattr(mode, "name", mode), "num_episodes": total,
               "num_unjudged": int(total - judged.sum())}
    if isinstance(mode, EvalMode) and mode.options():
        summary["mode_options"] = mode.options()
    summary["accuracy"] = means.pop("accurate")
    summary["accuracy_at_fault"] = means.pop("accurate_at_fault")
    summary["nuplan_score"] = means.pop("nuplan_score")
    summary["vmax_score"] = means.pop("vmax_score")
    summary["metrics"] = {k: (v if math.isfinite(v) else None) for k, v in sorted(means.items())}
    return summary


def evaluate(policy, data, mode: str | EvalMode = "non_reactive", *, data_config: DataConfig | None = None,
             env_config: EnvConfig | None = None, metrics_config: MetricsConfig | None = None,
             obs_config: ObservationConfig | None = None, num_scenarios: int | None = None,
             batch_size: int | None = None, seed: int = 0, policy_params=None, on_batch=None,
             progress=None, stop=None) -> EvaluationResult:
    """Runs one episode per scenario and scores it.

    policy: "expert", "constant", a `Policy`, or a jittable callable `fn(observation, key)` returning the
    SDC's (action_dim,) action (see `callable_policy`). mode: "non_reactive", "reactive", "perturbed" or an
    `EvalMode` with its options (vmax_sim.evaluation.modes; a name's perturbation seed is `seed`).
    data: a `DataConfig` (its path, num_objects, roadgraph and path sizes, batch_size), a shard path, or
    scenarios. Episodes start at
    env_config.init_steps - 1 (step 10) and run episode_length (80) steps in one jitted `lax.scan`,
    vmapped over the batch; by default an episode ends early on collision, off-road or red light
    (env_config.terminate_on). policy_params: the parameters handed to the policy's action_fn (a
    trained policy's network weights; an argument of the jitted rollout, so new ones never recompile).
    on_batch: called after every batch as on_batch(scenario ids, host batch, host Rollout, number of real
    episodes); the Rollout then also holds the simulated trajectories (`Rollout.trajectory`). The failure
    gallery and the difficulty report use it (vmax_sim.evaluation.gallery / difficulty).
    progress: a `scenariomax.progress.Progress` (or anything with `update(n)`) told the episodes done.
    stop: anything with a `requested` flag (vmax_sim.training.interrupt.StopRequests): checked after every
    batch; once set, the episodes finished so far are the result, marked partial (`mark_partial`).
    """
    mode = _check_mode(mode, seed)
    if isinstance(data, PreparedBatches):
        data_config = data.data_config
    if isinstance(data, DataConfig):
        data_config = data_config or data
    data_config = data_config or DataConfig()
    if batch_size is not None:
        data_config = dataclasses.replace(data_config, batch_size=batch_size)
    if not data_config.include_map_index:
        data_config = dataclasses.replace(data_config, include_map_index=True)  # the metrics need it
    if mode.is_reactive and not data_config.include_agent_paths:
        data_config = dataclasses.replace(data_config, include_agent_paths=True)  # the agents' routes
    env_config = env_config or EnvConfig(max_num_objects=data_config.num_objects)
    if env_config.max_num_objects != data_config.num_objects:
        raise ValueError(f"EnvConfig.max_num_objects ({env_config.max_num_objects}) must equal "
                         f"DataConfig.num_objects ({data_config.num_objects})")
    metrics_config = metrics_config or MetricsConfig()
    obs_config = obs_config or ObservationConfig()
    env = _environment(env_config, metrics_config)
    chosen = _named_policy(policy, env) if isinstance(policy, str) else make_policy(policy, env)
    run_batch = make_batch_runner(env, chosen, metrics_config, obs_config, mode, record_trajectory=on_batch is not None)

    params = policy_params
    key = jax.random.PRNGKey(seed)
    collected: dict[str, list[np.ndarray]] = {}
    scenario_ids: list[str] = []
    batches = data.batches if isinstance(data, PreparedBatches) else scenario_batches(data, data_config, num_scenarios)
    for ids, batch, real in batches:
        key, batch_key = jax.random.split(key)
        rollout = run_batch(jax.device_put(batch), jax.random.split(batch_key, data_config.batch_size), ids, params)
        for name, values in rollout.episode.items():
            collected.setdefault(name, []).append(np.asarray(values)[:real])
        scenario_ids += ids
        if on_batch is not None:
            on_batch(ids, batch, jax.device_get(rollout), real)
        if progress is not None:
            progress.update(real)
        if stop_requested(stop):
            break
    if not scenario_ids:
        raise InputError(f"{getattr(data_config, 'path', data)}: no scenarios to evaluate")
    episodes = {name: np.concatenate(parts).astype(np.float32) for name, parts in collected.items()}
    result = EvaluationResult(summary=_summary(episodes, chosen.name, mode), episodes=episodes,
                              scenario_ids=tuple(scenario_ids))
    return mark_partial(result, None) if stop_requested(stop) else result


def stop_requested(stop) -> bool:
    """Whether a stop flag (None: never) asks the evaluation to end after the batch in flight."""
    return stop is not None and bool(stop.requested)


def mark_partial(result: EvaluationResult, total: int | None) -> EvaluationResult:
    """The result with summary["partial"] = {"episodes": done, "of": total (None: unknown)}: an interrupted
    evaluation's means cover only the scenarios it finished."""
    done = len(result.scenario_ids)
    summary = {**result.summary, "partial": {"episodes": done, "of": total}}
    return dataclasses.replace(result, summary=summary)


def partial_note(summaries: dict[str, dict]) -> str | None:
    """One line saying which results are partial and how many episodes of how many; None if none is."""
    parts = [(name, s["partial"]) for name, s in summaries.items() if s.get("partial")]
    if not parts:
        return None
    counts = ", ".join(f"{name}: {p['episodes']} of {p['of'] if p['of'] is not None else '?'} episodes"
                       for name, p in parts)
    return f"partial results (interrupted): {counts}"


def format_summary(summary: dict) -> str:
    """A small table: episodes, the four scores, then the mean of every episode metric."""
    lines = [f"policy: {summary['policy']}  mode: {summary['mode']}  episodes: {summary['num_episodes']}"]
    if summary.get("partial"):
        lines[0] += f" of {summary['partial']['of'] or '?'} (PARTIAL: interrupted)"
    if summary.get("num_unjudged"):
        lines[0] += f" ({summary['num_unjudged']} with no judged step left out: their SDC log ends at the start)"
    lines += [f"  {key:<28}{summary[key]:>10.4f}" for key in SCORE_KEYS]
    if summary.get("mode_options"):
        lines[0] += "  (" + ", ".join(f"{k}={v}" for k, v in summary["mode_options"].items()) + ")"
    if summary["metrics"].get("other_collision") is not None:  # reactive mode: among the non-SDC objects
        lines.append(f"  {'other_collisions (non-SDC)':<28}{summary['metrics']['other_collision']:>10.4f}")
    lines.append("  metric means:")
    for key, value in summary["metrics"].items():
        lines.append(f"  {key:<28}{'n/a' if value is None else format(value, '>10.4f'):>10}")
    return "\n".join(lines)
