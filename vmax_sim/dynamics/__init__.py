"""Pure, jittable dynamics models (forward and inverse) and action normalisation."""

from vmax_sim.dynamics.bicycle import (
    ACCEL_BOUNDS,
    CURVATURE_BOUNDS,
    DT,
    bicycle_forward,
    bicycle_inverse,
    bicycle_inverse_step,
    bicycle_tracking_inverse_step,
    heading_speed,
    wrap_angle,
)
from vmax_sim.dynamics.delta import (
    DELTA_GLOBAL_BOUNDS,
    DELTA_LOCAL_BOUNDS,
    delta_global_forward,
    delta_global_inverse,
    delta_local_forward,
    delta_local_inverse,
)
from vmax_sim.dynamics.model import (
    BICYCLE,
    DELTA_GLOBAL,
    DELTA_LOCAL,
    STATE,
    DynamicsModel,
    dynamics_names,
    get_dynamics,
)
from vmax_sim.dynamics.state import state_forward, state_inverse

__all__ = [
    "ACCEL_BOUNDS",
    "BICYCLE",
    "CURVATURE_BOUNDS",
    "DELTA_GLOBAL",
    "DELTA_GLOBAL_BOUNDS",
    "DELTA_LOCAL",
    "DELTA_LOCAL_BOUNDS",
    "DT",
    "STATE",
    "DynamicsModel",
    "bicycle_forward",
    "bicycle_inverse",
    "bicycle_inverse_step",
    "bicycle_tracking_inverse_step",
    "delta_global_forward",
    "delta_global_inverse",
    "delta_local_forward",
    "delta_local_inverse",
    "dynamics_names",
    "get_dynamics",
    "heading_speed",
    "state_forward",
    "state_inverse",
    "wrap_angle",
]
