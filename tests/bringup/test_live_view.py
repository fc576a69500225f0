"""The live view (inflarm_bringup live_view): its scene core, and the page in a real browser.

The browser test runs the node in-process, fed over real DDS by a node publishing the demo's
scene (the paper's obstacle, an A* path around it, the ball on it, the inflatable arm under the
demo's load, a simulated camera image), loads the page in headless Chromium, waits for its
websocket client, checks the screenshot shows the scene, then clicks a control and sees the
plan_request arrive. Set INFLARM_WRITE_DOC_SCREENSHOT=1 to refresh the README's screenshot,
inflarm_bringup/doc/live_view.png, from it.
"""

import os
import pathlib
import socket
import subprocess
import sys
import threading

import cv2
import numpy as np
import pytest

from inflarm_bringup.headless_browser import INSTALL_HINT, HeadlessChromium, find_chromium
from inflarm_bringup.live_scene import (
    PortInUseError,
    RobotModel,
    ScrollingPlot,
    margin_colour,
    obstacle_boxes,
    rigid_positions,
    start_server,
)
from inflarm_model.elastostatics import spring_deflections
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.urdf import flexible_arm_urdf
from inflarm_msgs_json import Cuboid, ObstacleSet
from inflarm_planning.scenario import ALERT_MARGIN, GOAL, OBSTACLE, START

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
DOC_SCREENSHOT = REPO_ROOT / 'inflarm_bringup' / 'doc' / 'live_view.png'
ARM_MOTORS = (0.0, 0.6, -1.2)  # the demo's start [rad]
ARM_LOAD = np.array([0.0, 10.0, -15.0])  # the demo's load [N], base_link
SCENE_TIMEOUT_S = 90.0  # software WebGL on a loaded 2-core machine: generous


# -- the core, without ROS ---------------------------------------------------------------------

def loaded_arm() -> dict[str, float]:
    arm = FlexibleArm()
    q_k = spring_deflections(arm, ARM_MOTORS, ARM_LOAD, 172.71).q_k
    return dict(zip(FlexibleArm.JOINT_NAMES, FlexibleArm.assemble_q(ARM_MOTORS, q_k),
                    strict=True))


def test_robot_model_poses_the_urdf_cylinders_and_the_tip_as_the_kinematics_do():
    robot = RobotModel(flexible_arm_urdf())
    positions = loaded_arm()
    visuals, tip = robot.poses(positions)
    q = [positions[name] for name in FlexibleArm.JOINT_NAMES]
    np.testing.assert_allclose(tip, FlexibleArm().fk(q), atol=1e-12)
    assert sorted({v.link for v in visuals}) == ['link_1', 'link_2']
    assert sorted(robot.visual_links.values()) == ['link_1', 'link_1', 'link_2', 'link_2']
    # The rigid ghost: the same motors, no spring deflection; its tip is the rigid arm's.
    rigid = rigid_positions(positions)
    assert all(rigid[name] == 0.0 for name in FlexibleArm.SPRING_JOINT_NAMES)
    _, rigid_tip = robot.poses(rigid)
    assert np.linalg.norm(rigid_tip[:3, 3] - tip[:3, 3]) > 0.01  # the load deflects the arm
    # Each cylinder of a link ends where the next begins (frames of the URDF chain).
    main = [v for v in visuals if v.length > 0.5]
    assert len(main) == 2
    end_of_link_1 = main[0].pose[:3, 3] + main[0].pose[:3, 2] * main[0].length / 2
    assert np.linalg.norm(end_of_link_1 - main[1].pose[:3, 3]) < 0.6 / 2 + 0.04


@pytest.mark.parametrize('text, match', [
    ('not xml <', 'robot_description: not XML'),
    ('<html/>', 'expected a <robot> URDF'),
    ('<robot name="x"><link name="a"/></robot>', "no link 'tip'"),
])
def test_robot_model_rejects_a_bad_description_naming_it(text, match):
    with pytest.raises(ValueError, match=match):
        RobotModel(text)


def test_margin_colour_runs_from_green_to_red_as_the_margin_runs_out():
    assert margin_colour(10.0, 20.0) == (0, 200, 40)
    assert margin_colour(0.0, 20.0) == (230, 0, 40)
    assert margin_colour(-5.0, 20.0) == (230, 0, 40)
    reds = [margin_colour(m, 20.0)[0] for m in np.linspace(10.0, 0.0, 11)]
    greens = [margin_colour(m, 20.0)[1] for m in np.linspace(10.0, 0.0, 11)]
    assert reds == sorted(reds) and greens == sorted(greens, reverse=True)


def test_scrolling_plot_keeps_the_window_and_holds_missing_values():
    plot = ScrollingPlot(('a', 'b'), window_s=30.0)
    for t in range(60):
        plot.add(float(t), (float(t), float('nan') if t % 2 else -float(t)))
    t, a, b = plot.arrays(now=59.0)
    assert t[0] == pytest.approx(-30.0) and t[-1] == 0.0
    np.testing.assert_array_equal(a, np.arange(29, 60))
    assert np.isfinite(b).all() and b[-1] == -58.0  # held from the sample before
    with pytest.raises(ValueError, match='expected 2 values'):
        plot.add(60.0, (1.0,))


def test_obstacle_boxes_grow_the_alert_region_by_its_margin():
    boxes = obstacle_boxes(ObstacleSet('sra_mount', 0.03, (Cuboid((0, 0, 0), (0.1, 0.2, 0.3)),)))
    (_, centre, size, alert), (_, alert_centre, alert_size, is_alert) = boxes
    assert not alert and is_alert
    np.testing.assert_allclose(centre, (0.05, 0.1, 0.15))
    np.testing.assert_allclose(alert_centre, centre)
    np.testing.assert_allclose(alert_size - size, 0.06)


def test_a_port_in_use_is_an_error_naming_it():
    with socket.socket() as holder:
        holder.bind(('127.0.0.1', 0))
        holder.listen()
        port = holder.getsockname()[1]
        with pytest.raises(PortInUseError, match=f'port {port} on 127.0.0.1 is in use'):
            start_server('127.0.0.1', port)


@pytest.mark.system
def test_the_executable_exits_1_naming_a_port_in_use(domain_id, tmp_path):
    from inflarm_bringup.processes import NodeProcess, ros_environment
    with socket.socket() as holder:
        holder.bind(('127.0.0.1', 0))
        holder.listen()
        port = holder.getsockname()[1]
        command = NodeProcess('inflarm_bringup', 'live_view', {'port': port}).command()
        env = dict(ros_environment(), ROS_DOMAIN_ID=str(domain_id),
                   ROS_LOG_DIR=str(tmp_path / 'log'))
        result = subprocess.run(command, env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result.stdout + result.stderr
    assert f'port {port} on 127.0.0.1 is in use' in result.stdout + result.stderr


# -- the node and the page ---------------------------------------------------------------------

def demo_scene_publisher(context):
    """A node publishing the demo's scene: latched once, the streams from a timer."""
    from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
    from nav_msgs.msg import Path
    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo, JointState
    from std_msgs.msg import String

    from inflarm_hw.synthetic_camera import SraCamera
    from inflarm_msgs_json import ChamberPressures, LinkStatus
    from inflarm_msgs_json.ros.conversions import to_string_msg
    from inflarm_msgs_json.ros.image import numpy_to_image
    from inflarm_msgs_json.ros.qos import JOINT_STATE_QOS, LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS
    from inflarm_planning.astar import plan_path

    node = Node('demo_scene', context=context)
    path_points = plan_path(START, GOAL, [OBSTACLE], resolution=0.01, alert_margin=ALERT_MARGIN)
    ball = path_points[len(path_points) // 3]
    node.ball = ball

    def point(x, frame):
        msg = PointStamped()
        msg.header.frame_id = frame
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in x)
        return msg

    path = Path()
    path.header.frame_id = 'sra_mount'
    for p in path_points:
        pose = PoseStamped()
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in p)
        path.poses.append(pose)
    latched = {
        'robot_description': String(data=flexible_arm_urdf()),
        'planned_path': path,
        'obstacles': to_string_msg(ObstacleSet('sra_mount', ALERT_MARGIN, (
            Cuboid(OBSTACLE.min_corner, OBSTACLE.max_corner, 'paper obstacle'),))),
    }
    node.latched = {}
    for topic, msg in latched.items():
        node.latched[topic] = node.create_publisher(type(msg), topic, LATCHED_QOS)
        node.latched[topic].publish(msg)

    positions = loaded_arm()
    arm = FlexibleArm()
    tip = arm.fk([positions[n] for n in FlexibleArm.JOINT_NAMES])
    joints = JointState(name=list(positions), position=list(positions.values()))
    wrench = WrenchStamped()
    wrench.header.frame_id = 'tip'
    force_tip = tip[:3, :3].T @ ARM_LOAD
    wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = force_tip
    camera = SraCamera()
    image = numpy_to_image(camera.renderer(seed=7).render(ball).image, 'bgr8')
    intrinsics = camera.camera()
    info = CameraInfo(width=intrinsics.width, height=intrinsics.height,
                      k=intrinsics.k.reshape(-1).tolist(), d=intrinsics.d.tolist(),
                      distortion_model=intrinsics.distortion_model)
    streams = [
        ('estimated_joint_states', joints, JOINT_STATE_QOS),
        ('estimated_wrench', wrench, RELIABLE_QOS),
        ('estimated_tip', point(tip[:3, 3], 'base_link'), RELIABLE_QOS),
        ('tip_position_truth', point(tip[:3, 3] + 0.002, 'base_link'), SENSOR_QOS),
        ('link_status', to_string_msg(LinkStatus.from_moments('link_1', 50e3, 20.53, 15.94)),
         RELIABLE_QOS),
        ('link_status', to_string_msg(LinkStatus.from_moments('link_2', 50e3, 20.53, 6.0)),
         RELIABLE_QOS),
        ('ball_position', point(ball, 'sra_mount'), SENSOR_QOS),
        ('end_point_truth', point(ball + 0.001, 'sra_mount'), SENSOR_QOS),
        ('chamber_pressures', to_string_msg(ChamberPressures(chambers={
            'PEA': 60e3, 'B1': 6e3, 'B2': 6e3, 'B3': 14e3, 'B4': 9e3})), RELIABLE_QOS),
        ('camera/image_raw', image, SENSOR_QOS),
        ('camera/camera_info', info, SENSOR_QOS),
    ]
    publishers = {}
    for topic, msg, qos in streams:
        if topic not in publishers:
            publishers[topic] = node.create_publisher(type(msg), topic, qos)

    def publish() -> None:
        stamp = node.get_clock().now().to_msg()
        for topic, msg, _ in streams:
            if hasattr(msg, 'header'):
                msg.header.stamp = stamp
            publishers[topic].publish(msg)

    node.create_timer(0.2, publish)
    return node


class Spinner:
    """Spin an executor in a background thread (the test's thread drives the browser)."""

    def __init__(self, executor) -> None:
        self.executor, self.stop = executor, threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        while not self.stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=10)


def colour_pixels(png: bytes, width_share: float = 0.62) -> dict[str, int]:
    """Pixels of the ball's yellow and the path's blue in the 3D view (the left of the page;
    the control panel, with the camera image, is on the right)."""
    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    view = image[:, :int(image.shape[1] * width_share)].astype(int)
    b, g, r = view[..., 0], view[..., 1], view[..., 2]
    yellow = (r > 170) & (g > 140) & (b < 90) & (abs(r - g) < 90)
    blue = (b > 170) & (r < 90) & (g > 90) & (g < 210)
    return {'yellow': int(yellow.sum()), 'blue': int(blue.sum())}


def write_small_png(png: bytes, path: pathlib.Path, width: int = 960) -> None:
    """The screenshot scaled to ``width`` with a 256-colour palette: small enough for git."""
    import io

    from PIL import Image
    image = Image.open(io.BytesIO(png)).convert('RGB')
    image = image.resize((width, round(image.height * width / image.width)), Image.LANCZOS)
    path.parent.mkdir(exist_ok=True)
    image.quantize(256, dither=Image.Dither.NONE).save(path, optimize=True)
    assert path.stat().st_size < 200_000, path.stat().st_size


@pytest.fixture
def chromium():
    if find_chromium() is None:
        pytest.skip(f'no Chromium: {INSTALL_HINT}')
    with HeadlessChromium(width=1280, height=800, timeout_s=60.0) as browser:
        yield browser


@pytest.mark.system  # a headless Chromium process loads the page
def test_the_page_shows_the_scene_and_its_control_publishes_a_plan_request(
        ros_context, chromium):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from inflarm_bringup.nodes.live_view import LiveView
    from inflarm_msgs_json import PlanRequest, decode
    from inflarm_msgs_json.ros.qos import RELIABLE_QOS
    from ros_harness import wait_until

    view = LiveView(context=ros_context, parameter_overrides=[
        Parameter('port', value=0), Parameter('controls_enabled', value=True)])
    feeder = demo_scene_publisher(ros_context)
    requests = []
    feeder.create_subscription(String, 'plan_request', lambda m: requests.append(m.data),
                               RELIABLE_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(view)
    executor.add_node(feeder)
    spinner = Spinner(executor)
    try:
        # The view has the data before the page loads: a late page gets the whole scene.
        assert wait_until(lambda: view.ball is not None and view.path is not None
                          and view.robot is not None and view.image is not None, 30.0), \
            view.status_lines()
        chromium.navigate(view.url)
        assert wait_until(lambda: len(view.server.get_clients()) == 1, 60.0), \
            f'no websocket client connected; console: {chromium.console}'
        # Close the "software WebGL" notice: it would cover the scene.
        chromium.wait_for('document.body.innerText.includes("inflarm live view")', 60.0)
        chromium.evaluate('document.querySelectorAll(".mantine-Notification-closeButton")'
                          '.forEach(b => b.click())')
        shots = []

        def scene_drawn() -> bool:
            shots.append(chromium.screenshot())
            pixels = colour_pixels(shots[-1])
            return pixels['yellow'] >= 30 and pixels['blue'] >= 30

        drawn = wait_until(scene_drawn, SCENE_TIMEOUT_S)
        (pathlib.Path(os.environ.get('PYTEST_TMP', '/tmp')) / 'live_view_test.png').write_bytes(
            shots[-1])
        assert drawn, f'the scene is not drawn: {colour_pixels(shots[-1])}'
        if os.environ.get('INFLARM_WRITE_DOC_SCREENSHOT'):
            write_small_png(shots[-1], DOC_SCREENSHOT)
        assert 'Controls are enabled' in chromium.evaluate('document.body.innerText')
        # Served offline: the page asked nothing of any other host.
        foreign = [u for u in chromium.requests
                   if not u.startswith((view.url, 'data:', 'blob:'))]
        assert not foreign, foreign

        chromium.click_button('Plan path to goal')
        assert wait_until(lambda: requests, 30.0), 'no plan_request arrived'
        request = decode(requests[-1], expected=PlanRequest)
        assert request.frame_id == 'sra_mount'
        np.testing.assert_allclose(request.goal, GOAL)
        np.testing.assert_allclose(request.start, feeder.ball)
        assert wait_until(lambda: 'Plan requested' in chromium.evaluate(
            'document.body.innerText'), 30.0)
    finally:
        spinner.close()
        executor.shutdown()
        for node in (feeder, view):
            node.destroy_node()


def test_controls_are_disabled_by_default_and_a_bad_urdf_is_shown_not_fatal(ros_context,
                                                                            domain_id):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from inflarm_bringup.nodes.live_view import LiveView
    from inflarm_msgs_json.ros.qos import LATCHED_QOS
    from ros_harness import spin_until

    view = LiveView(context=ros_context, parameter_overrides=[Parameter('port', value=0)])
    # Another participant: one may not hold a topic under two types.
    other_context = rclpy.Context()
    rclpy.init(context=other_context, domain_id=domain_id)
    other = Node('bad_publisher', context=other_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(view)
    other_executor = SingleThreadedExecutor(context=other_context)
    other_executor.add_node(other)
    try:
        assert view.params['host'] == '127.0.0.1'
        assert view.params['controls_enabled'] is False
        assert view.scene.goal_button.disabled and view.scene.vent_button.disabled
        assert not view.publishers or all(
            p.topic_name not in ('/plan_request', '/control_task', '/tip_target')
            for p in view.publishers)
        other.create_publisher(String, 'robot_description', LATCHED_QOS).publish(
            String(data='<robot name="broken"><link'))
        assert spin_until(executor, lambda: view.urdf is not None, 15.0)  # latched: no spin
        executor.spin_once(timeout_sec=0.2)
        assert any('robot_description: **robot_description: not XML' in line
                   for line in view.status_lines()), view.status_lines()
        # A topic of another type: named on the page, the rest goes on.
        from geometry_msgs.msg import PointStamped
        other.create_publisher(PointStamped, 'obstacles', LATCHED_QOS)
        assert spin_until(executor, lambda: 'obstacles' in view.type_problems, 15.0)
        assert 'published as geometry_msgs/msg/PointStamped' in view.type_problems['obstacles']
        assert view.server.get_port() > 0  # still serving
    finally:
        executor.shutdown()
        other_executor.shutdown()
        for node in (other, view):
            node.destroy_node()
        rclpy.try_shutdown(context=other_context)


if __name__ == '__main__':
    sys.exit(pytest.main([__file__, '-v']))
