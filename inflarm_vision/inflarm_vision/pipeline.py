"""From camera images to the ball's centre in the arm's frame: the core of ``ball_tracker``.

`BallPipeline.process` tracks the ball in a BGR image (`inflarm_vision.tracker.BallTracker`),
locates its centre in the camera frame from the outline and the known diameter
(`inflarm_vision.geometry.locate_ball`, distortion included) and maps it into the mount frame
with the configured camera -> mount transform. `settings_from_parameters` turns the node's
flat parameter values into validated settings. Pure numpy/OpenCV, no rclpy.
"""

from dataclasses import dataclass, fields
import math

import numpy as np
import numpy.typing as npt

from inflarm_model.camera import PinholeCamera, RigidTransform
from inflarm_vision.geometry import BallLocation, locate_ball
from inflarm_vision.tracker import BallDetection, BallTracker, DetectorParams

__all__ = ['BallMeasurement', 'BallPipeline', 'TrackerSettings', 'settings_from_parameters']


@dataclass(frozen=True)
class TrackerSettings:
    """Everything `BallPipeline` needs besides the camera's intrinsics.

    Attributes
    ----------
    detector : DetectorParams
    ball_radius : float
        Radius of the yellow ball [m].
    camera2mount : RigidTransform
        Pose of the camera (optical frame) in the mount frame.
    search_radii, search_margin_px : float
        Tracking region around the last detection (`BallTracker`).
    """

    detector: DetectorParams
    ball_radius: float
    camera2mount: RigidTransform
    search_radii: float = 2.0
    search_margin_px: float = 16.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.ball_radius) and self.ball_radius > 0.0):
            raise ValueError(f'expected ball_radius > 0 [m], got {self.ball_radius}')


def settings_from_parameters(values: dict) -> TrackerSettings:
    """Settings from the ``ball_tracker`` parameter values.

    Parameters
    ----------
    values : dict
        ``detector.<field>`` for every field of `DetectorParams` (lists for the HSV triples),
        ``ball_diameter_m``, ``camera.translation_m`` (3 values), ``camera.rotation_xyzw``
        (4), ``tracking.search_radii``, ``tracking.search_margin_px``.

    Raises
    ------
    ValueError
        Naming the parameter that is wrong.
    """
    detector = {}
    for f in fields(DetectorParams):
        value = values[f'detector.{f.name}']
        detector[f.name] = tuple(value) if f.name.startswith('hsv_') else value
    try:
        params = DetectorParams(**detector)
    except ValueError as err:
        raise ValueError(f'detector.*: {err}') from None
    translation = values['camera.translation_m']
    if len(translation) != 3:
        raise ValueError(f'camera.translation_m: expected 3 values [m], got {list(translation)}')
    try:
        camera2mount = RigidTransform.from_quaternion(translation,
                                                      values['camera.rotation_xyzw'])
    except ValueError as err:
        raise ValueError(f'camera.rotation_xyzw / camera.translation_m: {err}') from None
    diameter = values['ball_diameter_m']
    if not (math.isfinite(diameter) and diameter > 0.0):
        raise ValueError(f'ball_diameter_m: expected > 0 [m], got {diameter}')
    radii, margin = values['tracking.search_radii'], values['tracking.search_margin_px']
    if not (math.isfinite(radii) and radii >= 1.0):
        raise ValueError(f'tracking.search_radii: expected >= 1, got {radii}')
    if not (math.isfinite(margin) and margin >= 0.0):
        raise ValueError(f'tracking.search_margin_px: expected >= 0 [px], got {margin}')
    return TrackerSettings(detector=params, ball_radius=0.5 * diameter,
                           camera2mount=camera2mount, search_radii=radii,
                           search_margin_px=margin)


@dataclass(frozen=True)
class BallMeasurement:
    """The ball in one image.

    Attributes
    ----------
    detection : BallDetection
        In the image [px].
    location : BallLocation
        Centre in the camera frame [m].
    position : ndarray, shape (3,)
        Centre in the mount frame [m].
    """

    detection: BallDetection
    location: BallLocation
    position: npt.NDArray[np.float64]


class BallPipeline:
    """Tracks the ball image after image and locates it in the mount frame.

    Parameters
    ----------
    settings : TrackerSettings
    """

    def __init__(self, settings: TrackerSettings) -> None:
        if not isinstance(settings, TrackerSettings):
            raise ValueError(f'expected settings a TrackerSettings, got {type(settings).__name__}')
        self.settings = settings
        self.tracker = BallTracker(settings.detector, settings.search_radii,
                                   settings.search_margin_px)

    def process(self, bgr_image: npt.ArrayLike,
                camera: PinholeCamera) -> BallMeasurement | None:
        """The ball in one BGR image taken by ``camera``, or None if it is not seen.

        Raises
        ------
        ValueError
            If the image is not a uint8 BGR array of the camera's size.
        """
        image = np.asarray(bgr_image)
        if image.shape[:2] != (camera.height, camera.width):
            raise ValueError(
                f'image of {image.shape[1]}x{image.shape[0]} px from a camera of '
                f'{camera.width}x{camera.height} px (camera_info does not match)')
        detection = self.tracker.update(image)
        if detection is None:
            return None
        try:
            location = locate_ball(detection, camera, self.settings.ball_radius)
        except ValueError:
            return None  # an outline that is no cone in front of the camera: not the ball
        return BallMeasurement(detection=detection, location=location,
                               position=self.settings.camera2mount.apply(location.position))
