"""The ch. 3 POMDP that chooses between observing again and sliding the target (thesis 3.4).

States (3.4.1): the target Shogi piece in one of 4 basic poses x 8 yaws of 45 deg = 32 discrete
states. An observation o_a is the target's observed points; a state's point cloud o_s is the
CAD model (`shogi_piece`) posed in that state and ray-cast from the same eye(s), past the same
occluders, so both clouds are what a depth sensor would return. The fit e(o_s, o_a) is the
mean nearest-neighbour distance between them (both ways) after a small ICP correction; it
gives a weight (eq. 3.5) that scales the belief, which is never normalised (eq. 3.4), so its
mass (eq. 3.8) falls as observations rule states out. Observing at a candidate viewpoint
(3.4.3) is worth alpha V1 + beta V2 (eq. 3.12): the mass it is expected to remove (eqs. 3.9,
3.10) and the share of the workspace grid it would reveal (eq. 3.11); sliding is worth the
belief on the flat states times the reward (eqs. 3.6, 3.7); the larger wins (eq. 3.3).

Frames and units: the chapter 3 world, metres: the board's top surface is z = 0, its centre the
origin, z up. Every point array is (N, 3) float64 in that frame. Cameras are OpenCV frames
(x right, y down, z forward), as in `observation.CameraModel`.

The package, one concept per module, each importing only those before it: `states` (the 32
states), `views` (model and observed clouds, occlusion), `belief` (fit, weights, belief
mass) and `values` (viewpoints, occupancy grid, values, `decide`). Every public name is
re-exported here, so `pomdp.decide` and `from clutterbench.planning.ch3.pomdp import ...` work.
"""

from __future__ import annotations

from clutterbench.planning.ch3.pomdp.belief import (
    E_TH_M,
    ICP_ITERATIONS,
    MAX_CORRESPONDENCE_M,
    MAX_ICP_ROTATION_DEG,
    MIN_OBSERVED_POINTS,
    belief_mass,
    fit_weight,
    icp_error,
    occluder_cloud,
    seen_cloud,
    state_errors,
    state_weights,
    uniform_belief,
    update_belief,
)
from clutterbench.planning.ch3.pomdp.states import (
    BASIC_POSES,
    LEAN_DEG,
    N_STATES,
    N_YAWS,
    SLIDABLE_STATES,
    check_state,
    equivalent_states,
    state_basic,
    state_pose,
    state_rotation,
    state_yaw,
)
from clutterbench.planning.ch3.pomdp.values import (
    ALPHA,
    BETA,
    Decision,
    OccupancyGrid,
    decide,
    expected_mass_after,
    observation_value,
    occupancy_grid,
    slide_value,
    uncertainty_reduction,
    viewpoint_candidates,
    visibility_value,
    visible_cells,
)
from clutterbench.planning.ch3.pomdp.views import (
    BOARD_CLEARANCE_M,
    DEPTH_TOLERANCE_M,
    LOOK_AT_HEIGHT_M,
    N_MODEL_POINTS,
    PIXEL_M,
    SPLAT_PIXELS,
    VIEW_RADIUS_M,
    VOXEL_M,
    EyeView,
    aim_point,
    look_at_pose,
    model_cloud,
    model_view,
    piece_view,
    visible_mask,
    visible_points,
    voxel_downsample,
)

__all__ = [
    "BASIC_POSES",
    "LEAN_DEG",
    "N_STATES",
    "N_YAWS",
    "SLIDABLE_STATES",
    "check_state",
    "equivalent_states",
    "state_basic",
    "state_pose",
    "state_rotation",
    "state_yaw",
    "BOARD_CLEARANCE_M",
    "DEPTH_TOLERANCE_M",
    "LOOK_AT_HEIGHT_M",
    "N_MODEL_POINTS",
    "PIXEL_M",
    "SPLAT_PIXELS",
    "VIEW_RADIUS_M",
    "VOXEL_M",
    "EyeView",
    "aim_point",
    "look_at_pose",
    "model_cloud",
    "model_view",
    "piece_view",
    "visible_mask",
    "visible_points",
    "voxel_downsample",
    "E_TH_M",
    "ICP_ITERATIONS",
    "MAX_CORRESPONDENCE_M",
    "MAX_ICP_ROTATION_DEG",
    "MIN_OBSERVED_POINTS",
    "belief_mass",
    "fit_weight",
    "icp_error",
    "occluder_cloud",
    "seen_cloud",
    "state_errors",
    "state_weights",
    "uniform_belief",
    "update_belief",
    "ALPHA",
    "BETA",
    "Decision",
    "OccupancyGrid",
    "decide",
    "expected_mass_after",
    "observation_value",
    "occupancy_grid",
    "slide_value",
    "uncertainty_reduction",
    "viewpoint_candidates",
    "visibility_value",
    "visible_cells",
]
