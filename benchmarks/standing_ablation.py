"""What keeps a student at rest where its teacher would pull away: the student drives `--data`, and at every step
where the SDC stands (< 0.5 m/s), the teacher's label says go (> +0.05) and the student holds (<= +0.05), the
student's action is computed again with one part of its observation masked (every object, its own history, the
road graph, the path targets, the traffic lights). A part whose masking makes the student go is what holds it.

Usage: python benchmarks/standing_ablation.py RUN_DIR --data SHARDS [--teacher pdm_state|pdm|idm] [--step N]
       [--num-scenarios N]
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np
from imitation_gap import PULL_AWAY, STANDING_MPS  # the same thresholds (this folder is on the path of its scripts)

# name -> the observation with that part marked invalid (the encoders read only valid entries)
MASKS = {
    "nothing": lambda o: o,
    "every object": lambda o: o.replace(objects_valid=jnp.zeros_like(o.objects_valid)),
    "own history": lambda o: o.replace(sdc_valid=o.sdc_valid.at[..., :-1].set(False)),
    "road graph": lambda o: o.replace(roadgraph_valid=jnp.zeros_like(o.roadgraph_valid)),
    "path targets": lambda o: o.replace(path_targets_valid=jnp.zeros_like(o.path_targets_valid)),
    "traffic lights": lambda o: o.replace(lights_valid=jnp.zeros_like(o.lights_valid)),
}


def held_steps(accel: np.ndarray, teacher: np.ndarray, speed: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(n,) each: the steps where the SDC stands, the teacher says go and the student holds. -> (n,) bool"""
    return valid & (speed < STANDING_MPS) & (teacher > PULL_AWAY) & (accel <= PULL_AWAY)


def main() -> None:
    from vmax_sim.datatypes import sdc_action
    from vmax_sim.env.metrics_adapter import sdc_index
    from vmax_sim.evaluation.evaluate import evaluate
    from vmax_sim.policies.base import Policy
    from vmax_sim.training.run import TEACHERS, components, data_config
    from vmax_sim.training.run_policy import load_trained_policy

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir")
    parser.add_argument("--data", required=True)
    parser.add_argument("--teacher", default="pdm_state", choices=[name for name in TEACHERS if name != "log"])
    parser.add_argument("--step", type=int)
    parser.add_argument("--num-scenarios", type=int)
    args = parser.parse_args()

    loaded = load_trained_policy(args.run_dir, args.step)
    env = components(loaded.config)[0]
    teacher_fn = TEACHERS[args.teacher](env.core)
    names = list(MASKS)
    records: list[tuple[np.ndarray, ...]] = []

    def record(accels, teacher, speed, valid):
        records.append((np.asarray(accels).reshape(len(names), -1), np.asarray(teacher).reshape(-1),
                        np.asarray(speed).reshape(-1), np.asarray(valid).reshape(-1)))

    def action_fn(params, state, observation, key):
        slot = sdc_index(state)
        act = lambda obs: loaded.policy.action_fn(params, state, obs, key).data[slot]  # noqa: E731
        accels = jnp.stack([act(mask(observation))[0] for mask in MASKS.values()])
        traj, t = state.sim_trajectory, state.timestep
        speed = jnp.hypot(traj.vel_x[slot, t], traj.vel_y[slot, t])
        jax.debug.callback(record, accels, teacher_fn(state)[0], speed, traj.valid[slot, t])
        return sdc_action(state, act(observation))

    evaluate(Policy("student", action_fn, needs_observation=True), data_config(loaded.config, args.data, batch_size=1),
             env_config=env.env_config, obs_config=loaded.config.obs, num_scenarios=args.num_scenarios,
             policy_params=loaded.params)
    accels = np.concatenate([r[0] for r in records], axis=1)  # (masks, n)
    teacher, speed, valid = (np.concatenate([r[i] for r in records]) for i in (1, 2, 3))
    held = held_steps(accels[0], teacher, speed, valid)
    print(f"{args.run_dir} at {loaded.env_steps} env steps on {args.data}: {int(valid.sum())} steps, "
          f"{int((valid & (speed < STANDING_MPS)).sum())} standing, {int(held.sum())} held where {args.teacher} goes")
    print(f"  {'masked':<16} {'mean accel':>10}  {'would go':>8}")
    for row, name in enumerate(names):
        chosen = accels[row, held]
        share = float(np.mean(chosen > PULL_AWAY)) if chosen.size else float("nan")
        mean = float(chosen.mean()) if chosen.size else float("nan")
        print(f"  {name:<16} {mean:>+10.3f}  {100 * share:>7.0f}%")


if __name__ == "__main__":
    main()
