"""A recorded camera replayed as real processes over DDS: camera_driver reads an MJPG AVI of the
rendered yellow ball and publishes its JPEGs untouched on camera/image_raw/compressed with the
calibration's camera_info; ball_tracker (transport compressed) publishes ball_position, which
must be where the ball was rendered in the frame of that stamp.

The ball is 80 mm across here, not the arm's 40 mm: the JPEGs of an MJPEG stream are 4:2:0
(chroma at half resolution), which moves the outline the tracker finds in the colour channels by
a fraction of a pixel; at 1.1 m a 40 mm ball (16 px radius) then measured up to 15 mm off along
the line of sight on these files, an 80 mm one (33 px) up to 5 mm (20 random positions, OpenCV's
MJPEG writer; across the line of sight under 0.6 mm for both).
"""

import cv2
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy
from sensor_msgs.msg import CompressedImage

from inflarm_hw.synthetic_camera import SraCamera
from inflarm_msgs_json.ros.qos import SENSOR_QOS
from inflarm_vision.calibration import CameraIntrinsics, write_camera_info_yaml
from inflarm_vision.capture import CaptureSettings, VideoSource
from ros_harness import spin_until

pytestmark = pytest.mark.system
BALL_DIAMETER_M = 0.08
FRAMES = 8
FPS = 5.0


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def record(path, rng: np.random.Generator) -> list[np.ndarray]:
    """An MJPG AVI of the ball at random points of the work space seen by sra_sim's camera;
    the true centres [m] in sra_mount."""
    setup = SraCamera(ball_diameter_m=BALL_DIAMETER_M)
    renderer = setup.renderer(seed=7)
    writer = cv2.VideoWriter(str(path), cv2.CAP_OPENCV_MJPEG, cv2.VideoWriter_fourcc(*'MJPG'),
                             FPS, (setup.width, setup.height))
    assert writer.isOpened()
    truths = []
    for _ in range(FRAMES):
        point = rng.uniform([-0.15, -0.12, 0.62], [0.15, 0.12, 0.92])
        frame = renderer.render(point)
        writer.write(frame.image)
        truths.append(frame.truth.position_world)
    writer.release()
    return truths


def test_a_replayed_mjpeg_recording_gives_the_rendered_ball_positions(node_processes, executor,
                                                                     tmp_path):
    video = tmp_path / 'ball.avi'
    truths = record(video, np.random.default_rng(7))
    with VideoSource(CaptureSettings(str(video), loop=False, pace=False,
                                     jpeg_passthrough=True)) as source:
        packets = [source.read().jpeg for _ in range(FRAMES)]
    assert len(set(packets)) == FRAMES
    calibration = tmp_path / 'camera.yaml'
    write_camera_info_yaml(CameraIntrinsics.from_pinhole_camera(SraCamera().camera()),
                           calibration)

    node_processes.start('inflarm_vision', 'camera_driver', parameters={
        'device': str(video), 'transport': 'compressed',
        'camera_info_url': f'file://{calibration}'})
    node_processes.start('inflarm_vision', 'ball_tracker', parameters={
        'transport': 'compressed', 'ball_diameter_m': BALL_DIAMETER_M})
    probe = rclpy.create_node('probe', context=executor.context)
    images: dict[int, int] = {}  # stamp -> frame of the recording
    points: list[PointStamped] = []
    probe.create_subscription(
        CompressedImage, 'camera/image_raw/compressed',
        lambda m: images.__setitem__(stamp_ns(m), packets.index(bytes(m.data))), SENSOR_QOS)
    probe.create_subscription(PointStamped, 'ball_position', points.append, SENSOR_QOS)
    executor.add_node(probe)

    def paired() -> list[tuple[int, PointStamped]]:
        return [(images[stamp_ns(p)], p) for p in points if stamp_ns(p) in images]
    # 5 frames a second; discovery takes up to 3 s, start-up of two processes a few more on a
    # loaded machine
    assert spin_until(executor, lambda: len({k for k, _ in paired()}) >= FRAMES
                      and len(paired()) >= 2 * FRAMES, timeout_s=60.0), (
        len(images), len(points), node_processes.output()[-3000:])

    errors = []
    for k, point in paired():
        assert point.header.frame_id == 'sra_mount'
        errors.append(np.array([point.point.x, point.point.y, point.point.z]) - truths[k])
    errors = np.abs(np.array(errors))
    # across the line of sight (x, z) a fraction of a millimetre, along it (y) a few
    assert errors[:, [0, 2]].max() < 0.0015, errors
    assert np.linalg.norm(errors, axis=1).max() < 0.008, errors
    assert 'JPEG pass-through' in node_processes.output()
