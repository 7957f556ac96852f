"""Which objects heading onto the SDC's route ahead the student's object slots leave out.

A car crossing the junction the SDC pulls into stands beside the route until it is in the way: route-first slots
(`obs.object_selection=route`) take the objects on the route now, then the nearest others, and on a crowded street
the crossing car is in neither. Its teacher forecasts every object 4 s ahead. This script lets the run's policy drive
`--data` and, at every step where the SDC is valid, marks the objects within NEAR_M ahead of the SDC, off the route
now, whose constant-velocity forecast enters the route corridor within `--seconds` (`obs.route_forecast_s`'s test):
the share of steps with such an object, and with one the run's slots leave out.

Usage: python benchmarks/route_entry.py RUN_DIR [--data SHARDS] [--num-scenarios N] [--seconds S] [--json]
(docs/learning.md, session 63: nuScenes scene-0553 t000, 73.8% of the steps; the 32 real scenes 16.1%).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _probe import drive_one_by_one, load_run, probe_parser, report  # noqa: E402

NEAR_M = 40.0  # only objects this near the SDC count


def entry_shares(entering: np.ndarray, shown: np.ndarray) -> dict:
    """Over n steps of N objects: entering (n, N) bool, heading onto the route; shown (n, N) bool, in the slots."""
    steps = max(len(entering), 1)
    return {"steps": int(len(entering)), "entering_share": float(entering.any(axis=1).sum() / steps),
            "left_out_share": float((entering & ~shown).any(axis=1).sum() / steps)}


def drive(loaded, env, data: str, num_scenarios: int, seconds: float) -> dict:
    """The run's policy drives `data`; `entry_shares` over every step where the SDC is valid."""
    import jax
    import jax.numpy as jnp

    from vmax_sim.datatypes import sdc_action
    from vmax_sim.env.metrics_adapter import observation_inputs, sdc_index
    from vmax_sim.geometry.transforms import to_local_points
    from vmax_sim.observation.features import (
        objects_heading_onto_route,
        objects_on_route,
        path_targets,
        route_first_objects,
    )

    config = loaded.config.obs
    forecast = dataclasses.replace(config, route_forecast_s=seconds)
    rows: list[tuple[np.ndarray, ...]] = []

    def record(entering, shown, valid):
        rows.append((np.asarray(entering)[None], np.asarray(shown)[None], np.asarray(valid).reshape(1)))

    def action_fn(params, state, observation, key):
        inputs = observation_inputs(state, config.num_history)
        route_xy, route_valid = path_targets(inputs, config, None, max(config.route_selection_targets,
                                                                      config.num_path_targets))
        indices, valid = route_first_objects(inputs, route_xy, route_valid, config)
        num = inputs.object_xy.shape[0]
        shown = jnp.zeros(num, bool).at[indices].max(valid)
        near = config.route_near_targets
        local = to_local_points(inputs.object_xy[:, -1], inputs.sdc_xy[-1], inputs.sdc_yaw[-1])
        entering = (objects_heading_onto_route(inputs, route_xy[:near], route_valid[:near], forecast)
                    & ~objects_on_route(local, route_xy[:near], route_valid[:near], config)
                    & inputs.object_valid[:, -1] & (jnp.hypot(local[:, 0], local[:, 1]) < NEAR_M))
        slot = sdc_index(state)
        jax.debug.callback(record, entering, shown, state.sim_trajectory.valid[slot, state.timestep])
        return sdc_action(state, loaded.policy.action_fn(params, state, observation, key).data[slot])

    drive_one_by_one(loaded, env, data, num_scenarios, "student", action_fn)
    entering, shown, valid = (np.concatenate([step[i] for step in rows]) for i in range(3))
    keep = valid.astype(bool)
    return entry_shares(entering[keep], shown[keep])


def main() -> None:
    parser = probe_parser(__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="forecast horizon, s")
    args = parser.parse_args()
    loaded, env, data = load_run(args)
    values = {"run": args.run_dir, "data": data, "seconds": args.seconds,
              **drive(loaded, env, data, args.num_scenarios, args.seconds)}
    report(args, values, f"{args.run_dir} drives {data} ({values['steps']} steps): an object within {NEAR_M:g} m "
           f"ahead heading onto the route within {args.seconds:g} s at {100 * values['entering_share']:.1f}% of the "
           f"steps, left out of the run's slots at {100 * values['left_out_share']:.1f}%")


if __name__ == "__main__":
    main()
