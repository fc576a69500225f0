"""The ball in 3D: from its outline in one image, from two cameras, and the camera's pose.

Pure numpy/scipy/OpenCV, no rclpy. Frames and pixels as in `inflarm_model.camera`.

**One camera** (`locate_ball`). Seen from the projection centre, a sphere of radius ``R`` with
its centre at distance ``D`` along the unit vector ``c`` fills the cone of rays ``r`` with
``r . c >= cos(a)``, ``sin(a) = R / D``. Its outline in the image is the projection of the rays on
that cone. So the edge points found in the raw image are undistorted into unit rays ``r_i``
(`inflarm_model.camera.pixel_rays`), and the cone is fitted to them by linear least squares:

    r_i . n = 1  for  n = c / cos(a)   =>   cos(a) = 1 / |n|,  c = n cos(a),  D = R / sin(a)

which needs no circle or ellipse in the image and no small-angle approximation. On the optical
axis it reduces to ``D = R sqrt(f^2 + r^2) / r`` for an image of radius ``r`` (``tan(a) =
r / f``), not ``f R / r``. Off the axis the image (before distortion) is an ellipse whose centre
is *not* the projection of ``c``; the fit gives ``c`` directly, and its projection is reported.

**Two or more cameras** (`triangulate_ball`): the point nearest, in the least-squares sense,
to the rays from each camera's centre along its fitted axis ``c``, in the mount frame.

**Calibration** (`calibrate_camera_to_mount`): the rigid transform camera -> mount that best
maps ball centres located in the camera frame onto the same balls' known positions in the
mount frame (Kabsch, by ``scipy.spatial.transform.Rotation.align_vectors``), with the residual
of every point.
"""

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from inflarm_model.camera import PinholeCamera, RigidTransform, pixel_rays, project_points

__all__ = [
    'BallLocation',
    'CameraCalibration',
    'TriangulatedBall',
    'calibrate_camera_to_mount',
    'locate_ball',
    'triangulate_ball',
]


@dataclass(frozen=True)
class BallLocation:
    """The ball's centre from its outline in one image.

    Attributes
    ----------
    position : ndarray, shape (3,)
        Centre of the ball in the camera frame [m].
    distance : float
        ``|position|`` [m].
    half_angle : float
        Half-angle ``a`` of the cone the ball subtends [rad].
    projected_center : ndarray, shape (2,)
        Projection of the centre into the raw image [px].
    residual : float
        Root mean square angle between the edge rays and the fitted cone [rad].
    """

    position: npt.NDArray[np.float64]
    distance: float
    half_angle: float
    projected_center: npt.NDArray[np.float64]
    residual: float


def locate_ball(edge_points, camera: PinholeCamera, ball_radius: float) -> BallLocation:
    """Locate the ball's centre in the camera frame from points on its outline.

    Parameters
    ----------
    edge_points : array-like, shape (n, 2), or BallDetection
        At least 5 points on the outline in the raw (distorted) image [px], or a detection
        (its ``edge_points``).
    camera : PinholeCamera
        Intrinsics, distortion included.
    ball_radius : float
        Radius of the ball [m].

    Returns
    -------
    BallLocation
        By the cone fit of the module docstring.

    Raises
    ------
    ValueError
        If the points are too few, not finite, or do not outline a cone in front of the camera.
    """
    points = np.asarray(getattr(edge_points, 'edge_points', edge_points), dtype=float)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 5:
        raise ValueError(f'expected edge_points of shape (n >= 5, 2), got {points.shape}')
    if not (math.isfinite(ball_radius) and ball_radius > 0.0):
        raise ValueError(f'expected ball_radius > 0 [m], got {ball_radius}')
    rays = pixel_rays(camera, points)
    n, _, rank, _ = np.linalg.lstsq(rays, np.ones(len(rays)), rcond=None)
    norm2 = float(n @ n)
    if rank < 3 or not (math.isfinite(norm2) and norm2 > 1.0):
        raise ValueError('edge_points do not outline a cone of rays (a ball) in front of the '
                         'camera')
    cos_a = 1.0 / math.sqrt(norm2)
    sin_a = math.sqrt((norm2 - 1.0) / norm2)
    axis = n * cos_a
    if axis[2] <= 0.0:
        raise ValueError('edge_points outline a cone behind the camera')
    distance = ball_radius / sin_a
    position = distance * axis
    half_angle = math.atan2(sin_a, cos_a)
    angles = np.arccos(np.clip(rays @ axis, -1.0, 1.0))
    return BallLocation(position=position, distance=distance, half_angle=half_angle,
                        projected_center=project_points(camera, position),
                        residual=float(np.sqrt(np.mean((angles - half_angle) ** 2))))


@dataclass(frozen=True)
class TriangulatedBall:
    """The ball's centre from several cameras.

    Attributes
    ----------
    position : ndarray, shape (3,)
        Centre in the common frame [m].
    ray_distances : ndarray, shape (n_cameras,)
        Distance of ``position`` from each camera's ray [m] (consistency of the views).
    """

    position: npt.NDArray[np.float64]
    ray_distances: npt.NDArray[np.float64]


def triangulate_ball(locations: Sequence[BallLocation],
                     cameras2frame: Sequence[RigidTransform]) -> TriangulatedBall:
    """Intersect, in least squares, the rays towards the ball's centre from several cameras.

    Parameters
    ----------
    locations : sequence of BallLocation
        The ball located in each camera's image (only the direction of ``position`` is used).
    cameras2frame : sequence of RigidTransform
        Pose of each camera in the common frame (e.g. ``sra_mount``).

    Returns
    -------
    TriangulatedBall
        The point minimizing the sum of squared distances to the rays.

    Raises
    ------
    ValueError
        Fewer than two views, mismatched lengths, or (nearly) parallel rays.
    """
    if len(locations) != len(cameras2frame) or len(locations) < 2:
        raise ValueError(
            f'expected as many camera poses as locations, at least 2; got {len(locations)} '
            f'locations and {len(cameras2frame)} poses')
    origins = np.array([pose.translation for pose in cameras2frame])
    directions = np.array([pose.rotation @ (loc.position / loc.distance)
                           for loc, pose in zip(locations, cameras2frame, strict=True)])
    projectors = np.eye(3) - directions[:, :, None] * directions[:, None, :]
    a = projectors.sum(axis=0)
    b = np.einsum('nij,nj->i', projectors, origins)
    if np.linalg.cond(a) > 1e8:
        raise ValueError('the cameras see the ball along (nearly) parallel rays')
    position = np.linalg.solve(a, b)
    offsets = position - origins
    along = np.einsum('ni,ni->n', offsets, directions)
    ray_distances = np.linalg.norm(offsets - along[:, None] * directions, axis=1)
    return TriangulatedBall(position=position, ray_distances=ray_distances)


@dataclass(frozen=True)
class CameraCalibration:
    """Result of `calibrate_camera_to_mount`.

    Attributes
    ----------
    camera2mount : RigidTransform
        Pose of the camera in the mount frame.
    residuals : ndarray, shape (n,)
        ``|camera2mount(p_camera) - p_mount|`` per point [m].
    rms : float
        Root mean square of ``residuals`` [m].
    """

    camera2mount: RigidTransform
    residuals: npt.NDArray[np.float64]
    rms: float


def calibrate_camera_to_mount(points_mount: npt.ArrayLike,
                              points_camera: npt.ArrayLike) -> CameraCalibration:
    """Estimate the camera's pose in the mount frame from balls seen at known positions.

    Parameters
    ----------
    points_mount : array-like, shape (n, 3)
        Known ball centres in the mount frame [m], n >= 4, not all on one line.
    points_camera : array-like, shape (n, 3)
        The same balls located by the camera (`locate_ball`), in the camera frame [m].

    Returns
    -------
    CameraCalibration
        The least-squares rigid transform (no scale) and its residuals.
    """
    pm = np.asarray(points_mount, dtype=float)
    pc = np.asarray(points_camera, dtype=float)
    if pm.ndim != 2 or pm.shape[1] != 3 or pm.shape != pc.shape or len(pm) < 4:
        raise ValueError(
            f'expected points_mount and points_camera of the same shape (n >= 4, 3), got '
            f'{pm.shape} and {pc.shape}')
    if not (np.all(np.isfinite(pm)) and np.all(np.isfinite(pc))):
        raise ValueError('expected finite points_mount and points_camera [m]')
    cm, cc = pm.mean(axis=0), pc.mean(axis=0)
    spread = np.linalg.svd(pm - cm, compute_uv=False)
    if spread[1] < 1e-6 * max(spread[0], 1e-12):
        raise ValueError('points_mount lie on one line: the rotation about it is unknown')
    rotation, _ = Rotation.align_vectors(pm - cm, pc - cc)
    r = rotation.as_matrix()
    transform = RigidTransform(r, cm - r @ cc)
    residuals = np.linalg.norm(transform.apply(pc) - pm, axis=1)
    return CameraCalibration(camera2mount=transform, residuals=residuals,
                             rms=float(np.sqrt(np.mean(residuals ** 2))))
