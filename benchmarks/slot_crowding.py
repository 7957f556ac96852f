"""Which near objects a longer route-first reach pushes out of the student's object slots.

With `obs.object_selection=route` the `obs.num_objects` slots go first to the objects on the route ahead. Reaching
further along it (`obs.route_selection_m`) shows the car standing 50-100 m ahead, but on a crowded street the far
on-route objects also take the slots of the pedestrians and cars beside the SDC. This script lets the run's policy
drive `--data` and, at every step, compares the slots of the default choice (the path targets' 50 m, no far slots)
with those of `--reach` metres and `--far-slots` extra slots (`obs.route_far_slots`): the share of steps where an
object within NEAR_M of the SDC that the default keeps is left out (by object type), and the share of steps where
an on-route object beyond the default's reach is shown.

Usage: python benchmarks/slot_crowding.py RUN_DIR [--data SHARDS] [--num-scenarios N] [--reach M] [--far-slots K]
[--json] (docs/learning.md, session 62: nuScenes scene-0553, reach 100 m, no far slots: 98.1% of the steps).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _probe import drive_one_by_one, load_run, probe_parser, report  # noqa: E402

NEAR_M = 25.0  # an object this near the SDC counts as near
TYPE_NAMES = {1: "vehicle", 2: "pedestrian", 3: "cyclist", 4: "other"}  # the schema's object types


def crowding_shares(base: np.ndarray, wide: np.ndarray, near: np.ndarray, far_on_route: np.ndarray,
                    types: np.ndarray) -> dict:
    """Over n steps of N objects: base, wide (n, N) bool, the objects each choice shows; near (n, N) bool, within
    NEAR_M; far_on_route (n, N) bool, on the route beyond the default's reach; types (n, N) int -> the shares."""
    lost = base & ~wide & near  # (n, N)
    steps = max(len(base), 1)
    by_type = {TYPE_NAMES.get(int(t), str(int(t))): int(np.count_nonzero(lost & (types == t)))
               for t in np.unique(types[lost])}
    return {"steps": int(len(base)), "near_lost_share": float(lost.any(axis=1).sum() / steps),
            "near_lost_by_type": by_type, "far_shown_share": float((wide & far_on_route).any(axis=1).sum() / steps)}


def drive(loaded, env, data: str, num_scenarios: int, reach: float, far_slots: int) -> dict:
    """The run's policy drives `data`; `crowding_shares` over every step where the SDC is valid."""
    import jax
    import jax.numpy as jnp

    from vmax_sim.datatypes import sdc_action
    from vmax_sim.env.metrics_adapter import observation_inputs, sdc_index
    from vmax_sim.geometry.transforms import to_local_points
    from vmax_sim.observation.features import objects_on_route, path_targets, route_first_objects

    config = loaded.config
    default = dataclasses.replace(config.obs, object_selection="route", route_selection_m=None, route_far_slots=0)
    wide = dataclasses.replace(default, route_selection_m=reach, route_far_slots=far_slots)
    count = max(wide.route_selection_targets, default.num_path_targets)
    rows: list[tuple[np.ndarray, ...]] = []

    def shown(indices, valid, num):
        return jnp.zeros(num, bool).at[indices].max(valid)

    def record(*values):
        rows.append(tuple(np.asarray(v).reshape((1,) + np.shape(v)[-1:] if i < 5 else (1,))
                          for i, v in enumerate(values)))

    def action_fn(params, state, observation, key):
        inputs = observation_inputs(state, config.obs.num_history)
        route_xy, route_valid = path_targets(inputs, wide, None, count)
        num = inputs.object_xy.shape[0]
        base = shown(*route_first_objects(inputs, route_xy, route_valid, default), num)
        wider = shown(*route_first_objects(inputs, route_xy, route_valid, wide), num)
        local = to_local_points(inputs.object_xy[:, -1], inputs.sdc_xy[-1], inputs.sdc_yaw[-1])
        near_route = objects_on_route(local, route_xy[:default.num_path_targets],
                               route_valid[:default.num_path_targets], default)
        far = objects_on_route(local, route_xy, route_valid, wide) & ~near_route
        near = jnp.hypot(local[:, 0], local[:, 1]) < NEAR_M
        slot = sdc_index(state)
        jax.debug.callback(record, base, wider, near, far, inputs.object_type,
                           state.sim_trajectory.valid[slot, state.timestep])
        return sdc_action(state, loaded.policy.action_fn(params, state, observation, key).data[slot])

    drive_one_by_one(loaded, env, data, num_scenarios, "student", action_fn)
    base, wider, near, far, types, valid = (np.concatenate([step[i] for step in rows]) for i in range(6))
    keep = valid.astype(bool)
    return crowding_shares(base[keep], wider[keep], near[keep], far[keep], types[keep])


def main() -> None:
    parser = probe_parser(__doc__.splitlines()[0])
    parser.add_argument("--far-slots", type=int, default=0)
    args = parser.parse_args()
    loaded, env, data = load_run(args)
    values = {"run": args.run_dir, "data": data, "reach_m": args.reach, "far_slots": args.far_slots,
              **drive(loaded, env, data, args.num_scenarios, args.reach, args.far_slots)}
    report(args, values, f"{args.run_dir} drives {data} ({values['steps']} steps); reach {args.reach:g} m, "
           f"{args.far_slots} far slots against the default slots: an object within {NEAR_M:g} m left out at "
           f"{100 * values['near_lost_share']:.1f}% of the steps {values['near_lost_by_type']}, an on-route object "
           f"beyond the default's reach shown at {100 * values['far_shown_share']:.1f}%")


if __name__ == "__main__":
    main()
