"""sensor_msgs/CameraInfo <-> `inflarm_vision.calibration.CameraIntrinsics`: the calibration a
camera driver loads from its ``camera_info_url`` and the message it publishes with each image.
"""

import numpy as np
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import Header

from inflarm_msgs_json.ros.problems import InputError
from inflarm_vision.calibration import CameraIntrinsics

__all__ = ['calibration_from_camera_info', 'camera_info_from_calibration']


def camera_info_from_calibration(calibration: CameraIntrinsics,
                                 header: Header | None = None) -> CameraInfo:
    """The ``sensor_msgs/CameraInfo`` of a calibration.

    Parameters
    ----------
    calibration : CameraIntrinsics
    header : std_msgs.msg.Header, optional
        Stamp and frame (those of the image it goes with).

    Returns
    -------
    sensor_msgs.msg.CameraInfo
        ``width``, ``height`` (``image_size``), ``distortion_model``, ``d``, ``k``, ``r``,
        ``p`` (row-major) from the calibration; no binning, full-image ROI.
    """
    width, height = calibration.image_size
    msg = CameraInfo(
        width=width, height=height, distortion_model=calibration.distortion_model,
        d=[float(x) for x in calibration.distortion],
        k=[float(x) for x in calibration.camera_matrix.reshape(-1)],
        r=[float(x) for x in calibration.rectification_matrix.reshape(-1)],
        p=[float(x) for x in calibration.projection_matrix.reshape(-1)])
    if header is not None:
        msg.header = header
    return msg


def calibration_from_camera_info(msg: CameraInfo, camera_name: str = 'camera'
                                 ) -> CameraIntrinsics:
    """The calibration a ``sensor_msgs/CameraInfo`` carries.

    Raises
    ------
    InputError
        Naming what is wrong (an empty size, a matrix that is not a camera matrix, an unknown
        distortion model or a ``d`` of the wrong length, values that are not finite).
    """
    try:
        return CameraIntrinsics(
            np.reshape(np.asarray(msg.k, dtype=float), (3, 3)), np.asarray(msg.d, dtype=float),
            (int(msg.width), int(msg.height)), camera_name, msg.distortion_model,
            np.reshape(np.asarray(msg.r, dtype=float), (3, 3)),
            np.reshape(np.asarray(msg.p, dtype=float), (3, 4)))
    except ValueError as err:
        raise InputError('camera_info', f'invalid camera_info: {err}') from None
