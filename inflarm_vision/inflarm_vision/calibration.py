"""Camera calibration: intrinsics from checkerboard views, the camera's pose from ball positions.

Pure numpy/OpenCV/PyYAML, no rclpy. Frames and pixels as in `inflarm_model.camera`.

**Intrinsics** (`calibrate_intrinsics`): the inner corners of a planar checkerboard are found in
each image (``cv2.findChessboardCorners`` with the flags of ROS's ``camera_calibration``:
adaptive threshold, normalized image, fast check), refined to sub-pixel accuracy
(``cv2.cornerSubPix``), and ``cv2.calibrateCameraExtended`` fits the camera matrix ``K`` and the
``plumb_bob`` distortion ``k1, k2, p1, p2, k3`` (``k3`` fixed at 0 unless ``k_coefficients=3``,
as ROS's ``--k-coefficients``) with the board's pose in every view, minimizing the
reprojection error. The result is a `CameraIntrinsics`, written and read in the YAML format of
ROS's ``camera_calibration_parsers`` (`write_camera_info_yaml`, `read_camera_info_yaml`), which
camera drivers load from their ``camera_info_url``.

**Extrinsics** (`calibrate_extrinsics`): the ball is put at known positions in ``sra_mount``;
in the image of each it is detected (`inflarm_vision.tracker.detect_ball`) and located in the
camera frame (`inflarm_vision.geometry.locate_ball`), and
`inflarm_vision.geometry.calibrate_camera_to_mount` fits the pose ``camera2mount``.
`write_ball_tracker_params` writes it as the ``ball_tracker`` node's parameters file.

**Synthetic views** (`CheckerboardRenderer`, `random_board_poses`, `render_ball`): images of a
checkerboard and of a flat-shaded ball through a `PinholeCamera`, distortion included, for
tests and for the example of ``inflarm-calibrate-camera synthetic``. Every pixel is the mean of
``supersample x supersample`` sub-pixel samples (the pixel's area, as a sensor integrates), each
sample's ray undistorted (`inflarm_model.camera.pixel_rays`): the board by intersecting the ray
with the board's plane, the ball by testing the ray against the cone the ball subtends (the
simulated camera's coverage, `inflarm_model.camera.sphere_coverage`).
"""

from collections.abc import Sequence
from dataclasses import dataclass
import math
import os
import re

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation
import yaml

from inflarm_model.camera import (
    DISTORTION_MODELS,
    PinholeCamera,
    RigidTransform,
    project_points,
    sphere_coverage,
    undistort_pixels,
)
from inflarm_vision import geometry
from inflarm_vision.tracker import DetectorParams, detect_ball

__all__ = [
    'CameraIntrinsics',
    'CheckerboardRenderer',
    'board_corners',
    'calibrate_extrinsics',
    'calibrate_intrinsics',
    'camera_info_yaml',
    'random_board_poses',
    'read_camera_info_yaml',
    'render_ball',
    'write_ball_tracker_params',
    'write_camera_info_yaml',
]

CAMERA_NAME_DEFAULT = 'camera'
"""``camera_name`` of a calibration unless one is given."""

# ROS camera_calibration's flags; the fast check returns quickly from images without a board.
_BOARD_FLAGS = (cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
                | cv2.CALIB_CB_FAST_CHECK)
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
# Corners closer than this to the image border are not used (their refinement window would
# leave the image): ROS camera_calibration's BORDER.
_BORDER_PX = 8.0


def _float_array(value, name: str, shape: tuple[int, ...]) -> npt.NDArray[np.float64]:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} numbers of shape {shape}') from None
    if a.size == math.prod(shape):
        a = a.reshape(shape)
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise ValueError(f'expected {name} finite numbers of shape {shape}, got shape {a.shape}')
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class CameraIntrinsics:
    """Intrinsics of a monocular camera, as a ``sensor_msgs/CameraInfo`` carries them.

    Validated on construction (``ValueError``); arrays are read-only. Compared by identity
    (its fields are arrays).

    Attributes
    ----------
    camera_matrix : ndarray, shape (3, 3)
        ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` [px].
    distortion : ndarray, shape (5,) or (8,)
        Coefficients of ``distortion_model`` (``plumb_bob``: ``k1, k2, p1, p2, k3``).
    image_size : tuple of 2 int
        ``(width, height)`` [px].
    camera_name : str
        Name of the camera (the driver's ``camera_name``).
    distortion_model : str
        ``'plumb_bob'`` or ``'rational_polynomial'`` (8 coefficients).
    rectification_matrix : ndarray, shape (3, 3)
        ``R``; default the identity (a monocular camera).
    projection_matrix : ndarray, shape (3, 4)
        ``P``; default ``[K | 0]``: the rectified image keeps the raw image's camera matrix.
        (ROS's ``cameracalibrator.py`` fills ``P[:, :3]`` from
        ``cv2.getOptimalNewCameraMatrix`` instead. ``P`` only matters to rectification, as in
        ``image_proc``; the ball tracker uses ``K`` and the distortion on the raw image. A ``P``
        read from a file is kept as written.)
    rms_px : float or None
        RMS reprojection error of the calibration over all corners [px]; None when read from a
        file (the format has no field for it).
    used_images : tuple of int
        Indices of the images the board was found in and that the calibration used (empty when
        read from a file).
    per_image_rms_px : tuple of float
        RMS reprojection error of each used image [px], in the order of ``used_images``.
    intrinsics_std : tuple of float
        Standard deviations of ``fx, fy, cx, cy`` [px] and ``k1, k2, p1, p2, k3`` estimated by
        ``cv2.calibrateCameraExtended`` (empty when read from a file).
    """

    camera_matrix: npt.NDArray[np.float64]
    distortion: npt.NDArray[np.float64]
    image_size: tuple[int, int]
    camera_name: str = CAMERA_NAME_DEFAULT
    distortion_model: str = 'plumb_bob'
    rectification_matrix: npt.NDArray[np.float64] | None = None
    projection_matrix: npt.NDArray[np.float64] | None = None
    rms_px: float | None = None
    used_images: tuple[int, ...] = ()
    per_image_rms_px: tuple[float, ...] = ()
    intrinsics_std: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        size = tuple(self.image_size)
        if len(size) != 2 or not all(isinstance(x, (int, np.integer))
                                     and not isinstance(x, bool) and x >= 1 for x in size):
            raise ValueError(f'expected image_size (width, height), integers >= 1 [px], got '
                             f'{self.image_size!r}')
        object.__setattr__(self, 'image_size', (int(size[0]), int(size[1])))
        if not isinstance(self.camera_name, str):
            raise ValueError(f'expected camera_name a string, got {self.camera_name!r}')
        k = _float_array(self.camera_matrix, 'camera_matrix', (3, 3))
        # one check of K, D and the model: the camera they make (an empty D: no distortion)
        camera = PinholeCamera(*self.image_size, k, np.array(self.distortion, dtype=float),
                               self.distortion_model)
        d = camera.d
        r = np.eye(3) if self.rectification_matrix is None else self.rectification_matrix
        r = _float_array(r, 'rectification_matrix', (3, 3))
        if self.projection_matrix is None:
            p = np.zeros((3, 4))
            p[:, :3] = k
        else:
            p = self.projection_matrix
        p = _float_array(p, 'projection_matrix', (3, 4))
        if self.rms_px is not None and not (math.isfinite(self.rms_px) and self.rms_px >= 0.0):
            raise ValueError(f'expected rms_px None or finite >= 0 [px], got {self.rms_px}')
        used = tuple(int(i) for i in self.used_images)
        per_image = tuple(float(e) for e in self.per_image_rms_px)
        if per_image and len(per_image) != len(used):
            raise ValueError(f'expected per_image_rms_px for each of the {len(used)} '
                             f'used_images, got {len(per_image)}')
        std = tuple(float(e) for e in self.intrinsics_std)
        if std and len(std) != 9:
            raise ValueError(f'expected intrinsics_std of 9 values, got {len(std)}')
        for name, value in (('intrinsics_std', std), ('camera_matrix', k), ('distortion', d),
                            ('rectification_matrix', r), ('projection_matrix', p),
                            ('rms_px', None if self.rms_px is None else float(self.rms_px)),
                            ('used_images', used), ('per_image_rms_px', per_image)):
            object.__setattr__(self, name, value)

    def pinhole_camera(self) -> PinholeCamera:
        """The camera model (`inflarm_model.camera.PinholeCamera`) of these intrinsics."""
        return PinholeCamera(*self.image_size, self.camera_matrix, self.distortion,
                             self.distortion_model)

    @classmethod
    def from_pinhole_camera(cls, camera: PinholeCamera,
                            camera_name: str = CAMERA_NAME_DEFAULT) -> 'CameraIntrinsics':
        """The calibration of a known camera (``R = I``, ``P = [K | 0]``, no ``rms_px``)."""
        return cls(camera.k, camera.d, (camera.width, camera.height), camera_name,
                   camera.distortion_model)


# -- intrinsics --------------------------------------------------------------------------------

def _check_board(board_size, square_m: float) -> tuple[int, int]:
    size = tuple(board_size)
    if len(size) != 2 or not all(isinstance(x, (int, np.integer)) and not isinstance(x, bool)
                                 and x >= 3 for x in size):
        raise ValueError(f'expected board_size (cols, rows) of inner corners, integers >= 3, '
                         f'got {board_size!r}')
    if size[0] == size[1]:
        # a square board is found in any of 4 orientations, some of them mirror images
        raise ValueError(f'expected board_size with cols != rows (a square board has no '
                         f'defined orientation), got {size[0]}x{size[1]}')
    if not (math.isfinite(square_m) and square_m > 0.0):
        raise ValueError(f'expected square_m > 0 [m], got {square_m}')
    return int(size[0]), int(size[1])


def board_corners(board_size: tuple[int, int], square_m: float) -> npt.NDArray[np.float64]:
    """The inner corners of a checkerboard in its own frame, in ``findChessboardCorners`` order.

    Parameters
    ----------
    board_size : tuple of 2 int
        ``(cols, rows)`` inner corners.
    square_m : float
        Side of a square [m].

    Returns
    -------
    corners : ndarray, shape (cols * rows, 3)
        ``(i square_m, j square_m, 0)``, row ``j`` after row, ``i`` fastest.
    """
    cols, rows = _check_board(board_size, square_m)
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return np.column_stack([grid, np.zeros(len(grid))])


def _grey(image, index: int) -> npt.NDArray[np.uint8]:
    a = np.asarray(image)
    if a.dtype != np.uint8 or not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (1, 3))) \
            or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f'image {index}: expected a uint8 array of shape (height, width) or '
                         f'(height, width, 3) (BGR), got {a.dtype} {a.shape}')
    if a.ndim == 3:
        return a[:, :, 0] if a.shape[2] == 1 else cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
    return a


def _find_corners(grey: npt.NDArray[np.uint8],
                  board_size: tuple[int, int]) -> npt.NDArray[np.float32] | None:
    found, corners = cv2.findChessboardCorners(grey, board_size, flags=_BOARD_FLAGS)
    if not found:
        return None
    h, w = grey.shape
    c = corners.reshape(-1, 2)
    if np.any(c < _BORDER_PX) or np.any(c[:, 0] > w - 1 - _BORDER_PX) \
            or np.any(c[:, 1] > h - 1 - _BORDER_PX):
        return None
    # the window reaches half-way to the nearest neighbouring corner (as ROS's calibrator)
    grid = c.reshape(board_size[1], board_size[0], 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    half = max(2, int(math.ceil(0.5 * spacing)))
    return cv2.cornerSubPix(grey, corners, (half, half), (-1, -1), _SUBPIX_CRITERIA)


def calibrate_intrinsics(images: Sequence[npt.ArrayLike], board_size: tuple[int, int],
                         square_m: float, *, camera_name: str = CAMERA_NAME_DEFAULT,
                         min_images: int = 3, k_coefficients: int = 2) -> CameraIntrinsics:
    """Calibrate a camera's intrinsics from images of a planar checkerboard.

    Parameters
    ----------
    images : sequence of ndarray, shape (height, width) or (height, width, 3), uint8
        Grey or BGR images, all of the same size, of the board in varied poses (tilted 15-45
        deg, over the whole image).
    board_size : tuple of 2 int
        ``(cols, rows)``: the number of **inner** corners along and across the board (as
        ``cv2.findChessboardCorners`` takes it), cols != rows.
    square_m : float
        Side of a square [m] (it sets the scale of the board's poses, not the intrinsics).
    camera_name : str
        Written into the calibration file.
    min_images : int
        The fewest images the board must be found in (at least 3: fewer leave the intrinsics
        undetermined).
    k_coefficients : int
        Radial coefficients fitted: 2 (``k1, k2``; ``k3 = 0``, ROS's default) or 3.

    Returns
    -------
    CameraIntrinsics
        ``K``, the ``plumb_bob`` distortion, ``R = I``, ``P = [K | 0]``, the RMS reprojection
        error (``cv2.calibrateCameraExtended``), the images used and each one's RMS error, and
        the standard deviations of the intrinsics.

    Raises
    ------
    ValueError
        Bad arguments; an image not uint8 grey/BGR or of another size than image 0 (naming its
        index); the board found in fewer than ``min_images`` images.
    """
    cols, rows = _check_board(board_size, square_m)
    if isinstance(min_images, bool) or not isinstance(min_images, (int, np.integer)) \
            or min_images < 3:
        raise ValueError(f'expected min_images an integer >= 3, got {min_images!r}')
    if k_coefficients not in (2, 3):
        raise ValueError(f'expected k_coefficients 2 or 3, got {k_coefficients!r}')
    if len(images) == 0:
        raise ValueError('expected at least one image, got none')
    greys = []
    for index, image in enumerate(images):
        grey = _grey(image, index)
        if greys and grey.shape != greys[0].shape:
            raise ValueError(f'image {index}: expected the size of image 0, '
                             f'{greys[0].shape[1]}x{greys[0].shape[0]} px, got '
                             f'{grey.shape[1]}x{grey.shape[0]} px')
        greys.append(grey)
    used, image_points = [], []
    for index, grey in enumerate(greys):
        corners = _find_corners(grey, (cols, rows))
        if corners is not None:
            used.append(index)
            image_points.append(corners)
    if len(used) < min_images:
        raise ValueError(
            f'checkerboard of {cols}x{rows} inner corners found in {len(used)} of {len(greys)} '
            f'images; at least {min_images} needed (board_size counts the inner corners, '
            f'cols x rows)')
    objects = board_corners((cols, rows), square_m).astype(np.float32)
    height, width = greys[0].shape
    flags = cv2.CALIB_FIX_K3 if k_coefficients == 2 else 0
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, k, d, _, _, std, _, per_view = cv2.calibrateCameraExtended(
        [objects] * len(used), image_points, (width, height), None, None, flags=flags,
        criteria=criteria)
    return CameraIntrinsics(k, d.reshape(-1)[:5], (width, height), camera_name, 'plumb_bob',
                             rms_px=float(rms), used_images=tuple(used),
                             per_image_rms_px=tuple(per_view.reshape(-1).tolist()),
                             intrinsics_std=tuple(std.reshape(-1)[:9].tolist()))


# -- camera_calibration_parsers YAML ----------------------------------------------------------

class _FlowListDumper(yaml.SafeDumper):
    """Block mappings, flow lists (``data: [...]``), as camera_calibration_parsers writes."""


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    return dumper.represent_sequence('tag:yaml.org,2002:seq', data, flow_style=True)


_FlowListDumper.add_representer(list, _represent_list)


def _dump(document: dict) -> str:
    return yaml.dump(document, Dumper=_FlowListDumper, sort_keys=False,
                     default_flow_style=False, width=4096)


def _matrix(a: npt.NDArray[np.float64]) -> dict:
    rows, cols = (1, a.size) if a.ndim == 1 else a.shape
    return {'rows': rows, 'cols': cols, 'data': [float(x) for x in a.reshape(-1)]}


def camera_info_yaml(calibration: CameraIntrinsics) -> str:
    """The text of `write_camera_info_yaml` (floats by ``repr``: they read back exactly)."""
    c = calibration
    return _dump({
        'image_width': c.image_size[0],
        'image_height': c.image_size[1],
        'camera_name': c.camera_name,
        'camera_matrix': _matrix(c.camera_matrix),
        'distortion_model': c.distortion_model,
        'distortion_coefficients': _matrix(c.distortion),
        'rectification_matrix': _matrix(c.rectification_matrix),
        'projection_matrix': _matrix(c.projection_matrix),
    })


def write_camera_info_yaml(calibration: CameraIntrinsics, path: str | os.PathLike) -> None:
    """Write a calibration in the YAML format of ROS's ``camera_calibration_parsers``.

    Parameters
    ----------
    calibration : CameraIntrinsics
    path : str or path-like
        The file (e.g. the camera driver's ``camera_info_url``, ``file:///path/camera.yaml``).

    Notes
    -----
    Keys ``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``,
    ``distortion_model``, ``distortion_coefficients``, ``rectification_matrix``,
    ``projection_matrix``; each matrix as ``rows``, ``cols`` and row-major ``data``.
    ``rms_px`` and the images used are not part of the format and are not written.
    """
    text = camera_info_yaml(calibration)
    with open(path, 'w', encoding='utf-8') as handle:
        handle.write(text)


# YAML 1.1 (PyYAML) reads 1e-05 (no dot) as a string; YAML 1.2 writers (yaml-cpp, as in
# camera_calibration_parsers) write it so. Such strings are taken as numbers.
_NUMBER = re.compile(r'[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?')


def _number(value, where: str) -> float:
    if isinstance(value, str) and _NUMBER.fullmatch(value.strip()):
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f'{where}: expected a number, got {value!r}')
    if not math.isfinite(value):
        raise ValueError(f'{where}: expected a finite number, got {value!r}')
    return float(value)


def _integer(document: dict, key: str) -> int:
    value = document[key]
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f'{key}: expected an integer >= 1, got {value!r}')
    return value


def _read_matrix(document: dict, key: str, shapes: Sequence[tuple[int, int]]) -> np.ndarray:
    node = document[key]
    if not isinstance(node, dict) or not {'rows', 'cols', 'data'} <= node.keys():
        raise ValueError(f'{key}: expected a mapping with rows, cols and data, got {node!r}')
    rows, cols, data = node['rows'], node['cols'], node['data']
    if not all(isinstance(x, int) and not isinstance(x, bool) for x in (rows, cols)):
        raise ValueError(f'{key}: expected integer rows and cols, got {rows!r} and {cols!r}')
    if not isinstance(data, list):
        raise ValueError(f'{key}: expected data a list of numbers, got {data!r}')
    if rows * cols != len(data):
        raise ValueError(f'{key}: rows * cols = {rows} * {cols} but data has {len(data)} '
                         f'values')
    if (rows, cols) not in shapes:
        raise ValueError(f'{key}: expected {" or ".join(f"{r}x{c}" for r, c in shapes)}, got '
                         f'{rows}x{cols}')
    values = [_number(x, f'{key} data[{i}]') for i, x in enumerate(data)]
    return np.array(values).reshape(rows, cols)


_KEYS = ('image_width', 'image_height', 'camera_name', 'camera_matrix', 'distortion_model',
         'distortion_coefficients', 'rectification_matrix', 'projection_matrix')


def read_camera_info_yaml(path: str | os.PathLike) -> CameraIntrinsics:
    """Read a calibration file in the YAML format of ROS's ``camera_calibration_parsers``.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    CameraIntrinsics
        With ``rms_px = None`` and no ``used_images`` (the format has neither). The
        distortion model may be ``plumb_bob`` (5 coefficients) or ``rational_polynomial`` (8).
        Integers and numbers like ``1e-05`` (a string to YAML 1.1) are read as floats.

    Raises
    ------
    ValueError
        Naming the file and what is wrong: not YAML, not a mapping, a key missing, a matrix of
        the wrong size or whose ``rows * cols`` is not the length of its ``data``, a value not
        a finite number, an unknown distortion model, a camera matrix that is not one.
    OSError
        The file cannot be read.
    """
    with open(path, 'rb') as handle:
        raw = handle.read()
    try:
        document = yaml.safe_load(raw)
    except yaml.YAMLError as err:
        raise ValueError(f'{os.fspath(path)}: not a YAML file: {err}') from None
    try:
        if not isinstance(document, dict):
            raise ValueError(f'expected a mapping of calibration keys, got '
                             f'{type(document).__name__}')
        missing = [key for key in _KEYS if key not in document]
        if missing:
            raise ValueError(f'missing {", ".join(missing)}: not a camera calibration')
        width, height = _integer(document, 'image_width'), _integer(document, 'image_height')
        name = document['camera_name']
        if name is None or isinstance(name, (list, dict)):
            raise ValueError(f'camera_name: expected a string, got {name!r}')
        model = document['distortion_model']
        if model not in DISTORTION_MODELS:
            raise ValueError(f'distortion_model: expected one of {sorted(DISTORTION_MODELS)}, '
                             f'got {model!r}')
        k = _read_matrix(document, 'camera_matrix', [(3, 3)])
        n = DISTORTION_MODELS[model]
        d = _read_matrix(document, 'distortion_coefficients', [(1, n), (n, 1)])
        r = _read_matrix(document, 'rectification_matrix', [(3, 3)])
        p = _read_matrix(document, 'projection_matrix', [(3, 4)])
        return CameraIntrinsics(k, d.reshape(-1), (width, height), str(name), model, r, p)
    except ValueError as err:
        raise ValueError(f'{os.fspath(path)}: {err}') from None


# -- extrinsics --------------------------------------------------------------------------------

def calibrate_extrinsics(points_mount: npt.ArrayLike, images: Sequence[npt.ArrayLike],
                         camera: PinholeCamera, ball_diameter_m: float = 0.04,
                         params: DetectorParams = DetectorParams(),  # noqa: B008 (frozen)
                         ) -> geometry.CameraCalibration:
    """The camera's pose in ``sra_mount`` from images of the ball at known positions.

    Parameters
    ----------
    points_mount : array-like, shape (n, 3)
        Known positions of the ball's centre in ``sra_mount`` [m], n >= 4, not on one line.
    images : sequence of ndarray, shape (height, width, 3), uint8
        The raw BGR image of the ball at each position.
    camera : PinholeCamera
        The camera's intrinsics (e.g. ``read_camera_info_yaml(path).pinhole_camera()``).
    ball_diameter_m : float
        The ball's diameter [m].
    params : DetectorParams
        Ball detector settings.

    Returns
    -------
    inflarm_vision.geometry.CameraCalibration
        ``camera2mount`` and the residual of each point (`geometry.calibrate_camera_to_mount`
        on the ball located by `detect_ball` and `geometry.locate_ball` in each image).

    Raises
    ------
    ValueError
        Not one image per point, an image of another size than the camera's, no ball found in
        an image (naming its index), or the errors of `geometry.calibrate_camera_to_mount`.
    """
    pm = np.asarray(points_mount, dtype=float)
    if pm.ndim != 2 or pm.shape[1] != 3 or len(pm) != len(images):
        raise ValueError(f'expected points_mount of shape (n, 3) and one image per point, got '
                         f'{pm.shape} and {len(images)} images')
    if not (math.isfinite(ball_diameter_m) and ball_diameter_m > 0.0):
        raise ValueError(f'expected ball_diameter_m > 0 [m], got {ball_diameter_m}')
    points_camera = []
    for index, image in enumerate(images):
        shape = np.shape(image)
        if shape[:2] != (camera.height, camera.width):
            raise ValueError(f'image {index}: expected {camera.width}x{camera.height} px (the '
                             f'calibration), got shape {shape}')
        detection = detect_ball(image, params)
        if detection is None:
            raise ValueError(f'image {index}: no ball found')
        try:
            location = geometry.locate_ball(detection, camera, 0.5 * ball_diameter_m)
        except ValueError as err:
            raise ValueError(f'image {index}: {err}') from None
        points_camera.append(location.position)
    return geometry.calibrate_camera_to_mount(pm, np.array(points_camera))


def write_ball_tracker_params(camera2mount: RigidTransform | geometry.CameraCalibration,
                              path: str | os.PathLike, node_name: str = 'ball_tracker') -> None:
    """Write the camera's pose as a parameters file of the ``ball_tracker`` node.

    Parameters
    ----------
    camera2mount : RigidTransform or inflarm_vision.geometry.CameraCalibration
        Pose of the camera's optical frame in ``sra_mount`` (a calibration's ``camera2mount``;
        its RMS residual is then written in a comment).
    path : str or path-like
        The file, for ``--ros-args --params-file``.
    node_name : str
        The node's name (its key in the file).

    Notes
    -----
    ``<node_name>: ros__parameters:`` with ``camera.translation_m: [x, y, z]`` [m] and
    ``camera.rotation_xyzw: [x, y, z, w]`` (`RigidTransform.as_quaternion`, ``w >= 0``), every
    value a YAML float (an integer would be a type error for a double parameter).
    """
    transform = getattr(camera2mount, 'camera2mount', camera2mount)
    if not isinstance(transform, RigidTransform):
        raise ValueError(f'expected a RigidTransform camera2mount, got '
                         f'{type(camera2mount).__name__}')
    header = '# pose of the camera optical frame in sra_mount (camera2mount)'
    if isinstance(camera2mount, geometry.CameraCalibration):
        header += (f': {len(camera2mount.residuals)} points, RMS residual '
                   f'{1e3 * camera2mount.rms:.2f} mm')
    text = _dump({node_name: {'ros__parameters': {
        'camera.translation_m': [float(x) for x in transform.translation],
        'camera.rotation_xyzw': [float(x) for x in transform.as_quaternion()],
    }}})
    with open(path, 'w', encoding='utf-8') as handle:
        handle.write(header + '\n' + text)


# -- synthetic views ---------------------------------------------------------------------------

def _subpixel_grid(width: int, height: int, supersample: int) -> npt.NDArray[np.float64]:
    """Centres of the sub-pixel samples, shape (height * s, width * s, 2) [px]."""
    s = supersample
    u = (np.arange(width * s) + 0.5) / s - 0.5
    v = (np.arange(height * s) + 0.5) / s - 0.5
    return np.stack(np.meshgrid(u, v), axis=-1)


def _area_mean(values: npt.NDArray, supersample: int) -> npt.NDArray[np.float64]:
    s = supersample
    h, w = values.shape[0] // s, values.shape[1] // s
    return values.reshape(h, s, w, s, *values.shape[2:]).mean(axis=(1, 3))


def _check_supersample(supersample: int) -> int:
    if isinstance(supersample, bool) or not isinstance(supersample, (int, np.integer)) \
            or not 1 <= supersample <= 8:
        raise ValueError(f'expected supersample an integer 1-8, got {supersample!r}')
    return int(supersample)


def _to_uint8(image: npt.NDArray[np.float64], noise_std: float,
              rng: np.random.Generator | None) -> npt.NDArray[np.uint8]:
    if noise_std > 0.0:
        if rng is None:
            raise ValueError('noise_std > 0 needs an rng')
        image = image + rng.normal(0.0, noise_std, image.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _board_outline(board_size: tuple[int, int], square_m: float) -> npt.NDArray[np.float64]:
    cols, rows = board_size
    lo, hi_x, hi_y = -2.0 * square_m, (cols + 1) * square_m, (rows + 1) * square_m
    return np.array([[lo, lo, 0.0], [hi_x, lo, 0.0], [hi_x, hi_y, 0.0], [lo, hi_y, 0.0]])


class CheckerboardRenderer:
    """Grey images of a planar checkerboard through a camera, lens distortion included.

    The board has ``(cols + 1) x (rows + 1)`` squares around its ``cols x rows`` inner corners
    (`board_corners`: corner ``(i, j)`` at ``(i, j) square_m`` in the board's plane ``z = 0``),
    the square before corner ``(0, 0)`` black, and a white margin one square wide all round,
    on a grey background. Each sub-pixel sample's ray (undistorted once, in the constructor,
    by `inflarm_model.camera.undistort_pixels`) is intersected with the board's plane.

    Parameters
    ----------
    camera : PinholeCamera
    board_size : tuple of 2 int
        ``(cols, rows)`` inner corners.
    square_m : float
        Side of a square [m].
    supersample : int
        Samples per pixel along each axis (1-8).
    levels : tuple of 3 float
        Grey levels of the black squares, the white squares and margin, the background.
    """

    def __init__(self, camera: PinholeCamera, board_size: tuple[int, int], square_m: float,
                 supersample: int = 4, levels: tuple[float, float, float] = (30.0, 225.0, 120.0)):
        self.camera = camera
        self.board_size = _check_board(board_size, square_m)
        self.square_m = float(square_m)
        self.supersample = _check_supersample(supersample)
        self.levels = tuple(float(x) for x in levels)
        self._normalized = undistort_pixels(camera, _subpixel_grid(camera.width, camera.height,
                                                                  self.supersample))

    def outline(self) -> npt.NDArray[np.float64]:
        """Corners of the board with its white margin in the board's frame, shape (4, 3) [m]."""
        return _board_outline(self.board_size, self.square_m)

    def render(self, board2camera: RigidTransform, noise_std: float = 0.0,
               rng: np.random.Generator | None = None) -> npt.NDArray[np.uint8]:
        """The image of the board in a pose.

        Parameters
        ----------
        board2camera : RigidTransform
            Pose of the board in the camera frame.
        noise_std : float
            Standard deviation of Gaussian noise added to each pixel [grey levels].
        rng : numpy.random.Generator, optional
            Needed for noise.

        Returns
        -------
        image : ndarray, shape (height, width), uint8
        """
        black, white, background = self.levels
        cols, rows = self.board_size
        sq, ss = self.square_m, self.supersample
        # only the samples in the bounding box of the board's image are cast
        box = self._box(board2camera)
        image = np.full((self.camera.height, self.camera.width), background)
        if box is not None:
            u0, v0, u1, v1 = box
            normalized = self._normalized[v0 * ss:v1 * ss, u0 * ss:u1 * ss]
            # ray o + l d in the board's frame, o the projection centre, d = R^T (x, y, 1)
            r, t = board2camera.rotation, board2camera.translation
            origin = -r.T @ t
            x, y = normalized[..., 0], normalized[..., 1]
            dx = r[0, 0] * x + r[1, 0] * y + r[2, 0]
            dy = r[0, 1] * x + r[1, 1] * y + r[2, 1]
            dz = r[0, 2] * x + r[1, 2] * y + r[2, 2]
            with np.errstate(divide='ignore', invalid='ignore'):
                length = -origin[2] / dz
            hit = np.isfinite(length) & (length > 0.0)
            length = np.where(hit, length, 0.0)
            bx, by = (origin[0] + length * dx) / sq, (origin[1] + length * dy) / sq
            on_board = hit & (bx >= -1.0) & (bx < cols) & (by >= -1.0) & (by < rows)
            on_margin = hit & (bx >= -2.0) & (bx < cols + 1) & (by >= -2.0) & (by < rows + 1)
            dark = (np.floor(bx).astype(np.int64) + np.floor(by).astype(np.int64)) % 2 == 0
            samples = np.where(on_board & dark, black, np.where(on_margin, white, background))
            image[v0:v1, u0:u1] = _area_mean(samples, ss)
        return _to_uint8(image, noise_std, rng)

    def _box(self, board2camera: RigidTransform) -> tuple[int, int, int, int] | None:
        """Pixels ``(u0, v0, u1, v1)`` (end exclusive) holding the board's image, or None."""
        w, h = self.camera.width, self.camera.height
        outline = self.outline()
        edges = np.concatenate([np.linspace(a, b, 64, endpoint=False) for a, b in
                                zip(outline, np.roll(outline, -1, axis=0), strict=True)])
        points = board2camera.apply(edges)
        if np.any(points[:, 2] <= 1e-6):
            return 0, 0, w, h  # the plane crosses the camera's: cast every ray
        uv = project_points(self.camera, points)
        u0, v0 = np.floor(uv.min(axis=0)).astype(int) - 2
        u1, v1 = np.ceil(uv.max(axis=0)).astype(int) + 3
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
        return None if u0 >= u1 or v0 >= v1 else (int(u0), int(v0), int(u1), int(v1))


def random_board_poses(camera: PinholeCamera, board_size: tuple[int, int], square_m: float,
                       n: int, rng: np.random.Generator,
                       tilt_deg: tuple[float, float] = (15.0, 45.0),
                       fill: tuple[float, float] = (0.4, 0.75),
                       margin_px: float = 10.0) -> list[RigidTransform]:
    """Varied poses of a checkerboard that keep it, with its margin, inside the image.

    Parameters
    ----------
    camera : PinholeCamera
    board_size, square_m
        As `CheckerboardRenderer`.
    n : int
        Number of poses.
    rng : numpy.random.Generator
    tilt_deg : tuple of 2 float
        Range of the angle between the board's normal and the optical axis [deg], about an
        axis of random direction in the board's plane.
    fill : tuple of 2 float
        Range of the board's width (with margin), seen face on, over the image width.
    margin_px : float
        Least distance of the board's outline from the image border [px].

    Returns
    -------
    list of RigidTransform
        ``board2camera`` of each pose, in-plane rotation within +-30 deg. Pose ``i`` is pushed
        into the image's top-left, top-right, bottom-right, bottom-left corner, or left where it
        is, for ``i % 5`` = 0-4: the corners of the image, where distortion is largest, are
        covered as a calibration needs.
    """
    cols, rows = _check_board(board_size, square_m)
    outline = _board_outline((cols, rows), square_m)
    centre = outline.mean(axis=0)
    width_m = outline[1, 0] - outline[0, 0]
    lo = np.array([margin_px, margin_px])
    hi = np.array([camera.width - 1.0 - margin_px, camera.height - 1.0 - margin_px])
    poses: list[RigidTransform] = []
    for _ in range(1000 * max(int(n), 1)):
        if len(poses) == n:
            return poses
        distance = camera.k[0, 0] * width_m / (rng.uniform(*fill) * camera.width)
        axis_angle = rng.uniform(0.0, 2.0 * np.pi)
        tilt = Rotation.from_rotvec(math.radians(rng.uniform(*tilt_deg))
                                    * np.array([math.cos(axis_angle), math.sin(axis_angle), 0]))
        spin = Rotation.from_rotvec([0.0, 0.0, math.radians(rng.uniform(-30.0, 30.0))])
        rotation = (tilt * spin).as_matrix()
        xy = undistort_pixels(camera, rng.uniform(0.25 * hi, 0.75 * hi))
        translation = distance * np.array([xy[0], xy[1], 1.0]) - rotation @ centre
        corner = len(poses) % 5
        for _ in range(4 if corner < 4 else 0):  # shift sideways until the outline touches
            points = RigidTransform(rotation, translation).apply(outline)
            if np.any(points[:, 2] <= 0.05):
                break
            uv = project_points(camera, points)
            target = np.where([corner in (0, 3), corner in (0, 1)], lo, hi)
            edge = np.where([corner in (0, 3), corner in (0, 1)], uv.min(axis=0),
                            uv.max(axis=0))
            translation = translation + np.append((target - edge) * distance
                                                  / np.diag(camera.k)[:2], 0.0)
        pose = RigidTransform(rotation, translation)
        points = pose.apply(outline)
        if np.any(points[:, 2] <= 0.05):
            continue
        uv = project_points(camera, points)
        if np.all(uv >= lo - 1e-9) and np.all(uv <= hi + 1e-9):
            poses.append(pose)
    if len(poses) < n:
        raise ValueError(f'found {len(poses)} of {n} board poses inside the image: the board '
                         f'is too large for the camera at this fill')
    return poses


def render_ball(camera: PinholeCamera, center: npt.ArrayLike, radius_m: float,
                colour_bgr: tuple[float, float, float] = (20.0, 200.0, 230.0),
                background_bgr: tuple[float, float, float] = (110.0, 110.0, 110.0),
                supersample: int = 4, noise_std: float = 0.0,
                rng: np.random.Generator | None = None) -> npt.NDArray[np.uint8]:
    """A flat-shaded ball on a plain background through a camera, distortion included.

    Parameters
    ----------
    camera : PinholeCamera
    center : array-like, shape (3,)
        The ball's centre in the camera frame [m].
    radius_m : float
        The ball's radius [m].
    colour_bgr, background_bgr : tuple of 3 float
        Colours [grey levels]; the default ball is yellow (hue 26 of OpenCV's 180).
    supersample : int
        Samples per pixel along each axis (1-8).
    noise_std : float
        Standard deviation of Gaussian noise [grey levels] (needs ``rng``).
    rng : numpy.random.Generator, optional

    Returns
    -------
    image : ndarray, shape (height, width, 3), uint8
        Ball and background mixed by the fraction of each pixel the ball covers
        (`inflarm_model.camera.sphere_coverage`, ``supersample`` rays a side near the
        outline).
    """
    coverage = np.zeros((camera.height, camera.width, 1))
    covered = sphere_coverage(camera, center, radius_m, _check_supersample(supersample))
    if covered is not None:
        h, w = covered.coverage.shape
        coverage[covered.v0:covered.v0 + h, covered.u0:covered.u0 + w, 0] = covered.coverage
    image = (coverage * np.asarray(colour_bgr, dtype=float)
             + (1.0 - coverage) * np.asarray(background_bgr, dtype=float))
    return _to_uint8(image, noise_std, rng)
