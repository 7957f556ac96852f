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
averaging two answers there would be wider than where it drives).

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

from vmax_sim.agents.bc.config import BCConfig

STANDING_MPS = 0.5  # the SDC counts as standing below this speed
PULL_AWAY = BCConfig.pull_away_accel  # a normalised acceleration label above this asks the SDC to move off
SATURATED = 0.99  # a label beyond this is a full brake or throttle
SAMPLES = 32  # actions drawn from the student's Gaussian per step for its spread
LABEL_EPS = BCConfig.expert_action_eps  # BC's default: labels are clipped to [-1 + eps, 1 - eps] before atanh


def _median(values: np.ndarray) -> float | None:
    return float(np.median(values)) if values.size else None


def gap_statistics(student: np.ndarray, teacher: np.ndarray, speed: np.ndarray,
                   sample_std: np.ndarray | None = None) -> dict:
    """student, teacher (n, A) actions at the same n states, speed (n,) m/s, sample_std (n,) the spread of the
    student's sampled accelerations (or None) -> the summary (plain floats; None where no step qualifies)."""
    error = student - teacher
    standing = speed < STANDING_MPS
    stuck = standing & (teacher[:, 0] > PULL_AWAY) & (student[:, 0] <= PULL_AWAY)
    spread = {}
    if sample_std is not None:
        spread = {"held_sample_std": _median(sample_std[stuck]), "moving_sample_std": _median(sample_std[~standing])}
    return {**spread, "steps": int(len(error)),
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

    def record(student, teacher, speed, live, sample_std):
        pairs.append((np.asarray(student).reshape(-1, 2), np.asarray(teacher).reshape(-1, 2),
                      np.asarray(speed).reshape(-1), np.asarray(live).reshape(-1), np.asarray(sample_std).reshape(-1)))

    def action_fn(params, state, observation, key):
        slot = sdc_index(state)
        student = loaded.policy.action_fn(params, state, observation, key).data[slot]
        batched = jax.tree.map(lambda a: a[None], observation)
        samples = jax.vmap(lambda k: loaded.learner.act(params, batched, k, False)[0, 0])(
            jax.random.split(key, SAMPLES))  # (SAMPLES,) sampled accelerations
        teacher = teacher_fn(state)
        traj, t = state.sim_trajectory, state.timestep
        speed = jnp.hypot(traj.vel_x[slot, t], traj.vel_y[slot, t])
        jax.debug.callback(record, student, teacher, speed, traj.valid[slot, t], jnp.std(samples))
        return sdc_action(state, teacher if driver == "teacher" else student)

    result = evaluate(Policy(f"{driver}-driven", action_fn, needs_observation=True),
                      data_config(config, data, batch_size=8), env_config=env_config,
                      obs_config=config.obs, num_scenarios=num_scenarios, policy_params=loaded.params)
    student, teacher, speed, live, sample_std = (np.concatenate(parts) for parts in zip(*pairs))
    summary = gap_statistics(student[live], teacher[live], speed[live], sample_std[live])
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


def _text(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


if __name__ == "__main__":
    main()
