"""sra_sim's simulated camera in-process: images of the ball at the true end point, camera_info,
capture-time stamps, the latency, placement parameters."""

from geometry_msgs.msg import PointStamped
import numpy as np
import rclpy
from rclpy.parameter import Parameter
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, Image

from inflarm_hw.nodes.camera_publisher import CAMERA_PARAMETERS
from inflarm_hw.nodes.sra_sim import SraSim
from inflarm_model.camera import PinholeCamera, RigidTransform, project_points
from inflarm_msgs_json.ros.image import image_to_numpy
from inflarm_msgs_json.ros.qos import SENSOR_QOS
from inflarm_vision.nodes.ball_tracker import PARAMETERS as TRACKER_PARAMETERS
from inflarm_vision.tracker import detect_ball
from ros_harness import spin_until


def test_sra_sim_and_ball_tracker_default_to_the_same_camera_pose_and_ball():
    sim = {p.name: p.default for p in CAMERA_PARAMETERS}
    tracker = {p.name: p.default for p in TRACKER_PARAMETERS}
    assert sim['camera.translation_m'] == tracker['camera.translation_m']
    assert sim['camera.rotation_xyzw'] == tracker['camera.rotation_xyzw']
    assert sim['camera.ball_diameter_m'] == tracker['ball_diameter_m']


def test_images_show_the_ball_at_the_end_point_stamped_at_capture(executor):
    latency = 0.15
    sim = SraSim(context=executor.context, parameter_overrides=[
        Parameter('seed', value=7), Parameter('camera_rate_hz', value=10.0),
        Parameter('camera.latency_s', value=latency), Parameter('camera.width', value=320),
        Parameter('camera.height', value=240), Parameter('camera.focal_px', value=450.0)])
    probe = rclpy.create_node('probe', context=executor.context)
    images: list[tuple[Image, Time]] = []
    infos: list[CameraInfo] = []
    truth: list[PointStamped] = []
    probe.create_subscription(
        Image, 'camera/image_raw',
        lambda m: images.append((m, probe.get_clock().now())), SENSOR_QOS)
    probe.create_subscription(CameraInfo, 'camera/camera_info', infos.append, SENSOR_QOS)
    probe.create_subscription(PointStamped, 'end_point_truth', truth.append, SENSOR_QOS)
    executor.add_node(sim)
    executor.add_node(probe)
    assert spin_until(executor, lambda: len(images) >= 3 and infos and truth, timeout_s=15.0)

    msg, received = images[-1]
    assert (msg.height, msg.width, msg.encoding) == (240, 320, 'bgr8')
    assert msg.header.frame_id == 'camera_optical_frame'
    # stamped with the capture time, published the latency later
    age = (received - Time.from_msg(msg.header.stamp)).nanoseconds * 1e-9
    assert latency - 0.02 <= age <= latency + 1.0
    assert spin_until(executor, lambda: any(i.header.stamp == msg.header.stamp for i in infos))
    info = next(i for i in infos if i.header.stamp == msg.header.stamp)
    camera = PinholeCamera.from_camera_info(info.width, info.height, info.k, info.d,
                                            info.distortion_model)
    assert camera.focal_px == 450.0 and list(info.d) == [-0.12, 0.05, 0.0, 0.0, 0.0]
    # the ball is where the camera model puts the true end point (at rest: 0, 0, 0.604)
    end = np.array([truth[-1].point.x, truth[-1].point.y, truth[-1].point.z])
    pose = RigidTransform.from_quaternion(sim.params['camera.translation_m'],
                                          sim.params['camera.rotation_xyzw'])
    expected = project_points(camera, pose.inverse().apply(end))
    detection = detect_ball(image_to_numpy(msg))
    assert detection is not None
    assert np.linalg.norm(detection.center - expected) < 0.5
    # 20 mm radius at 1.1 m, f = 450 px
    assert abs(detection.radius - 450.0 * 0.02 / 1.1) < 0.3


def test_no_images_without_a_subscriber_and_none_when_disabled(executor):
    sim = SraSim(context=executor.context, parameter_overrides=[
        Parameter('camera_rate_hz', value=20.0)])
    executor.add_node(sim)
    rng_state = sim.camera.renderer.rng.bit_generator.state
    spin_until(executor, lambda: False, timeout_s=0.3)
    assert sim.camera.renderer.rng.bit_generator.state == rng_state  # nothing was rendered
    off = SraSim(context=executor.context,
                 parameter_overrides=[Parameter('camera.enabled', value=False)])
    assert off.camera is None
    off.destroy_node()
