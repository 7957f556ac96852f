"""What the probes of benchmarks/ share: a run's policy or teacher drives shards one scenario per batch while a
`jax.debug.callback` records per-step values, and the same command line (RUN_DIR, --data, --num-scenarios, --reach,
--json)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable


def probe_parser(description: str) -> argparse.ArgumentParser:
    """The arguments every probe takes; a probe adds its own."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("run_dir")
    parser.add_argument("--data", help="shards to drive (default: the run's held-out split)")
    parser.add_argument("--num-scenarios", type=int, default=48)
    parser.add_argument("--reach", type=float, default=100.0, help="metres along the route")
    parser.add_argument("--json", action="store_true")
    return parser


def load_run(args: argparse.Namespace):
    """args -> (the run's loaded policy, its environment, the shards to drive)."""
    from vmax_sim.training.run import components, resolve_eval_data
    from vmax_sim.training.run_policy import load_trained_policy

    loaded = load_trained_policy(args.run_dir, None)
    env = components(loaded.config)[0]
    return loaded, env, args.data or resolve_eval_data(loaded.config, lambda line: None)


def drive_one_by_one(loaded, env, data: str, num_scenarios: int, name: str, action_fn: Callable) -> None:
    """Runs `action_fn(params, state, observation, key)` (it records through `jax.debug.callback`) over `data`.
    One scenario per batch: a last batch is padded with repeats, whose steps a callback cannot tell apart."""
    from vmax_sim.evaluation.evaluate import evaluate
    from vmax_sim.policies.base import Policy
    from vmax_sim.training.run import data_config

    config = loaded.config
    evaluate(Policy(name, action_fn, needs_observation=True), data_config(config, data, batch_size=1),
             env_config=env.env_config, obs_config=config.obs, num_scenarios=num_scenarios,
             policy_params=loaded.params)


def report(args: argparse.Namespace, values: dict, sentence: str) -> None:
    """Prints `values` as JSON with --json, else the one-line `sentence`."""
    print(json.dumps(values, indent=1) if args.json else sentence)
