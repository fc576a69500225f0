"""Validation of the path planner node's inputs, without ROS (the node only converts messages).

Every function raises ``ValueError`` naming what was wrong; the node logs the text, answers the
request with it and keeps running.
"""

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from inflarm_model.soft_arm import WORKSPACE_POSITIVE, Workspace
import inflarm_msgs_json
from inflarm_planning.astar import COSTS
from inflarm_planning.collision import Cuboid, as_cuboids, check_margin
from inflarm_planning.free_space import Lattice, check_resolution

MAX_COORDINATE = 1000.0
"""[m] An obstacle corner farther than this from the mount is not a measurement of anything."""

MAX_ALERT_MARGIN = 1.0
"""[m] An alert margin above this would cover the whole work space (404 mm across)."""


@dataclass(frozen=True)
class ObstacleModel:
    """Obstacles as the planner uses them.

    Attributes
    ----------
    obstacles : tuple of Cuboid
        The boxes, ``sra_mount`` [m].
    alert_margin : float
        The margin planned with [m]: the message's, raised to the node's minimum if smaller.
    requested_margin : float
        The margin the message asked for [m].
    """

    obstacles: tuple[Cuboid, ...]
    alert_margin: float
    requested_margin: float

    @property
    def raised(self) -> bool:
        """Whether the requested margin was below the minimum and was raised."""
        return self.alert_margin > self.requested_margin


@dataclass(frozen=True)
class PlanQuery:
    """A validated plan request.

    Attributes
    ----------
    start, goal : tuple of 3 float
        End points, ``sra_mount`` [m].
    resolution : float
        Grid spacing [m].
    """

    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    resolution: float


def check_frame(frame_id: str, expected: str, what: str) -> None:
    """Raise unless ``frame_id`` is ``expected``."""
    if frame_id != expected:
        raise ValueError(f"{what}: frame_id '{frame_id}' is not '{expected}'")


def obstacle_model(
    message: inflarm_msgs_json.ObstacleSet, frame_id: str, min_alert_margin: float
) -> ObstacleModel:
    """Check an ObstacleSet and raise its margin to the node's minimum.

    Parameters
    ----------
    message : inflarm_msgs_json.ObstacleSet
        Decoded message (its boxes are valid: min <= max, finite).
    frame_id : str
        The planner's frame; the message must be in it.
    min_alert_margin : float
        Smallest alert margin planned with [m].

    Returns
    -------
    ObstacleModel
    """
    check_frame(message.frame_id, frame_id, 'obstacles')
    minimum = check_margin(min_alert_margin, 'min_alert_margin')
    requested = check_margin(message.alert_margin)
    if requested > MAX_ALERT_MARGIN:
        raise ValueError(f'obstacles: alert_margin {requested:g} m is above '
                         f'{MAX_ALERT_MARGIN:g} m (it would cover the whole work space)')
    boxes = as_cuboids(message)
    for k, box in enumerate(boxes):
        if np.max(np.abs(box.bounds)) > MAX_COORDINATE:
            raise ValueError(f'obstacles[{k}]: a corner is more than {MAX_COORDINATE:g} m from '
                             f'the mount: {box.bounds.tolist()}')
    return ObstacleModel(boxes, max(requested, minimum), requested)


def _point(value: npt.ArrayLike, name: str) -> tuple[float, float, float]:
    p = np.asarray(value, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f'{name}: expected 3 finite coordinates [m], got {p.tolist()}')
    return tuple(float(v) for v in p)


def plan_query(
    start: npt.ArrayLike, goal: npt.ArrayLike, resolution: float, frames: tuple[str, ...],
    frame_id: str, max_cells: int, workspace: Workspace = WORKSPACE_POSITIVE,
    limit: str = 'for memory',
) -> PlanQuery:
    """Check a plan request's end points, frames and resolution.

    Parameters
    ----------
    start, goal : array-like, shape (3,)
        End points [m].
    resolution : float
        Grid spacing [m], > 0.
    frames : tuple of str
        The frames the request gives (one for a PlanRequest, start's and goal's for GetPlan).
    frame_id : str
        The planner's frame.
    max_cells : int
        Largest grid accepted.
    workspace : Workspace
        Bounds of the grid.
    limit : str
        Why ``max_cells`` is the limit, for the message (``'for memory'``).

    Returns
    -------
    PlanQuery
    """
    for frame in frames:
        check_frame(frame, frame_id, 'plan request')
    p_start = _point(start, 'start')
    p_goal = _point(goal, 'goal')
    if p_start == p_goal:
        raise ValueError(f'plan request: start and goal are the same point {list(p_start)}')
    lattice = Lattice.over(workspace, check_resolution(resolution))
    if lattice.size > max_cells:
        finest = (lattice.size / max_cells) ** (1.0 / 3.0) * lattice.resolution
        raise ValueError(
            f'resolution {lattice.resolution:g} m is too fine {limit}: {lattice.size:.3g} grid '
            f'points, more than {max_cells:.3g}; use resolution >= '
            f'{math.ceil(finest * 1e5) / 1e5:g} m')
    return PlanQuery(p_start, p_goal, lattice.resolution)


def check_cost(cost: str) -> str:
    """Raise unless ``cost`` is one of the planner's costs."""
    if cost not in COSTS:
        raise ValueError(f"cost: expected one of {sorted(COSTS)}, got '{cost}'")
    return cost
