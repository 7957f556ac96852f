"""A gymnasium-style loop over V-Max shards (no gymnasium needed).

    scenariomax convert --num-scenarios 8 --out /tmp/shards
    python examples/gym_loop.py /tmp/shards
"""

import sys

import numpy as np

from vmax_sim.data import DataConfig, load_batch
from vmax_sim.env import EnvConfig, GymEnv, make_environment


def main(path: str) -> None:
    config = DataConfig(path=path, num_objects=64)
    scenarios = load_batch(config, num_scenarios=4)  # a pool the adapter draws episodes from
    env = GymEnv(make_environment(EnvConfig(max_num_objects=64)), scenarios)
    observation, info = env.reset(seed=0)
    total, steps = 0.0, 0
    while True:
        action = np.array([0.5, 0.0], np.float32)  # accelerate gently, drive straight
        observation, reward, terminated, truncated, info = env.step(action)
        total, steps = total + float(reward), steps + 1
        if terminated or truncated:
            break
    print(f"episode: {steps} steps, return {total:.2f}, terminated={terminated}, observation {observation.shape}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "runs/demo/shards")
