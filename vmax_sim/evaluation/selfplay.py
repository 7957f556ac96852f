"""Self-play evaluation: one policy drives every agent of held-out scenes (`SelfPlayEnv`), one episode per scene;
goal-reaching, collision, off-road and red-light rates per agent and per scene.

An agent reaches its goal within `SelfPlayConfig.goal_radius_m` of its last logged position (GPUDrive's
goal-reaching); its episode ends there, at a collision, off the road, at a red light or at the scene's time limit.
The policy acts every simulator step (action repeat 1), deterministically, as in the SDC evaluation.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable

import jax
import jax.numpy as jnp
import numpy as np

from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.selfplay import SelfPlayEnv

AGENT_OUTCOMES = ("goal_reached", "overlap", "offroad", "red_light")
# act(params, observation (R, ...), key) -> actions (R, A) in [-1, 1]; None: every agent drives by its teacher's
# label (`SelfPlayEnv.teacher`, a rule driver on the agent's own view)
ActFn = Callable[[object, object, jax.Array], jax.Array] | None


def episode_outcomes(env: SelfPlayEnv, act: ActFn, params, scenes: SimulatorState, key: jax.Array) -> dict:
    """One episode of each of the B scenes -> name -> (B, K): `present` (the slot held an agent) and, per agent,
    each of AGENT_OUTCOMES during its episode and `length` (its policy steps). Jittable."""
    if act is None and env.teacher is None:
        raise ValueError("a self-play episode without a policy needs SelfPlayEnv(teacher=...) to drive the agents")
    batch = scenes.timestep.shape[0]
    state = env.reset(scenes, batch, key)
    present = state.present
    steps = math.ceil(env.env_config.episode_length / env.action_repeat)
    k = state.slots.shape[1]

    def one(carry, step_key):
        state, finished = carry  # finished (B,): the scene's episode is over (later steps are a new one)
        act_key, _ = jax.random.split(step_key)
        action = state.expert_action if act is None else act(params, state.observation, act_key)
        state, out = env.step(state, action, scenes)
        counted = jnp.repeat(~finished, k)  # (B * K,)
        record = {name: out.episode_flags[name] & counted for name in AGENT_OUTCOMES}
        record["length"] = jnp.where(counted, out.episode_length, 0)
        return (state, finished | out.scene_done), record

    _, records = jax.lax.scan(one, (state, jnp.zeros(batch, bool)), jax.random.split(key, steps))
    outcomes = {name: jnp.any(records[name], axis=0).reshape(batch, k) for name in AGENT_OUTCOMES}
    outcomes["length"] = jnp.max(records["length"], axis=0).reshape(batch, k)
    outcomes["present"] = present
    return outcomes


@dataclasses.dataclass(frozen=True)
class SelfPlayResult:
    agents: dict  # name -> (num_agents,) per present agent: AGENT_OUTCOMES (bool), length, scene (int)
    scene_ids: list[str]

    @property
    def num_agents(self) -> int:
        return int(len(self.agents["scene"]))

    def summary(self) -> dict:
        """Rates over agents and scenes (fractions in [0, 1])."""
        agents = self.agents
        crashed = agents["overlap"] | agents["offroad"]
        clean_goal = agents["goal_reached"] & ~crashed & ~agents["red_light"]
        scenes = np.unique(agents["scene"])
        all_clean = [bool(np.all(clean_goal[agents["scene"] == s])) for s in scenes]
        rate = (lambda x: float(np.mean(x))) if self.num_agents else (lambda x: math.nan)  # noqa: E731
        return {"mode": "selfplay", "num_scenes": len(self.scene_ids), "num_agents": self.num_agents,
                "agents_per_scene": self.num_agents / max(len(self.scene_ids), 1),
                "goal_reached": rate(agents["goal_reached"]), "collision": rate(agents["overlap"]),
                "offroad": rate(agents["offroad"]), "red_light": rate(agents["red_light"]),
                "collision_or_offroad": rate(crashed), "goal_reached_clean": rate(clean_goal),
                "scenes_all_agents_clean_goal": float(np.mean(all_clean)) if all_clean else math.nan}


def evaluate_selfplay(env: SelfPlayEnv, act: ActFn, params, batches: Iterable[tuple[list[str], SimulatorState, int]],
                      seed: int = 0, on_batch: Callable[[int], None] | None = None) -> SelfPlayResult:
    """Every batch of (scenario ids, scenes (B, ...) padded to the batch size, number of real ones), as
    `vmax_sim.evaluation.evaluate.scenario_batches` gives them -> per agent outcomes of the real scenes."""
    run = _compiled(env, act)
    collected: dict[str, list] = {name: [] for name in (*AGENT_OUTCOMES, "length", "scene")}
    ids: list[str] = []
    for number, (scene_ids, scenes, real) in enumerate(batches):
        outcomes = jax.device_get(run(params, jax.device_put(scenes), jax.random.PRNGKey(seed + number)))
        present = np.asarray(outcomes["present"])[:real]
        for name in (*AGENT_OUTCOMES, "length"):
            collected[name].append(np.asarray(outcomes[name])[:real][present])
        scene_index = np.broadcast_to(np.arange(len(ids), len(ids) + real)[:, None], present.shape)
        collected["scene"].append(scene_index[present])
        ids.extend(scene_ids)
        if on_batch is not None:
            on_batch(real)
    agents = {name: np.concatenate(parts) if parts else np.zeros(0) for name, parts in collected.items()}
    return SelfPlayResult(agents=agents, scene_ids=ids)


_COMPILED: dict = {}


def _compiled(env: SelfPlayEnv, act: ActFn):
    """The jitted episode of (env, act), once per process (a training run evaluates many times)."""
    if (env, act) not in _COMPILED:
        _COMPILED[(env, act)] = jax.jit(lambda p, scenes, key: episode_outcomes(env, act, p, scenes, key))
    return _COMPILED[(env, act)]


def format_selfplay(summary: dict, title: str = "self-play") -> str:
    """The summary as a small aligned table (percentages; goal higher is better, the rest lower)."""
    rows = [("goal reached (higher is better)", summary["goal_reached"]),
            ("goal reached, no collision / off-road / red light", summary["goal_reached_clean"]),
            ("collision (overlap)", summary["collision"]), ("off-road", summary["offroad"]),
            ("red light", summary["red_light"]), ("collision or off-road (lower is better)",
                                                  summary["collision_or_offroad"]),
            ("scenes where every agent reached its goal cleanly", summary["scenes_all_agents_clean_goal"])]
    lines = [f"{title}: {summary['num_agents']} agents in {summary['num_scenes']} scenes "
             f"({summary['agents_per_scene']:.1f} per scene)"]
    lines += [f"  {name:<52} {100 * value:6.1f} %" for name, value in rows]
    return "\n".join(lines)
