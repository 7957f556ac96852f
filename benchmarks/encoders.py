"""Cost of every observation encoder at default sizes: parameters, FLOPs, forward and forward+backward time.

For each name in ENCODER_NAMES: the parameter count; XLA's FLOP count of one forward pass on one
observation (`cost_analysis()` of the compiled forward); the median wall-clock ms of the jitted forward
and of the jitted value_and_grad of sum(output) w.r.t. the parameters at batch 64 (median and min of
--runs after warm-up). The observation is random with ~70 % valid entries, default sizes (k=5, n=8, m=200, L=5, P=10).

Usage: python benchmarks/encoders.py [--batch 64] [--runs 50] [--names lq,mtr] [--set embed_dim=32 ...] [--json]
Numbers go to docs/encoders.md with the machine they were taken on.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import time

import jax
import jax.numpy as jnp
import numpy as np

from vmax_sim.networks import ENCODER_NAMES, make_encoder
from vmax_sim.observation import Observation


def random_observation(key: jax.Array, lead: tuple[int, ...] = (), num_history: int = 5, num_objects: int = 8,
                       num_points: int = 200, num_lights: int = 5, num_targets: int = 10,
                       valid_fraction: float = 0.7) -> Observation:
    """Normal features and Bernoulli(valid_fraction) masks, any leading dims."""
    keys = jax.random.split(key, 10)
    shapes = {"sdc": (num_history, 6), "objects": (num_objects, num_history, 12), "roadgraph": (num_points, 8),
              "lights": (num_lights, 6), "path_targets": (num_targets, 2)}
    fields = {}
    for i, (name, shape) in enumerate(shapes.items()):
        fields[name] = jax.random.normal(keys[2 * i], lead + shape, jnp.float32)
        fields[f"{name}_valid"] = jax.random.uniform(keys[2 * i + 1], lead + shape[:-1]) < valid_fraction
    return Observation(**fields)


def forward_flops(fn, *args) -> float:
    """XLA's FLOP estimate of the compiled fn (cost_analysis returns a dict, or a list of one dict)."""
    cost = jax.jit(fn).lower(*args).compile().cost_analysis()
    if isinstance(cost, (list, tuple)):
        cost = cost[0] if cost else {}
    return float((cost or {}).get("flops", float("nan")))


def timed_ms(fn, *args, runs: int = 50, warmup: int = 3) -> tuple[float, float]:
    """(median, min) wall-clock ms of fn(*args) (jitted, results waited for) after warm-up calls.

    The min shows the cost without interference from other processes on a shared machine.
    """
    for _ in range(warmup):
        jax.block_until_ready(fn(*args))
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return float(np.median(times) * 1e3), float(np.min(times) * 1e3)


def bench_encoder(name: str, batch: int, runs: int, overrides: dict) -> dict:
    encoder = make_encoder(name, **overrides)
    single = random_observation(jax.random.PRNGKey(0))
    batched = random_observation(jax.random.PRNGKey(1), (batch,))
    params = encoder.init(jax.random.PRNGKey(2), single)
    forward = jax.jit(encoder.apply)
    loss_and_grad = jax.jit(jax.value_and_grad(lambda p, o: jnp.sum(encoder.apply(p, o))))
    forward_ms, forward_min_ms = timed_ms(forward, params, batched, runs=runs)
    both_ms, both_min_ms = timed_ms(loss_and_grad, params, batched, runs=runs)
    return {
        "encoder": name,
        "params": int(sum(x.size for x in jax.tree.leaves(params))),
        "mflops_per_obs": forward_flops(encoder.apply, params, single) / 1e6,
        "forward_ms": forward_ms,
        "forward_min_ms": forward_min_ms,
        "forward_backward_ms": both_ms,
        "forward_backward_min_ms": both_min_ms,
    }


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        model = next(line.split(":", 1)[1].strip() for line in lscpu.splitlines() if line.startswith("Model name"))
    except (OSError, StopIteration):
        pass
    return f"{model}, {os.cpu_count()} cores, jax {jax.__version__} on {jax.devices()[0].platform}"


def format_table(rows: list[dict], batch: int) -> str:
    lines = [f"| encoder | params | MFLOP / obs (forward) | forward ms, B={batch}: median (min) "
             f"| forward+backward ms, B={batch}: median (min) |",
             "| --- | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['encoder']} | {r['params']:,} | {r['mflops_per_obs']:.2f} "
                     f"| {r['forward_ms']:.2f} ({r['forward_min_ms']:.2f}) "
                     f"| {r['forward_backward_ms']:.2f} ({r['forward_backward_min_ms']:.2f}) |")
    return "\n".join(lines)


def _parse_override(text: str) -> tuple[str, object]:
    key, value = text.split("=", 1)
    return key, int(value) if value.lstrip("-").isdigit() else value


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--runs", type=int, default=50, help="timed runs per measurement (median reported)")
    parser.add_argument("--names", default=",".join(ENCODER_NAMES))
    parser.add_argument("--set", nargs="*", default=[], help="EncoderConfig overrides, e.g. embed_dim=32")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    overrides = dict(_parse_override(item) for item in args.set)
    load_before = os.getloadavg()[0]
    rows = [bench_encoder(name, args.batch, args.runs, overrides) for name in args.names.split(",")]
    load_after = os.getloadavg()[0]
    if args.json:
        print(json.dumps({"machine": machine(), "batch": args.batch, "rows": rows}, indent=2))
        return
    print(f"machine: {machine()}; 1-min load average {load_before:.1f} before, {load_after:.1f} after")
    print(format_table(rows, args.batch))


if __name__ == "__main__":
    main()
