"""`RewardConfig`: a preset of the V-Max paper, or any weighted sum of reward terms."""

from __future__ import annotations

import dataclasses

# The paper's three presets (weights of the terms in vmax_sim.rewards.terms).
SAFETY = (("collision", -1.0), ("offroad", -1.0), ("red_light", -1.0))
NAVIGATION = SAFETY + (("off_route", -0.2), ("progress", 0.2))
BEHAVIOR = NAVIGATION + (("comfortable", 0.2), ("overspeed", -0.1))
REWARD_PRESETS = {"safety": SAFETY, "navigation": NAVIGATION, "behavior": BEHAVIOR}


@dataclasses.dataclass(frozen=True)
class RewardConfig:
    preset: str = "navigation"  # a key of REWARD_PRESETS, or "none" to use `weights` alone
    # (term, weight) pairs added to the preset; a term named in both takes the weight given here
    weights: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        if self.preset != "none" and self.preset not in REWARD_PRESETS:
            raise ValueError(f"RewardConfig.preset must be one of {sorted(REWARD_PRESETS)} or 'none', "
                             f"got {self.preset!r}")
        object.__setattr__(self, "weights", tuple((str(k), float(w)) for k, w in self.weights))
        if self.preset == "none" and not self.weights:
            raise ValueError("RewardConfig: preset 'none' needs at least one (term, weight) in weights")

    def resolved(self) -> tuple[tuple[str, float], ...]:
        """The final (term, weight) pairs, preset first, in a stable order."""
        weights = dict(REWARD_PRESETS.get(self.preset, ()))
        weights.update(dict(self.weights))
        return tuple(weights.items())
