"""`vmax-sim bench`: scene-steps per second of the simulator step on synthetic scenes.

Scenes are random but plausible (straight multi-lane roads crossing the region, vehicles driving
along lanes, lights, SDC paths), generated in numpy as `SimulatorState`s; the map index is built
once per scene on the host, as the data loader builds it. What is timed is the environment training
and evaluation step, built and stepped by their own code: the `Environment` of `make_environment`,
reset at the start of each episode with the route reference arcs (`reference_arcs`), then per step
`Environment.step` with the SDC's action (`sdc_action`), the step's shared queries (`step_inputs`,
`shared_queries`), the metrics (`step_metrics`) and the SDC's observation (`sdc_observation`, which
reuses the shared queries), each only in the configurations that include it. Timings run inside a
jitted `lax.scan` over steps and `vmap` over the batch; compile time is reported separately.

Each row also gives the device memory a scene takes (the nbytes of the batched `SimulatorState`, map index
included, per scene; on an accelerator also the allocator's peak). A batch whose states would not fit in the
free memory is skipped with a note rather than run out of memory. `compare_waymax` times Waymax's own step on
the same scenes with the user's Waymax interpreter (`waymax_timing.py`, run in a subprocess) and prints the
ratios ours / Waymax.
"""

from __future__ import annotations

import json as json_lib
import os
import subprocess
import sys
import tempfile
import time
from functools import lru_cache
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from scenariomax.schema import (
    OBJECT_TYPE_VEHICLE,
    RG_BROKEN_SINGLE_WHITE,
    RG_LANE_SURFACE_STREET,
    RG_ROAD_EDGE_BOUNDARY,
    RG_SOLID_DOUBLE_YELLOW,
    TL_GO,
    TL_STOP,
)
from vmax_sim.datatypes import (
    ObjectMetadata,
    Paths,
    RoadgraphPoints,
    SimulatorState,
    TrafficLights,
    Trajectory,
)
from vmax_sim.env import EnvConfig, make_environment
from vmax_sim.env.chunked_vmap import CPU_CHUNK, chunked_vmap
from vmax_sim.env.metrics_adapter import reference_arcs, sdc_observation, step_inputs
from vmax_sim.evaluation.policies import sdc_action
from vmax_sim.map_index.build import build_map_index, path_arc_length
from vmax_sim.map_index.structure import MapIndexConfig
from vmax_sim.metrics import MetricsConfig, shared_queries, step_metrics
from vmax_sim.observation import ObservationConfig

__all__ = ["CONFIGS", "DEFAULT_BATCH_SIZES", "ENV_KINDS", "compare_with_waymax", "format_table", "make_episode_fns",
           "run_bench", "scene_state", "state_bytes_per_scene", "synthetic_scene", "time_waymax", "timing_runs"]

NUM_STEPS_LOG = 91
LANE_WIDTH = 3.7
HISTORY = 5  # steps from the log before the policy acts (EnvConfig.init_steps); the metrics use the last 3
MIN_MEASURE_S = 1.5  # seconds of timed runs per configuration
DEFAULT_BATCH_SIZES = (1, 32, 256, 1024, 4096)
LARGE_BATCH = 1024  # from here on one run takes seconds on a CPU: 1 warm-up and 3 timed runs keep the bench short
MEMORY_HEADROOM = 2.0  # peak RSS / nbytes of the batch's states, CPU, full step: 2.4 at batch 1024, 1.4 at 4096
WAYMAX_SCRIPT = Path(__file__).with_name("waymax_timing.py")
BENCH_ACTION = (0.2, 0.001)  # the SDC's constant action: acceleration m/s^2, curvature 1/m
# `--env` choices: "real" is the environment above; "minimal" named a stand-in array step that no
# product code ran, now removed: it (and "both") time the real environment.
ENV_KINDS = ("real", "minimal")


# ----------------------------------------------------------------------------- synthetic scenes


def _road_polylines(origin, angle, length, rng_id):
    """Lanes, lines and edges of a 2+2-lane road through `origin`. -> list of (xy (n, 2), type, id)."""
    heading = np.array([np.cos(angle), np.sin(angle)])
    left = np.array([-heading[1], heading[0]])
    s = np.arange(-0.5 * length, 0.5 * length, 1.0)
    out = []
    for k, (offset, kind, backwards) in enumerate([
            (-0.5 * LANE_WIDTH, RG_LANE_SURFACE_STREET, False), (-1.5 * LANE_WIDTH, RG_LANE_SURFACE_STREET, False),
            (0.5 * LANE_WIDTH, RG_LANE_SURFACE_STREET, True), (1.5 * LANE_WIDTH, RG_LANE_SURFACE_STREET, True),
            (0.0, RG_SOLID_DOUBLE_YELLOW, False), (-LANE_WIDTH, RG_BROKEN_SINGLE_WHITE, False),
            (LANE_WIDTH, RG_BROKEN_SINGLE_WHITE, False),
            (-2 * LANE_WIDTH, RG_ROAD_EDGE_BOUNDARY, False), (2 * LANE_WIDTH, RG_ROAD_EDGE_BOUNDARY, True)]):
        ss = s[::-1] if backwards else s
        xy = origin + ss[:, None] * heading + offset * left
        out.append((xy, kind, rng_id * 16 + k))
    return out


def synthetic_scene(num_roadgraph: int, num_objects: int = 64, seed: int = 0) -> dict:
    """A random scene as plain numpy arrays in the shard's conventions (SDC in slot 0)."""
    rng = np.random.default_rng(seed)
    polylines = _road_polylines(np.zeros(2), 0.0, 600.0, 0)
    road = 1
    while sum(len(p[0]) for p in polylines) < num_roadgraph:
        origin = rng.uniform(-250, 250, 2)
        polylines += _road_polylines(origin, rng.uniform(0, np.pi), 500.0, road)
        road += 1
    xy = np.concatenate([p[0] for p in polylines])[:num_roadgraph]
    types = np.concatenate([np.full(len(p[0]), p[1]) for p in polylines])[:num_roadgraph]
    ids = np.concatenate([np.full(len(p[0]), p[2]) for p in polylines])[:num_roadgraph]
    xyz = np.concatenate([xy, np.zeros((len(xy), 1))], 1).astype(np.float32)
    diff = np.diff(xy, axis=0, append=xy[-1:])
    dirs = np.concatenate([diff / np.maximum(np.linalg.norm(diff, axis=1, keepdims=True), 1e-6),
                           np.zeros((len(xy), 1))], 1).astype(np.float32)
    speed_limit = np.where(types == RG_LANE_SURFACE_STREET, 13.4, -1.0).astype(np.float32)

    # vehicles along the lanes of road 0 (both directions), the SDC first on the right lane
    t = np.arange(NUM_STEPS_LOG) * 0.1
    lane_y = rng.choice([-0.5, -1.5, 0.5, 1.5], num_objects) * LANE_WIDTH
    lane_y[0] = -0.5 * LANE_WIDTH
    direction = np.where(lane_y < 0, 1.0, -1.0)
    x0 = rng.uniform(-120, 120, num_objects)
    x0[0] = -40.0
    speed = rng.uniform(3, 14, num_objects)
    speed[0] = 10.0
    obj_x = x0[:, None] + direction[:, None] * speed[:, None] * t[None]
    obj_xy = np.stack([obj_x, np.broadcast_to(lane_y[:, None], obj_x.shape)], -1).astype(np.float32)
    obj_yaw = np.broadcast_to(np.where(direction > 0, 0.0, np.pi)[:, None], obj_x.shape).astype(np.float32)
    obj_vel = np.stack([direction[:, None] * speed[:, None] * np.ones_like(t), np.zeros_like(obj_x)], -1)
    size = np.stack([rng.uniform(4.0, 5.5, num_objects), rng.uniform(1.8, 2.2, num_objects)], -1)

    lights_xy = np.stack([np.linspace(-100, 200, 16), np.full(16, -0.5 * LANE_WIDTH)], -1).astype(np.float32)
    lights_state = np.where(np.arange(16) % 2 == 0, TL_STOP, TL_GO).astype(np.int32)

    px = np.linspace(-60, 240, 300)
    path_xy = np.stack([np.stack([px, np.full(300, -k * 0.5 * LANE_WIDTH)], -1)
                        for k in range(1, 11)]).astype(np.float32)
    path_valid = np.ones((10, 300), bool)
    return {"xyz": xyz, "dir": dirs, "types": types, "ids": ids, "valid": np.ones(len(xy), bool),
                "speed_limit": speed_limit,
                "obj_xy": obj_xy, "obj_yaw": obj_yaw, "obj_vel": obj_vel.astype(np.float32),
                "obj_size": size.astype(np.float32),
                "obj_type": np.full(num_objects, OBJECT_TYPE_VEHICLE, np.int32),
                "obj_valid": np.ones(obj_x.shape, bool),
                "light_xy": lights_xy, "light_lane_id": np.full(16, 0, np.int32), "light_state": lights_state,
                "light_valid": np.ones(16, bool), "path_xy": path_xy, "path_valid": path_valid,
                "path_arc": path_arc_length(path_xy, path_valid),
                "path_on_route": np.arange(10) < 2}


# ----------------------------------------------------------------------------- the environment's states


def scene_state(arrays: dict, map_index_config: MapIndexConfig | None = None) -> SimulatorState:
    """A `synthetic_scene` as a `SimulatorState` at timestep HISTORY - 1, with its map index built on the
    host around the SDC's position there (as the data loader centres it on the current step)."""
    num_objects, num_steps = arrays["obj_valid"].shape
    full = lambda a: np.broadcast_to(np.asarray(a, np.float32)[:, None], (num_objects, num_steps))  # noqa: E731
    log = Trajectory(
        x=arrays["obj_xy"][..., 0], y=arrays["obj_xy"][..., 1], z=np.zeros((num_objects, num_steps), np.float32),
        vel_x=arrays["obj_vel"][..., 0], vel_y=arrays["obj_vel"][..., 1], yaw=arrays["obj_yaw"],
        length=full(arrays["obj_size"][:, 0]), width=full(arrays["obj_size"][:, 1]),
        height=full(np.full(num_objects, 1.6)),
        valid=arrays["obj_valid"],
        timestamp_micros=np.broadcast_to(np.arange(num_steps, dtype=np.int32) * 100_000, (num_objects, num_steps)))
    is_sdc = np.arange(num_objects) == 0
    metadata = ObjectMetadata(ids=np.arange(num_objects, dtype=np.int32), object_types=arrays["obj_type"],
                              is_sdc=is_sdc, is_controlled=is_sdc, is_controllable=is_sdc,
                              is_valid=np.ones(num_objects, bool), objects_of_interest=np.zeros(num_objects, bool))
    xyz, dirs = arrays["xyz"], arrays["dir"]
    roadgraph = RoadgraphPoints(x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], dir_x=dirs[:, 0], dir_y=dirs[:, 1],
                                dir_z=dirs[:, 2], types=arrays["types"].astype(np.int32),
                                ids=arrays["ids"].astype(np.int32),
                                valid=arrays["valid"], speed_limit=arrays["speed_limit"])
    num_lights = arrays["light_xy"].shape[0]
    over_time = lambda a: np.broadcast_to(np.asarray(a)[:, None], (num_lights, num_steps))  # noqa: E731
    lights = TrafficLights(x=over_time(arrays["light_xy"][:, 0]), y=over_time(arrays["light_xy"][:, 1]),
                           z=over_time(np.zeros(num_lights, np.float32)), state=over_time(arrays["light_state"]),
                           lane_ids=over_time(arrays["light_lane_id"]), valid=over_time(arrays["light_valid"]))
    path_xy = arrays["path_xy"]
    paths = Paths(x=path_xy[..., 0], y=path_xy[..., 1], z=np.zeros(path_xy.shape[:2], np.float32),
                  ids=np.full(path_xy.shape[:2], -1, np.int32), valid=arrays["path_valid"],
                  arc_length=arrays["path_arc"],
                  on_route=arrays["path_on_route"])
    map_index = build_map_index(xyz, dirs, arrays["types"], arrays["ids"], arrays["valid"], map_index_config,
                                arrays["obj_xy"][0, HISTORY - 1], speed_limit=arrays["speed_limit"])
    state = SimulatorState(log_trajectory=log, sim_trajectory=log, object_metadata=metadata, roadgraph_points=roadgraph,
                           log_traffic_light=lights, sdc_paths=paths, map_index=map_index,
                           timestep=np.asarray(HISTORY - 1, np.int32))
    return jax.tree_util.tree_map(jnp.asarray, state)


@lru_cache(maxsize=4)
def _distinct_scenes(count: int, num_objects: int, num_roadgraph: int) -> SimulatorState:
    """`count` different scene states stacked on a leading axis (kept: building a map index takes ~1 s)."""
    distinct = [scene_state(synthetic_scene(num_roadgraph, num_objects, seed)) for seed in range(count)]
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *distinct)


def _scenes(batch: int, num_objects: int, num_roadgraph: int, num_distinct: int = 4) -> SimulatorState:
    """`batch` states (leading axis) cycling through `num_distinct` different scenes."""
    distinct = _distinct_scenes(min(batch, num_distinct), num_objects, num_roadgraph)
    cycle = jnp.arange(batch) % min(batch, num_distinct)  # one gather per array, not `batch` copies to stack
    return jax.tree_util.tree_map(lambda x: jnp.take(x, cycle, axis=0), distinct)


# ----------------------------------------------------------------------------- the timed step


def make_episode_fns(with_observation: bool, with_metrics: bool, num_objects: int = 64,
                     metrics_config: MetricsConfig | None = None, obs_config: ObservationConfig | None = None):
    """(init_fn, step_fn) of one scene's episode, as evaluation (`run_episode`) and training (`LearningEnv`)
    run it. init_fn(state) -> (env state, route reference arcs): `Environment.reset`, then `reference_arcs`.
    step_fn(arcs, state, action (2,)) -> (state, a scalar that keeps every computed part alive): the SDC's
    action through `Environment.step`; with metrics or observation, the step's shared queries (candidate
    objects, path projection); with metrics, `step_metrics`; with observation, `sdc_observation`."""
    metrics_config = metrics_config or MetricsConfig()
    obs_config = obs_config or ObservationConfig()
    env = make_environment(EnvConfig(max_num_objects=num_objects, init_steps=HISTORY), metrics_config)

    def init_fn(state: SimulatorState):
        state = env.reset(state)
        return state, reference_arcs(state, env.config)

    def step_fn(arcs, state: SimulatorState, action):
        state = env.step(state, sdc_action(state, action))
        out = jnp.sum(state.current_sim_trajectory.x)  # keeps the log replay alive in the env-only config
        if with_metrics or with_observation:
            inputs = step_inputs(state, arcs)
            shared = shared_queries(inputs, metrics_config)
        if with_metrics:
            values = step_metrics(state.map_index, inputs, metrics_config, shared)
            out = out + sum(values.values())
        if with_observation:
            obs = sdc_observation(state, shared, obs_config)
            out = out + jnp.sum(obs.objects) + jnp.sum(obs.roadgraph) + jnp.sum(obs.lights) + jnp.sum(obs.path_targets)
        return state, out

    return init_fn, step_fn


def timing_runs(batch: int) -> dict:
    """How a batch is timed: `warmups` untimed runs, then at least `repeats` runs and `min_seconds` of them."""
    if batch >= LARGE_BATCH:
        return {"warmups": 1, "repeats": 3, "min_seconds": 0.0}
    return {"warmups": 3, "repeats": 5, "min_seconds": MIN_MEASURE_S}


def make_rollout(init_fn, step_fn, steps: int):
    """The timed program: each scene's episode (init_fn, then `steps` of step_fn with BENCH_ACTION in a
    `lax.scan`) vmapped over the batch and jitted. scenes (B, ...) -> () float32 that keeps every step and the
    written trajectory alive."""
    action = jnp.asarray(BENCH_ACTION, jnp.float32)

    def episode(scene):
        state, arcs = init_fn(scene)

        def body(state, _):
            state, out = step_fn(arcs, state, action)
            return state, out
        final, outs = jax.lax.scan(body, state, None, length=steps)
        return jnp.sum(outs) + written_checksum(final.sim_trajectory)

    return jax.jit(chunked_vmap(episode))


WRITTEN_FIELDS = ("x", "y", "yaw", "vel_x", "vel_y", "valid")  # what a step writes that a user reads


def written_checksum(trajectory) -> jax.Array:
    """Sum of the final trajectory's WRITTEN_FIELDS. Without it, a simulator that caches the current step
    would have its trajectory writes removed as dead code and time less work than one that reads the
    trajectory back (Waymax's timing program keeps the same fields). (..., N, T) -> () float32."""
    return sum(jnp.sum(getattr(trajectory, name).astype(jnp.float32)) for name in WRITTEN_FIELDS)


def _time_config(scenes: SimulatorState, init_fn, step_fn, steps: int) -> dict:
    """{compile_s, runs, best and median scene-steps/s} of `steps` steps of a batch in one jitted program.

    Like evaluation and training rollouts, each scene's episode (init + `lax.scan` over steps) is vmapped
    over the batch. The episode starts inside the vmapped function, so the timestep is a shared scalar
    (all scenes step in lockstep) and trajectory reads/writes are slices, not gathers/scatters.
    """
    rollout = make_rollout(init_fn, step_fn, steps)
    batch = jax.tree_util.tree_leaves(scenes)[0].shape[0]
    runs = timing_runs(batch)
    start = time.perf_counter()
    compiled = rollout.lower(scenes).compile()
    compile_s = time.perf_counter() - start
    for _ in range(runs["warmups"]):  # the first runs in a process pay for thread pools and page faults
        jax.block_until_ready(compiled(scenes))
    # Best of at least `repeats` runs and at least `min_seconds` of measuring: a shared or virtual machine has
    # bursts of contention, and the best run is the one that reflects the code (the median is for comparisons).
    times: list[float] = []
    while len(times) < runs["repeats"] or sum(times) < runs["min_seconds"]:
        start = time.perf_counter()
        jax.block_until_ready(compiled(scenes))
        times.append(time.perf_counter() - start)
    return {"compile_s": compile_s, "runs": len(times), "best_sps": batch * steps / min(times),
            "median_sps": batch * steps / float(np.median(times))}


def state_bytes_per_scene(scenes: SimulatorState) -> dict:
    """Device bytes one scene of a batch takes: the whole state (map index included) and its map index."""
    batch = jax.tree_util.tree_leaves(scenes)[0].shape[0]
    nbytes = lambda tree: sum(leaf.nbytes for leaf in jax.tree_util.tree_leaves(tree))  # noqa: E731
    return {"bytes_per_scene": round(nbytes(scenes) / batch), "map_index_bytes_per_scene":
            round(nbytes(scenes.map_index) / batch)}


def _device_peak_bytes() -> int | None:
    """The allocator's peak bytes in use so far in this process (accelerators; None where not reported)."""
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")


def _available_bytes() -> int | None:
    """Free memory for a batch: the allocator's limit minus use on an accelerator, MemAvailable on a CPU.
    (waymax_timing.py has its own copy: it runs without vmax_sim.)"""
    stats = jax.devices()[0].memory_stats() or {}
    if "bytes_limit" in stats:
        return int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


@lru_cache(maxsize=8)
def _scene_bytes(num_objects: int, num_roadgraph: int) -> int:
    """nbytes of one scene's state, built as the bench builds them (before building a whole batch)."""
    state = scene_state(synthetic_scene(num_roadgraph, num_objects, 0))
    return sum(leaf.nbytes for leaf in jax.tree_util.tree_leaves(state))


def _does_not_fit(batch: int, num_objects: int, num_roadgraph: int) -> str | None:
    """Why a batch would run the device out of memory, or None when it fits (or free memory is unknown)."""
    available = _available_bytes()
    needed = MEMORY_HEADROOM * batch * _scene_bytes(num_objects, num_roadgraph)
    if available is None or needed <= available:
        return None
    return f"needs ~{needed / 1e9:.1f} GB, {available / 1e9:.1f} GB free"


CONFIGS = {"env": (False, False), "env+obs": (True, False), "env+metrics": (False, True),
           "env+metrics+obs": (True, True)}


def _timed(batch: int, num_objects: int, roadgraph: int, config: str, steps: int) -> dict:
    with_obs, with_metrics = CONFIGS[config]
    init_fn, step_fn = make_episode_fns(with_obs, with_metrics, num_objects)
    scenes = _scenes(batch, num_objects, roadgraph)
    timing = _time_config(scenes, init_fn, step_fn, steps)
    row = {"env": "real", "config": config, "batch": batch, "roadgraph": roadgraph,
           "compile_s": round(timing["compile_s"], 2), "scene_steps_per_s": round(timing["best_sps"]),
           "median_scene_steps_per_s": round(timing["median_sps"]), "runs": timing["runs"],
           **state_bytes_per_scene(scenes)}
    peak = _device_peak_bytes()
    if peak is not None:
        row["device_peak_bytes"] = int(peak)
    return row


def _check_env_kinds(env_kinds) -> None:
    """Every `--env` choice times the real environment; say so when the retired stand-in is asked for."""
    unknown = sorted(set(env_kinds) - set(ENV_KINDS))
    if unknown:
        raise ValueError(f"unknown env kind(s) {', '.join(unknown)}; choose among {', '.join(ENV_KINDS)}")
    if "minimal" in env_kinds:
        print("note: the minimal array step was removed; timing the real environment only", file=sys.stderr)


def run_bench(batch_sizes=DEFAULT_BATCH_SIZES, num_objects: int = 64, roadgraph_sizes=(5000, 15000, 30000),
              steps: int = 80, json: bool = False, configs=tuple(CONFIGS), env_kinds=("real",),
              compare_waymax: str | None = None) -> dict:
    """Time every configuration at each batch size (largest roadgraph), then the full step at
    each roadgraph size (batch 32 or the nearest given). A batch whose states would not fit in free memory is
    skipped (listed under "skipped"). env_kinds: kept for `--env`; every kind times the real environment (see
    ENV_KINDS). compare_waymax: path of a Python interpreter with Waymax installed; its physics step is timed
    on the same scenes first (before this process takes the device's memory). Prints a table (or JSON) and
    returns {"device", "configs": [...], "roadgraph_scaling": [...], "skipped": [...], "waymax": {...}}.
    Raises ValueError (one line) when the Waymax interpreter cannot be run or has no Waymax."""
    _check_env_kinds(env_kinds)
    biggest = max(roadgraph_sizes)
    waymax = time_waymax(compare_waymax, batch_sizes, num_objects, biggest, steps) if compare_waymax else None
    device = f"{jax.devices()[0].platform}:{jax.devices()[0].device_kind}"
    results = {"device": device, "num_objects": num_objects, "steps": steps, "configs": [], "roadgraph_scaling": [],
               "skipped": []}
    for batch in batch_sizes:
        reason = _does_not_fit(batch, num_objects, biggest)
        if reason:
            results["skipped"].append({"batch": batch, "reason": reason})
            continue
        for name in configs:
            results["configs"].append(_timed(batch, num_objects, biggest, name, steps))
    timed_batches = sorted({row["batch"] for row in results["configs"]}) or list(batch_sizes)
    scaling_batch = min(timed_batches, key=lambda b: abs(b - 32))
    timed = {(row["batch"], row["roadgraph"], row["config"]): row for row in results["configs"]}
    for size in roadgraph_sizes:  # the largest size's full step at this batch was timed above: reuse that row
        row = timed.get((scaling_batch, size, "env+metrics+obs"))
        results["roadgraph_scaling"].append(row or _timed(scaling_batch, num_objects, size, "env+metrics+obs", steps))
    if waymax is not None:
        results["waymax"] = compare_with_waymax(waymax, results["configs"])
    if json:
        print(json_lib.dumps(results, indent=2))
    else:
        print(format_table(results))
    return results


# ----------------------------------------------------------------------------- Waymax side by side


def _waymax_request(batch_sizes, num_objects: int, steps: int) -> dict:
    """What waymax_timing.py runs: the bench's episode (init steps, action, steps) and timing policy per batch."""
    return {"num_objects": num_objects, "steps": steps, "init_steps": HISTORY, "action": list(BENCH_ACTION),
            "runs": [{"batch": batch, **timing_runs(batch)} for batch in batch_sizes]}


def _write_scenes(path: Path, count: int, num_objects: int, num_roadgraph: int) -> None:
    """The bench's synthetic scenes (seeds 0..count-1, as `_scenes` cycles them) as `<seed>/<field>` arrays."""
    arrays = {f"{seed}/{name}": value for seed in range(count)
              for name, value in synthetic_scene(num_roadgraph, num_objects, seed).items()}
    np.savez(path, **arrays)


def _check_interpreter(python: str) -> None:
    path = Path(python)
    hint = "give --compare-waymax the path of a Python interpreter with Waymax installed, e.g. ~/waymax-venv/bin/python"
    if not path.exists():
        raise ValueError(f"{python}: no such file; {hint}")
    if path.is_dir() or not os.access(path, os.X_OK):
        raise ValueError(f"{python}: not an executable file; {hint}")


def time_waymax(python: str, batch_sizes, num_objects: int, num_roadgraph: int, steps: int) -> dict:
    """Time Waymax's physics step on the bench's scenes with the interpreter `python` (waymax_timing.py in a
    subprocess). Returns the script's JSON ({"waymax", "jax", "device", "rows", "skipped"}) plus "python".
    Raises ValueError, one line naming the interpreter, when it cannot run or its environment lacks Waymax."""
    _check_interpreter(python)
    print(f"timing Waymax's step with {python} (batch {', '.join(map(str, batch_sizes))}) ...", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="vmax-bench-") as folder:
        scenes = Path(folder) / "scenes.npz"
        _write_scenes(scenes, min(max(batch_sizes), 4), num_objects, num_roadgraph)
        request = json_lib.dumps(_waymax_request(batch_sizes, num_objects, steps))
        env = {**os.environ, "TF_CPP_MIN_LOG_LEVEL": "3"}  # Waymax imports TensorFlow: keep its banner quiet
        try:
            done = subprocess.run([python, str(WAYMAX_SCRIPT), str(scenes), request], capture_output=True, text=True,
                                  env=env, check=False)
        except OSError as error:
            raise ValueError(f"{python}: cannot run it ({error.strerror or error}); it must be a Python "
                             "interpreter with Waymax installed") from None
    reply = _last_json_line(done.stdout)
    if reply is None:
        last = (done.stderr.strip().splitlines() or [f"exit status {done.returncode}, no output"])[-1]
        raise ValueError(f"{python}: the Waymax timing script failed: {last}")
    if "error" in reply:
        raise ValueError(f"{python}: {reply['error']}; install Waymax into that environment from its source "
                         "(github.com/waymo-research/waymax; the PyPI package named 'waymax' is another project)")
    return {"python": python, **reply}


def _last_json_line(text: str) -> dict | None:
    for line in reversed(text.strip().splitlines()):
        try:
            value = json_lib.loads(line)
        except ValueError:
            continue
        return value if isinstance(value, dict) else None
    return None


def compare_with_waymax(waymax: dict, rows: list[dict]) -> dict:
    """Median scene-steps/s side by side at each batch both timed: ours / Waymax for the physics-only step
    ("env"), and our full step (env + metrics + observation) over Waymax's physics step."""
    ours = {(row["batch"], row["config"]): row.get("median_scene_steps_per_s") for row in rows}
    compared = []
    for row in waymax.get("rows", []):
        theirs = row["median_scene_steps_per_s"]
        physics, full = ours.get((row["batch"], "env")), ours.get((row["batch"], "env+metrics+obs"))
        compared.append({"batch": row["batch"], "waymax_physics": theirs, "ours_physics": physics,
                         "physics_ratio": round(physics / theirs, 3) if physics and theirs else None,
                         "ours_full": full, "full_over_waymax_physics": round(full / theirs, 3) if full and theirs
                         else None, "waymax_bytes_per_scene": row.get("bytes_per_scene")})
    return {key: waymax.get(key) for key in ("python", "waymax", "jax", "device")} | {
        "rows": compared, "skipped": waymax.get("skipped", [])}


def _row_key(row: dict) -> tuple:
    return row.get("env"), row["config"], row["batch"], row["roadgraph"]


def table_rows(results: dict) -> list[dict]:
    """Every timed configuration, then the roadgraph-scaling rows not among them: run_bench reuses the full step
    it timed at the largest roadgraph for that size's scaling row, which would otherwise be printed twice."""
    rows = list(results["configs"])
    seen = {_row_key(row) for row in rows}
    for row in results["roadgraph_scaling"]:
        if _row_key(row) not in seen:
            rows.append(row)
            seen.add(_row_key(row))
    return rows


def table_legend(with_peak: bool) -> list[str]:
    """What the columns measure, under the table."""
    peak = "; peak MB: the device allocator's peak so far" if with_peak else ""
    return ["scene-steps/s: scenes x steps simulated per second of wall time, best timed run (median: the median run)",
            "env: real = make_environment's Environment; config: env = its step alone, +obs / +metrics add the SDC's "
            "observation / the step metrics",
            f"compile s: compiling the jitted rollout; MB/scene: one scene's state on the device, map index "
            f"included{peak}"]


def format_table(results: dict) -> str:
    rows = table_rows(results)
    with_peak = any("device_peak_bytes" in row for row in rows)
    lines = [f"device: {results['device']}  objects: {results['num_objects']}  steps: {results['steps']}",
             f"{'env':<9}{'config':<18}{'batch':>6}{'roadgraph':>10}{'compile s':>10}{'scene-steps/s':>15}"
             f"{'median':>10}{'MB/scene':>10}" + (f"{'peak MB':>10}" if with_peak else "")]
    for row in rows:
        line = (f"{row.get('env', 'minimal'):<9}{row['config']:<18}{row['batch']:>6}{row['roadgraph']:>10}"
                f"{row['compile_s']:>10}{row['scene_steps_per_s']:>15,}"
                f"{_cell(row.get('median_scene_steps_per_s'), '{:,}'):>10}"
                f"{_cell(row.get('bytes_per_scene'), '{:.2f}', 1e-6):>10}")
        if with_peak:
            line += f"{_cell(row.get('device_peak_bytes'), '{:,.0f}', 1e-6):>10}"
        lines.append(line)
    lines += table_legend(with_peak)
    index_bytes = sorted({row["map_index_bytes_per_scene"] for row in rows if "map_index_bytes_per_scene" in row})
    if index_bytes:  # one value per roadgraph size at most; the map index's shapes do not depend on it
        lines.append(f"map index bytes per scene: {', '.join(f'{b:,}' for b in index_bytes)}")
    lines += [f"skipped batch {skip['batch']}: {skip['reason']}" for skip in results.get("skipped", [])]
    if results["device"].startswith("cpu") and any(row["batch"] > CPU_CHUNK for row in rows):
        lines.append(f"batches above {CPU_CHUNK} ran as a loop over chunks of {CPU_CHUNK} episodes (chunked_vmap, as "
                     "evaluation runs them on CPU)")
    if "waymax" in results:
        lines += ["", *format_waymax(results["waymax"], results["device"])]
    return "\n".join(lines)


def _cell(value, pattern: str, scale: float = 1.0) -> str:
    """A table cell: `value * scale` formatted with `pattern`, or "-" when the value is missing."""
    return "-" if value is None else pattern.format(value * scale if scale != 1.0 else value)


def format_waymax(waymax: dict, device: str) -> list[str]:
    ratio = lambda value: _cell(value, "{:.2f}x")  # noqa: E731
    count = lambda value: _cell(value, "{:,}")  # noqa: E731
    lines = [f"Waymax {waymax['waymax']} (jax {waymax['jax']}, {waymax['device']}) run by {waymax['python']}",
             "median scene-steps/s on the same scenes; physics = env step only, full = env + metrics + observation;",
             "both sides keep the written trajectory (bench.WRITTEN_FIELDS)",
             f"{'batch':>6}{'Waymax physics':>16}{'ours physics':>14}{'ours/Waymax':>13}{'ours full':>11}"
             f"{'ours full/Waymax physics':>26}"]
    for row in waymax["rows"]:
        lines.append(f"{row['batch']:>6}{count(row['waymax_physics']):>16}{count(row['ours_physics']):>14}"
                     f"{ratio(row['physics_ratio']):>13}{count(row['ours_full']):>11}"
                     f"{ratio(row['full_over_waymax_physics']):>26}")
    lines += [f"Waymax skipped batch {skip['batch']}: {skip['reason']}" for skip in waymax.get("skipped", [])]
    if waymax["device"] != device:
        lines.append(f"note: Waymax ran on {waymax['device']} and ours on {device}: the ratios compare two devices")
    return lines
