"""Evaluation modes: how the world around the evaluated SDC behaves.

- `non_reactive`: every other object replays its log (`vmax_sim.evaluation.rollout`).
- `reactive`: the objects flagged `is_controllable` in the shards are driven along their own paths
  (`SimulatorState.agent_paths`) by IDM, PDM-Closed or the evaluated policy itself
  (`vmax_sim.evaluation.reactive`); the rest replay the log. Collisions among the non-SDC objects
  are counted apart (`other_collision`), never in the SDC's scores.
- `perturbed`: the SDC's logged history is bent sideways over its last `num_steps` steps so that the
  policy starts off the log with a heading error, then the policy drives (`vmax_sim.evaluation.perturb`).

`EvalMode` is the static description (hashable: one compilation per mode); `parse_mode` makes one
from a name and options, with one-line errors.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from vmax_sim.policies.traffic import AGENT_SPEEDS

MODE_NAMES = ("non_reactive", "reactive", "perturbed", "adversarial")
PLANNED_MODES: tuple[str, ...] = ()
AGENT_DRIVERS = ("idm", "pdm", "same", "learned")


@dataclasses.dataclass(frozen=True)
class PerturbConfig:
    """ChauffeurNet-style start perturbation of the SDC (see `vmax_sim.evaluation.perturb`)."""

    sigma: float = 1.0  # m, standard deviation of the lateral offset at the first policy step
    heading_sigma: float | None = None  # rad, of the heading error there; None: 0.05 rad per metre of sigma
    num_steps: int = 10  # history steps over which the offset blends in from the log (1 s)
    max_sigmas: float = 2.5  # draws are clipped to this many standard deviations
    min_travel: float = 2.0  # m; an SDC driving less than this over the blend is shifted as a whole
    scales: tuple[float, ...] = (1.0, 0.5, 0.25, 0.0)  # the first that starts on the road and clear of others

    def __post_init__(self):
        if self.sigma < 0 or (self.heading_sigma is not None and self.heading_sigma < 0):
            raise ValueError(f"perturbation sigmas must not be negative, got {self.sigma}, {self.heading_sigma}")
        if self.num_steps < 1 or self.max_sigmas <= 0 or not self.scales:
            raise ValueError("PerturbConfig needs num_steps >= 1, max_sigmas > 0 and at least one scale")
        object.__setattr__(self, "scales", tuple(float(v) for v in self.scales))

    @property
    def heading_sigma_rad(self) -> float:
        return 0.05 * self.sigma if self.heading_sigma is None else float(self.heading_sigma)


@dataclasses.dataclass(frozen=True)
class AdversaryConfig:
    """ReGentS-style cut-in attack by one logged vehicle (see `vmax_sim.evaluation.adversary`)."""

    num_candidates: int = 4  # vehicles attacked in parallel, nearest logged approach to the SDC first
    search_radius: float = 40.0  # m; vehicles whose logged future never comes this close are not candidates
    iterations: int = 80  # Adam steps
    learning_rate: float = 0.05  # in units of max_accel / max_curvature
    softmin_temperature: float = 0.5  # m
    rear_penalty: float = 3.0  # extra distance per metre the adversary is behind the SDC's rear bumper
    log_weight: float = 0.5  # pull towards the logged actions (mean squared, normalised units)
    min_contact_step: int = 15  # policy steps (1.5 s) before the adversary may touch the SDC
    # kinematic bounds of the adversary (every planned trajectory stays inside them)
    max_accel: float = 3.0  # m/s^2
    max_decel: float = 6.0  # m/s^2
    max_curvature: float = 0.2  # 1/m (5 m radius)
    max_curvature_rate: float = 0.01  # 1/m per 0.1 s step (no swinging turns)
    max_lateral_accel: float = 4.0  # m/s^2, v^2 |k|
    speed_factor: float = 1.25  # top speed: this times the vehicle's fastest logged speed ...
    min_max_speed: float = 8.0  # ... but at least this, m/s (a parked car may pull out)

    def __post_init__(self):
        for name in ("num_candidates", "iterations", "min_contact_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"AdversaryConfig.{name} must be at least 1, got {getattr(self, name)}")
        for name in ("search_radius", "learning_rate", "softmin_temperature", "max_accel", "max_decel",
                     "max_curvature", "max_curvature_rate", "max_lateral_accel", "speed_factor", "min_max_speed"):
            if getattr(self, name) <= 0:
                raise ValueError(f"AdversaryConfig.{name} must be positive, got {getattr(self, name)}")


@dataclasses.dataclass(frozen=True)
class EvalMode:
    name: str = "non_reactive"  # one of MODE_NAMES
    # reactive: who drives the controllable agents: "idm", "pdm", "same" (the evaluated policy, self-play) or
    # "learned" (a trained policy of its own, `agent_policy`: learned traffic)
    agents: str = "idm"
    # agents="learned": (Policy, its params, its ObservationConfig), e.g. a self-play run's; `agent_run` names it
    # (and keys the compiled rollouts: the policy itself is not compared)
    agent_policy: Any = dataclasses.field(default=None, compare=False, hash=False, repr=False)
    agent_run: str = ""
    max_agents: int = 48  # reactive: at most this many agents (nearest the SDC) are driven; the rest replay
    # reactive, agents="idm": a vmax_sim.policies.IDMConfig (None: its defaults; not imported here, as
    # vmax_sim.policies imports this package)
    agent_idm: Any = None
    agent_speed: str = "log"  # reactive idm: desired speed = the lane's limit ("limit") or at most the agent's
    # fastest logged speed in the episode ("log", so that it keeps its logged pace when the road is free)
    # reactive idm / pdm / learned: never get ahead of the agent's own logged position along its path (the log is a
    # virtual leader it may fall behind but not overtake; see docs/evaluation-modes.md)
    agent_follow_log: bool = True
    perturb: PerturbConfig = PerturbConfig()
    adversary: AdversaryConfig = AdversaryConfig()
    seed: int = 0  # perturbed: with the scenario id, picks each scenario's perturbation

    def __post_init__(self):
        if self.name in PLANNED_MODES:
            raise ValueError(f"evaluation mode {self.name!r} is not implemented yet; available: {MODE_NAMES}")
        if self.name not in MODE_NAMES:
            raise ValueError(f"unknown evaluation mode {self.name!r}; choose one of {MODE_NAMES}")
        if self.agents not in AGENT_DRIVERS:
            raise ValueError(f"unknown agent driver {self.agents!r}; choose one of {AGENT_DRIVERS}")
        if self.agent_speed not in AGENT_SPEEDS:
            raise ValueError(f"EvalMode.agent_speed must be one of {AGENT_SPEEDS}, got {self.agent_speed!r}")
        if self.max_agents < 1:
            raise ValueError(f"EvalMode.max_agents must be at least 1, got {self.max_agents}")
        if (self.agents == "learned") != (self.agent_policy is not None):
            raise ValueError("learned traffic (agents='learned') takes a trained policy: give a training run "
                             "directory as --agents")

    @property
    def is_reactive(self) -> bool:
        return self.name == "reactive"

    @property
    def is_perturbed(self) -> bool:
        return self.name == "perturbed"

    @property
    def is_adversarial(self) -> bool:
        return self.name == "adversarial"

    def options(self) -> dict:
        """The settings that matter for this mode (JSON-serialisable; {} for non_reactive)."""
        if self.is_reactive:
            rules = {"agent_follow_log": self.agent_follow_log}
            if self.agents == "idm":
                rules["agent_speed"] = self.agent_speed
            if self.agents == "learned":
                return {"agents": self.agent_run or "learned", "max_agents": self.max_agents, **rules}
            return {"agents": self.agents, "max_agents": self.max_agents, **(rules if self.agents != "same" else {})}
        if self.is_perturbed:
            return {"sigma": self.perturb.sigma, "heading_sigma": self.perturb.heading_sigma_rad,
                    "num_steps": self.perturb.num_steps, "seed": self.seed}
        if self.is_adversarial:
            return dataclasses.asdict(self.adversary)
        return {}


def parse_mode(mode: str | EvalMode = "non_reactive", *, agents: str | None = None,
               perturb_sigma: float | None = None, max_agents: int | None = None, seed: int = 0,
               agents_follow_log: bool | None = None) -> EvalMode:
    """An `EvalMode` from a name and the command line's options (None: the default).

    An `EvalMode` is returned as it is (the options must then be None). Options that do not apply
    to the mode raise ValueError, so a mistyped command does not silently evaluate something else.
    """
    if isinstance(mode, EvalMode):
        if any(option is not None for option in (agents, perturb_sigma, max_agents, agents_follow_log)):
            raise ValueError("pass the options inside the EvalMode, not beside it")
        return mode
    if not isinstance(mode, str):
        raise ValueError(f"an evaluation mode is a name {MODE_NAMES} or an EvalMode, got {type(mode).__name__}")
    result = EvalMode(name=mode, seed=seed)
    if agents is not None or max_agents is not None or agents_follow_log is not None:
        if not result.is_reactive:
            raise ValueError(f"--agents / --max-agents / --agents-follow-log apply to --mode reactive, not {mode!r}")
        result = dataclasses.replace(result, agents=agents or result.agents,
                                     max_agents=result.max_agents if max_agents is None else max_agents,
                                     agent_follow_log=(result.agent_follow_log if agents_follow_log is None
                                                       else agents_follow_log))
        if agents_follow_log is not None and result.agents == "same":
            raise ValueError("--agents-follow-log applies to idm, pdm and learned agents; --agents same drives them "
                             "with the evaluated policy itself")
    if perturb_sigma is not None:
        if not result.is_perturbed:
            raise ValueError(f"--perturb-sigma applies to --mode perturbed, not {mode!r}")
        result = dataclasses.replace(result, perturb=PerturbConfig(sigma=perturb_sigma))
    return result
