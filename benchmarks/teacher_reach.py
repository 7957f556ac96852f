"""Where the teacher brakes for something beyond the student's object slots.

The teacher (PDM-Closed) reads every object; the student reads `obs.num_objects` slots, and with
`obs.object_selection=route` those go first to the objects on the route within the span of its path targets (50 m).
A teacher braking for a car standing 50-100 m ahead labels states whose observation holds no reason to brake. This
script lets the run's teacher drive `--data` and, at every step where the SDC moves (> MOVING_MPS), records its
acceleration label and whether route-first slots reaching `--reach` metres along the route show an object further
ahead than the run's own slots do. It prints the share of moving steps where the teacher brakes (label < BRAKE),
and how often such an object exists at those steps and at the others.

Usage: python benchmarks/teacher_reach.py RUN_DIR [--data SHARDS] [--num-scenarios N] [--reach M] [--json]
(docs/learning.md, session 61: the 32 real scenes 44.6% of the braking steps, held-out synthetic 11.1%).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _probe import drive_one_by_one, load_run, probe_parser, report  # noqa: E402

MOVING_MPS = 3.0  # the SDC counts as moving above this speed
BRAKE = -0.2  # a normalised acceleration label below this brakes


def reach_shares(label: np.ndarray, speed: np.ndarray, further: np.ndarray) -> dict:
    """label (n,) normalised accelerations, speed (n,) m/s, further (n,) bool (an object further ahead shown only
    with the reach) -> the shares, over the moving steps."""
    moving = speed > MOVING_MPS
    brakes = moving & (label < BRAKE)
    calm = moving & ~brakes

    def share(mask: np.ndarray) -> float | None:
        return float(further[mask].mean()) if mask.any() else None

    return {"moving_steps": int(moving.sum()), "braking_share": float(brakes.sum() / max(int(moving.sum()), 1)),
            "further_when_braking": share(brakes), "further_otherwise": share(calm)}


def drive(loaded, env, teacher_fn, data: str, num_scenarios: int, reach: float) -> dict:
    """The teacher drives `data`; the shares of `reach_shares` over every valid step."""
    import jax
    import jax.numpy as jnp

    from vmax_sim.datatypes import sdc_action
    from vmax_sim.env.metrics_adapter import sdc_index, sdc_observation, step_inputs
    from vmax_sim.metrics import MetricsConfig, shared_queries

    config = loaded.config
    reaching = dataclasses.replace(config.obs, route_selection_m=reach)
    rows: list[np.ndarray] = []

    def record(label, speed, further, valid):
        rows.append(np.stack([np.asarray(v, np.float64).reshape(-1) for v in (label, speed, further, valid)], 1))

    def furthest_ahead(observation) -> jax.Array:
        """The largest x (ahead, SDC frame) among the observed objects now, -inf when none."""
        return jnp.max(jnp.where(observation.objects_valid[:, -1], observation.objects[:, -1, 0], -jnp.inf))

    def action_fn(params, state, observation, key):
        slot, t = sdc_index(state), state.timestep
        label = teacher_fn(state)
        wide = sdc_observation(state, shared_queries(step_inputs(state), MetricsConfig()), reaching)
        traj = state.sim_trajectory
        jax.debug.callback(record, label[0], jnp.hypot(traj.vel_x[slot, t], traj.vel_y[slot, t]),
                           furthest_ahead(wide) > furthest_ahead(observation), traj.valid[slot, t])
        return sdc_action(state, label)

    drive_one_by_one(loaded, env, data, num_scenarios, "teacher", action_fn)
    label, speed, further, valid = np.concatenate(rows).T
    keep = valid > 0
    return reach_shares(label[keep], speed[keep], further[keep] > 0)


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.1f}%"


def main() -> None:
    from vmax_sim.training.run import TEACHERS

    args = probe_parser(__doc__.splitlines()[0]).parse_args()
    loaded, env, data = load_run(args)
    name = loaded.config.train.teacher if loaded.config.train.teacher != "log" else "pdm"
    values = {"run": args.run_dir, "teacher": name, "data": data, "reach_m": args.reach,
              **drive(loaded, env, TEACHERS[name](env.core), data, args.num_scenarios, args.reach)}
    report(args, values, f"{args.run_dir}: teacher {name} drives {data}; {values['moving_steps']} moving steps, "
           f"braking at {_percent(values['braking_share'])}; an object further along the route within "
           f"{args.reach:g} m than the run's slots show: {_percent(values['further_when_braking'])} of the braking "
           f"steps, {_percent(values['further_otherwise'])} of the others")


if __name__ == "__main__":
    main()
