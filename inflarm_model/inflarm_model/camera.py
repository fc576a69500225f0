"""Pinhole camera with lens distortion, rigid transforms, and the exact image of a sphere.

Shared by the simulated camera (``inflarm_hw.synthetic_camera``) and the ball tracker
(``inflarm_vision``), which must not import each other. Pure numpy/scipy/OpenCV, no rclpy.

Conventions (those of ROS ``sensor_msgs/CameraInfo`` and OpenCV):

- Camera (optical) frame: origin at the projection centre, ``+z`` along the optical axis, ``+x``
  to the right of the image, ``+y`` down the image. Metres.
- Pixels: ``(u, v)`` with ``u`` along the columns; pixel ``i`` spans ``[i - 0.5, i + 0.5]``, so
  the centre of the top-left pixel is ``(0, 0)``.
- Intrinsics: camera matrix ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` [px] and the
  distortion coefficients ``D`` of the ``plumb_bob`` (``k1, k2, p1, p2, k3``) or
  ``rational_polynomial`` (``k1, k2, p1, p2, k3, k4, k5, k6``) model, applied to the raw image
  (CameraInfo's ``R`` is the identity and ``P = [K | 0]``: a monocular camera).
- A `RigidTransform` named ``a2b`` maps points given in frame ``a`` to frame ``b``:
  ``p_b = R p_a + t``; ``camera2mount`` is the camera's pose in ``sra_mount``.

The image of a sphere (`sphere_image`): seen from the projection centre, a sphere of radius
``R`` whose centre is at distance ``D`` fills the circular cone with axis along the centre and
half-angle ``a``, ``sin(a) = R / D``. Its outline in the image is the projection of that cone's
rays: on the optical axis a circle of radius ``f tan(a)`` (so ``D = R sqrt(f^2 + r^2) / r``, not
``f R / r``), off the axis an ellipse (before distortion) whose centre is not the projection of
the sphere's centre.
"""

from dataclasses import dataclass
import math

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from inflarm_model.validation import check_batch

__all__ = [
    'DISTORTION_MODELS',
    'PinholeCamera',
    'RigidTransform',
    'SphereCoverage',
    'SphereImage',
    'cone_rays',
    'look_at',
    'pixel_rays',
    'project_points',
    'sphere_coverage',
    'sphere_image',
    'sphere_position_std',
    'undistort_pixels',
]

DISTORTION_MODELS = {'plumb_bob': 5, 'rational_polynomial': 8}
"""CameraInfo distortion models handled (OpenCV's standard model), with their length of ``D``."""

# Undistortion is an iterative inversion in OpenCV; its default (5 iterations) leaves errors of
# 1e-3 px at the edge of a moderately distorted image. These criteria make it exact to 1e-9 px.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-13)


@dataclass(frozen=True)
class PinholeCamera:
    """Intrinsics of a camera, as in ``sensor_msgs/CameraInfo`` (monocular, raw image).

    Attributes
    ----------
    width, height : int
        Image size [px].
    k : ndarray, shape (3, 3)
        Camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` [px] (a skew ``K[0, 1]`` is
        allowed).
    d : ndarray, shape (5,) or (8,)
        Distortion coefficients of ``distortion_model``.
    distortion_model : str
        ``'plumb_bob'`` (5 coefficients) or ``'rational_polynomial'`` (8).
    """

    width: int
    height: int
    k: npt.NDArray[np.float64]
    d: npt.NDArray[np.float64]
    distortion_model: str = 'plumb_bob'

    def __post_init__(self) -> None:
        for name in ('width', 'height'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f'expected {name} an integer >= 1 [px], got {value!r}')
            object.__setattr__(self, name, int(value))
        k = np.array(self.k, dtype=float)
        if k.shape == (9,):
            k = k.reshape(3, 3)
        if k.shape != (3, 3) or not np.all(np.isfinite(k)):
            raise ValueError(f'expected k a finite 3x3 camera matrix, got shape {k.shape}')
        if not (k[0, 0] > 0.0 and k[1, 1] > 0.0) or np.any(k[1:, 0] != 0.0) or k[2, 1] != 0.0 \
                or k[2, 2] != 1.0:
            raise ValueError(
                f'expected k = [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got '
                f'{k.tolist()}')
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(
                f'distortion_model: expected one of {sorted(DISTORTION_MODELS)}, got '
                f'{self.distortion_model!r}')
        d = np.array(self.d, dtype=float).reshape(-1)
        if d.size == 0:
            d = np.zeros(DISTORTION_MODELS[self.distortion_model])
        if d.size != DISTORTION_MODELS[self.distortion_model] or not np.all(np.isfinite(d)):
            raise ValueError(
                f'expected d {DISTORTION_MODELS[self.distortion_model]} finite coefficients '
                f'for {self.distortion_model}, got {d.tolist()}')
        k.setflags(write=False)
        d.setflags(write=False)
        object.__setattr__(self, 'k', k)
        object.__setattr__(self, 'd', d)

    @classmethod
    def ideal(cls, width: int, height: int, focal_px: float, d: npt.ArrayLike = (),
              distortion_model: str = 'plumb_bob') -> 'PinholeCamera':
        """A camera with square pixels, ``fx = fy = focal_px`` and the principal point at the
        image centre ``((width - 1) / 2, (height - 1) / 2)``."""
        if not (np.isfinite(focal_px) and focal_px > 0.0):
            raise ValueError(f'expected focal_px > 0, got {focal_px}')
        k = [[focal_px, 0.0, (width - 1) / 2.0], [0.0, focal_px, (height - 1) / 2.0],
             [0.0, 0.0, 1.0]]
        return cls(width, height, np.array(k), np.array(d, dtype=float), distortion_model)

    @classmethod
    def from_camera_info(cls, width: int, height: int, k: npt.ArrayLike, d: npt.ArrayLike,
                         distortion_model: str) -> 'PinholeCamera':
        """From the fields of a ``sensor_msgs/CameraInfo`` (``k`` row-major, 9 values).

        An empty ``distortion_model`` with an empty ``d`` means no distortion.
        """
        if distortion_model == '' and len(d) == 0:
            distortion_model = 'plumb_bob'
        return cls(width, height, np.asarray(k, dtype=float), np.asarray(d, dtype=float),
                   distortion_model)

    def camera_info_fields(self) -> dict:
        """The ``sensor_msgs/CameraInfo`` fields of this camera: ``width``, ``height``,
        ``distortion_model``, ``d``, ``k``, ``r`` (identity) and ``p`` (``[K | 0]``), as lists."""
        p = np.zeros((3, 4))
        p[:, :3] = self.k
        return {'width': self.width, 'height': self.height,
                'distortion_model': self.distortion_model, 'd': self.d.tolist(),
                'k': self.k.reshape(-1).tolist(), 'r': np.eye(3).reshape(-1).tolist(),
                'p': p.reshape(-1).tolist()}

    @property
    def focal_px(self) -> float:
        """Geometric mean of ``fx`` and ``fy`` [px]."""
        return math.sqrt(self.k[0, 0] * self.k[1, 1])


def project_points(camera: PinholeCamera, points: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Pixel coordinates of points given in the camera frame, lens distortion included.

    Parameters
    ----------
    camera : PinholeCamera
    points : array-like, shape (3,) or (..., 3)
        Points in the camera frame [m], in front of the camera (``z > 0``).

    Returns
    -------
    pixels : ndarray, shape (2,) or (..., 2)
        ``(u, v)`` [px] (``cv2.projectPoints``).
    """
    p = check_batch('points', points, 3, 'm', single=True)
    if np.any(p[..., 2] <= 0.0):
        raise ValueError('expected points in front of the camera (z > 0)')
    flat = p.reshape(-1, 3)
    pixels, _ = cv2.projectPoints(flat, np.zeros(3), np.zeros(3), camera.k, camera.d)
    return pixels.reshape(p.shape[:-1] + (2,))


def undistort_pixels(camera: PinholeCamera, pixels: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Normalized image coordinates ``(x / z, y / z)`` of the rays through pixels.

    Parameters
    ----------
    camera : PinholeCamera
    pixels : array-like, shape (2,) or (..., 2)
        ``(u, v)`` in the raw (distorted) image [px].

    Returns
    -------
    normalized : ndarray, shape (2,) or (..., 2)
        The inverse of `project_points` (``cv2.undistortPoints``, iterated to convergence).
    """
    p = check_batch('pixels', pixels, 2, 'px', single=True)
    flat = p.reshape(-1, 1, 2)
    normalized = cv2.undistortPoints(flat, camera.k, camera.d, None, None, None,
                                     _UNDISTORT_CRITERIA)
    return normalized.reshape(p.shape)


def pixel_rays(camera: PinholeCamera, pixels: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Unit direction vectors, in the camera frame, of the rays through pixels.

    Parameters
    ----------
    camera : PinholeCamera
    pixels : array-like, shape (2,) or (..., 2)
        ``(u, v)`` in the raw image [px].

    Returns
    -------
    rays : ndarray, shape (3,) or (..., 3)
        Unit vectors with ``z > 0``.
    """
    xy = undistort_pixels(camera, pixels)
    rays = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


@dataclass(frozen=True)
class RigidTransform:
    """A rigid transform ``a2b``: ``p_b = rotation @ p_a + translation``.

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        Proper rotation matrix (orthonormal to 1e-6, determinant +1).
    translation : ndarray, shape (3,)
        Origin of frame ``a`` expressed in frame ``b`` [m].
    """

    rotation: npt.NDArray[np.float64]
    translation: npt.NDArray[np.float64]

    def __post_init__(self) -> None:
        r = np.array(self.rotation, dtype=float)
        t = np.array(self.translation, dtype=float)
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise ValueError(f'expected rotation a finite 3x3 matrix, got shape {r.shape}')
        if not (np.allclose(r @ r.T, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0.0):
            raise ValueError('expected rotation a proper rotation matrix (R R^T = I, det +1)')
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f'expected translation a finite (3,) vector [m], got {t.shape}')
        r.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, 'rotation', r)
        object.__setattr__(self, 'translation', t)

    @classmethod
    def identity(cls) -> 'RigidTransform':
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_quaternion(cls, translation: npt.ArrayLike,
                        quaternion_xyzw: npt.ArrayLike) -> 'RigidTransform':
        """From a translation [m] and a unit quaternion ``(x, y, z, w)`` (ROS order).

        The quaternion is normalized; a zero or non-finite one is a ``ValueError``.
        """
        q = np.asarray(quaternion_xyzw, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-9:
            raise ValueError(f'expected quaternion_xyzw 4 finite values, not all 0, got {q}')
        return cls(Rotation.from_quat(q).as_matrix(), translation)

    def as_quaternion(self) -> npt.NDArray[np.float64]:
        """The rotation as a unit quaternion ``(x, y, z, w)`` with ``w >= 0``."""
        q = Rotation.from_matrix(self.rotation).as_quat()
        return -q if q[3] < 0.0 else q

    def apply(self, points: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Map points, shape (3,) or (..., 3) [m], from frame ``a`` to frame ``b``."""
        p = check_batch('points', points, 3, 'm', single=True)
        return p @ self.rotation.T + self.translation

    def inverse(self) -> 'RigidTransform':
        """The transform ``b2a``."""
        return RigidTransform(self.rotation.T, -self.rotation.T @ self.translation)

    def __matmul__(self, other: 'RigidTransform') -> 'RigidTransform':
        """Composition: ``(b2c @ a2b)`` is ``a2c``."""
        return RigidTransform(self.rotation @ other.rotation,
                              self.rotation @ other.translation + self.translation)


def look_at(eye: npt.ArrayLike, target: npt.ArrayLike,
            up: npt.ArrayLike = (0.0, 0.0, -1.0)) -> RigidTransform:
    """Pose ``camera2frame`` of a camera at ``eye`` looking at ``target``.

    Parameters
    ----------
    eye, target : array-like, shape (3,)
        Projection centre and a point on the optical axis, in the frame [m].
    up : array-like, shape (3,)
        Direction that appears up in the image (``-y`` of the camera frame), in the frame.
        Default ``-z``: in ``sra_mount`` (``+z`` points away from the mount, down the hanging
        arm) up is towards the mount.

    Returns
    -------
    camera2frame : RigidTransform
    """
    eye = check_batch('eye', eye, 3, 'm', single=True).reshape(3)
    target = check_batch('target', target, 3, 'm', single=True).reshape(3)
    up = check_batch('up', up, 3, single=True).reshape(3)
    z = target - eye
    if np.linalg.norm(z) < 1e-9:
        raise ValueError('expected target different from eye')
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError('expected up not parallel to the viewing direction')
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RigidTransform(np.column_stack([x, y, z]), eye)


def cone_rays(center: npt.ArrayLike, radius: float, n: int) -> npt.NDArray[np.float64]:
    """Unit rays from the origin tangent to a sphere: the boundary of the cone it subtends.

    Parameters
    ----------
    center : array-like, shape (3,)
        Sphere centre [m], seen from the origin (the camera's projection centre).
    radius : float
        Sphere radius [m], smaller than ``|center|``.
    n : int
        Number of rays, equally spaced in azimuth about the cone's axis.

    Returns
    -------
    rays : ndarray, shape (n, 3)
        ``cos(a) c + sin(a) (cos(phi) e1 + sin(phi) e2)`` with ``c`` the unit axis, ``e1, e2``
        orthonormal to it and ``sin(a) = radius / |center|``.
    """
    c = check_batch('center', center, 3, 'm', single=True).reshape(3)
    distance = float(np.linalg.norm(c))
    if not (np.isfinite(radius) and 0.0 < radius < distance):
        raise ValueError(f'expected 0 < radius < |center| = {distance:.6g} m, got {radius}')
    axis = c / distance
    e1 = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    sin_a = radius / distance
    cos_a = math.sqrt(1.0 - sin_a * sin_a)
    phi = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
    return (cos_a * axis + sin_a * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2))


@dataclass(frozen=True)
class SphereImage:
    """The exact image of a sphere through a `PinholeCamera`.

    Attributes
    ----------
    outline : ndarray, shape (n, 2)
        Points of the outline [px], the projected tangent cone (`cone_rays`), in order.
    center : ndarray, shape (2,)
        Centroid of the region inside the outline [px]: the centre of the ellipse when there is
        no distortion. Not the projection of the sphere's centre off the optical axis.
    radius : float
        Radius of the disc of the same area, ``sqrt(area / pi)`` [px] (``sqrt(a b)`` of the
        ellipse).
    projected_center : ndarray, shape (2,)
        Projection of the sphere's centre [px].
    """

    outline: npt.NDArray[np.float64]
    center: npt.NDArray[np.float64]
    radius: float
    projected_center: npt.NDArray[np.float64]

    def inside_image(self, camera: PinholeCamera, margin: float = 0.0) -> bool:
        """Whether the whole outline lies at least ``margin`` px inside the image."""
        u, v = self.outline[:, 0], self.outline[:, 1]
        return bool(u.min() >= margin - 0.5 and v.min() >= margin - 0.5
                    and u.max() <= camera.width - 0.5 - margin
                    and v.max() <= camera.height - 0.5 - margin)


def sphere_image(camera: PinholeCamera, center: npt.ArrayLike, radius: float,
                 n: int = 2048) -> SphereImage:
    """The outline, centre and apparent radius of a sphere's image.

    Parameters
    ----------
    camera : PinholeCamera
    center : array-like, shape (3,)
        Sphere centre in the camera frame [m].
    radius : float
        Sphere radius [m].
    n : int
        Number of outline points. The default 2048 puts the polygon's area within 2e-6 of the
        curve's (radius within 1e-4 px for images up to 100 px across).

    Returns
    -------
    SphereImage
        Outline by `project_points` of `cone_rays`; centroid and area by the shoelace formula.
    """
    rays = cone_rays(center, radius, n)
    if np.any(rays[:, 2] <= 1e-6):
        raise ValueError('expected the whole sphere in front of the camera')
    outline = project_points(camera, rays)
    x, y = outline[:, 0], outline[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    centroid = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)
    return SphereImage(outline=outline, center=centroid, radius=math.sqrt(abs(area) / math.pi),
                       projected_center=project_points(camera, center))


@dataclass(frozen=True)
class SphereCoverage:
    """The pixels a sphere's image covers: ``coverage[v - v0, u - u0]`` is the fraction of pixel
    ``(u, v)`` whose rays hit the sphere, for ``u0 <= u < u0 + width``, ``v0 <= v < v0 +
    height`` (a region of the image around the outline; all pixels outside it are 0)."""

    u0: int
    v0: int
    coverage: npt.NDArray[np.float32]
    undistorted: npt.NDArray[np.float64]  # (height, width, 2): normalized (x, y) of the centres


def sphere_coverage(camera: PinholeCamera, center: npt.ArrayLike, radius: float,
                    supersample: int = 16) -> SphereCoverage | None:
    """Anti-aliased coverage of a sphere's image, distortion included; None if it lies outside
    the image.

    Pixels more than one pixel (in angle) inside or outside the outline are full or empty; in
    the others the ray through each of ``supersample`` x ``supersample`` sub-pixel centres is
    tested against the sphere's tangent cone, ``(ray . c)^2 >= (|c|^2 - R^2) |ray|^2`` for
    ``ray = (x, y, 1)``, with ``(x, y)`` interpolated bilinearly between the undistorted pixel
    centres (the distortion is smooth: within 1e-4 px).
    """
    c = np.asarray(center, dtype=float)
    outline = sphere_image(camera, c, radius).outline
    u0 = max(int(math.floor(outline[:, 0].min())) - 1, 0)
    v0 = max(int(math.floor(outline[:, 1].min())) - 1, 0)
    u1 = min(int(math.ceil(outline[:, 0].max())) + 2, camera.width)
    v1 = min(int(math.ceil(outline[:, 1].max())) + 2, camera.height)
    if u1 <= u0 or v1 <= v0:
        return None
    # undistorted coordinates of the region's pixel centres and a ring of one around them
    uu, vv = np.meshgrid(np.arange(u0 - 1, u1 + 1, dtype=float),
                         np.arange(v0 - 1, v1 + 1, dtype=float))
    grid = undistort_pixels(camera, np.stack([uu, vv], axis=-1))
    distance = float(np.linalg.norm(c))
    cos2 = distance * distance - radius ** 2
    half_angle = math.asin(radius / distance)
    inner = grid[1:-1, 1:-1]
    dot = inner[..., 0] * c[0] + inner[..., 1] * c[1] + c[2]
    norm = np.sqrt(inner[..., 0] ** 2 + inner[..., 1] ** 2 + 1.0) * distance
    angle = np.arccos(np.clip(dot / norm, -1.0, 1.0))
    tolerance = 1.0 / camera.focal_px
    coverage = (angle < half_angle - tolerance).astype(np.float32)
    rows, cols = np.nonzero(np.abs(angle - half_angle) <= tolerance)
    if len(rows):
        # bilinear interpolation of the 3 x 3 grid nodes around each pixel (pixel (r, c) is
        # node (r + 1, c + 1)) at its sub-pixel centres: the weights are the same for every
        # pixel, one (s, 3) matrix per axis
        offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
        weights = np.stack([np.maximum(-offsets, 0.0), 1.0 - np.abs(offsets),
                            np.maximum(offsets, 0.0)], axis=1)
        around = np.stack([grid[rows + dr, cols + dc] for dr in range(3) for dc in range(3)],
                          axis=1).reshape(len(rows), 3, 3, 2)
        xy = np.einsum('ia,jb,pabk->pijk', weights, weights, around, optimize=True)
        x, y = xy[..., 0], xy[..., 1]
        d = x * c[0] + y * c[1] + c[2]
        hit = (d > 0.0) & (d * d >= cos2 * (x * x + y * y + 1.0))
        coverage[rows, cols] = hit.mean(axis=(1, 2))
    return SphereCoverage(u0=u0, v0=v0, coverage=coverage, undistorted=inner)


def sphere_position_std(
    distance: npt.ArrayLike, radius: float, focal_px: float, center_px_std: float,
    radius_px_std: float,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Spread of a sphere's centre located from one image: across and along the line of sight.

    The image of a sphere of radius ``R`` at distance ``D`` is (on the optical axis) a circle of
    radius ``r = f tan(a)``, ``sin(a) = R / D`` (module docstring), so
    ``D = R sqrt(f^2 + r^2) / r`` and a radius error ``dr`` moves the centre along the line of
    sight by ``|dD/dr| dr = R f^2 / (r^2 sqrt(f^2 + r^2)) dr``, while a centre error ``du``
    moves it across by ``D du / f``: depth is the noisy direction of a monocular measurement.

    Parameters
    ----------
    distance : array-like, any shape
        ``D``, distance from the projection centre to the sphere's centre [m], > ``radius``.
    radius : float
        ``R``, sphere radius [m], > 0.
    focal_px : float
        ``f``, focal length [px], > 0.
    center_px_std, radius_px_std : float
        Standard deviations of the image centre (per image axis) and of the image radius [px].

    Returns
    -------
    lateral, depth : ndarray, shape of ``distance``
        Standard deviations across (per axis) and along the line of sight [m].
    """
    d = np.asarray(distance, dtype=float)
    if not (math.isfinite(radius) and radius > 0.0):
        raise ValueError(f'expected radius > 0 m, got {radius}')
    if not (math.isfinite(focal_px) and focal_px > 0.0):
        raise ValueError(f'expected focal_px > 0, got {focal_px}')
    if not (np.all(np.isfinite(d)) and np.all(d > radius)):
        raise ValueError(f'expected finite distance > radius = {radius} m')
    for name, value in (('center_px_std', center_px_std), ('radius_px_std', radius_px_std)):
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f'expected {name} >= 0 px, got {value}')
    r = focal_px * radius / np.sqrt(d * d - radius * radius)  # f tan(a)
    depth = radius * focal_px ** 2 / (r * r * np.sqrt(focal_px ** 2 + r * r)) * radius_px_std
    return d * center_px_std / focal_px, depth
