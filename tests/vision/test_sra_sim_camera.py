"""sra_sim's simulated camera in-process: images of the ball at the true end point, camera_info,
capture-time stamps, the latency (on simulated time the test steps), placement parameters."""

from geometry_msgs.msg import PointStamped
import numpy as np
import rclpy
from rclpy.parameter import Parameter
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
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


STEP_NS = 10_000_000  # the simulated clock's step: 10 ms


def step_clock(executor, clock_pub, nodes, now_ns: int) -> None:
    """Publish simulated time ``now_ns``, wait until every node has it, then run what is due."""
    clock_pub.publish(Clock(clock=Time(nanoseconds=now_ns).to_msg()))
    assert spin_until(executor, lambda: all(
        n.get_clock().now().nanoseconds == now_ns for n in nodes), timeout_s=10.0)
    for _ in range(10):  # the timers due at now_ns (ready by the clock, whatever the load)
        executor.spin_once(timeout_sec=0.0)


def test_images_show_the_ball_at_the_end_point_stamped_at_capture(executor):
    # On simulated time (use_sim_time, /clock from the test): stamps and the latency are exact
    # however late this process runs.
    latency = 0.15
    sim_time = Parameter('use_sim_time', value=True)
    sim = SraSim(context=executor.context, parameter_overrides=[
        sim_time, Parameter('seed', value=7), Parameter('camera_rate_hz', value=10.0),
        Parameter('camera.latency_s', value=latency), Parameter('camera.width', value=320),
        Parameter('camera.height', value=240), Parameter('camera.focal_px', value=450.0)])
    probe = rclpy.create_node('probe', context=executor.context, parameter_overrides=[sim_time])
    clock_pub = probe.create_publisher(Clock, '/clock', 10)
    published: list[tuple[Image, Time]] = []  # each image and the simulated time it left at
    publish = sim.camera.publish
    sim.camera.publish = lambda image, info: (
        published.append((image, sim.get_clock().now())), publish(image, info))
    images: list[Image] = []
    infos: list[CameraInfo] = []
    truth: list[PointStamped] = []
    probe.create_subscription(Image, 'camera/image_raw', images.append, SENSOR_QOS)
    probe.create_subscription(CameraInfo, 'camera/camera_info', infos.append, SENSOR_QOS)
    probe.create_subscription(PointStamped, 'end_point_truth', truth.append, SENSOR_QOS)
    executor.add_node(sim)
    executor.add_node(probe)
    assert spin_until(executor, lambda: clock_pub.get_subscription_count() >= 2, timeout_s=15.0)
    now_ns = 1_000_000_000
    step_clock(executor, clock_pub, [sim, probe], now_ns)
    deadline_ns = now_ns + 60_000_000_000
    while not (len(images) >= 3 and infos and truth):
        now_ns += STEP_NS
        assert now_ns < deadline_ns, 'no images in 60 s of simulated time'
        step_clock(executor, clock_pub, [sim, probe], now_ns)

    assert len(published) >= 3
    for image, left in published:
        # stamped with the capture time, published the latency later (on the step it fell due)
        age_ns = (left - Time.from_msg(image.header.stamp)).nanoseconds
        assert latency * 1e9 <= age_ns < latency * 1e9 + STEP_NS, age_ns
    msg = images[-1]
    assert (msg.height, msg.width, msg.encoding) == (240, 320, 'bgr8')
    assert msg.header.frame_id == 'camera_optical_frame'
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


def test_frames_leave_in_capture_order_when_a_later_one_is_due_first(executor):
    # A frame due at capture (its render outlasted the latency; here the latency was lowered)
    # while an earlier one waits: both leave now, the earlier first (before, the later frame
    # left alone, and a system test on a busy machine took a stamp 0.2 s past its last truth).
    sim_time = Parameter('use_sim_time', value=True)
    sim = SraSim(context=executor.context, parameter_overrides=[
        sim_time, Parameter('camera_rate_hz', value=10.0),
        Parameter('camera.latency_s', value=0.15), Parameter('camera.width', value=160),
        Parameter('camera.height', value=120), Parameter('camera.focal_px', value=225.0)])
    probe = rclpy.create_node('probe', context=executor.context, parameter_overrides=[sim_time])
    clock_pub = probe.create_publisher(Clock, '/clock', 10)
    published: list[int] = []  # the stamps [ns] of the images, in the order they left
    publish = sim.camera.publish
    sim.camera.publish = lambda image, info: (
        published.append(Time.from_msg(image.header.stamp).nanoseconds), publish(image, info))
    renders: list[int] = []  # the simulated times [ns] of the captures
    render = sim.camera.renderer.render
    sim.camera.renderer.render = lambda *a, **k: (
        renders.append(sim.get_clock().now().nanoseconds), render(*a, **k))[1]
    probe.create_subscription(Image, 'camera/image_raw', lambda _: None, SENSOR_QOS)
    executor.add_node(sim)
    executor.add_node(probe)
    assert spin_until(executor, lambda: clock_pub.get_subscription_count() >= 2, timeout_s=15.0)
    assert spin_until(executor, lambda: sim.camera.image_pub.get_subscription_count() == 1)
    now_ns = 1_000_000_000
    step_clock(executor, clock_pub, [sim, probe], now_ns)
    while not renders:  # the first frame, waiting for its 0.15 s
        now_ns += STEP_NS
        step_clock(executor, clock_pub, [sim, probe], now_ns)
    assert published == []
    sim.set_parameters([Parameter('camera.latency_s', value=0.0)])
    while len(renders) == 1:  # the second, 0.1 s later: due at once
        now_ns += STEP_NS
        step_clock(executor, clock_pub, [sim, probe], now_ns)
    assert renders[1] < renders[0] + 150_000_000  # before the first fell due
    assert published == renders


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
