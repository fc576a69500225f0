"""The simulated external camera a simulator node (``sra_sim``, ``sim_mcu``) carries (not an
executable).

`CameraPublisher` renders the yellow ball at a point the node supplies through
`inflarm_hw.synthetic_camera` and publishes, on the node:

    camera/image_raw (sensor_msgs/Image, bgr8, SENSOR_QOS), with ``camera.transport`` raw:
        stamped with the capture time, published ``camera.latency_s`` later, in capture order.
    camera/image_raw/compressed (sensor_msgs/CompressedImage, JPEG, SENSOR_QOS), with
        ``camera.transport`` compressed, instead: the same images, stamps and latency, JPEG at
        ``camera.jpeg_quality`` (format ``bgr8; jpeg compressed bgr8``, as image_transport's
        compressed publisher writes it).
    camera/camera_info (sensor_msgs/CameraInfo, SENSOR_QOS): the intrinsics, same stamp,
        published right after the image (as image_transport's CameraPublisher does; published
        before it, a subscriber to both received half the images over UDP in a test here).

Frames are captured at the node's ``camera_rate_hz`` and only while the image topic has a
subscriber: rendering a frame is the costliest work of the node's thread.

Parameters (`CAMERA_PARAMETERS`, declared by the node with its own; the defaults are those of
`inflarm_hw.synthetic_camera.SraCamera`, which tools without ROS render with):
    camera.enabled (bool, read-only): publish images at all.
    camera.width, camera.height (int, read-only): image size [px].
    camera.focal_px (double, read-only): focal length, square pixels, principal point at the
        image centre [px].
    camera.distortion (double[5], read-only): plumb_bob k1, k2, p1, p2, k3.
    camera.translation_m (double[3], read-only): camera (optical frame) origin in the node's
        frame (``sra_mount``) [m].
    camera.rotation_xyzw (double[4], read-only): camera -> mount rotation, quaternion.
        The defaults put the camera 1.1 m from the arm's axis on -y, level with the middle of
        the work space, looking along +y (``look_at([0, -1.1, 0.78], [0, 0, 0.78])``).
    camera.ball_diameter_m (double, read-only): diameter of the yellow ball [m].
    camera.background (string, read-only): plain, noise or clutter.
    camera.noise_std (double, read-only): sensor noise [grey levels].
    camera.blur_sigma_px, camera.exposure (double): blur [px] and exposure gain, changeable
        at runtime.
    camera.latency_s (double): delay from capture to publication [s].
    camera.frame_id (string, read-only): frame of the images.
    camera.transport (string, read-only): ``raw`` (default) or ``compressed``.
    camera.jpeg_quality (int, 1-100): JPEG quality of compressed images, changeable at
        runtime.
"""

import collections
from collections.abc import Callable

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

from inflarm_hw.synthetic_camera import SraCamera, SyntheticCamera
from inflarm_msgs_json.ros.image import bgr_to_compressed, numpy_to_image
from inflarm_msgs_json.ros.parameters import Parameter
from inflarm_msgs_json.ros.qos import SENSOR_QOS

_C = SraCamera()
CAMERA_TRANSPORTS = {'raw': (Image, 'camera/image_raw'),
                     'compressed': (CompressedImage, 'camera/image_raw/compressed')}
"""``camera.transport`` -> (message type, topic); topics as image_transport's."""
CAMERA_PARAMETERS = (
    Parameter('camera.enabled', True, 'publish simulated camera images', read_only=True),
    Parameter('camera.width', _C.width, 'image width [px]', range=(16, 4096), read_only=True),
    Parameter('camera.height', _C.height, 'image height [px]', range=(16, 4096),
              read_only=True),
    Parameter('camera.focal_px', _C.focal_px, 'focal length [px]', range=(10.0, 20000.0),
              read_only=True),
    Parameter('camera.distortion', list(_C.distortion),
              'plumb_bob distortion k1, k2, p1, p2, k3', read_only=True),
    Parameter('camera.translation_m', list(_C.translation_m),
              'camera origin in sra_mount [m]', read_only=True),
    Parameter('camera.rotation_xyzw', list(_C.rotation_xyzw),
              'camera -> sra_mount rotation, quaternion x, y, z, w', read_only=True),
    Parameter('camera.ball_diameter_m', _C.ball_diameter_m, 'diameter of the yellow ball [m]',
              range=(0.001, 0.5), read_only=True),
    Parameter('camera.background', _C.background, 'background: plain, noise or clutter',
              read_only=True),
    Parameter('camera.noise_std', _C.noise_std, 'sensor noise [grey levels]',
              range=(0.0, 50.0), read_only=True),
    Parameter('camera.blur_sigma_px', _C.blur_sigma_px, 'image blur [px]', range=(0.0, 10.0)),
    Parameter('camera.exposure', _C.exposure, 'exposure gain', range=(0.05, 10.0)),
    Parameter('camera.latency_s', _C.latency_s, 'delay from capture to publication [s]',
              range=(0.0, 2.0)),
    Parameter('camera.frame_id', 'camera_optical_frame', 'frame of the images',
              read_only=True),
    Parameter('camera.transport', 'raw', "images as 'raw' (camera/image_raw) or 'compressed' "
              '(JPEG on camera/image_raw/compressed)', read_only=True),
    Parameter('camera.jpeg_quality', 90, 'JPEG quality of compressed images', range=(1, 100)),
)


def camera_from_parameters(params: dict) -> SraCamera:
    """The camera set-up the ``camera.*`` parameter values describe."""
    return SraCamera(
        width=params['camera.width'], height=params['camera.height'],
        focal_px=params['camera.focal_px'], distortion=tuple(params['camera.distortion']),
        translation_m=tuple(params['camera.translation_m']),
        rotation_xyzw=tuple(params['camera.rotation_xyzw']),
        ball_diameter_m=params['camera.ball_diameter_m'],
        background=params['camera.background'], noise_std=params['camera.noise_std'],
        blur_sigma_px=params['camera.blur_sigma_px'], exposure=params['camera.exposure'],
        latency_s=params['camera.latency_s'])


def synthetic_camera_from_parameters(params: dict, seed: int | None) -> SyntheticCamera:
    """The renderer the ``camera.*`` parameters describe; ``ValueError`` naming a bad one."""
    return camera_from_parameters(params).renderer(seed)


class CameraPublisher:
    """Publishes rendered images of the ball at ``ball_position()`` on ``node``.

    Parameters
    ----------
    node : rclpy.node.Node with inflarm_msgs_json.ros.node.GuardedCallbacks
        Has declared `CAMERA_PARAMETERS` and ``camera_rate_hz``; ``params`` holds their
        current values (the node keeps it up to date). Its timers are guarded.
    params : dict
    ball_position : callable
        Returns the ball's centre in the node's frame [m], shape (3,).
    seed : int or None
        Seed of the background and the noise.

    Raises
    ------
    ValueError
        A ``camera.*`` value the camera cannot have, naming the parameter.
    """

    def __init__(self, node: Node, params: dict,
                 ball_position: Callable[[], np.ndarray], seed: int | None) -> None:
        self.node = node
        self.params = params
        self.ball_position = ball_position
        transport = params['camera.transport']
        if transport not in CAMERA_TRANSPORTS:
            raise ValueError(f'camera.transport must be one of {list(CAMERA_TRANSPORTS)}, '
                             f"got '{transport}'")
        self.compressed = transport == 'compressed'
        self.renderer = synthetic_camera_from_parameters(params, seed)
        self.image_pub = node.create_publisher(*CAMERA_TRANSPORTS[transport], SENSOR_QOS)
        self.info_pub = node.create_publisher(CameraInfo, 'camera/camera_info', SENSOR_QOS)
        self.timer = node.create_guarded_timer(1.0 / params['camera_rate_hz'], self.capture,
                                               name='camera')
        # frames waiting for their latency, oldest first: (capture number, image, info)
        self._queue: collections.deque = collections.deque()
        self._captured = 0

    def capture(self) -> None:
        if self.image_pub.get_subscription_count() == 0:
            return
        stamp = self.node.get_clock().now()
        frame = self.renderer.render(self.ball_position(),
                                     exposure=self.params['camera.exposure'],
                                     blur_sigma_px=self.params['camera.blur_sigma_px'])
        header = Header(stamp=stamp.to_msg(), frame_id=self.params['camera.frame_id'])
        if self.compressed:
            image = bgr_to_compressed(frame.image, 'jpeg', self.params['camera.jpeg_quality'],
                                      header)
        else:
            image = numpy_to_image(frame.image, 'bgr8', header)
        info = CameraInfo(**self.renderer.camera.camera_info_fields())
        info.header = header
        self._captured += 1
        number = self._captured
        self._queue.append((number, image, info))
        remaining = self.params['camera.latency_s'] - (
            self.node.get_clock().now() - stamp).nanoseconds * 1e-9
        if remaining <= 0.0:
            self._publish_through(number)
            return
        holder: list = []

        def deliver() -> None:
            self.node.destroy_timer(holder[0])
            self._publish_through(number)

        holder.append(self.node.create_guarded_timer(remaining, deliver, name='camera'))

    def _publish_through(self, number: int) -> None:
        """Publish the frames up to capture ``number``, in capture order: a frame that is due
        takes the earlier ones still waiting along (their render outlasted the latency, or the
        latency was lowered): a process that ran late would otherwise send a later stamp
        before an earlier one, as no camera does."""
        while self._queue and self._queue[0][0] <= number:
            _, image, info = self._queue.popleft()
            self.publish(image, info)

    def publish(self, image: Image | CompressedImage, info: CameraInfo) -> None:
        self.image_pub.publish(image)
        self.info_pub.publish(info)
