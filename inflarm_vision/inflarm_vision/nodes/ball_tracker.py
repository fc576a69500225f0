"""Tracks the yellow ball in camera images and publishes its centre in the arm's frame.

The vision sensor of ``001_b59ad71c956a1751`` (3.1, 3.3): every image goes through
`inflarm_vision.pipeline.BallPipeline` (HSV candidates, sub-pixel outline, tracking region,
3D centre from the outline and the ball's diameter with the camera_info intrinsics, then the
camera -> mount transform). Processing happens in the image callback; raw and compressed
images differ only in how they become a BGR array.

Subscribes (the images on one of the two topics, by ``transport``):
    camera/image_raw (sensor_msgs/Image, SENSOR_QOS), ``transport`` raw: bgr8, rgb8, bgra8,
        rgba8, mono8, the 16-bit and 4:2:2 encodings of ``inflarm_msgs_json.ros.image``.
    camera/image_raw/compressed (sensor_msgs/CompressedImage, SENSOR_QOS), ``transport``
        compressed: JPEG or PNG, as image_transport's compressed transport publishes them
        (``inflarm_msgs_json.ros.image.compressed_to_bgr``).
    camera/camera_info (sensor_msgs/CameraInfo, SENSOR_QOS): intrinsics (plumb_bob or
        rational_polynomial), the latest valid one is used.
Publishes:
    ball_position (geometry_msgs/PointStamped, SENSOR_QOS): ball centre in ``frame_id`` [m],
        stamped with the image's stamp; only for images where the ball is found.
    ~/debug_image (sensor_msgs/Image, bgr8, SENSOR_QOS): the image with the fitted outline,
        when ``publish_debug_image``.
    diagnostics (diagnostic_msgs/DiagnosticArray, RELIABLE_QOS): every
        ``diagnostics_period_s``: images, detection rate, latency (now - image stamp at
        publication), processing time, rejected images, whole-frame searches.
Parameters:
    transport (string, read-only): ``raw`` (default) or ``compressed``: which image topic.
    detector.* : `inflarm_vision.tracker.DetectorParams` (HSV thresholds, radius range, shape
        limits), changeable at runtime.
    tracking.search_radii, tracking.search_margin_px (double): the tracking region.
    ball_diameter_m (double): diameter of the yellow ball [m].
    camera.translation_m (double[3]), camera.rotation_xyzw (double[4]): pose of the camera's
        optical frame in ``frame_id`` (camera -> mount), changeable at runtime (calibration,
        `inflarm_vision.geometry.calibrate_camera_to_mount`).
    frame_id (string, read-only): frame of the published points.
    publish_debug_image (bool): publish ``~/debug_image``.
    diagnostics_period_s (double, read-only).
Bad input (empty, truncated or wrongly sized images, unknown encodings, compressed data that
does not decode or is not of its ``format``, unknown compressed formats, images before any
camera_info or of another size than it, invalid camera_info) is rejected by the callback guards
(``inflarm_msgs_json.ros.node``): a warning throttled per kind of problem, nothing published,
the node keeps running.
"""

import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from inflarm_model.camera import PinholeCamera
from inflarm_msgs_json.ros.image import compressed_to_bgr, image_to_bgr, numpy_to_image
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node
from inflarm_vision.pipeline import BallPipeline, settings_from_parameters
from inflarm_vision.tracker import DetectorParams, warm_up

TRANSPORTS = {
    'raw': (Image, 'camera/image_raw', image_to_bgr),
    'compressed': (CompressedImage, 'camera/image_raw/compressed', compressed_to_bgr),
}
"""``transport`` -> (message type, topic, message -> BGR array); topics as image_transport's."""

_D = DetectorParams()
PARAMETERS = (
    Parameter('transport', 'raw', "images as 'raw' (camera/image_raw) or 'compressed' "
              '(camera/image_raw/compressed, jpeg or png)', read_only=True),
    Parameter('detector.hsv_lower', list(_D.hsv_lower),
              'lower HSV thresholds (H 0-180, S, V 0-255)'),
    Parameter('detector.hsv_upper', list(_D.hsv_upper), 'upper HSV thresholds'),
    Parameter('detector.min_radius_px', _D.min_radius_px, 'smallest apparent radius [px]',
              range=(2.0, 1000.0)),
    Parameter('detector.max_radius_px', _D.max_radius_px, 'largest apparent radius [px]',
              range=(2.0, 4000.0)),
    Parameter('detector.min_circularity', _D.min_circularity,
              'smallest 4 pi A / P^2 of a candidate blob', range=(0.0, 1.0)),
    Parameter('detector.min_fill', _D.min_fill, 'smallest share of a blob not in holes',
              range=(0.0, 1.0)),
    Parameter('detector.max_aspect_ratio', _D.max_aspect_ratio,
              'largest axis ratio of the fitted ellipse', range=(1.0, 10.0)),
    Parameter('detector.min_confidence', _D.min_confidence,
              'smallest share of the outline on the fitted ellipse', range=(0.0, 1.0)),
    Parameter('detector.min_chroma', _D.min_chroma,
              "smallest distance of the ball's colour from grey [grey levels]",
              range=(0.0, 255.0)),
    Parameter('detector.min_saturation', _D.min_saturation,
              "smallest saturation of the ball's colour (1 - min / max of B, G, R)",
              range=(0.0, 1.0)),
    Parameter('detector.opening_px', _D.opening_px,
              'opening of the candidate mask [px], 0 for none', range=(0, 15)),
    Parameter('detector.max_candidates', _D.max_candidates, 'candidates refined per frame',
              range=(1, 20)),
    Parameter('tracking.search_radii', 2.0,
              'half-size of the tracking region in radii of the last detection',
              range=(1.0, 20.0)),
    Parameter('tracking.search_margin_px', 16.0, 'extra half-size of the tracking region [px]',
              range=(0.0, 1000.0)),
    Parameter('ball_diameter_m', 0.04, 'diameter of the yellow ball [m]', range=(0.001, 0.5)),
    Parameter('camera.translation_m', [0.0, -1.1, 0.78],
              'camera optical frame origin in frame_id [m]'),
    Parameter('camera.rotation_xyzw', [0.0, 0.70710678, 0.70710678, 0.0],
              'camera -> frame_id rotation, quaternion x, y, z, w'),
    Parameter('frame_id', 'sra_mount', 'frame of the published points', read_only=True),
    Parameter('publish_debug_image', False, 'publish ~/debug_image'),
    Parameter('diagnostics_period_s', 1.0, 'diagnostics period [s]', range=(0.05, 60.0),
              read_only=True),
)


class _Window:
    """Counters over one diagnostics period."""

    def __init__(self) -> None:
        self.images = 0
        self.detections = 0
        self.rejected = 0
        self.latency_s: list[float] = []
        self.processing_s: list[float] = []


class BallTrackerNode(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('ball_tracker', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, check=settings_from_parameters,
                                         on_set=self.on_parameters_set)
        if self.params['transport'] not in TRANSPORTS:
            raise ValueError(f"transport must be one of {list(TRANSPORTS)}, got "
                             f"'{self.params['transport']}'")
        image_type, self.image_topic, self.to_bgr = TRANSPORTS[self.params['transport']]
        self.pipeline = BallPipeline(settings_from_parameters(self.params))
        warm_up()  # the compiled kernels before the first image, not in its callback
        self.camera: PinholeCamera | None = None
        self.window = _Window()
        self.point_pub = self.create_publisher(
            PointStamped, 'ball_position', SENSOR_QOS,
            event_callbacks=publisher_events(self, 'ball_position'))
        self.debug_pub = self.create_publisher(Image, '~/debug_image', SENSOR_QOS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, 'diagnostics', RELIABLE_QOS)
        self.create_guarded_subscription(CameraInfo, 'camera/camera_info', self.on_camera_info,
                                         SENSOR_QOS)
        self.create_guarded_subscription(image_type, self.image_topic, self.on_image,
                                         SENSOR_QOS)
        self.create_guarded_timer(self.params['diagnostics_period_s'], self.publish_diagnostics)
        self.get_logger().info(
            f"ready: tracking a {self.params['ball_diameter_m'] * 1000:.0f} mm yellow ball on "
            f"{self.image_topic}, publishing ball_position in {self.params['frame_id']}")

    # -- parameters ----------------------------------------------------------------------------

    def on_parameters_set(self, changed: dict) -> None:
        self.pipeline = BallPipeline(settings_from_parameters(self.params))

    # -- inputs --------------------------------------------------------------------------------

    def on_camera_info(self, msg: CameraInfo) -> None:
        camera = PinholeCamera.from_camera_info(msg.width, msg.height, msg.k, msg.d,
                                                msg.distortion_model)  # ValueError: rejected
        if self.camera is None:
            self.get_logger().info(
                f'camera_info: {camera.width}x{camera.height} px, f = {camera.focal_px:.1f} px, '
                f'{camera.distortion_model}')
        self.camera = camera

    def on_image(self, msg: Image | CompressedImage) -> None:
        """Image in (of the ``transport``), point out; a ValueError rejects the image (warned
        by the guard)."""
        start = time.perf_counter()
        self.window.images += 1
        try:
            if self.camera is None:
                raise InputError('no camera_info', 'no camera_info received yet')
            bgr = self.to_bgr(msg)
            measurement = self.pipeline.process(bgr, self.camera)
        except ValueError:
            self.window.rejected += 1
            raise
        if measurement is not None:
            point = PointStamped()
            point.header.stamp = msg.header.stamp
            point.header.frame_id = self.params['frame_id']
            point.point.x, point.point.y, point.point.z = (float(v) for v in
                                                           measurement.position)
            self.point_pub.publish(point)
            self.window.detections += 1
            stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            self.window.latency_s.append((self.get_clock().now().nanoseconds - stamp_ns) * 1e-9)
        if self.params['publish_debug_image']:
            self.debug_pub.publish(numpy_to_image(annotate(bgr, measurement), 'bgr8',
                                                  header=msg.header))
        self.window.processing_s.append(time.perf_counter() - start)

    # -- diagnostics ---------------------------------------------------------------------------

    def publish_diagnostics(self) -> None:
        w, self.window = self.window, _Window()
        rate = w.detections / w.images if w.images else 0.0
        if w.images == 0:
            level, message = DiagnosticStatus.WARN, 'no images'
        elif rate < 0.5:
            level, message = DiagnosticStatus.WARN, f'ball found in {rate:.0%} of the images'
        else:
            level, message = DiagnosticStatus.OK, f'ball found in {rate:.0%} of the images'

        def stat(values: list[float], scale: float) -> str:
            return f'{np.mean(values) * scale:.2f}' if values else 'n/a'

        status = DiagnosticStatus(
            name='ball_tracker: detection', hardware_id='camera', level=level, message=message,
            values=[
                KeyValue(key='images', value=str(w.images)),
                KeyValue(key='detections', value=str(w.detections)),
                KeyValue(key='detection_rate', value=f'{rate:.3f}'),
                KeyValue(key='rejected_images', value=str(w.rejected)),
                KeyValue(key='latency_mean_ms', value=stat(w.latency_s, 1e3)),
                KeyValue(key='latency_max_ms',
                         value=f'{max(w.latency_s) * 1e3:.2f}' if w.latency_s else 'n/a'),
                KeyValue(key='processing_mean_ms', value=stat(w.processing_s, 1e3)),
                KeyValue(key='region_searches',
                         value=str(self.pipeline.tracker.region_searches)),
                KeyValue(key='full_frame_searches',
                         value=str(self.pipeline.tracker.full_frame_searches)),
                KeyValue(key='last_problem', value='; '.join(
                    f'{source}: {message}' for source, message in self.problems.last.items())),
            ])
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(array)


def annotate(bgr: np.ndarray, measurement) -> np.ndarray:
    """A copy of the image with the fitted outline, its centre and the 3D point written on."""
    image = np.array(bgr, copy=True)
    if measurement is None:
        cv2.putText(image, 'no ball', (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 255), 2)
        return image
    d = measurement.detection
    shift = 4
    center = tuple(int(round(c * (1 << shift))) for c in d.center)
    axes = tuple(int(round(a * (1 << shift))) for a in d.axes)
    cv2.ellipse(image, center, axes, float(np.degrees(d.angle)), 0.0, 360.0, (255, 0, 255), 1,
                cv2.LINE_AA, shift)
    cv2.drawMarker(image, tuple(int(round(c)) for c in d.center), (255, 0, 255),
                   cv2.MARKER_CROSS, 8, 1)
    x, y, z = measurement.position
    cv2.putText(image, f'({x:+.3f}, {y:+.3f}, {z:+.3f}) m  conf {d.confidence:.2f}', (10, 24),
                cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 0, 255), 2)
    return image


def main(args: list[str] | None = None) -> None:
    spin_node(BallTrackerNode, args)


if __name__ == '__main__':
    main()
