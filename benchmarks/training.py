"""Training throughput by algorithm and encoder: `python benchmarks/training.py [--quick] [--json]`.

Each configuration runs in its own process (peak RSS is per process): the jitted chunk is timed after
warm-up with learning active from the first step. Results go to docs/benchmarks.md with the machine.
Extra `section.field=value` arguments apply to every configuration (e.g. data.train=shards/).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

CONFIGS = [  # (preset, overrides); a PPO chunk step is a whole update (2,560 env steps by default)
    ("paper-sac-lq", ["algo.buffer_size=100000"]),
    ("paper-sac-lq", ["algo.buffer_size=100000", "algo.shared_encoder=true"]),
    ("sac-lq", []),
    ("sac-lq", ["algo.shared_encoder=true"]),
    ("sac-mlp", []),
    ("sac-none", []),
    ("sac-lqh", []),
    ("sac-wayformer", []),
    ("sac-mtr", []),
    # one update per chunk (the default train.chunk_steps for ppo) of 10,240 transitions, as the rows in
    # docs/benchmarks.md were measured; the default's 2,560-transition updates spend more time learning per env step
    ("ppo-lq", ["algo.batch_size=64"]),
    ("ppo-mlp", ["algo.batch_size=64"]),
    ("ppo-none", ["algo.batch_size=64"]),
    ("ppo-mlp", []),
    ("bc-mlp", []),
    # the default preset: BC labelled by PDM-Closed every step, IDM training traffic, a 600k-transition buffer
    ("bc-dagger", []),
    ("bc_sac-lq", []),
    # self-play: one policy drives the SDC and up to K - 1 controllable agents of each of num_envs scenes; env steps
    # count scenes, agent steps the agents acting in them (the synthetic scenes hold ~7 movable agents)
    ("ppo-selfplay", ["selfplay.max_agents=1"]),
    ("ppo-selfplay", ["selfplay.max_agents=8"]),
    ("ppo-selfplay", ["selfplay.max_agents=8", "algo.num_envs=16"]),
    ("ppo-selfplay", ["selfplay.max_agents=32", "algo.num_envs=4"]),
]


def _one(preset: str, overrides: list[str], chunks: int) -> dict:
    from vmax_sim.training import apply_overrides, preset_config
    from vmax_sim.training.throughput import measure_throughput

    # one simulator step per env step, as the peers count them (the sac / ppo defaults hold an action for 4)
    config = apply_overrides(preset_config(preset), ["train.pool_size=32", "train.action_repeat=1", *overrides])
    result = measure_throughput(config, num_chunks=chunks)
    result["preset"] = preset
    result["overrides"] = overrides
    return result


def _selected(wanted: list[str]) -> list[tuple[str, list[str]]]:
    """The CONFIGS rows a preset name or a whole 'preset override ...' row names; a row with overrides that is
    not in CONFIGS runs as written (e.g. larger self-play batches on a GPU)."""
    names = {" ".join([preset, *overrides]) for preset, overrides in CONFIGS}
    rows = [c for c in CONFIGS if c[0] in wanted or " ".join([c[0], *c[1]]) in wanted]
    return rows + [(text.split()[0], text.split()[1:]) for text in wanted if " " in text.strip() and text not in names]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="three configurations, fewer chunks")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--only", default=None, help="comma-separated presets (or 'preset override ...' rows)")
    parser.add_argument("--chunks", type=int, default=6)
    parser.add_argument("--child", nargs="*", help=argparse.SUPPRESS)
    args, extra = parser.parse_known_args()
    if args.child is not None:
        preset, *overrides = args.child
        print(json.dumps(_one(preset, overrides, args.chunks)))
        return
    configs = CONFIGS[:3] if args.quick else CONFIGS
    if args.only:
        configs = _selected(args.only.split(","))
    rows = []
    for preset, overrides in configs:
        done = subprocess.run([sys.executable, __file__, "--chunks", str(args.chunks), "--child", preset,
                               *overrides, *extra], capture_output=True, text=True)
        if done.returncode != 0:
            tail = "\n  ".join(done.stderr.strip().splitlines()[-12:])
            print(f"{preset}: failed:\n  {tail}", file=sys.stderr)
            continue
        row = json.loads(done.stdout.strip().splitlines()[-1])
        rows.append(row)
        if not args.json:
            agents = f"  {row['agent_steps_per_s']:>9,.0f} agent steps/s" if "agent_steps_per_s" in row else ""
            print(f"{preset:<16} {' '.join(overrides):<24} envs {row['num_envs']:>4}  "
                  f"{row['env_steps_per_s']:>9,.0f} env steps/s{agents}  "
                  f"(min {row['min']:,.0f}, max {row['max']:,.0f})  "
                  f"peak RSS {row['peak_rss_mb']:,.0f} MB  buffer {row['buffer_mib']:,.0f} MiB  [{row['device']}]",
                  flush=True)
    if args.json:
        print(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
