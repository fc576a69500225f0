"""The simulated camera on the compressed transport in-process: sra_sim (and sim_mcu, which
carries the same camera) with ``camera.transport`` compressed publish JPEG CompressedImages on
camera/image_raw/compressed instead of raw images, stamped and delayed as raw ones, with
camera_info unchanged; the quality changes at runtime; a bad transport is refused at startup."""

from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, CompressedImage

from inflarm_hw.nodes.sim_mcu import SimMcuNode
from inflarm_hw.nodes.sra_sim import SraSim
from inflarm_model.camera import PinholeCamera, RigidTransform, project_points
from inflarm_msgs_json.ros.image import compressed_to_bgr
from inflarm_msgs_json.ros.qos import SENSOR_QOS
from inflarm_vision.tracker import detect_ball
from ros_harness import spin_until

SMALL = {'camera.width': 320, 'camera.height': 240, 'camera.focal_px': 450.0}


def sra_sim(executor, **overrides) -> SraSim:
    sim = SraSim(context=executor.context, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])
    executor.add_node(sim)
    return sim


def test_compressed_images_are_jpeg_of_the_ball_at_the_end_point_stamped_at_capture(executor):
    latency = 0.15
    sim = sra_sim(executor, seed=7, camera_rate_hz=10.0, **SMALL, **{
        'camera.latency_s': latency, 'camera.transport': 'compressed'})
    probe = rclpy.create_node('probe', context=executor.context)
    images: list[tuple[CompressedImage, Time]] = []
    infos: list[CameraInfo] = []
    truth: list[PointStamped] = []
    probe.create_subscription(
        CompressedImage, 'camera/image_raw/compressed',
        lambda m: images.append((m, probe.get_clock().now())), SENSOR_QOS)
    probe.create_subscription(CameraInfo, 'camera/camera_info', infos.append, SENSOR_QOS)
    probe.create_subscription(PointStamped, 'end_point_truth', truth.append, SENSOR_QOS)
    executor.add_node(probe)
    assert spin_until(executor, lambda: len(images) >= 3 and infos and truth, timeout_s=15.0)
    # instead of the raw images, not beside them
    assert probe.count_publishers('/camera/image_raw') == 0
    assert probe.count_publishers('/camera/image_raw/compressed') == 1

    msg, received = images[-1]
    assert msg.format == 'bgr8; jpeg compressed bgr8'
    assert bytes(msg.data[:3]) == b'\xff\xd8\xff'
    assert msg.header.frame_id == 'camera_optical_frame'
    age = (received - Time.from_msg(msg.header.stamp)).nanoseconds * 1e-9
    assert latency - 0.02 <= age <= latency + 1.0
    assert spin_until(executor, lambda: any(i.header.stamp == msg.header.stamp for i in infos))
    info = next(i for i in infos if i.header.stamp == msg.header.stamp)
    camera = PinholeCamera.from_camera_info(info.width, info.height, info.k, info.d,
                                            info.distortion_model)
    bgr = compressed_to_bgr(msg)
    assert bgr.shape == (240, 320, 3) == (info.height, info.width, 3)
    assert len(msg.data) < bgr.nbytes / 5
    end = np.array([truth[-1].point.x, truth[-1].point.y, truth[-1].point.z])
    pose = RigidTransform.from_quaternion(sim.params['camera.translation_m'],
                                          sim.params['camera.rotation_xyzw'])
    expected = project_points(camera, pose.inverse().apply(end))
    detection = detect_ball(bgr)
    assert detection is not None
    # the ball where the camera model puts the true end point: measured on 200 JPEG frames of
    # this scene (seed 7) at most 0.14 px of centre and 0.15 px of radius off; twice the raw
    # images' bounds (tests/vision/test_sra_sim_camera.py), this checks the camera, not the
    # detector's precision on JPEG (tests/vision/test_ball_tracker_node.py)
    assert np.linalg.norm(detection.center - expected) < 1.0
    assert abs(detection.radius - 450.0 * 0.02 / 1.1) < 0.6


def test_only_while_someone_subscribes_and_the_quality_changes_at_runtime(executor):
    sim = sra_sim(executor, camera_rate_hz=20.0, **SMALL, **{'camera.transport': 'compressed'})
    assert sim.get_parameter('camera.jpeg_quality').value == 90
    rng_state = sim.camera.renderer.rng.bit_generator.state
    spin_until(executor, lambda: False, timeout_s=0.3)
    assert sim.camera.renderer.rng.bit_generator.state == rng_state  # nothing was rendered

    probe = rclpy.create_node('probe', context=executor.context)
    images: list[CompressedImage] = []
    probe.create_subscription(CompressedImage, 'camera/image_raw/compressed', images.append,
                              SENSOR_QOS)
    executor.add_node(probe)
    assert spin_until(executor, lambda: len(images) >= 2, timeout_s=15.0)
    fine = len(images[-1].data)
    assert sim.set_parameters([Parameter('camera.jpeg_quality', value=20)])[0].successful
    count = len(images)
    assert spin_until(executor, lambda: len(images) >= count + 3, timeout_s=15.0)
    assert len(images[-1].data) < 0.7 * fine  # the same scene, coarser
    for bad in (0, 101):
        assert not sim.set_parameters([Parameter('camera.jpeg_quality', value=bad)])[0].successful
    assert not sim.set_parameters([Parameter('camera.transport', value='raw')])[0].successful


def test_the_default_is_raw_and_a_bad_transport_is_refused_naming_the_parameter(executor):
    raw = sra_sim(executor)
    assert raw.get_parameter('camera.transport').value == 'raw'
    topics = {p.topic_name for p in raw.publishers}
    assert '/camera/image_raw' in topics and '/camera/image_raw/compressed' not in topics
    with pytest.raises(ValueError, match=r"camera.transport must be one of \['raw', "
                                         r"'compressed'\], got 'theora'"):
        SraSim(context=executor.context,
               parameter_overrides=[Parameter('camera.transport', value='theora')])


def test_sim_mcu_carries_the_same_camera_on_the_compressed_transport(executor, tmp_path):
    mcu = SimMcuNode(context=executor.context, parameter_overrides=[
        Parameter('plant', value='sra'), Parameter('camera_rate_hz', value=10.0),
        Parameter('camera.transport', value='compressed'), Parameter('camera.jpeg_quality',
                                                                     value=80),
        *(Parameter(k, value=v) for k, v in SMALL.items())])
    executor.add_node(mcu)
    probe = rclpy.create_node('probe', context=executor.context)
    images: list[CompressedImage] = []
    probe.create_subscription(CompressedImage, 'camera/image_raw/compressed', images.append,
                              SENSOR_QOS)
    executor.add_node(probe)
    assert spin_until(executor, lambda: images, timeout_s=15.0)
    assert compressed_to_bgr(images[-1]).shape == (240, 320, 3)
    assert '/camera/image_raw' not in {p.topic_name for p in mcu.publishers}
