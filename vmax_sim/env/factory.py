"""`make_environment`: the `Environment` evaluation and users step, with termination from the metrics.

`Environment` takes its termination predicate injected (it knows nothing of metrics); this builds the
one named by `EnvConfig.terminate_on` from the metric predicates of `vmax_sim.env.metrics_adapter`.
Training steps the same core environment through `vmax_sim.env.learning.LearningEnv`, which reads the
termination from the metrics its step computes anyway.
"""

from __future__ import annotations

from vmax_sim.env.config import EnvConfig
from vmax_sim.env.environment import Environment
from vmax_sim.env.metrics_adapter import make_termination_fn
from vmax_sim.metrics import MetricsConfig


def make_environment(env_config: EnvConfig | None = None, metrics_config: MetricsConfig | None = None) -> Environment:
    """An `Environment` whose termination follows `env_config.terminate_on` (needs states with a map index)."""
    env_config = env_config or EnvConfig()
    return Environment(env_config, termination_fn=make_termination_fn(env_config, metrics_config))
