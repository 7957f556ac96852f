"""End-to-end training throughput: env steps per second of the jitted chunk (env + observation + reward
+ replay + learner updates), with learning active from the first step, and the process's peak memory.

`benchmarks/training.py` runs one configuration per process (peak RSS is per process) and prints the table
recorded in docs/benchmarks.md.
"""

from __future__ import annotations

import dataclasses
import statistics
import time

import jax

from vmax_sim.training.config import TrainConfig
from vmax_sim.training.run import peak_rss_mb, resolve_data, setup_training


def measure_throughput(config: TrainConfig, num_chunks: int = 8, warmup_chunks: int = 2) -> dict:
    """Median env steps/s over `num_chunks` chunks after `warmup_chunks` (compilation), learning on."""
    if hasattr(config.algo_config, "learning_starts"):
        config = dataclasses.replace(config, algo_config=dataclasses.replace(config.algo_config, learning_starts=0))
    train_path, _ = resolve_data(config, lambda line: None)
    setup = setup_training(config, train_path, print_fn=lambda line: None)
    carry, timings, agent_rates = setup.carry, [], []
    try:
        for index in range(warmup_chunks + num_chunks):
            start = time.perf_counter()
            carry, stats = setup.chunk_fn(carry, setup.pool)
            jax.block_until_ready(stats)
            if index >= warmup_chunks:
                timings.append(time.perf_counter() - start)
                agent_rates.append(float(stats["agent_steps"]) / timings[-1])
    finally:
        setup.stream.close()
    sps = [setup.per_chunk / t for t in timings]
    extra = {}
    if config.is_selfplay:  # agents acting per second (env steps count scenes)
        extra = {"agent_steps_per_s": statistics.median(agent_rates), "max_agents": config.selfplay.max_agents}
    return {"algo": config.algo, "encoder": config.network.name, "num_envs": config.algo_config.num_envs, **extra,
            "env_steps_per_s": statistics.median(sps), "min": min(sps), "max": max(sps),
            "env_steps_per_chunk": setup.per_chunk, "buffer_mib": setup.buffer_mib, "peak_rss_mb": peak_rss_mb(),
            "device": str(jax.devices()[0].device_kind), "num_devices": jax.device_count()}
