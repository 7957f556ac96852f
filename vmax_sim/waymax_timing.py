"""The Waymax side of `vmax-sim bench --compare-waymax PYTHON`: a standalone script run by the user's interpreter.

    PYTHON waymax_timing.py SCENES.npz REQUEST_JSON

It imports only the standard library, numpy, jax and waymax (never vmax_sim: the interpreter that runs it is the
user's Waymax environment). SCENES.npz holds the bench's synthetic scenes as plain arrays (keys `<seed>/<name>`,
the fields of `vmax_sim.bench.synthetic_scene`), so both simulators step the same scenes. Each scene becomes a
Waymax `SimulatorState`; the batch cycles through the scenes as the bench's does. The timed program is Waymax's
planning-agent environment (`PlanningAgentEnvironment` with the invertible bicycle model; the SDC is driven by a
constant action, the others replay the log): reset, then a `lax.scan` of `env.step` over the steps, vmapped over
the batch and jitted — the bench's "env" (physics-only) configuration.

REQUEST_JSON: {"num_objects", "steps", "init_steps", "action": [accel, curvature],
"runs": [{"batch", "warmups", "repeats", "min_seconds"}, ...]}.
Prints one JSON line on stdout: {"waymax", "jax", "device", "rows": [{"batch", "compile_s", "runs",
"best_scene_steps_per_s", "median_scene_steps_per_s", "bytes_per_scene"}], "skipped": [{"batch", "reason"}]},
or {"error": "..."} with exit status 2 when waymax cannot be imported or the request cannot be run.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import time

try:
    import jax
    import jax.numpy as jnp
    import numpy as np
except ImportError as error:  # main() reports it as JSON: this interpreter is no Waymax environment
    _MISSING_MODULE: ImportError | None = error
else:
    _MISSING_MODULE = None

MEMORY_HEADROOM = 2.0  # the batch's arrays, the scan's carried copy and temporaries (as the bench estimates)


def _emit(payload: dict, status: int = 0) -> None:
    print(json.dumps(payload), flush=True)
    sys.exit(status)


def _available_bytes() -> int | None:
    """Free memory of the default device: the allocator's limit on an accelerator, MemAvailable on a CPU."""
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


def _waymax_scene(arrays: dict, datatypes):
    """One bench scene (plain arrays) as an uninitialised Waymax `SimulatorState`."""
    num_objects, num_steps = arrays["obj_valid"].shape
    per_step = lambda a: np.broadcast_to(np.asarray(a, np.float32)[:, None], (num_objects, num_steps))  # noqa: E731
    trajectory = datatypes.Trajectory(
        x=arrays["obj_xy"][..., 0], y=arrays["obj_xy"][..., 1], z=np.zeros((num_objects, num_steps), np.float32),
        vel_x=arrays["obj_vel"][..., 0], vel_y=arrays["obj_vel"][..., 1], yaw=arrays["obj_yaw"],
        valid=arrays["obj_valid"],
        timestamp_micros=np.broadcast_to(np.arange(num_steps, dtype=np.int32) * 100_000, (num_objects, num_steps)),
        length=per_step(arrays["obj_size"][:, 0]), width=per_step(arrays["obj_size"][:, 1]),
        height=per_step(np.full(num_objects, 1.6)))
    is_sdc = np.arange(num_objects) == 0
    metadata = datatypes.ObjectMetadata(
        ids=np.arange(num_objects, dtype=np.int32), object_types=arrays["obj_type"].astype(np.int32), is_sdc=is_sdc,
        is_modeled=is_sdc, is_valid=np.ones(num_objects, bool), objects_of_interest=np.zeros(num_objects, bool),
        is_controlled=is_sdc)
    xyz, dirs = arrays["xyz"], arrays["dir"]
    roadgraph = datatypes.RoadgraphPoints(
        x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], dir_x=dirs[:, 0], dir_y=dirs[:, 1], dir_z=dirs[:, 2],
        types=arrays["types"].astype(np.int32), ids=arrays["ids"].astype(np.int32), valid=arrays["valid"])
    num_lights = arrays["light_xy"].shape[0]
    over_time = lambda a: np.broadcast_to(np.asarray(a)[:, None], (num_lights, num_steps))  # noqa: E731
    lights = datatypes.TrafficLights(
        x=over_time(arrays["light_xy"][:, 0]), y=over_time(arrays["light_xy"][:, 1]),
        z=over_time(np.zeros(num_lights, np.float32)), state=over_time(arrays["light_state"].astype(np.int32)),
        lane_ids=over_time(arrays["light_lane_id"].astype(np.int32)), valid=over_time(arrays["light_valid"]))
    path_xy = arrays["path_xy"]
    paths = datatypes.Paths(
        x=path_xy[..., 0], y=path_xy[..., 1], z=np.zeros(path_xy.shape[:2], np.float32),
        ids=np.full(path_xy.shape[:2], -1, np.int32), valid=arrays["path_valid"], arc_length=arrays["path_arc"],
        on_route=arrays["path_on_route"][:, None])
    state = datatypes.SimulatorState(
        sim_trajectory=trajectory, log_trajectory=trajectory, log_traffic_light=lights, object_metadata=metadata,
        timestep=np.asarray(-1, np.int32), sdc_paths=paths, roadgraph_points=roadgraph)
    return jax.tree_util.tree_map(jnp.asarray, state)


def _scenes_by_seed(npz) -> list[dict]:
    seeds = sorted({key.split("/", 1)[0] for key in npz.files}, key=int)
    return [{key.split("/", 1)[1]: npz[key] for key in npz.files if key.split("/", 1)[0] == seed} for seed in seeds]


def _time_batch(rollout, batch_scenes, run: dict) -> dict:
    """Compile, warm up, then time at least `repeats` runs and `min_seconds` of runs (as the bench does)."""
    start = time.perf_counter()
    compiled = rollout.lower(batch_scenes).compile()
    compile_s = time.perf_counter() - start
    for _ in range(run["warmups"]):
        jax.block_until_ready(compiled(batch_scenes))
    times: list[float] = []
    while len(times) < run["repeats"] or sum(times) < run["min_seconds"]:
        start = time.perf_counter()
        jax.block_until_ready(compiled(batch_scenes))
        times.append(time.perf_counter() - start)
    return {"compile_s": round(compile_s, 2), "runs": len(times), "best_s": min(times),
            "median_s": statistics.median(times)}


def main(argv: list[str]) -> None:
    if len(argv) != 3:
        _emit({"error": "usage: waymax_timing.py SCENES.npz REQUEST_JSON"}, 2)
    try:
        if _MISSING_MODULE is not None:
            raise _MISSING_MODULE
        from waymax import config as waymax_config
        from waymax import datatypes, dynamics, env
    except ImportError as error:
        _emit({"error": f"cannot import {error.name or 'waymax'}: {error}"}, 2)
    try:
        from importlib.metadata import version

        waymax_version = version("waymo-waymax")
    except Exception:  # noqa: BLE001 - a source checkout on sys.path has no distribution metadata
        waymax_version = "unknown"

    request = json.loads(argv[2])
    with np.load(argv[1]) as npz:
        distinct = [_waymax_scene(arrays, datatypes) for arrays in _scenes_by_seed(npz)]
    environment = env.PlanningAgentEnvironment(
        dynamics_model=dynamics.InvertibleBicycleModel(),
        config=waymax_config.EnvironmentConfig(max_num_objects=request["num_objects"],
                                               init_steps=request["init_steps"],
                                               controlled_object=waymax_config.ObjectType.SDC, compute_reward=False))
    action = datatypes.Action(data=jnp.asarray(request["action"], jnp.float32), valid=jnp.ones((1,), bool))

    def episode(scene):
        state = environment.reset(scene)

        def body(state, _):
            state = environment.step(state, action)
            return state, jnp.sum(state.current_sim_trajectory.x)  # as the bench's env-only step keeps it alive
        final, outs = jax.lax.scan(body, state, None, length=request["steps"])
        # the trajectory fields the bench's program keeps alive too (vmax_sim.bench.WRITTEN_FIELDS)
        written = final.sim_trajectory
        return jnp.sum(outs) + sum(jnp.sum(getattr(written, name).astype(jnp.float32))
                                   for name in ("x", "y", "yaw", "vel_x", "vel_y", "valid"))

    rollout = jax.jit(jax.vmap(episode))
    device = jax.devices()[0]
    result = {"waymax": waymax_version, "jax": jax.__version__, "device": f"{device.platform}:{device.device_kind}",
              "rows": [], "skipped": []}
    scene_bytes = sum(leaf.nbytes for leaf in jax.tree_util.tree_leaves(distinct[0]))
    stacked = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *distinct)
    for run in request["runs"]:
        batch = run["batch"]
        available, needed = _available_bytes(), MEMORY_HEADROOM * batch * scene_bytes
        if available is not None and needed > available:
            reason = f"needs ~{needed / 1e9:.1f} GB, {available / 1e9:.1f} GB free"
            result["skipped"].append({"batch": batch, "reason": reason})
            continue
        cycle = jnp.arange(batch) % min(batch, len(distinct))  # the batch cycles through the scenes, as the bench's
        batch_scenes = jax.tree_util.tree_map(lambda leaf, index=cycle: jnp.take(leaf, index, axis=0), stacked)
        timing = _time_batch(rollout, batch_scenes, run)
        scene_steps = batch * request["steps"]
        result["rows"].append({"batch": batch, "compile_s": timing["compile_s"], "runs": timing["runs"],
                               "best_scene_steps_per_s": round(scene_steps / timing["best_s"]),
                               "median_scene_steps_per_s": round(scene_steps / timing["median_s"]),
                               "bytes_per_scene": scene_bytes})
        del batch_scenes
    _emit(result)


if __name__ == "__main__":
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")  # waymax imports TensorFlow; keep its banner off stderr
    main(sys.argv)
