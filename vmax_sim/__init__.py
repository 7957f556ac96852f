"""vmax_sim: a JAX driving simulator, metrics, observations and evaluation over scenariomax shards.

Sub-packages: `datatypes`, `data` (loader), `dynamics`, `env`, `geometry`, `metrics`, `observation`,
`evaluation`; `map_index` (per-scenario acceleration structure) and `bench`.
"""

from vmax_sim.data import DataConfig, make_data_iterator, scenario_to_state
from vmax_sim.env import EnvConfig, Environment, MultiAgentEnvironment, make_environment
from vmax_sim.evaluation import evaluate

__version__ = "0.1.0"

__all__ = ["DataConfig", "EnvConfig", "Environment", "MultiAgentEnvironment", "evaluate", "make_data_iterator",
           "make_environment", "scenario_to_state", "__version__"]
