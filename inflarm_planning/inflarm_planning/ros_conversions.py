"""Planner results to ROS messages: the trajectory as nav_msgs/Path, the scene as markers."""

from collections.abc import Sequence

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PoseStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.duration import Duration
from rclpy.time import Time as RclpyTime
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from inflarm_planning.collision import Cuboid, box_array
from inflarm_planning.trajectory import Trajectory

OBSTACLE_COLOR = ColorRGBA(r=0.63, g=0.32, b=0.18, a=0.8)
ALERT_COLOR = ColorRGBA(r=0.12, g=0.47, b=0.71, a=0.2)
PATH_COLOR = ColorRGBA(r=0.0, g=0.0, b=0.0, a=1.0)
PATH_WIDTH = 0.003  # [m]
FLAT = 1e-4  # [m]: RViz draws no zero-thickness cube


def point_of(pose: PoseStamped) -> tuple[float, float, float]:
    """Position of a stamped pose [m]."""
    p = pose.pose.position
    return (p.x, p.y, p.z)


def trajectory_to_path(trajectory: Trajectory, frame_id: str, start: RclpyTime) -> Path:
    """A trajectory as a Path: each pose stamped with the time it is due (``start + t``)."""
    path = Path()
    path.header.frame_id = frame_id
    path.header.stamp = start.to_msg()
    for point, t in zip(trajectory.points, trajectory.times, strict=True):
        pose = PoseStamped()
        pose.header.frame_id = frame_id
        pose.header.stamp = (start + Duration(nanoseconds=int(round(t * 1e9)))).to_msg()
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (
            float(v) for v in point)
        pose.pose.orientation.w = 1.0
        path.poses.append(pose)
    return path


def empty_path(frame_id: str, stamp: Time) -> Path:
    """A Path without poses (the service's answer when there is no path)."""
    path = Path()
    path.header.frame_id = frame_id
    path.header.stamp = stamp
    return path


def _cube(ns: str, index: int, low: np.ndarray, high: np.ndarray, color: ColorRGBA,
          frame_id: str, stamp: Time) -> Marker:
    marker = Marker(ns=ns, id=index, type=Marker.CUBE, action=Marker.ADD, color=color)
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    centre = low / 2.0 + high / 2.0
    size = np.maximum(high - low, FLAT)
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = (
        float(v) for v in centre)
    marker.pose.orientation.w = 1.0
    marker.scale.x, marker.scale.y, marker.scale.z = (float(v) for v in size)
    return marker


def scene_markers(
    obstacles: Sequence[Cuboid], alert_margin: float, path: np.ndarray | None, frame_id: str,
    stamp: Time,
) -> MarkerArray:
    """Obstacles, their alert regions and the path (if any), after clearing older markers."""
    markers = [Marker(action=Marker.DELETEALL)]
    markers[0].header.frame_id = frame_id
    markers[0].header.stamp = stamp
    for k, (low, high) in enumerate(box_array(obstacles)):
        markers.append(_cube('obstacles', k, low, high, OBSTACLE_COLOR, frame_id, stamp))
    for k, (low, high) in enumerate(box_array(obstacles, alert_margin)):
        markers.append(_cube('alert_regions', k, low, high, ALERT_COLOR, frame_id, stamp))
    if path is not None and len(path) >= 2:
        line = Marker(ns='path', id=0, type=Marker.LINE_STRIP, action=Marker.ADD,
                      color=PATH_COLOR)
        line.header.frame_id = frame_id
        line.header.stamp = stamp
        line.pose.orientation.w = 1.0
        line.scale.x = PATH_WIDTH
        line.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in path]
        markers.append(line)
    return MarkerArray(markers=markers)
