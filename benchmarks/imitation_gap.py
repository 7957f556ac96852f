"""How far a behaviour-cloning student is from its teacher, at the teacher's states and at its own.

A student can match its teacher's labels closely along the teacher's own driving and still drift once it drives
itself (covariate shift), or copy what its observation shows of the last action (a teacher whose label depends on
the last action makes that copy a good fit). This script drives a training run's held-out split twice, once with
the teacher, once with the student, and at every step compares the student's action with the teacher's label for
that state: mean absolute error and bias per action dimension (normalised units, [-1, 1]), and the share of steps
where the student stands (< 0.5 m/s) and holds still while the teacher would pull away (label > +0.05). And how
much the likelihood's atanh stretches the acceleration labels (BC fits a Gaussian before the tanh, so its mode
follows tanh(mean(atanh(label))), which hard brakes near -1 would pull down): the share of labels beyond +-0.99
and that stretched mean beside the plain one. And how sure the student is where it holds: the spread (std) of
SAMPLES actions drawn from its Gaussian at each step, median over the held steps beside the moving ones (a student
averaging two answers there would be wider than where it drives). And what holds it there: at each held step the
student's mean acceleration again with one part of its observation changed (VARIANTS: the other objects hidden, its
own past hidden, the map hidden, the route targets hidden, a green light shown ahead), and the share of held steps
where it would then pull away. And the other side: the share of steps where the SDC moves and the teacher brakes
(label < BRAKE) but the student does not (its acceleration above -PULL_AWAY), split by what stands nearest in a
corridor ahead of the SDC (crossing_traffic.nearest_ahead: 15 m long, 3 m to each side; nothing, a vehicle, a
pedestrian, a cyclist): a
student that drives on into people its teacher yields to shows here before it fails a whole scene.

Usage: python benchmarks/imitation_gap.py RUN_DIR [--teacher pdm|pdm_state|idm] [--data SHARDS] [--num-scenarios N]
       [--step N] [--json]
The teacher defaults to the run's own `train.teacher` (a run taught by the log is compared with PDM-Closed).
"""

from __future__ import annotations

import argparse
import json

import jax
import jax.numpy as jnp
import numpy as np
from crossing_traffic import nearest_ahead  # the same corridor (this folder is on the path of its scripts)

from vmax_sim.agents.bc.config import BCConfig

STANDING_MPS = 0.5  # the SDC counts as standing below this speed
PULL_AWAY = BCConfig.pull_away_accel  # a normalised acceleration label above this asks the SDC to move off
SATURATED = 0.99  # a label beyond this is a full brake or throttle
SAMPLES = 32  # actions drawn from the student's Gaussian per step for its spread
LABEL_EPS = BCConfig.expert_action_eps  # BC's default: labels are clipped to [-1 + eps, 1 - eps] before atanh
VARIANTS = ("no_objects", "no_own_past", "no_map", "no_route", "green_ahead")
GREEN_AHEAD_M = 6.0  # the shown light stands this far ahead of the SDC's centre, on its axis
BRAKE = -0.2  # a normalised acceleration label below this asks the moving SDC to brake
AHEAD_KINDS = ("nothing", "vehicle", "pedestrian", "cyclist", "other")  # index = the object type enum (0: none)


def _median(values: np.ndarray) -> float | None:
    return float(np.median(values)) if values.size else None


def observation_variants(observation, max_distance: float) -> dict:
    """VARIANTS of one unbatched observation: a part hidden (its valid flags cleared) or a green light shown
    GREEN_AHEAD_M ahead in the first light slot. max_distance: the observation's position scale (m)."""
    import jax.numpy as jnp

    from vmax_sim.observation.features import light_row

    o = observation
    green = light_row((GREEN_AHEAD_M, 0.0), "green", max_distance)
    return {"no_objects": o.replace(objects_valid=jnp.zeros_like(o.objects_valid)),
            "no_own_past": o.replace(sdc_valid=o.sdc_valid.at[:-1].set(False)),
            "no_map": o.replace(roadgraph_valid=jnp.zeros_like(o.roadgraph_valid)),
            "no_route": o.replace(path_targets_valid=jnp.zeros_like(o.path_targets_valid)),
            "green_ahead": o.replace(lights=o.lights.at[0].set(green), lights_valid=o.lights_valid.at[0].set(True))}


def nearest_ahead_type(x: jnp.ndarray, y: jnp.ndarray, yaw: jnp.ndarray, valid: jnp.ndarray,
                       object_type: jnp.ndarray, slot) -> jnp.ndarray:
    """The type enum of the object nearest ahead of object `slot` (the SDC) in crossing_traffic's corridor; 0 when
    none. x, y, yaw, valid, object_type (N,) at one step."""
    nearest, found = nearest_ahead(x, y, yaw, valid, slot, jnp)
    return jnp.where(found, object_type[nearest], 0)


def drove_on(student: np.ndarray, teacher: np.ndarray, speed: np.ndarray, ahead_type: np.ndarray) -> dict:
    """Where the SDC moves and the teacher brakes (label < BRAKE): the share of those steps where the student does
    not brake (acceleration above -PULL_AWAY), over all of them and by what stands nearest ahead (AHEAD_KINDS),
    with the number of such steps. (n, A), (n, A), (n,), (n,) int -> {"share", "by_ahead": {kind: [share, steps]}}"""
    brakes = (speed >= STANDING_MPS) & (teacher[:, 0] < BRAKE)
    on = brakes & (student[:, 0] > -PULL_AWAY)
    by_ahead = {}
    for code, kind in enumerate(AHEAD_KINDS):
        here = brakes & (ahead_type == code)
        by_ahead[kind] = [float(on[here].mean()) if here.any() else None, int(here.sum())]
    return {"share": float(on[brakes].mean()) if brakes.any() else None, "by_ahead": by_ahead}


def gap_statistics(student: np.ndarray, teacher: np.ndarray, speed: np.ndarray,
                   sample_std: np.ndarray | None = None, variant_accel: dict | None = None,
                   ahead_type: np.ndarray | None = None) -> dict:
    """student, teacher (n, A) actions at the same n states, speed (n,) m/s, sample_std (n,) the spread of the
    student's sampled accelerations (or None), variant_accel {VARIANT: (n,) the student's acceleration with that
    change} (or None), ahead_type (n,) the type enum nearest ahead (or None) -> the summary (plain floats; None where
    no step qualifies)."""
    error = student - teacher
    standing = speed < STANDING_MPS
    stuck = standing & (teacher[:, 0] > PULL_AWAY) & (student[:, 0] <= PULL_AWAY)
    optional = {} if ahead_type is None else {"drove_on": drove_on(student, teacher, speed, ahead_type)}
    if sample_std is not None:
        optional.update(held_sample_std=_median(sample_std[stuck]), moving_sample_std=_median(sample_std[~standing]))
    if variant_accel is not None:  # share of the held steps where the changed observation pulls away
        optional["pulls_away_with"] = {name: float((accel[stuck] > PULL_AWAY).mean()) if stuck.any() else None
                                     for name, accel in variant_accel.items()}
    return {**optional, "steps": int(len(error)),
            "mae_accel": float(np.abs(error[:, 0]).mean()), "mae_steer": float(np.abs(error[:, 1]).mean()),
            "bias_accel": float(error[:, 0].mean()), "bias_steer": float(error[:, 1].mean()),
            "standing_share": float(standing.mean()),
            "held_still_share": float(stuck.sum() / max(int((standing & (teacher[:, 0] > PULL_AWAY)).sum()), 1)),
            "saturated_label_share": float((np.abs(teacher[:, 0]) >= SATURATED).mean()),
            "mean_label_accel": float(teacher[:, 0].mean()),
            "stretched_mean_label_accel": float(np.tanh(np.arctanh(np.clip(teacher[:, 0], LABEL_EPS - 1,
                                                                           1 - LABEL_EPS)).mean()))}


def drive(loaded, env_config, teacher_fn, data: str, num_scenarios: int | None, driver: str) -> dict:
    """One evaluation of `data` driven by "teacher" or "student", the pairs recorded at every valid step.
    env_config: the run's (its LearningEnv's `env_config`)."""
    from vmax_sim.datatypes import sdc_action
    from vmax_sim.env.metrics_adapter import sdc_index
    from vmax_sim.evaluation.evaluate import evaluate
    from vmax_sim.policies.base import Policy
    from vmax_sim.training.run import data_config

    config = loaded.config
    pairs: list[tuple[np.ndarray, ...]] = []

    def record(student, teacher, speed, live, sample_std, variants, ahead):
        pairs.append((np.asarray(student).reshape(-1, 2), np.asarray(teacher).reshape(-1, 2),
                      np.asarray(speed).reshape(-1), np.asarray(live).reshape(-1), np.asarray(sample_std).reshape(-1),
                      np.asarray(variants).reshape(-1, len(VARIANTS)), np.asarray(ahead).reshape(-1)))

    def student_accel(params, observation, key, deterministic):
        return loaded.learner.act(params, jax.tree.map(lambda a: a[None], observation), key, deterministic)[0, 0]

    def action_fn(params, state, observation, key):
        slot = sdc_index(state)
        student = loaded.policy.action_fn(params, state, observation, key).data[slot]
        samples = jax.vmap(lambda k: student_accel(params, observation, k, False))(
            jax.random.split(key, SAMPLES))  # (SAMPLES,) sampled accelerations
        variants = observation_variants(observation, config.obs.max_distance)
        variant_accel = jnp.stack([student_accel(params, variants[name], key, True) for name in VARIANTS])  # (V,)
        teacher = teacher_fn(state)
        traj, t = state.sim_trajectory, state.timestep
        speed = jnp.hypot(traj.vel_x[slot, t], traj.vel_y[slot, t])
        ahead = nearest_ahead_type(traj.x[:, t], traj.y[:, t], traj.yaw[:, t], traj.valid[:, t],
                                   state.object_metadata.object_types, slot)
        jax.debug.callback(record, student, teacher, speed, traj.valid[slot, t], jnp.std(samples), variant_accel, ahead)
        return sdc_action(state, teacher if driver == "teacher" else student)

    result = evaluate(Policy(f"{driver}-driven", action_fn, needs_observation=True),
                      data_config(config, data, batch_size=8), env_config=env_config,
                      obs_config=config.obs, num_scenarios=num_scenarios, policy_params=loaded.params)
    student, teacher, speed, live, sample_std, variants, ahead = (np.concatenate(parts) for parts in zip(*pairs))
    summary = gap_statistics(student[live], teacher[live], speed[live], sample_std[live],
                             {name: variants[live, i] for i, name in enumerate(VARIANTS)}, ahead[live])
    summary["accuracy"] = float(result.summary["accuracy"])
    return summary


def main() -> None:
    from vmax_sim.training.run import TEACHERS, components, resolve_eval_data
    from vmax_sim.training.run_policy import load_trained_policy

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir")
    parser.add_argument("--teacher", choices=[name for name in TEACHERS if name != "log"])
    parser.add_argument("--data")
    parser.add_argument("--num-scenarios", type=int, default=50)
    parser.add_argument("--step", type=int)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    loaded = load_trained_policy(args.run_dir, args.step)
    name = args.teacher or (loaded.config.train.teacher if loaded.config.train.teacher != "log" else "pdm")
    env = components(loaded.config)[0]
    teacher_fn = TEACHERS[name](env.core)  # the core takes normalised actions, as in training
    data = args.data or resolve_eval_data(loaded.config, lambda line: None)
    report = {"run": args.run_dir, "env_steps": loaded.env_steps, "teacher": name, "data": data,
              "teacher_driving": drive(loaded, env.env_config, teacher_fn, data, args.num_scenarios, "teacher"),
              "student_driving": drive(loaded, env.env_config, teacher_fn, data, args.num_scenarios, "student")}
    if args.json:
        print(json.dumps(report, indent=1))
        return
    print(f"{args.run_dir} at {loaded.env_steps} env steps, teacher {name}, {data}")
    for driver in ("teacher_driving", "student_driving"):
        r = report[driver]
        print(f"  {driver.replace('_', ' ')}: {r['steps']} steps, accel MAE {r['mae_accel']:.3f} "
              f"(bias {r['bias_accel']:+.3f}), steer MAE {r['mae_steer']:.3f}; "
              f"standing {100 * r['standing_share']:.1f}% of steps, held still where the teacher pulls away "
              f"{100 * r['held_still_share']:.1f}%; acceleration labels: {100 * r['saturated_label_share']:.1f}% "
              f"at +-{SATURATED}, mean {r['mean_label_accel']:+.3f}, tanh(mean atanh) "
              f"{r['stretched_mean_label_accel']:+.3f}; student's sampled acceleration std "
              f"{_text(r['held_sample_std'])} where held, {_text(r['moving_sample_std'])} moving; "
              f"accuracy {100 * r['accuracy']:.1f}%")
        print("    held steps where it pulls away once changed: " + ", ".join(
            f"{name} {_percent(share)}" for name, share in r["pulls_away_with"].items()))
        print(f"    moving steps where the teacher brakes and the student does not: {_percent(r['drove_on']['share'])}"
              " (by what is nearest ahead: " + ", ".join(
                  f"{kind} {_percent(share)} of {steps}" for kind, (share, steps) in r["drove_on"]["by_ahead"].items())
              + ")")


def _percent(share: float | None) -> str:
    return "-" if share is None else f"{100 * share:.0f}%"


def _text(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


if __name__ == "__main__":
    main()
