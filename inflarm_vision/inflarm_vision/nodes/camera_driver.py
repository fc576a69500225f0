"""A camera driver: images from a V4L2 camera (a USB camera) or a video file, through OpenCV.

usb_cam and v4l2_camera are C++ and not on PyPI; this node stands in for them. The capture is
`inflarm_vision.capture.VideoSource`, run in a thread of its own (a blocking read must not stall
the executor); that thread publishes each frame as it comes. Each image is stamped with the
node clock's time right after the grab returned (the capture time, as near as OpenCV tells it);
its camera_info carries the same stamp and frame and is published right after it (as
image_transport's CameraPublisher does).

Publishes (one image topic, by ``transport``; topic names as image_transport's):
    camera/image_raw (sensor_msgs/Image, bgr8, SENSOR_QOS): ``transport`` raw.
    camera/image_raw/compressed (sensor_msgs/CompressedImage, SENSOR_QOS): ``transport``
        compressed; format ``bgr8; jpeg compressed bgr8``. An MJPEG source's JPEG bytes as it
        delivered them (no decode, no re-encode: the ``jpeg_passthrough`` of
        `inflarm_vision.capture`); other sources' frames encoded at ``jpeg_quality``.
    camera/camera_info (sensor_msgs/CameraInfo, SENSOR_QOS): the calibration of
        ``camera_info_url``, with each image; none without a calibration, nor while the
        calibration's size differs from the frames' (a warning, throttled).
    diagnostics (diagnostic_msgs/DiagnosticArray, RELIABLE_QOS): every
        ``diagnostics_period_s``: state, frames captured and published, frame rate, size,
        format, JPEG pass-through, reconnects, camera_info, last problem.
Parameters:
    device (string, read-only): ``/dev/video0``, a device index (``0``), or a video file to
        replay (OpenCV's FFmpeg backend).
    width, height (int, read-only): requested image size of a device [px], 0 for its default.
    fps (double, read-only): requested frame rate of a device, the pace of a file [Hz]; 0 for
        the device's default or the file's recorded rate.
    fourcc (string, read-only): pixel format requested from a device, 4 characters (``MJPG``,
        ``YUYV``), or '' for its default.
    transport (string, read-only): ``raw`` or ``compressed``.
    jpeg_quality (int, 1-100): JPEG quality of frames the node encodes itself.
    camera_info_url (string, read-only): ``file:///path/camera.yaml``,
        ``package://<package>/<path>`` or a plain path of a calibration in the YAML format of
        camera_calibration_parsers (`inflarm_vision.calibration.read_camera_info_yaml`); ''
        for none.
    frame_id (string, read-only): frame of the images (the camera's optical frame).
    loop (bool, read-only): restart a file at its end; a file that does not loop ends the
        capture (the node keeps running, publishing nothing).
    reconnect_period_s (double): wait between attempts to open the source [s].
    diagnostics_period_s (double, read-only).
Bad input: a bad parameter (an unknown ``transport``, a fourcc that is not 4 characters, a
``jpeg_quality`` out of 1-100, a ``camera_info_url`` that cannot be read or is not a
calibration) stops the node at start with the reason. A source that is not there or cannot be
opened, or that stops delivering frames (unplugged), is warned about (throttled, naming it) and
opened again every ``reconnect_period_s`` until it is back; the node never exits for it.
"""

import array
import os
import threading
import urllib.parse

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

from inflarm_msgs_json.ros.diagnostics import (
    ERROR,
    OK,
    WARN,
    DiagnosticsPublisher,
    diagnostic_status,
)
from inflarm_msgs_json.ros.image import bgr_to_compressed, numpy_to_image
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import ProblemReporter
from inflarm_msgs_json.ros.qos import SENSOR_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node
from inflarm_vision.calibration import CameraIntrinsics, read_camera_info_yaml
from inflarm_vision.capture import CaptureError, CaptureSettings, Frame, VideoSource
from inflarm_vision.ros_conversions import camera_info_from_calibration

TRANSPORTS = {
    'raw': (Image, 'camera/image_raw'),
    'compressed': (CompressedImage, 'camera/image_raw/compressed'),
}
"""``transport`` -> (message type, topic), as image_transport names them."""
JPEG_FORMAT = 'bgr8; jpeg compressed bgr8'
"""``CompressedImage.format`` of the JPEGs, as image_transport's compressed publisher writes it."""
SOURCE_WARNING_PERIOD_S = 10.0
"""Least time between two warnings of the same kind about the source [s]."""

PARAMETERS = (
    Parameter('device', '/dev/video0',
              "camera device ('/dev/video0'), its index ('0'), or a video file to replay",
              read_only=True),
    Parameter('width', 0, "requested image width [px], 0 for the device's default",
              range=(0, 16384), read_only=True),
    Parameter('height', 0, "requested image height [px], 0 for the device's default",
              range=(0, 16384), read_only=True),
    Parameter('fps', 0.0, "requested frame rate, or a file's pace [Hz]; 0 for the source's",
              range=(0.0, 1000.0), read_only=True),
    Parameter('fourcc', 'MJPG',
              "pixel format requested from a device, 4 characters ('MJPG', 'YUYV'), '' for "
              'its default', read_only=True),
    Parameter('transport', 'raw',
              "'raw' (sensor_msgs/Image bgr8 on camera/image_raw) or 'compressed' "
              '(sensor_msgs/CompressedImage JPEG on camera/image_raw/compressed)',
              read_only=True),
    Parameter('jpeg_quality', 90, 'JPEG quality of frames the node encodes itself',
              range=(1, 100)),
    Parameter('camera_info_url', '',
              "calibration file (file:///path.yaml, package://pkg/path.yaml or a path), '' "
              'for none', read_only=True),
    Parameter('frame_id', 'camera_optical_frame', 'frame of the images', read_only=True),
    Parameter('loop', True, 'restart a video file at its end', read_only=True),
    Parameter('reconnect_period_s', 1.0, 'wait between attempts to open the source [s]',
              range=(0.05, 60.0)),
    Parameter('diagnostics_period_s', 1.0, 'diagnostics period [s]', range=(0.05, 60.0),
              read_only=True),
)


def calibration_path(url: str) -> str | None:
    """The file a ``camera_info_url`` names: ``file://`` URL, ``package://`` URL, or a path;
    None for ''.

    Raises
    ------
    ValueError
        Another scheme, a relative ``file://`` path, an unknown package.
    """
    text = url.strip()
    if not text:
        return None
    if text.startswith('file://'):
        path = urllib.parse.unquote(text[len('file://'):])
        if not path.startswith('/'):
            raise ValueError(f"camera_info_url '{url}': expected file:///<absolute path>")
        return path
    if text.startswith('package://'):
        package, _, relative = text[len('package://'):].partition('/')
        try:
            return os.path.join(get_package_share_directory(package), relative)
        except PackageNotFoundError:
            raise ValueError(f"camera_info_url '{url}': no package '{package}'") from None
    if '://' in text:
        raise ValueError(f"camera_info_url '{url}': expected file://, package:// or a path")
    return os.path.expanduser(text)


def load_calibration(url: str) -> CameraIntrinsics | None:
    """The calibration of ``camera_info_url`` (None for ''); ``ValueError`` naming the URL."""
    path = calibration_path(url)
    if path is None:
        return None
    try:
        return read_camera_info_yaml(path)
    except OSError as err:
        raise ValueError(f"camera_info_url '{url}': cannot read {path}: "
                         f'{err.strerror or err}') from None
    except ValueError as err:
        raise ValueError(f"camera_info_url '{url}': {err}") from None


def settings_from_parameters(params: dict) -> CaptureSettings:
    """The capture settings of the parameters; ``ValueError`` naming a bad one."""
    if params['transport'] not in TRANSPORTS:
        raise ValueError(f"transport must be one of {list(TRANSPORTS)}, got "
                         f"'{params['transport']}'")
    return CaptureSettings(
        device=params['device'], width=params['width'], height=params['height'],
        fps=params['fps'], fourcc=params['fourcc'], loop=params['loop'],
        jpeg_passthrough=params['transport'] == 'compressed')


class _Counters:
    """What the capture thread did, read by the diagnostics timer (under ``lock``)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.captured = 0
        self.published = 0
        self.window_published = 0
        self.reconnects = 0
        self.state = 'opening'
        self.source: dict[str, object] = {}
        self.camera_info = 'none (no camera_info_url)'
        self.passthrough = False


class CameraDriverNode(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('camera_driver', **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        self.settings = settings_from_parameters(self.params)
        self.calibration = load_calibration(self.params['camera_info_url'])
        self.camera_info = (None if self.calibration is None
                            else camera_info_from_calibration(self.calibration))
        image_type, self.image_topic = TRANSPORTS[self.params['transport']]
        self.image_pub = self.create_publisher(
            image_type, self.image_topic, SENSOR_QOS,
            event_callbacks=publisher_events(self, self.image_topic))
        self.info_pub = self.create_publisher(
            CameraInfo, 'camera/camera_info', SENSOR_QOS,
            event_callbacks=publisher_events(self, 'camera/camera_info'))
        self.source_problems = ProblemReporter(self.get_logger(), SOURCE_WARNING_PERIOD_S)
        self.counters = _Counters()
        self.diagnostics = DiagnosticsPublisher(self, self.diagnostic_status,
                                                self.params['diagnostics_period_s'])
        self._stop = threading.Event()
        self.capture_thread = threading.Thread(target=self._capture, name='camera_capture',
                                               daemon=True)
        if self.calibration is None:
            calibration = 'no camera_info_url: publishing no camera/camera_info'
        else:
            w, h = self.calibration.image_size
            calibration = f"camera_info {w}x{h} px from {self.params['camera_info_url']}"
            self.counters.camera_info = 'published'
        self.get_logger().info(
            f"ready: capturing from {self.params['device']}, publishing {self.image_topic} in "
            f"{self.params['frame_id']}; {calibration}")
        self.capture_thread.start()

    def destroy_node(self) -> None:
        """Stop the capture thread (it finishes the frame in hand), then destroy the node."""
        self._stop.set()
        thread = self.capture_thread
        if thread.is_alive() and thread is not threading.current_thread():
            thread.join(timeout=10.0)
            if thread.is_alive():
                self.get_logger().error('the capture thread did not stop within 10 s')
        super().destroy_node()

    # -- the capture thread --------------------------------------------------------------------

    def _running(self) -> bool:
        return not self._stop.is_set() and self.context.ok()

    def _capture(self) -> None:
        source: VideoSource | None = None
        lost = False  # the source was unavailable or lost: its next opening is a reconnect
        try:
            while self._running():
                if source is None:
                    source = self._open(lost)
                    lost = source is None
                    continue
                try:
                    frame = source.read()
                except CaptureError as error:
                    source.close()
                    source, lost = None, True
                    self._source_problem(f'{error}; reopening it every '
                                         f"{self.params['reconnect_period_s']:g} s", 'lost')
                    self._stop.wait(self.params['reconnect_period_s'])
                    continue
                except Exception as error:  # noqa: BLE001 (a bug: logged, the source reopened)
                    source.close()
                    source, lost = None, True
                    self.problems.bug('capture', error)
                    self._stop.wait(self.params['reconnect_period_s'])
                    continue
                if frame is None:
                    self.get_logger().info(
                        f"end of {self.params['device']} (loop is off): capture stopped")
                    with self.counters.lock:
                        self.counters.state = 'ended'
                    break
                self._guarded_publish(frame)
        finally:
            if source is not None:
                source.close()

    def _open(self, reconnect: bool) -> VideoSource | None:
        """The source opened, or None after a warning and a wait of ``reconnect_period_s``."""
        try:
            source = VideoSource(self.settings, clock=self.get_clock().now,
                                 sleep=self._stop.wait)
        except CaptureError as error:
            with self.counters.lock:
                self.counters.state = 'waiting for the source'
            self._source_problem(f"{error}; trying again every "
                                 f"{self.params['reconnect_period_s']:g} s", 'open')
            self._stop.wait(self.params['reconnect_period_s'])
            return None
        except Exception as error:  # noqa: BLE001 (a bug: logged, tried again)
            self.problems.bug('capture', error)
            self._stop.wait(self.params['reconnect_period_s'])
            return None
        mode = 'JPEG pass-through' if source.passthrough else 'decoded frames'
        self.get_logger().info(
            f"{'reopened' if reconnect else 'opened'} {self.params['device']}: "
            f'{source.width}x{source.height} px, {source.fourcc or "unknown format"}, '
            f'{source.fps:g} Hz, {mode}')
        with self.counters.lock:
            self.counters.reconnects += int(reconnect)
            self.counters.state = 'capturing'
            self.counters.source = {'width': source.width, 'height': source.height,
                                    'fourcc': source.fourcc, 'source_fps': source.fps}
        return source

    def _source_problem(self, message: str, kind: str) -> None:
        self.source_problems.warn('source', message, kind)

    def _guarded_publish(self, frame: Frame) -> None:
        with self.counters.lock:
            self.counters.captured += 1
        try:
            self.publish(frame)
        except ValueError as error:
            self.problems.reject('frame', error)
        except Exception as error:  # noqa: BLE001 (the capture thread must never die)
            if self._running():
                self.problems.bug('capture', error)

    def publish(self, frame: Frame) -> None:
        """Publish a frame's image, then its camera_info (same header)."""
        header = Header(stamp=frame.stamp.to_msg(), frame_id=self.params['frame_id'])
        if self.params['transport'] == 'raw':
            msg = numpy_to_image(frame.image(), 'bgr8', header)
        elif frame.jpeg is not None:
            msg = CompressedImage(header=header, format=JPEG_FORMAT)
            data = array.array('B')
            data.frombytes(frame.jpeg)
            msg.data = data
        else:
            msg = bgr_to_compressed(frame.bgr, 'jpeg', self.params['jpeg_quality'], header)
        self.image_pub.publish(msg)
        with self.counters.lock:
            self.counters.published += 1
            self.counters.window_published += 1
            self.counters.passthrough = frame.jpeg is not None
        if self.camera_info is None:
            return
        if (frame.width, frame.height) != self.calibration.image_size:
            w, h = self.calibration.image_size
            message = (f"the calibration of {self.params['camera_info_url']} is for {w}x{h} "
                       f'px, the frames are {frame.width}x{frame.height} px: publishing no '
                       'camera_info')
            self.source_problems.warn('camera_info', message, 'size mismatch')
            with self.counters.lock:
                self.counters.camera_info = 'none (size mismatch)'
            return
        self.camera_info.header = header
        self.info_pub.publish(self.camera_info)
        with self.counters.lock:
            self.counters.camera_info = 'published'

    # -- diagnostics ---------------------------------------------------------------------------

    def diagnostic_status(self) -> list[DiagnosticStatus]:
        c = self.counters
        with c.lock:
            published, c.window_published = c.window_published, 0
            state, values = c.state, dict(c.source)
            values.update(frames_captured=c.captured, frames_published=c.published,
                          reconnects=c.reconnects, camera_info=c.camera_info,
                          jpeg_passthrough=c.passthrough)
        fps = published / self.params['diagnostics_period_s']
        if state != 'capturing':
            level, message = (OK if state == 'ended' else ERROR), state
        elif published == 0:
            level, message = WARN, 'no frames'
        else:
            level, message = OK, f'{fps:.1f} frames/s'
        last = {**self.problems.last, **self.source_problems.last}
        return [diagnostic_status(
            'camera_driver: capture', self.params['device'], level, message, state=state,
            fps=fps, **values,
            last_problem='; '.join(f'{source}: {text}' for source, text in last.items()))]


def main(args: list[str] | None = None) -> None:
    spin_node(CameraDriverNode, args)


if __name__ == '__main__':
    main()
