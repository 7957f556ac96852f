"""vmax_sim: a JAX driving simulator, metrics, observations and RL tooling over scenariomax shards."""

__version__ = "0.1.0"
