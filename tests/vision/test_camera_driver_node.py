"""camera_driver in-process over real DDS, replaying MJPG AVI files written by cv2.VideoWriter:
bgr8 images, the file's own JPEGs on the compressed transport, camera_info from a calibration
file, a source that appears after start or fails while running, and bad parameters refused."""

import os

import cv2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import pytest
import rclpy
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from inflarm_model.camera import PinholeCamera
from inflarm_msgs_json.ros.image import compressed_to_bgr, image_to_bgr
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, SENSOR_QOS
from inflarm_vision.calibration import CameraIntrinsics, write_camera_info_yaml
from inflarm_vision.capture import CaptureError, CaptureSettings, VideoSource
from inflarm_vision.nodes import camera_driver
from inflarm_vision.nodes.camera_driver import PARAMETERS, CameraDriverNode
from inflarm_vision.ros_conversions import (
    calibration_from_camera_info,
    camera_info_from_calibration,
)
from ros_harness import spin_until

WIDTH, HEIGHT, FRAMES = 160, 120, 8
TIMEOUT_S = 20.0  # generous: a loaded 2-core machine; these take 1-2 s when idle
DEFAULTS = {p.name: p.default for p in PARAMETERS}


def frames_of(seed: int = 7) -> list[np.ndarray]:
    """Frames of one colour each, well apart, with the frame number written on."""
    rng = np.random.default_rng(seed)
    frames = []
    for k in range(FRAMES):
        frame = np.empty((HEIGHT, WIDTH, 3), np.uint8)
        frame[:] = rng.integers(0, 256, 3)
        frame[:, :, k % 3] = 30 * k
        cv2.putText(frame, str(k), (50, 90), cv2.FONT_HERSHEY_SIMPLEX, 2.5, (255, 255, 255), 4)
        frames.append(frame)
    return frames


def write_video(path, frames, fourcc='MJPG', fps=20.0):
    """Written under a temporary name, then renamed: the file appears complete at once."""
    partial = path.with_name('partial_' + path.name)
    writer = cv2.VideoWriter(str(partial), cv2.VideoWriter_fourcc(*fourcc), fps,
                             (frames[0].shape[1], frames[0].shape[0]))
    assert writer.isOpened()
    for frame in frames:
        writer.write(frame)
    writer.release()
    os.replace(partial, path)
    return path


def which(image: np.ndarray, frames) -> tuple[int, float]:
    """The written frame an image is closest to, and the mean difference [grey levels]."""
    errors = [np.abs(image.astype(float) - f).mean() for f in frames]
    return int(np.argmin(errors)), float(min(errors))


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


@pytest.fixture
def video(tmp_path):
    frames = frames_of()
    return write_video(tmp_path / 'frames.avi', frames), frames


class Rig:
    """The driver plus a probe subscribed to everything it publishes."""

    def __init__(self, executor, **overrides) -> None:
        self.executor = executor
        self.node = CameraDriverNode(
            context=executor.context,
            parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node('probe', context=executor.context)
        self.images: list[Image] = []
        self.compressed: list[CompressedImage] = []
        self.infos: list[CameraInfo] = []
        self.diagnostics: list[DiagnosticStatus] = []
        for msg_type, topic, store in (
                (Image, 'camera/image_raw', self.images),
                (CompressedImage, 'camera/image_raw/compressed', self.compressed),
                (CameraInfo, 'camera/camera_info', self.infos)):
            self.probe.create_subscription(msg_type, topic, store.append, SENSOR_QOS)
        self.probe.create_subscription(
            DiagnosticArray, 'diagnostics', lambda m: self.diagnostics.extend(m.status),
            RELIABLE_QOS)
        executor.add_node(self.node)
        executor.add_node(self.probe)

    def until(self, predicate, timeout_s: float = TIMEOUT_S) -> bool:
        return spin_until(self.executor, predicate, timeout_s)

    def values(self, status: DiagnosticStatus) -> dict[str, str]:
        return {v.key: v.value for v in status.values}


def test_a_file_is_published_as_bgr8_images_stamped_at_capture(executor, video):
    path, frames = video
    rig = Rig(executor, device=str(path), fps=50.0, diagnostics_period_s=0.25)
    assert rig.until(lambda: len(rig.images) >= 2 * FRAMES), rig.node.problems.last
    now = rig.node.get_clock().now().nanoseconds
    stamps = [stamp_ns(m) for m in rig.images]
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False)), stamps
    assert now - 10e9 < stamps[0] and stamps[-1] <= now  # the node clock's time of capture
    seen = []
    for msg in rig.images:
        assert (msg.width, msg.height, msg.encoding) == (WIDTH, HEIGHT, 'bgr8')
        assert msg.header.frame_id == 'camera_optical_frame'
        k, error = which(image_to_bgr(msg), frames)
        assert error < 4.0, (k, error)  # the file's JPEG at OpenCV's quality: about 1 level
        seen.append(k)
    # the file in order, again and again (best effort: a lost image skips one)
    steps = {(b - a) % FRAMES for a, b in zip(seen, seen[1:], strict=False)}
    assert 1 in steps and 0 not in steps, seen
    assert rig.infos == []  # no calibration, no camera_info
    assert rig.until(lambda: any(rig.values(s).get('frames_published', '0') != '0'
                                 for s in rig.diagnostics))
    status = next(s for s in rig.diagnostics if rig.values(s)['frames_published'] != '0')
    assert status.name == 'camera_driver: capture' and status.hardware_id == str(path)
    values = rig.values(status)
    assert values['state'] == 'capturing' and values['width'] == str(WIDTH)
    assert values['fourcc'] == 'MJPG' and values['jpeg_passthrough'] == 'False'
    assert values['camera_info'].startswith('none')


def test_compressed_transport_publishes_the_files_jpegs_unchanged(executor, video):
    path, frames = video
    with VideoSource(CaptureSettings(str(path), loop=False, pace=False,
                                     jpeg_passthrough=True)) as source:
        packets = [source.read().jpeg for _ in range(FRAMES)]
    rig = Rig(executor, device=str(path), transport='compressed', fps=50.0)
    assert rig.until(lambda: len(rig.compressed) >= 2 * FRAMES), rig.node.problems.last
    assert rig.images == []
    for msg in rig.compressed:
        assert msg.format == 'bgr8; jpeg compressed bgr8'
        data = bytes(msg.data)
        assert data in packets  # byte for byte the file's JPEG: no decode, no re-encode
        k, error = which(compressed_to_bgr(msg), frames)
        assert data == packets[k] and error < 4.0
    assert rig.node.counters.passthrough


def test_a_file_of_another_codec_is_encoded_at_jpeg_quality(executor, tmp_path):
    frames = frames_of(seed=5)
    path = write_video(tmp_path / 'frames.mp4', frames, fourcc='mp4v')
    rig = Rig(executor, device=str(path), transport='compressed', fps=50.0, jpeg_quality=60)
    assert rig.until(lambda: len(rig.compressed) >= 4), rig.node.problems.last
    sizes = []
    for msg in rig.compressed[:4]:
        assert bytes(msg.data[:3]) == b'\xff\xd8\xff'
        assert which(compressed_to_bgr(msg), frames)[1] < 8.0  # MPEG-4, then JPEG at 60
        sizes.append(len(msg.data))
    # quality is applied: the same frames at 100 are larger
    assert rig.node.set_parameters([Parameter('jpeg_quality', value=100)])[0].successful
    start = len(rig.compressed)
    assert rig.until(lambda: len(rig.compressed) >= start + 2 * FRAMES)
    assert np.mean([len(m.data) for m in rig.compressed[start + FRAMES:]]) > 1.3 * np.mean(
        sizes)
    assert not rig.node.counters.passthrough


def test_camera_info_comes_from_the_calibration_with_each_images_stamp(executor, video,
                                                                        tmp_path):
    path, _ = video
    camera = PinholeCamera.ideal(WIDTH, HEIGHT, 210.0, d=[-0.1, 0.02, 0.001, -0.002, 0.0])
    calibration_file = tmp_path / 'camera.yaml'
    write_camera_info_yaml(CameraIntrinsics.from_pinhole_camera(camera, 'usb_cam'),
                           calibration_file)
    rig = Rig(executor, device=str(path), camera_info_url=f'file://{calibration_file}',
              frame_id='cam', fps=50.0)

    def pairs() -> list[tuple[Image, CameraInfo]]:
        by_stamp = {stamp_ns(m): m for m in rig.images}
        return [(by_stamp[stamp_ns(i)], i) for i in rig.infos if stamp_ns(i) in by_stamp]
    assert rig.until(lambda: len(pairs()) >= 6), rig.node.problems.last
    for image, info in pairs():
        assert image.header.frame_id == info.header.frame_id == 'cam'
        assert (info.width, info.height) == (WIDTH, HEIGHT)
        assert info.distortion_model == 'plumb_bob'
        np.testing.assert_allclose(info.k, camera.k.reshape(-1))
        np.testing.assert_allclose(info.d, camera.d)
        np.testing.assert_allclose(info.r, np.eye(3).reshape(-1))
        assert list(info.p[:3]) == list(info.k[:3]) and info.p[3] == 0.0
    assert len({stamp_ns(i) for i in rig.infos}) == len(rig.infos)  # one per image
    # the conversion both ways
    back = calibration_from_camera_info(rig.infos[0])
    np.testing.assert_allclose(back.camera_matrix, camera.k)
    assert camera_info_from_calibration(back).k.tolist() == list(rig.infos[0].k)


def test_a_calibration_of_another_size_gives_no_camera_info_and_a_warning(executor, video,
                                                                          tmp_path):
    path, _ = video
    calibration_file = tmp_path / 'camera.yaml'
    write_camera_info_yaml(CameraIntrinsics.from_pinhole_camera(
        PinholeCamera.ideal(320, 240, 400.0)), calibration_file)
    rig = Rig(executor, device=str(path), camera_info_url=str(calibration_file), fps=50.0)
    assert rig.until(lambda: len(rig.images) >= FRAMES)
    assert rig.infos == []
    warning = rig.node.source_problems.last['camera_info']
    assert 'is for 320x240 px, the frames are 160x120 px: publishing no camera_info' in warning
    # warned once, then throttled (10 s) however many frames came
    assert rig.node.source_problems.counts['camera_info'] >= FRAMES - 1


def test_a_missing_file_keeps_the_node_waiting_until_it_appears(executor, tmp_path):
    path = tmp_path / 'later.avi'
    rig = Rig(executor, device=str(path), fps=50.0, reconnect_period_s=0.1,
              diagnostics_period_s=0.2)
    assert rig.until(lambda: any(s.level == DiagnosticStatus.ERROR for s in rig.diagnostics))
    assert 'no such file' in rig.node.source_problems.last['source']
    assert str(path) in rig.node.source_problems.last['source']
    waiting = next(s for s in rig.diagnostics if s.level == DiagnosticStatus.ERROR)
    assert waiting.message == 'waiting for the source' and 'no such file' in rig.values(
        waiting)['last_problem']
    assert rig.images == [] and rig.node.capture_thread.is_alive()
    frames = frames_of(seed=3)
    write_video(path, frames)
    assert rig.until(lambda: len(rig.images) >= FRAMES), rig.node.problems.last
    assert which(image_to_bgr(rig.images[-1]), frames)[1] < 4.0
    assert rig.node.counters.reconnects == 1
    assert rig.node.problems.unexpected == 0


def test_a_source_that_stops_delivering_is_reopened(executor, video, monkeypatch):
    path, _ = video
    opened: list[VideoSource] = []

    class FailingSource(VideoSource):
        """The first opening fails after 3 frames, as an unplugged camera would."""

        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            opened.append(self)

        def read(self):
            if len(opened) == 1 and self._index >= 3:
                raise CaptureError(self.settings.device, 'no frame in 3 reads in a row')
            return super().read()

    monkeypatch.setattr(camera_driver, 'VideoSource', FailingSource)
    rig = Rig(executor, device=str(path), fps=50.0, reconnect_period_s=0.1)
    assert rig.until(lambda: len(opened) >= 2 and len(rig.images) >= FRAMES + 3), (
        rig.node.problems.last, len(opened))
    assert 'no frame in 3 reads in a row; reopening it' in rig.node.source_problems.last[
        'source']
    assert rig.node.counters.reconnects == 1 and rig.node.problems.unexpected == 0


def test_a_file_that_does_not_loop_ends_and_the_node_stops_its_capture(executor, video):
    path, _ = video
    rig = Rig(executor, device=str(path), fps=100.0, loop=False)
    assert rig.until(lambda: rig.node.counters.state == 'ended')
    assert rig.node.counters.captured == FRAMES
    rig.node.capture_thread.join(timeout=TIMEOUT_S)
    assert not rig.node.capture_thread.is_alive()


def test_destroying_the_node_stops_the_capture(executor, video):
    path, _ = video
    rig = Rig(executor, device=str(path), fps=2.0)  # a long pacing wait in progress
    assert rig.until(lambda: len(rig.images) >= 1)
    executor.remove_node(rig.node)
    rig.node.destroy_node()
    assert not rig.node.capture_thread.is_alive()


def test_defaults_and_bad_parameters(executor, ros_context, tmp_path):
    rig = Rig(executor, device=str(tmp_path / 'none.avi'))
    node = rig.node
    for name in ('device', 'width', 'height', 'fps', 'fourcc', 'transport', 'jpeg_quality',
                 'camera_info_url', 'frame_id', 'loop', 'reconnect_period_s'):
        assert name in DEFAULTS
    assert DEFAULTS['device'] == '/dev/video0' and DEFAULTS['transport'] == 'raw'
    assert DEFAULTS['fourcc'] == 'MJPG' and DEFAULTS['jpeg_quality'] == 90
    for name, value in (('jpeg_quality', 0), ('jpeg_quality', 101), ('transport', 'compressed'),
                        ('device', '/dev/video1'), ('reconnect_period_s', 0.0)):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and result.reason, (name, value)
    assert node.set_parameters([Parameter('reconnect_period_s', value=0.5)])[0].successful
    assert node.params['reconnect_period_s'] == 0.5

    def make(**overrides):
        return CameraDriverNode(context=ros_context, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
    with pytest.raises(ValueError, match=r"transport must be one of \['raw', 'compressed'\], "
                                         r"got 'bogus'"):
        make(transport='bogus')
    with pytest.raises(InvalidParameterValueException, match='jpeg_quality'):
        make(jpeg_quality=0)
    with pytest.raises(ValueError, match="fourcc of 4 ASCII characters.*got 'MJPEG'"):
        make(fourcc='MJPEG')
    with pytest.raises(ValueError, match="camera_info_url 'http://host/c.yaml': expected"):
        make(camera_info_url='http://host/c.yaml')
    with pytest.raises(ValueError, match=r"camera_info_url 'file:///nowhere/c.yaml': cannot "
                                         r'read /nowhere/c.yaml'):
        make(camera_info_url='file:///nowhere/c.yaml')
    not_calibration = tmp_path / 'c.yaml'
    not_calibration.write_text('a: 1\n')
    with pytest.raises(ValueError, match='missing image_width'):
        make(camera_info_url=str(not_calibration))


def test_every_parameter_out_of_range_or_read_only_is_refused_at_runtime(executor, tmp_path):
    # as tests/test_hostile_input.py does for the nodes of its table
    node = Rig(executor, device=str(tmp_path / 'none.avi')).node
    refused = 0
    for name in DEFAULTS:
        descriptor = node.describe_parameter(name)
        value = node.get_parameter(name).value
        candidates = [value] if descriptor.read_only else []
        for r in descriptor.floating_point_range:
            candidates += [r.to_value * 10.0 + 1.0, r.from_value - abs(r.from_value) - 1.0]
        for r in descriptor.integer_range:
            candidates += [r.to_value + 1, r.from_value - 1]
        for bad in candidates:
            result = node.set_parameters([Parameter(name, value=bad)])[0]
            assert not result.successful and result.reason, (name, bad)
            refused += 1
    assert refused >= len(DEFAULTS)
