"""Cost of the rule drivers on every agent's view, and of the self-play step with and without its teacher:
`python benchmarks/rule_drivers.py [--scenes 8] [--agents 8] [--steps 32]`.

Self-play's teacher (IDM at 1.4x the limit) and IDM / PDM traffic run once per agent and step on the agent's own
view (`vmax_sim.env.agent_view`), so their cost per view multiplies by the agent slots. Times the jitted IDM and
PDM-Closed actions over scenes x agents views, and `SelfPlayEnv.step` (zero actions, a `lax.scan` of --steps) of the
`ppo-selfplay` preset with its teacher and without it. Medians of timed runs after a warm-up; figures go to
docs/benchmarks.md with the machine. To time another tree: PYTHONPATH=/path/to/tree python benchmarks/...
"""

from __future__ import annotations

import argparse
import json


def _median_seconds(fn, *args, repeats: int) -> float:
    """Median wall-clock seconds of the jitted fn(*args) after one compiling call."""
    from encoders import timed_ms  # the same timer (this folder is on the path of its scripts)

    return timed_ms(fn, *args, runs=repeats, warmup=1)[0] / 1e3


def _selfplay_setup(scenes: int, agents: int, with_teacher: bool):
    from vmax_sim.training import apply_overrides, preset_config
    from vmax_sim.training.run import resolve_data, setup_training

    overrides = ["train.pool_size=32", "train.action_repeat=1", f"algo.num_envs={scenes}",
                 f"selfplay.max_agents={agents}"]
    if not with_teacher:  # the preset's PPO without the imitation term (no labels to compute)
        overrides += ["algo.imitation_coef=0", "train.teacher=log", "train.teacher_speed_factor=1.0",
                      "train.teacher_max_accel=None", "train.teacher_bend_lateral_accel=None"]
    config = apply_overrides(preset_config("ppo-selfplay"), overrides)
    train_path, _ = resolve_data(config, lambda line: None)
    setup = setup_training(config, train_path, print_fn=lambda line: None)
    setup.stream.close()
    return config, setup.env, setup.pool


def bench_step(env, pool, scenes: int, agents: int, steps: int, repeats: int) -> dict:
    import jax
    import jax.numpy as jnp

    state = env.reset(pool, scenes, jax.random.PRNGKey(0))
    zeros = jnp.zeros((scenes * agents, env.action_dim))

    @jax.jit
    def rollout(state):
        return jax.lax.scan(lambda s, _: (env.step(s, zeros, pool)[0], None), state, None, length=steps)[0]

    seconds = _median_seconds(rollout, state, repeats=repeats)
    return {"scene_steps_per_s": steps * scenes / seconds, "slot_steps_per_s": steps * scenes * agents / seconds}


def bench_rule_drivers(config, env, pool, scenes: int, agents: int, repeats: int) -> dict:
    """Microseconds per agent view of IDM (the preset's teacher, as `config` sets it) and PDM-Closed, on states 10
    steps in."""
    import jax
    import jax.numpy as jnp

    from vmax_sim.env.agent_view import agent_view
    from vmax_sim.policies.teacher import idm_teacher, pdm_teacher

    state = env.reset(pool, scenes, jax.random.PRNGKey(0))
    zeros = jnp.zeros((scenes * agents, env.action_dim))
    for _ in range(10):
        state, _ = env.step(state, zeros, pool)
    train = config.train
    drivers = {"idm": idm_teacher(env.core, train.teacher_speed_factor, train.teacher_max_accel,
                                  train.teacher_bend_lateral_accel),
               "pdm": pdm_teacher(env.core)}

    def over_views(driver):
        def every_view(sim, slots, signs):
            return jax.vmap(lambda slot: driver(agent_view(sim, slot, signs)))(slots)
        return jax.jit(lambda s: jax.vmap(every_view)(s.sim, s.slots, s.signs))

    views = scenes * agents
    return {f"{name}_us_per_view": 1e6 * _median_seconds(over_views(fn), state, repeats=repeats) / views
            for name, fn in drivers.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=8)
    parser.add_argument("--agents", type=int, default=8)
    parser.add_argument("--steps", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sizes = (args.scenes, args.agents)
    config, env, pool = _selfplay_setup(*sizes, with_teacher=True)
    _, untaught_env, untaught_pool = _selfplay_setup(*sizes, with_teacher=False)
    report = {"scenes": args.scenes, "agents": args.agents,
              **bench_rule_drivers(config, env, pool, *sizes, args.repeats * 3),
              "step_with_teacher": bench_step(env, pool, *sizes, args.steps, args.repeats),
              "step_without_teacher": bench_step(untaught_env, untaught_pool, *sizes, args.steps, args.repeats)}
    if args.json:
        print(json.dumps(report, indent=1))
        return
    print(f"{args.scenes} scenes x {args.agents} agent views: IDM {report['idm_us_per_view']:.0f} us per view, "
          f"PDM-Closed {report['pdm_us_per_view']:.0f} us per view")
    for label in ("with", "without"):
        row = report[f"step_{label}_teacher"]
        print(f"SelfPlayEnv.step {label} the IDM teacher: {row['scene_steps_per_s']:,.0f} scene steps/s, "
              f"{row['slot_steps_per_s']:,.0f} agent-slot steps/s")


if __name__ == "__main__":
    main()
