"""Training: the jitted loop (env steps + updates in one `lax.scan`), device replay buffer, scenario pool,
Orbax checkpoints, CSV / TensorBoard logs, resume, data-parallel sharding, and `train`."""

from vmax_sim.training.buffer import ReplayBuffer, buffer_add, buffer_init, buffer_sample, transition_bytes
from vmax_sim.training.config import (
    LoopConfig,
    TrainConfig,
    TrainDataConfig,
    apply_overrides,
    config_from_dict,
    config_to_dict,
    preset_config,
)
from vmax_sim.training.replay import TransitionReplay, replay_add, replay_init, replay_sample
from vmax_sim.training.run import TrainResult, load_run_config, train
from vmax_sim.training.run_policy import LoadedPolicy, evaluate_run, load_trained_policy

__all__ = ["LoadedPolicy", "LoopConfig", "ReplayBuffer", "TrainConfig", "TrainDataConfig", "TrainResult",
           "TransitionReplay", "apply_overrides", "buffer_add", "buffer_init", "buffer_sample", "config_from_dict",
           "config_to_dict", "evaluate_run", "load_run_config", "load_trained_policy", "preset_config", "replay_add",
           "replay_init", "replay_sample", "train", "transition_bytes"]
