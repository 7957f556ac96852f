"""Expert (log-replay) actions from the inverse dynamics."""

from __future__ import annotations

from vmax_sim.datatypes import Action, SimulatorState
from vmax_sim.dynamics import BICYCLE, DynamicsModel


def expert_actions(state: SimulatorState, dynamics: DynamicsModel = BICYCLE) -> Action:
    """Actions taking each object from its current simulated state to its next logged state.

    Closing the loop on the simulated state (rather than the log at t) keeps the replay from
    drifting; the bicycle model's expert controller also feeds back position error (see
    `bicycle_tracking_inverse_step`). state (...) -> Action (..., N, dim); valid where both exist.
    """
    current, target = state.current_sim_trajectory, state.next_log_trajectory
    return Action(data=dynamics.expert_step(current, target), valid=current.valid & target.valid)


def log_actions(state: SimulatorState, dynamics: DynamicsModel = BICYCLE) -> Action:
    """Open-loop actions reproducing the log step timestep -> timestep + 1. Action (..., N, dim)"""
    current, target = state.current_log_trajectory, state.next_log_trajectory
    return Action(data=dynamics.inverse_step(current, target), valid=current.valid & target.valid)
