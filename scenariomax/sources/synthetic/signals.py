"""Fixed-time signal plans: one phase per light group, then a pedestrian-only phase.

A group is one approach (split phasing: movements released together never cross each other) or, with the
`paired_signals` knob, two opposite approaches (their turns cross the oncoming lanes). Either way the reservation
logic in `traffic` orders whatever crosses inside the junction, including anything a phase change leaves there.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.schema import TL_CAUTION, TL_GO, TL_STOP


@dataclasses.dataclass(frozen=True)
class SignalPlan:
    num_groups: int  # light groups: one per junction approach, or one per pair of opposite approaches
    green_s: float  # green time per approach
    yellow_s: float
    all_red_s: float  # clearance after each yellow
    pedestrian_s: float  # all-red phase in which pedestrians cross (0: none)
    offset_s: float  # where in the cycle the episode's first step falls

    @property
    def cycle_s(self) -> float:
        return self.num_groups * (self.green_s + self.yellow_s + self.all_red_s) + self.pedestrian_s


def signal_states(plan: SignalPlan, times_s: np.ndarray) -> np.ndarray:
    """Light state per group and time (enum 6 go, 5 caution, 4 stop). (T,) -> (num_groups, T) int64"""
    phase_len = plan.green_s + plan.yellow_s + plan.all_red_s
    in_cycle = (np.asarray(times_s) + plan.offset_s) % plan.cycle_s
    group = np.arange(plan.num_groups)[:, None]
    local = in_cycle[None, :] - group * phase_len
    states = np.full(local.shape, TL_STOP, np.int64)
    states[(local >= 0) & (local < plan.green_s)] = TL_GO
    states[(local >= plan.green_s) & (local < plan.green_s + plan.yellow_s)] = TL_CAUTION
    return states


def pedestrian_phase(plan: SignalPlan, times_s: np.ndarray) -> np.ndarray:
    """True while the pedestrian-only phase runs. (T,) -> (T,) bool"""
    in_cycle = (np.asarray(times_s) + plan.offset_s) % plan.cycle_s
    return in_cycle >= plan.cycle_s - plan.pedestrian_s


def random_plan(rng: np.random.Generator, num_groups: int, has_crosswalks: bool) -> SignalPlan:
    plan = SignalPlan(
        num_groups=num_groups,
        green_s=float(rng.uniform(5.0, 10.0)),
        yellow_s=3.0,
        all_red_s=float(rng.uniform(1.0, 2.0)),
        pedestrian_s=float(rng.uniform(6.0, 9.0)) if has_crosswalks else 0.0,
        offset_s=0.0,
    )
    return dataclasses.replace(plan, offset_s=float(rng.uniform(0.0, plan.cycle_s)))
