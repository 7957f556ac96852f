"""`EnvConfig`: the static settings of an environment."""

from __future__ import annotations

import dataclasses

CONTROLLED_CHOICES = ("sdc", "controllable")


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    max_num_objects: int = 64  # must equal the loaded states' num_objects (DataConfig.num_objects)
    # "sdc": the SDC only; "controllable": the SDC plus every object flagged is_controllable;
    # or an explicit per-slot tuple of bools of length max_num_objects.
    controlled: str | tuple[bool, ...] = "sdc"
    dynamics: str = "bicycle"  # see vmax_sim.dynamics.dynamics_names()
    normalize_actions: bool = False  # step() takes actions in [-1, 1] (mapped onto the model's bounds)
    init_steps: int = 11  # steps taken from the log before the policy acts (timestep starts at init_steps - 1)
    episode_length: int = 80  # policy steps before truncation
    # Metric names an integration layer turns into the env's termination_fn (see combine_termination_fns).
    terminate_on: tuple[str, ...] = ("collision", "offroad", "red_light")

    def __post_init__(self) -> None:
        if self.max_num_objects < 1:
            raise ValueError(f"EnvConfig.max_num_objects must be at least 1, got {self.max_num_objects}")
        if self.init_steps < 1 or self.episode_length < 1:
            raise ValueError("EnvConfig.init_steps and episode_length must be at least 1")
        if isinstance(self.controlled, str):
            if self.controlled not in CONTROLLED_CHOICES:
                raise ValueError(f"EnvConfig.controlled must be one of {CONTROLLED_CHOICES} or a mask, "
                                 f"got {self.controlled!r}")
        elif len(self.controlled) != self.max_num_objects:
            raise ValueError(f"EnvConfig.controlled mask has {len(self.controlled)} entries, "
                             f"expected max_num_objects={self.max_num_objects}")
        object.__setattr__(self, "terminate_on", tuple(self.terminate_on))
        if not isinstance(self.controlled, str):
            object.__setattr__(self, "controlled", tuple(bool(v) for v in self.controlled))

    @property
    def first_policy_timestep(self) -> int:
        """The timestep reset() sets: the last step taken from the log."""
        return self.init_steps - 1

    @property
    def last_timestep(self) -> int:
        """The timestep at which an episode is truncated."""
        return self.init_steps - 1 + self.episode_length
