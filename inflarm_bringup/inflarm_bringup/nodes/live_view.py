"""A live view of both arms in the browser, with controls: viser on ``http://<host>:<port>``.

The scene (`inflarm_bringup.live_scene`): the inflatable arm from ``robot_description``, posed
by ``estimated_joint_states`` (the deflected arm, each inflated link coloured by its wrinkling
margin from ``link_status``), the rigid arm at the same motor angles as a translucent ghost,
the true and estimated tips, the estimated load as an arrow at the tip (``estimated_wrench`` is
in the ``tip`` frame: turned into ``base_link`` with the pose of the same estimate), the
commanded tip trajectory; the soft arm's actuator axes at the measured end point, the yellow
ball, the true end point, the planned path, the obstacles and their alert regions; the camera
image (the tracker's debug image when it publishes one, else the raw image with the measured
ball drawn on it); plots of the last ``history_s`` seconds. Frames as in RViz
(`inflarm_bringup.systems.STATIC_FRAMES`).

Callbacks only store the latest message; a timer at ``rate_hz`` redraws what changed, the camera
panel at ``camera_rate_hz``, so a slow browser never slows a publisher (the sensor topics are
best effort, the rest keep their last few). Latched topics (robot description, path, obstacles)
reach the view whenever it starts. A URDF that does not parse, a message that does not decode,
a topic published with another type: a warning naming it, shown on the page too, and the view
keeps drawing the rest.

Controls (``controls_enabled``; off by default, since they move an arm, and the page says so):
the soft arm's goal gizmo publishes a ``plan_request`` from the measured end when dropped, as does
"Plan path to goal"; "Start pid_ilc trial to goal" publishes a ``control_task``; "Vent" calls
``pressure_controller/vent``; the tip target gizmo (or "Send tip target") publishes
``tip_target``.

Subscribes:
    robot_description (std_msgs/String, LATCHED_QOS): the arm's URDF.
    estimated_joint_states (sensor_msgs/JointState, JOINT_STATE_QOS), estimated_wrench
        (geometry_msgs/WrenchStamped, RELIABLE_QOS), estimated_tip (geometry_msgs/PointStamped,
        RELIABLE_QOS), link_status (std_msgs/String: LinkStatus JSON, RELIABLE_QOS),
        tip_trajectory (nav_msgs/Path, RELIABLE_QOS), tip_position_truth (PointStamped,
        SENSOR_QOS): the inflatable arm, ``base_link``.
    ball_position, end_point_truth (geometry_msgs/PointStamped, SENSOR_QOS), planned_path
        (nav_msgs/Path, LATCHED_QOS), obstacles (std_msgs/String: ObstacleSet JSON, LATCHED_QOS),
        chamber_pressures (std_msgs/String: ChamberPressures JSON, RELIABLE_QOS): the soft arm,
        ``sra_mount``.
    camera/image_raw, ball_tracker/debug_image (sensor_msgs/Image, SENSOR_QOS),
        camera/camera_info (sensor_msgs/CameraInfo, SENSOR_QOS).
Publishes (only with ``controls_enabled``):
    plan_request (std_msgs/String: PlanRequest JSON, RELIABLE_QOS), control_task (std_msgs/
    String: ControlTask JSON, RELIABLE_QOS), tip_target (geometry_msgs/PointStamped,
    COMMAND_QOS).
Calls:
    pressure_controller/vent (std_srvs/Trigger).
Parameters (read-only):
    host, port (0: any free port), rate_hz, camera_rate_hz, history_s, controls_enabled,
    plan.resolution_m, camera.translation_m, camera.rotation_xyzw, ball_diameter_m.
"""

import math
import time

from geometry_msgs.msg import PointStamped, WrenchStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_bringup.live_scene import (
    Controls,
    LiveScene,
    RobotModel,
    mark_ball,
    path_distance,
    start_server,
)
from inflarm_model.camera import PinholeCamera, RigidTransform
from inflarm_model.soft_arm import CHAMBERS
from inflarm_msgs_json import (
    ChamberPressures,
    ControlTask,
    LinkStatus,
    ObstacleSet,
    PlanRequest,
)
from inflarm_msgs_json.ros.conversions import from_string_msg, to_string_msg
from inflarm_msgs_json.ros.image import image_to_numpy
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import (
    COMMAND_QOS,
    JOINT_STATE_QOS,
    LATCHED_QOS,
    RELIABLE_QOS,
    SENSOR_QOS,
    publisher_events,
)
from inflarm_msgs_json.ros.spin import spin_node
from inflarm_planning.scenario import GOAL

ARM_FRAME, SRA_FRAME = 'base_link', 'sra_mount'
TYPE_CHECK_PERIOD_S = 2.0
STALE_S = 2.0  # a plot sample older than this is not plotted again
CAMERA_WIDTH_PX = 480  # the camera panel's image width

PARAMETERS = (
    Parameter('host', '127.0.0.1', "address to serve on: localhost unless set (e.g. '0.0.0.0' "
              'for the lab network), since the controls can move an arm', read_only=True),
    Parameter('port', 8080, 'HTTP and websocket port; 0 for any free one', range=(0, 65535),
              read_only=True),
    Parameter('rate_hz', 20.0, 'redraw rate of the scene [Hz]', range=(0.5, 60.0),
              read_only=True),
    Parameter('camera_rate_hz', 2.0, 'update rate of the camera panel [Hz]', range=(0.1, 30.0),
              read_only=True),
    Parameter('plot_rate_hz', 4.0, 'sample and redraw rate of the plots [Hz]',
              range=(0.1, 30.0), read_only=True),
    Parameter('history_s', 30.0, 'time span of the plots [s]', range=(1.0, 600.0),
              read_only=True),
    Parameter('controls_enabled', False,
              'let the page command the system (plan_request, control_task, vent, tip_target); '
              'off by default: on hardware they move an arm', read_only=True),
    Parameter('plan.resolution_m', 0.005, 'grid spacing of the plan requests [m]',
              range=(0.001, 0.05), read_only=True),
    Parameter('camera.translation_m', [0.0, -1.1, 0.78],
              'camera optical frame origin in sra_mount [m] (to draw the ball on raw images)',
              read_only=True),
    Parameter('camera.rotation_xyzw', [0.0, 0.70710678, 0.70710678, 0.0],
              'camera -> sra_mount rotation, quaternion x, y, z, w', read_only=True),
    Parameter('ball_diameter_m', 0.04, 'diameter of the yellow ball [m]', range=(0.001, 1.0),
              read_only=True),
)

# What each subscribed topic must carry (a publisher of another type never connects).
TOPIC_TYPES = {
    'robot_description': 'std_msgs/msg/String', 'estimated_joint_states':
    'sensor_msgs/msg/JointState', 'estimated_wrench': 'geometry_msgs/msg/WrenchStamped',
    'estimated_tip': 'geometry_msgs/msg/PointStamped', 'link_status': 'std_msgs/msg/String',
    'tip_trajectory': 'nav_msgs/msg/Path', 'tip_position_truth': 'geometry_msgs/msg/PointStamped',
    'ball_position': 'geometry_msgs/msg/PointStamped',
    'end_point_truth': 'geometry_msgs/msg/PointStamped', 'planned_path': 'nav_msgs/msg/Path',
    'obstacles': 'std_msgs/msg/String', 'chamber_pressures': 'std_msgs/msg/String',
    'camera/image_raw': 'sensor_msgs/msg/Image', 'ball_tracker/debug_image':
    'sensor_msgs/msg/Image', 'camera/camera_info': 'sensor_msgs/msg/CameraInfo',
}


def _point(msg: PointStamped, frame: str, topic: str) -> np.ndarray:
    if msg.header.frame_id and msg.header.frame_id != frame:
        raise InputError('frame', f"{topic}: expected frame '{frame}', got "
                         f"'{msg.header.frame_id}'")
    p = np.array([msg.point.x, msg.point.y, msg.point.z])
    if not np.isfinite(p).all():
        raise InputError('non-finite', f'{topic}: expected finite coordinates, got {p}')
    return p


def _path(msg: Path, frame: str, topic: str) -> np.ndarray:
    if msg.header.frame_id and msg.header.frame_id != frame:
        raise InputError('frame', f"{topic}: expected frame '{frame}', got "
                         f"'{msg.header.frame_id}'")
    points = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                       for p in msg.poses]).reshape(-1, 3)
    if not np.isfinite(points).all():
        raise InputError('non-finite', f'{topic}: expected finite positions')
    return points


class LiveView(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('live_view', **kwargs)
        p = self.params = declare_parameters(self, PARAMETERS)
        self.camera2mount = RigidTransform.from_quaternion(p['camera.translation_m'],
                                                           p['camera.rotation_xyzw'])
        # The latest of everything (callbacks only store; the timers draw).
        self.urdf: str | None = None
        self.robot: RobotModel | None = None
        self.urdf_error = ''
        self.joint_positions: dict[str, float] | None = None
        self.poses_by_stamp: dict[tuple[int, int], dict[str, float]] = {}
        self.wrench: tuple[np.ndarray, dict[str, float]] | None = None  # force, its pose
        self.link_status: dict[str, LinkStatus] = {}
        self.link_status_time = -math.inf
        self.tip_estimate = self.tip_truth = self.trajectory = None
        self.ball = self.end_truth = self.path = None
        self.ball_time = self.end_time = self.wrench_time = self.pressure_time = -math.inf
        self.obstacles: ObstacleSet | None = None
        self.pressures: dict[str, float] | None = None
        self.image: Image | None = None
        self.debug_image: Image | None = None
        self.camera: PinholeCamera | None = None
        self.image_shown: Image | None = None
        self.type_problems: dict[str, str] = {}

        self.server = start_server(p['host'], p['port'])  # PortInUseError (ValueError): exit 1
        self.url = f"http://{p['host']}:{self.server.get_port()}"
        if p['controls_enabled']:
            self.plan_pub = self.create_publisher(String, 'plan_request', RELIABLE_QOS,
                                                  event_callbacks=publisher_events(
                                                      self, 'plan_request'))
            self.task_pub = self.create_publisher(String, 'control_task', RELIABLE_QOS,
                                                  event_callbacks=publisher_events(
                                                      self, 'control_task'))
            self.tip_pub = self.create_publisher(PointStamped, 'tip_target', COMMAND_QOS,
                                                 event_callbacks=publisher_events(
                                                     self, 'tip_target'))
            self.vent_client = self.create_client(Trigger, 'pressure_controller/vent')
        self.trial_id = 0
        self.scene = LiveScene(self.server, Controls(self.plan_to, self.start_trial, self.vent,
                                                     self.send_tip_target),
                               p['controls_enabled'], GOAL, (0.8, 0.3, 0.1), p['history_s'])

        sub = self.create_guarded_subscription
        sub(String, 'robot_description', self.on_robot_description, LATCHED_QOS)
        sub(JointState, 'estimated_joint_states', self.on_joint_states, JOINT_STATE_QOS)
        sub(WrenchStamped, 'estimated_wrench', self.on_wrench, RELIABLE_QOS)
        sub(PointStamped, 'estimated_tip', self.on_tip_estimate, RELIABLE_QOS)
        sub(String, 'link_status', self.on_link_status, RELIABLE_QOS)
        sub(Path, 'tip_trajectory', self.on_trajectory, RELIABLE_QOS)
        sub(PointStamped, 'tip_position_truth', self.on_tip_truth, SENSOR_QOS)
        sub(PointStamped, 'ball_position', self.on_ball, SENSOR_QOS)
        sub(PointStamped, 'end_point_truth', self.on_end_truth, SENSOR_QOS)
        sub(Path, 'planned_path', self.on_path, LATCHED_QOS)
        sub(String, 'obstacles', self.on_obstacles, LATCHED_QOS)
        sub(String, 'chamber_pressures', self.on_pressures, RELIABLE_QOS)
        sub(Image, 'camera/image_raw', self.on_image, SENSOR_QOS)
        sub(Image, 'ball_tracker/debug_image', self.on_debug_image, SENSOR_QOS)
        sub(CameraInfo, 'camera/camera_info', self.on_camera_info, SENSOR_QOS)
        self.create_guarded_timer(1.0 / p['rate_hz'], self.draw)
        self.create_guarded_timer(1.0 / p['camera_rate_hz'], self.draw_camera)
        self.create_guarded_timer(1.0 / p['plot_rate_hz'], self.draw_plots)
        self.create_guarded_timer(TYPE_CHECK_PERIOD_S, self.check_topic_types)
        self.get_logger().info(
            f"ready: serving the live view on {self.url} (controls "
            f"{'enabled' if p['controls_enabled'] else 'disabled'})")

    # --- callbacks: store the latest ----------------------------------------------------------

    def on_robot_description(self, msg: String) -> None:
        self.urdf = msg.data
        try:
            robot = RobotModel(msg.data)
        except ValueError as error:
            self.urdf_error = str(error)
            raise InputError('robot_description', f'{error}; still drawing the last arm '
                             'that parsed' if self.robot else str(error)) from None
        self.urdf_error = ''
        self.robot = robot
        self.scene.set_robot(robot)

    def on_joint_states(self, msg: JointState) -> None:
        if len(msg.name) != len(msg.position):
            raise InputError('joint_states', f'estimated_joint_states: {len(msg.name)} names '
                             f'but {len(msg.position)} positions')
        positions = dict(zip(msg.name, (float(v) for v in msg.position), strict=True))
        if not all(math.isfinite(v) for v in positions.values()):
            raise InputError('non-finite', f'estimated_joint_states: {positions}')
        self.joint_positions = positions
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        self.poses_by_stamp[stamp] = positions
        while len(self.poses_by_stamp) > 50:
            self.poses_by_stamp.pop(next(iter(self.poses_by_stamp)))

    def on_wrench(self, msg: WrenchStamped) -> None:
        f = msg.wrench.force
        force = np.array([f.x, f.y, f.z])
        if not np.isfinite(force).all():
            raise InputError('non-finite', f'estimated_wrench: {force}')
        # The wrench is in the tip frame of the pose estimated with it (same stamp).
        pose = self.poses_by_stamp.get((msg.header.stamp.sec, msg.header.stamp.nanosec),
                                       self.joint_positions)
        if pose is not None:
            self.wrench = (force, pose)
            self.wrench_time = time.monotonic()

    def on_tip_estimate(self, msg: PointStamped) -> None:
        self.tip_estimate = _point(msg, ARM_FRAME, 'estimated_tip')

    def on_tip_truth(self, msg: PointStamped) -> None:
        self.tip_truth = _point(msg, ARM_FRAME, 'tip_position_truth')

    def on_link_status(self, msg: String) -> None:
        status = from_string_msg(msg, LinkStatus)
        self.link_status[status.link] = status
        self.link_status_time = time.monotonic()

    def on_trajectory(self, msg: Path) -> None:
        self.trajectory = _path(msg, ARM_FRAME, 'tip_trajectory')

    def on_ball(self, msg: PointStamped) -> None:
        self.ball = _point(msg, SRA_FRAME, 'ball_position')
        self.ball_time = time.monotonic()

    def on_end_truth(self, msg: PointStamped) -> None:
        self.end_truth = _point(msg, SRA_FRAME, 'end_point_truth')
        self.end_time = time.monotonic()

    def on_path(self, msg: Path) -> None:
        self.path = _path(msg, SRA_FRAME, 'planned_path')

    def on_obstacles(self, msg: String) -> None:
        obstacles = from_string_msg(msg, ObstacleSet)
        if obstacles.frame_id != SRA_FRAME:
            raise InputError('frame', f"obstacles: expected frame '{SRA_FRAME}', got "
                             f"'{obstacles.frame_id}'")
        self.obstacles = obstacles

    def on_pressures(self, msg: String) -> None:
        self.pressures = from_string_msg(msg, ChamberPressures).as_dict()
        self.pressure_time = time.monotonic()

    def on_image(self, msg: Image) -> None:
        self.image = msg

    def on_debug_image(self, msg: Image) -> None:
        self.debug_image = msg

    def on_camera_info(self, msg: CameraInfo) -> None:
        if self.camera is None:
            self.camera = PinholeCamera.from_camera_info(msg.width, msg.height, msg.k, msg.d,
                                                         msg.distortion_model)

    # --- timers: draw -------------------------------------------------------------------------

    def draw(self) -> None:
        margins = {name: (s.margin, s.wrinkling_moment) for name, s in self.link_status.items()}
        self.scene.draw_inflatable_arm(self.joint_positions, margins, self.tip_truth,
                                       self.tip_estimate, self.trajectory)
        if self.wrench is not None:
            force, pose = self.wrench
            self.scene.draw_load(pose, force)  # at the tip of the pose it was estimated in
        self.scene.draw_soft_arm(self.ball, self.end_truth, self.path, self.obstacles)
        self.scene.set_status(self.status_lines())

    def status_lines(self) -> list[str]:
        lines = []
        if self.urdf_error:
            lines.append(f'robot_description: **{self.urdf_error}**')
        elif self.robot is None:
            lines.append('robot_description: waiting')
        if self.joint_positions is None:
            lines.append('estimated_joint_states: waiting')
        if self.ball is None:
            lines.append('ball_position: waiting')
        if self.path is None:
            lines.append('planned_path: waiting')
        for topic, problem in sorted(self.type_problems.items()):
            lines.append(f'{topic}: **{problem}**')
        return lines or ['receiving every topic']

    def draw_camera(self) -> None:
        msg = self.debug_image if self.debug_image is not None else self.image
        if msg is None or msg is self.image_shown:
            return
        self.image_shown = msg
        import cv2

        pixels = image_to_numpy(msg)
        if msg.encoding == 'bgr8':
            pixels = cv2.cvtColor(pixels, cv2.COLOR_BGR2RGB)
        elif msg.encoding in ('mono8', '8UC1'):
            pixels = cv2.cvtColor(pixels, cv2.COLOR_GRAY2RGB)
        elif msg.encoding != 'rgb8':
            raise InputError('encoding', f'camera image: cannot show encoding {msg.encoding!r}')
        if msg is self.image and self.camera is not None and self.ball is not None \
                and time.monotonic() - self.ball_time < STALE_S:
            pixels = mark_ball(pixels, self.camera, self.camera2mount, self.ball,
                               self.params['ball_diameter_m'])
        height = max(1, round(pixels.shape[0] * CAMERA_WIDTH_PX / pixels.shape[1]))
        self.scene.set_camera_image(cv2.resize(pixels, (CAMERA_WIDTH_PX, height),
                                               interpolation=cv2.INTER_AREA))

    def draw_plots(self) -> None:
        now = time.monotonic()
        samples = {}
        if self.path is not None:
            def error(point, at):
                if point is None or now - at > STALE_S:
                    return math.nan
                return 1e3 * path_distance(point, self.path)
            truth, camera = error(self.end_truth, self.end_time), error(self.ball, self.ball_time)
            if math.isfinite(truth) or math.isfinite(camera):
                samples['tracking'] = (truth, camera)
        if self.pressures is not None and now - self.pressure_time < STALE_S:
            samples['pressures'] = tuple(self.pressures.get(c, math.nan) / 1e3 for c in CHAMBERS)
        if self.wrench is not None and now - self.wrench_time < STALE_S:
            samples['load'] = (float(np.linalg.norm(self.wrench[0])),)
        if self.link_status and now - self.link_status_time < STALE_S:
            samples['margins'] = tuple(
                self.link_status[k].margin if k in self.link_status else math.nan
                for k in ('link_1', 'link_2'))
        self.scene.sample_plots(now, samples)
        self.scene.draw_plots(now)

    def check_topic_types(self) -> None:
        """Name a topic whose publishers carry another type (DDS never connects them)."""
        problems = {}
        for topic, expected in TOPIC_TYPES.items():
            name = self.resolve_topic_name(topic)
            others = sorted({i.topic_type for i in self.get_publishers_info_by_topic(name)}
                            - {expected})
            if others:
                problems[topic] = (f'published as {", ".join(others)}, expected {expected}: '
                                   'not received')
        for topic in sorted(set(problems) - set(self.type_problems)):
            self.get_logger().warning(f"topic '{topic}' {problems[topic]}")
        self.type_problems = problems

    # --- controls (from viser's threads) ------------------------------------------------------

    def plan_to(self, goal: np.ndarray) -> str:
        if self.ball is None:
            return 'No plan requested: no ball_position yet (the start of the path).'
        request = PlanRequest(SRA_FRAME, tuple(float(v) for v in self.ball),
                              tuple(float(v) for v in goal), self.params['plan.resolution_m'])
        self.plan_pub.publish(to_string_msg(request))
        self.get_logger().info(f'plan_request to {np.round(goal * 1e3).tolist()} mm')
        return f'Plan requested to {np.round(goal * 1e3).astype(int).tolist()} mm.'

    def start_trial(self, goal: np.ndarray) -> str:
        task = ControlTask(SRA_FRAME, tuple(float(v) for v in goal), 'pid_ilc', self.trial_id)
        self.trial_id += 1
        self.task_pub.publish(to_string_msg(task))
        self.get_logger().info(f'control_task: pid_ilc trial {task.trial_id} to '
                               f'{np.round(goal * 1e3).tolist()} mm')
        return f'pid_ilc trial {task.trial_id} to {np.round(goal * 1e3).astype(int).tolist()} mm.'

    def vent(self) -> str:
        if not self.vent_client.service_is_ready():
            return 'Not vented: pressure_controller/vent is not available.'
        self.vent_client.call_async(Trigger.Request())
        self.get_logger().info('vent requested')
        return 'Vent requested.'

    def send_tip_target(self, target: np.ndarray) -> str:
        msg = PointStamped()
        msg.header.frame_id = ARM_FRAME
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in target)
        self.tip_pub.publish(msg)
        self.get_logger().info(f'tip_target {np.round(target * 1e3).tolist()} mm')
        return f'Tip target {np.round(target * 1e3).astype(int).tolist()} mm sent.'

    def destroy_node(self) -> None:
        self.server.stop()
        super().destroy_node()


def main(args=None) -> None:
    spin_node(LiveView, args)


if __name__ == '__main__':
    main()
