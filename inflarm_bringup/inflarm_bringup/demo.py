"""``inflarm-demo``: the whole simulated system, end to end, in under three minutes.

    inflarm-demo [--out DIR] [--backend sim|sim_mcu] [--timeout S] [--seed N] [--view]
                 [--bag-storage sqlite3|mcap]

Starts the ``sim`` system (``inflarm_bringup.systems``: both simulated arms, the camera, the
tracker, the planner, the estimator and both controllers) as processes over DDS, records a bag,
and runs the two missions side by side:

- the soft arm (paper 001, sections 3.2 and 4.3): an experiential knowledge database of the
  scenario's region (1 cm grid, 30 learning trials a point, on the simulated plant) is built
  first; seeded by it, a PID + ILC trial brings the camera-tracked end near the paper's start
  (0, 130, 710) mm; the obstacle of Fig 10 (x 35-140, y 40-140, z 650-780 mm) is published with
  its alert region; a short planned path settles the end on the start (switching the bellows to
  their antagonistic preload moves it), and once it has stayed there a plan from where it rests
  to the goal (130, 0, 730) mm is requested; the pressure controller follows each planned path
  (``inflarm_control.path_following``: a reference moving along it that waits for the arm, the
  knowledge's holding pressures as feedforward, a PI per axis, the bellows pairs driven
  antagonistically).
  Measured on the simulator's true end point: the distance to the planned path (the paper:
  under 5 mm), the clearance of the end and of the actuators' axes to the obstacle;
- the inflatable arm (paper 000, section 2.4 and Figs 10-11): under a tip load it is not told,
  the tip follows a straight path there and back by elastostatic IK on the estimated load.
  Measured: the estimated load against the true one, the true tip's distance to the path along
  the way, and each link's bending moment against its wrinkling moment.

It prints its progress, then a summary table, and writes to DIR (default ``out/demo``):
``summary.md``, ``soft_arm_path.png`` (Fig 10 of 001: planned and driven path, obstacle, alert
region), ``soft_arm_clearance.png`` (Fig 12: distance to the obstacle surface against time),
``inflatable_arm_tip.png`` (the tip's path and its error), ``inflatable_arm_motors.png``
(Fig 11 of 000: motor angles with and without deflection compensation), ``nodes.log`` (every
node's output) and ``bag/`` (rosbag2). Exit code 0 when every target of the table is met.

``--seed`` seeds the simulators (default 0; -1 for a random seed): their sensor noise and the
simulated camera's background, whose texture biases the ball's measured depth by up to a few
millimetres where the ball's outline crosses it, so a seed gives the same scene every run.

``--bag-storage mcap`` records the bag as MCAP, which Foxglove opens directly.

``--view`` also starts the live view (``live_view``, ``http://127.0.0.1:8080``) to watch the
missions in a browser; its controls are live, so steering the arms there can miss the targets.
"""

import argparse
from dataclasses import dataclass, field, replace
import math
import os
import pathlib
import shutil
import signal
import sys
import tempfile
import time

import numpy as np

from inflarm_bringup.bag_regression import NODES as REPLAYABLE_NODES
from inflarm_bringup.processes import NodeProcess, ProcessGroup, ros_environment
from inflarm_bringup.systems import (
    VIEW_HOST,
    VIEW_PORT,
    Backend,
    live_view_node,
    live_view_url,
    system_nodes,
)
from inflarm_control.path_following import project_on_polyline

SOFT_START = (0.0, 0.130, 0.710)  # the paper's start and goal [m], sra_mount
SOFT_GOAL = (0.130, 0.0, 0.730)
TASK_RETRY_S = 2.0  # the task to the start is sent again after this long without a command
NEAR_START_M = 0.015  # the trial to the start hands over to path following this close
AT_START_M = 0.004  # the path to the goal starts once the measured end is this close,
SETTLE_S = 2.0  # on average over this long (its depth is noisy), and none of it twice as far
SETTLE_DRIFT_M = 0.001  # and at rest: the means of its halves this close (the PEA creeps)
ARRIVAL_TOLERANCE_M = 0.004  # at the goal when the measured end is this close
TRACKING_TARGET_M = 0.005  # the paper: "an error smaller than 5 mm"
ARM_LOAD_N = (0.0, 10.0, -15.0)  # the sample load of section 4 of 000 [N], base frame
ARM_PATH_END = (0.80, 0.30, 0.10)  # the other end of the tip's path [m], base frame
ARM_TRAVERSE_S = 6.0
ARM_LEAD_S = 0.5  # a path is due this long after it is sent
ARM_TIP_TARGET_M = 0.002
ARM_LOAD_TARGET = 0.05  # relative
SIMULATORS = ('arm_sim', 'sra_sim', 'sim_mcu')  # the nodes --seed seeds
# Knowledge points around the scenario (x, y -10..140 mm, z 700..740 mm): 1,280 of the paper's
# 1 cm grid, a few seconds to learn.
KNOWLEDGE_ORIGIN, KNOWLEDGE_SHAPE = (-0.01, -0.01, 0.70), (16, 16, 5)
RECORDED_TOPICS = (
    'ball_position', 'end_point_truth', 'chamber_pressure_command', 'chamber_pressures',
    'planned_path', 'planning_markers', 'obstacles', 'plan_request', 'control_task',
    'trial_report', 'joint_states', 'estimated_joint_states', 'estimated_wrench',
    'tip_position_truth', 'tip_trajectory', 'motor_position_command', 'link_status',
    'robot_description', 'callback_log',
)


@dataclass
class Samples:
    """Time-stamped samples of a 3-vector."""

    times: list[float] = field(default_factory=list)
    values: list[tuple[float, float, float]] = field(default_factory=list)

    def add(self, t: float, value) -> None:
        self.times.append(t)
        self.values.append(tuple(float(v) for v in value))

    def arrays(self, start: float = -math.inf, stop: float = math.inf):
        t, v = np.array(self.times), np.array(self.values).reshape(-1, 3)
        keep = (t >= start) & (t <= stop)
        return t[keep], v[keep]


def mission_node_class():
    """The demo's own node (defined here so that rclpy is imported only when it runs)."""
    from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
    from nav_msgs.msg import Path
    from rclpy.duration import Duration
    from rclpy.node import Node
    from rclpy.time import Time
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    from inflarm_model.kinematics import FlexibleArm
    from inflarm_msgs_json import ControlTask, LinkStatus, ObstacleSet, PlanRequest, decode
    from inflarm_msgs_json.ros.conversions import to_string_msg
    from inflarm_msgs_json.ros.node import GuardedCallbacks
    from inflarm_msgs_json.ros.qos import (
        COMMAND_QOS,
        JOINT_STATE_QOS,
        LATCHED_QOS,
        RELIABLE_QOS,
        SENSOR_QOS,
    )
    from inflarm_planning.scenario import ALERT_MARGIN, OBSTACLE

    def seconds(stamp) -> float:
        return Time.from_msg(stamp).nanoseconds * 1e-9

    class DemoMission(GuardedCallbacks, Node):
        """Sends the two missions' tasks and records what the system does."""

        def __init__(self, **kwargs) -> None:
            super().__init__('demo_mission', **kwargs)
            self.arm = FlexibleArm()
            self.ball = Samples()  # measured (camera) end of the soft arm
            self.soft_truth = Samples()
            self.tip_truth = Samples()
            self.forces = Samples()  # estimated tip force, base frame
            self.poses: dict[int, list[float]] = {}  # estimated joint states by stamp [ns]
            self.wrenches: list = []  # waiting for their pose
            self.link_moments: dict[str, float] = {}
            self.link_pressures: dict[str, float] = {}
            self.wrinkling_moments: dict[str, float] = {}
            self.motors: list[tuple[float, list[float]]] = []
            self.planned: np.ndarray | None = None
            self.plan_stamps: np.ndarray | None = None
            self.arm_paths: list[tuple[np.ndarray, np.ndarray]] = []  # (due times, points)
            self.soft_phase, self.soft_since = 'waiting for the camera', time.monotonic()
            self.arm_phase, self.arm_since = 'waiting for an estimate', time.monotonic()
            self.soft_times: dict[str, float] = {}
            self.pressure_commands = 0  # seen from the controller
            self.arm_traverses = 0
            for topic, kind, callback, qos in (
                    ('ball_position', PointStamped, self.on_ball, SENSOR_QOS),
                    ('end_point_truth', PointStamped, self.on_soft_truth, SENSOR_QOS),
                    ('tip_position_truth', PointStamped, self.on_tip_truth, SENSOR_QOS),
                    ('planned_path', Path, self.on_planned_path, LATCHED_QOS),
                    ('estimated_wrench', WrenchStamped, self.on_wrench, RELIABLE_QOS),
                    ('estimated_joint_states', JointState, self.on_pose, JOINT_STATE_QOS),
                    ('joint_states', JointState, self.on_joint_states, JOINT_STATE_QOS),
                    ('link_status', String, self.on_link_status, RELIABLE_QOS),
                    ('chamber_pressure_command', String, self.on_pressure_command, COMMAND_QOS)):
                self.create_guarded_subscription(kind, topic, callback, qos)
            self.task_pub = self.create_publisher(String, 'control_task', RELIABLE_QOS)
            self.obstacles_pub = self.create_publisher(String, 'obstacles', LATCHED_QOS)
            self.request_pub = self.create_publisher(String, 'plan_request', RELIABLE_QOS)
            self.tip_path_pub = self.create_publisher(Path, 'tip_trajectory', RELIABLE_QOS)
            self.obstacle_set = ObstacleSet('sra_mount', ALERT_MARGIN, (OBSTACLE.to_message(),))
            self.ControlTask, self.PlanRequest = ControlTask, PlanRequest
            self.decode, self.to_string_msg, self.LinkStatus = decode, to_string_msg, LinkStatus
            self.Path, self.PoseStamped, self.Duration = Path, PoseStamped, Duration
            self.seconds = seconds

        # -- what the system says --------------------------------------------------------------

        def now(self) -> float:
            return self.get_clock().now().nanoseconds * 1e-9

        def on_ball(self, msg) -> None:
            self.ball.add(seconds(msg.header.stamp), (msg.point.x, msg.point.y, msg.point.z))

        def on_soft_truth(self, msg) -> None:
            self.soft_truth.add(seconds(msg.header.stamp),
                                (msg.point.x, msg.point.y, msg.point.z))

        def on_tip_truth(self, msg) -> None:
            self.tip_truth.add(seconds(msg.header.stamp),
                               (msg.point.x, msg.point.y, msg.point.z))

        def on_planned_path(self, msg) -> None:
            if msg.poses:
                self.planned = np.array([[p.pose.position.x, p.pose.position.y,
                                          p.pose.position.z] for p in msg.poses])
                self.plan_stamps = np.array([seconds(p.header.stamp) for p in msg.poses])

        def on_pose(self, msg) -> None:
            self.poses[Time.from_msg(msg.header.stamp).nanoseconds] = list(msg.position)
            self.pair_wrenches()

        def on_wrench(self, msg) -> None:
            self.wrenches.append(msg)
            self.pair_wrenches()

        def pair_wrenches(self) -> None:
            """Estimated forces in the base frame: each tip-frame wrench turned by the
            estimated pose of its stamp, as a tf2 lookup would."""
            while self.wrenches:
                stamp = Time.from_msg(self.wrenches[0].header.stamp).nanoseconds
                if stamp not in self.poses:
                    if len(self.wrenches) > 100:
                        self.wrenches.pop(0)
                        continue
                    return
                wrench = self.wrenches.pop(0)
                rotation = self.arm.fk(self.poses.pop(stamp))[:3, :3]
                f = wrench.wrench.force
                self.forces.add(stamp * 1e-9, rotation @ np.array([f.x, f.y, f.z]))

        def on_joint_states(self, msg) -> None:
            names = list(FlexibleArm.MOTOR_JOINT_NAMES)
            if all(n in msg.name for n in names):
                self.motors.append((seconds(msg.header.stamp),
                                    [msg.position[list(msg.name).index(n)] for n in names]))

        def on_pressure_command(self, msg) -> None:
            self.pressure_commands += 1

        def on_link_status(self, msg) -> None:
            status = decode(msg.data, LinkStatus)
            self.link_moments[status.link] = max(self.link_moments.get(status.link, 0.0),
                                                 status.moment)
            self.link_pressures[status.link] = status.pressure
            self.wrinkling_moments[status.link] = status.wrinkling_moment

        # -- the missions ----------------------------------------------------------------------

        def enter(self, arm: str, phase: str) -> None:
            if arm == 'soft':
                self.soft_phase, self.soft_since = phase, time.monotonic()
                self.soft_times[phase] = self.now()
            else:
                self.arm_phase, self.arm_since = phase, time.monotonic()

        def connected(self, *publishers) -> bool:
            """Whether every publisher has found its subscribers (a volatile message sent
            before that is lost)."""
            return all(p.get_subscription_count() > 0 for p in publishers)

        def step_soft(self) -> None:
            latest = self.ball.values[-1] if self.ball.values else None
            first = (self.soft_phase == 'waiting for the camera' and latest is not None
                     and self.connected(self.task_pub, self.obstacles_pub, self.request_pub))
            again = (self.soft_phase == 'moving to the start' and not self.pressure_commands
                     and time.monotonic() - self.soft_since > TASK_RETRY_S)
            if first or again:
                # The paper's way to a new target: a PID + ILC trial seeded by the knowledge
                # database (section 3.2), the obstacle far from this move. Sent again while no
                # command comes: the controller refuses a task before its first ball position.
                self.task_pub.publish(self.to_string_msg(self.ControlTask(
                    'sra_mount', SOFT_START, 'pid_ilc', 0)))
                self.enter('soft', 'moving to the start')
            elif self.soft_phase == 'moving to the start' and np.linalg.norm(
                    np.subtract(latest, SOFT_START)) < NEAR_START_M:
                # Then onto it by path following (its bellows preload: no limit cycle at x = 0),
                # with the obstacle known from here on.
                self.obstacles_pub.publish(self.to_string_msg(self.obstacle_set))
                self.request_plan(latest, SOFT_START)
                self.enter('soft', 'planning onto the start')
            elif self.soft_phase == 'planning onto the start' and self.plan_to(SOFT_START):
                # The settling is timed from here: a first plan can take seconds (its free
                # space is built, its kernel compiled), while the trial still holds the end.
                self.enter('soft', 'settling at the start')
            elif self.soft_phase == 'settling at the start' and self.settled_at(SOFT_START):
                # From where the end rests (the settling window's mean), not from the start
                # itself: it rests up to AT_START_M off, and a path begun there began with
                # that error (up to 4 mm of the paper's 5; the bellows creep added more).
                _, recent = self.ball.arrays(self.now() - SETTLE_S)
                self.request_plan(recent.mean(axis=0), SOFT_GOAL)
                self.enter('soft', 'planning')
            elif self.soft_phase == 'planning' and self.plan_to(SOFT_GOAL):
                self.enter('soft', 'following the path')
            elif self.soft_phase == 'following the path' and np.linalg.norm(
                    np.subtract(latest, SOFT_GOAL)) < ARRIVAL_TOLERANCE_M:
                self.enter('soft', 'at the goal')

        def step_arm(self) -> None:
            # The IK needs estimates too: wait until they have flowed for a while.
            estimating = (len(self.forces.times) > 1
                          and self.forces.times[-1] - self.forces.times[0] > 2.0)
            if self.arm_phase == 'waiting for an estimate' and estimating \
                    and self.tip_truth.values and self.connected(self.tip_path_pub):
                self.arm_start = np.array(self.tip_truth.values[-1])
                self.send_tip_path(self.arm_start, np.array(ARM_PATH_END))
                self.enter('arm', 'traverse 1 of 2')
            elif self.arm_phase.startswith('traverse') and self.now() > (
                    self.arm_paths[-1][0][-1] + 1.0):
                self.arm_traverses += 1
                if self.arm_traverses == 2:
                    self.enter('arm', 'done')
                else:  # back, from where the tip is
                    self.send_tip_path(np.array(self.tip_truth.values[-1]), self.arm_start)
                    self.enter('arm', 'traverse 2 of 2')

        def settled_at(self, point) -> bool:
            """Whether the measured end has rested at ``point`` for the last `SETTLE_S` of
            this phase: its mean within `AT_START_M`, no sample twice as far, and the means of
            the window's halves within `SETTLE_DRIFT_M`. (One sample near it is not enough:
            switching to the path follower's bellows preload first moves the end by up to
            15 mm, and a path begun then starts with that error; nor is a mean alone: an end
            swinging through the point at 7 mm/s passed it, and the path began 11 mm off.)"""
            now = self.now()
            if now - self.soft_times[self.soft_phase] < SETTLE_S:
                return False
            _, recent = self.ball.arrays(now - SETTLE_S)
            if len(recent) < 4:
                return False
            offsets = np.linalg.norm(recent - np.asarray(point), axis=1)
            first, second = np.array_split(recent, 2)
            return bool(np.linalg.norm(recent.mean(axis=0) - point) < AT_START_M
                        and offsets.max() < 2.0 * AT_START_M
                        and np.linalg.norm(second.mean(axis=0) - first.mean(axis=0))
                        < SETTLE_DRIFT_M)

        def request_plan(self, start, goal) -> None:
            self.request_pub.publish(self.to_string_msg(self.PlanRequest(
                'sra_mount', tuple(float(v) for v in start), goal, 0.005)))

        def plan_to(self, goal) -> bool:
            """Whether the latest planned path ends at ``goal``."""
            return self.planned is not None and bool(
                np.linalg.norm(self.planned[-1] - np.asarray(goal)) < 1e-6)

        def send_tip_path(self, start: np.ndarray, end: np.ndarray, samples: int = 60) -> None:
            now = self.get_clock().now() + self.Duration(seconds=ARM_LEAD_S)
            path = self.Path()
            path.header.stamp, path.header.frame_id = now.to_msg(), 'base_link'
            times = np.linspace(0.0, ARM_TRAVERSE_S, samples)
            s = 0.5 - 0.5 * np.cos(np.pi * times / ARM_TRAVERSE_S)  # smooth start and stop
            points = start + s[:, None] * (end - start)
            for t, point in zip(times, points, strict=True):
                pose = self.PoseStamped()
                pose.header.frame_id = 'base_link'
                pose.header.stamp = (now + self.Duration(seconds=float(t))).to_msg()
                pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (
                    float(v) for v in point)
                pose.pose.orientation.w = 1.0
                path.poses.append(pose)
            self.tip_path_pub.publish(path)
            self.arm_paths.append((now.nanoseconds * 1e-9 + times, points))

        def done(self) -> bool:
            return self.soft_phase == 'at the goal' and self.arm_phase == 'done'

    return DemoMission


# -- measurements -----------------------------------------------------------------------------

@dataclass
class Figures:
    """What the summary reports (SI units)."""

    soft_error_max: float = math.nan
    soft_error_rms: float = math.nan
    soft_clearance: float = math.nan  # end to the obstacle surface
    soft_axes_clearance: float = math.nan  # PEA axes to the obstacle
    soft_contact: bool = True
    soft_path_time: float = math.nan
    arm_load: tuple = (math.nan,) * 3
    arm_load_error: float = math.nan  # relative
    arm_tip_error_max: float = math.nan
    arm_tip_error_rms: float = math.nan
    link_rows: list = field(default_factory=list)  # (link, moment, Mw, pressure, required)


def tip_off_path(mission, due: np.ndarray, points: np.ndarray, margin_s: float):
    """Times and distances of the true tip to one sent tip path (the straight line, not the
    point due at that time: a late command shifts the tip along the line, which is no error of
    the deflection compensation), from ``margin_s`` before the path is due to as long after."""
    t, tips = mission.tip_truth.arrays(due[0] - margin_s, due[-1] + margin_s)
    return t, project_on_polyline(tips, points)[0]


def measure(mission) -> Figures:
    from inflarm_model.link import min_pressure_for_moment
    from inflarm_planning.collision import arm_collides, box_array
    from inflarm_planning.plan_figures import axes_clearance, end_clearance

    figures = Figures()
    times = mission.soft_times
    if mission.planned is not None and 'following the path' in times:
        stop = times.get('at the goal', mission.now())
        _, driven = mission.soft_truth.arrays(times['following the path'], stop)
        if len(driven):
            errors = project_on_polyline(driven, mission.planned)[0]
            figures.soft_error_max = float(errors.max())
            figures.soft_error_rms = float(np.sqrt(np.mean(errors**2)))
            figures.soft_clearance = float(end_clearance(driven).min())
            figures.soft_axes_clearance = axes_clearance(driven)
            figures.soft_contact = bool(arm_collides(driven, box_array(
                [mission.obstacle_set.obstacles[0]])).any())
            figures.soft_path_time = stop - times['following the path']
    if mission.arm_paths:
        first, last = mission.arm_paths[0][0][0], mission.arm_paths[-1][0][-1]
        _, forces = mission.forces.arrays(first, last)
        if len(forces):
            mean = forces.mean(axis=0)
            figures.arm_load = tuple(mean)
            figures.arm_load_error = float(np.linalg.norm(mean - ARM_LOAD_N)
                                           / np.linalg.norm(ARM_LOAD_N))
        errors = np.concatenate([tip_off_path(mission, due, points, 0.0)[1]
                                 for due, points in mission.arm_paths])
        if errors.size:
            figures.arm_tip_error_max = float(errors.max())
            figures.arm_tip_error_rms = float(np.sqrt(np.mean(errors**2)))
    for link in sorted(mission.link_moments):
        moment = mission.link_moments[link]
        figures.link_rows.append((link, moment, mission.wrinkling_moments[link],
                                  mission.link_pressures[link],
                                  float(min_pressure_for_moment(moment, 0.055))))
    return figures


def targets_met(f: Figures) -> bool:
    return (f.soft_error_max < TRACKING_TARGET_M and not f.soft_contact
            and f.arm_load_error <= ARM_LOAD_TARGET and f.arm_tip_error_max <= ARM_TIP_TARGET_M)


def summary_table(f: Figures) -> str:
    def mm(v: float) -> str:
        return f'{v * 1000:.2f} mm'

    def yes(ok: bool) -> str:
        return 'yes' if ok else '**no**'

    rows = [
        ('soft arm', 'tracking error, max (true end to the planned path)',
         mm(f.soft_error_max), '< 5 mm (the paper)', yes(f.soft_error_max < TRACKING_TARGET_M)),
        ('soft arm', 'tracking error, RMS', mm(f.soft_error_rms), '', ''),
        ('soft arm', 'clearance of the end to the obstacle', mm(f.soft_clearance),
         f'alert region {mm(0.03)}', ''),
        ('soft arm', "clearance of the actuators' axes", mm(f.soft_axes_clearance), '> 0', ''),
        ('soft arm', 'contact with the obstacle', 'yes' if f.soft_contact else 'none', 'none',
         yes(not f.soft_contact)),
        ('soft arm', 'time to follow the path', f'{f.soft_path_time:.1f} s', '', ''),
        ('inflatable arm', 'estimated load (mean, base frame)',
         '(' + ', '.join(f'{v:.2f}' for v in f.arm_load) + ') N',
         '(' + ', '.join(f'{v:.1f}' for v in ARM_LOAD_N) + ') N, unknown to it', ''),
        ('inflatable arm', 'load error', f'{f.arm_load_error * 100:.2f} %', '<= 5 %',
         yes(f.arm_load_error <= ARM_LOAD_TARGET)),
        ('inflatable arm', 'true tip off the path, max', mm(f.arm_tip_error_max), '<= 2 mm',
         yes(f.arm_tip_error_max <= ARM_TIP_TARGET_M)),
        ('inflatable arm', 'true tip off the path, RMS', mm(f.arm_tip_error_rms), '', ''),
    ]
    for link, moment, mw, pressure, required in f.link_rows:
        rows.append(('inflatable arm', f'{link}: largest moment / Mw at {pressure / 1e3:.0f} kPa',
                     f'{moment:.2f} / {mw:.2f} N m (margin {mw - moment:.2f})',
                     f'needs >= {required / 1e3:.1f} kPa (eq. 3)', yes(moment <= mw)))
    lines = ['| arm | quantity | measured | target | met |', '|---|---|---|---|---|']
    lines += [f'| {" | ".join(row)} |' for row in rows]
    return '\n'.join(lines)


def plot(mission, figures: Figures, out: pathlib.Path) -> list[pathlib.Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from inflarm_control.elastostatic_ik import solve_rigid_ik
    from inflarm_model.kinematics import RigidArm
    from inflarm_planning.collision import box_array
    from inflarm_planning.plan_figures import end_clearance
    from inflarm_planning.scenario import ALERT_MARGIN, OBSTACLE

    written = []
    times = mission.soft_times
    if mission.planned is not None and 'following the path' in times:
        stop = times.get('at the goal', mission.now())
        t, driven = mission.soft_truth.arrays(times['following the path'], stop)
        fig = plt.figure(figsize=(7, 6))
        ax = fig.add_subplot(projection='3d')
        for (low, high), style in ((box_array([OBSTACLE])[0], dict(color='saddlebrown')),
                                   (box_array([OBSTACLE], ALERT_MARGIN)[0],
                                    dict(color='tab:orange', alpha=0.4))):
            corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                                for z in (low[2], high[2])]) * 1000
            for i in range(8):
                for j in range(i + 1, 8):
                    if np.count_nonzero(corners[i] != corners[j]) == 1:
                        ax.plot(*corners[[i, j]].T, **style)
        ax.plot(*(mission.planned * 1000).T, 'k-', label='planned path')
        ax.plot(*(driven * 1000).T, 'r-', lw=1, label='true end (camera-tracked control)')
        ax.set_xlabel('x [mm]'), ax.set_ylabel('y [mm]'), ax.set_zlabel('z [mm]')
        ax.set_title('Soft arm around the obstacle (Fig 10 of 001)')
        ax.legend()
        written.append(out / 'soft_arm_path.png')
        fig.savefig(written[-1], dpi=120)
        plt.close(fig)

        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(t - t[0], end_clearance(driven) * 1000, 'r-', label='true end')
        if mission.plan_stamps is not None:
            ax.plot(mission.plan_stamps - mission.plan_stamps[0],
                    end_clearance(mission.planned) * 1000, 'k-', label='planned')
        ax.axhline(ALERT_MARGIN * 1000, color='tab:blue', label='alert region border')
        ax.set_xlabel('time [s]'), ax.set_ylabel('distance to the obstacle surface [mm]')
        ax.set_title('Clearance along the path (Fig 12 of 001)')
        ax.legend()
        written.append(out / 'soft_arm_clearance.png')
        fig.savefig(written[-1], dpi=120)
        plt.close(fig)
    if mission.arm_paths:
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        origin = mission.arm_paths[0][0][0]
        for due, points in mission.arm_paths:
            t, tips = mission.tip_truth.arrays(due[0] - 0.5, due[-1] + 0.5)
            for i, name in enumerate('xyz'):
                top.plot(t - origin, tips[:, i], color=f'C{i}', label=f'true tip {name}'
                         if due is mission.arm_paths[0][0] else None)
                top.plot(due - origin, points[:, i], 'k--', lw=0.8)
            t, errors = tip_off_path(mission, due, points, 0.5)
            bottom.plot(t - origin, errors * 1000, 'r-')
        bottom.axhline(ARM_TIP_TARGET_M * 1000, color='tab:blue', label='2 mm')
        top.set_ylabel('tip [m]'), top.legend(fontsize=8)
        bottom.set_ylabel('off the path [mm]'), bottom.set_xlabel('time [s]')
        bottom.legend()
        top.set_title('Inflatable arm: tip path by elastostatic IK, unknown load')
        written.append(out / 'inflatable_arm_tip.png')
        fig.savefig(written[-1], dpi=120)
        plt.close(fig)

        motors = [(t, q) for t, q in mission.motors if origin - 0.5 <= t <= mission.arm_paths[
            -1][0][-1] + 0.5]
        if motors:
            t = np.array([m[0] for m in motors]) - origin
            q = np.array([m[1] for m in motors])
            t_tip, tips = mission.tip_truth.arrays(origin - 0.5, mission.arm_paths[-1][0][-1])
            rigid_arm, rigid, guess = RigidArm(mission.arm.link_length), [], q[0]
            for tip in tips[::10]:
                guess = solve_rigid_ik(rigid_arm, tip, guess)
                rigid.append(guess)
            fig, ax = plt.subplots(figsize=(7, 4))
            for i in range(3):
                ax.plot(t, q[:, i], color=f'C{i}', label=f'joint_{i + 1}, flexible (commanded)')
                ax.plot(t_tip[::10] - origin, np.array(rigid)[:, i], '--', color=f'C{i}',
                        label=f'joint_{i + 1}, rigid links')
            ax.set_xlabel('time [s]'), ax.set_ylabel('motor angle [rad]')
            ax.set_title('Motor angles compensating the deflection (Fig 11 of 000)')
            ax.legend(fontsize=7)
            written.append(out / 'inflatable_arm_motors.png')
            fig.savefig(written[-1], dpi=120)
            plt.close(fig)
    return written


# -- the run ----------------------------------------------------------------------------------

def demo_nodes(backend: Backend, knowledge: pathlib.Path, seed: int, bag: pathlib.Path,
               bag_storage: str) -> tuple[NodeProcess, ...]:
    """The ``sim`` system's nodes, the simulators seeded with ``seed``, the pressure
    controller on the ``knowledge`` database, and the recorder of the ``bag``."""
    ours = {simulator: {'seed': seed} for simulator in SIMULATORS}
    # the bag's nodes record their callbacks: inflarm-bag-regression replays them
    ours.update({node: {'callback_log': True} for node in REPLAYABLE_NODES})
    ours['pressure_controller']['knowledge_db_path'] = str(knowledge)
    return tuple(replace(n, parameters={**n.parameters, **ours.get(n.executable, {})})
                 for n in system_nodes('sim', backend)) + (
        NodeProcess('inflarm_hw', 'bag_recorder', parameters={
            'topics': list(RECORDED_TOPICS), 'output': str(bag.resolve()),
            'storage': bag_storage}),)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='inflarm-demo',
                                     description=__doc__.splitlines()[0].split(': ', 1)[1])
    parser.add_argument('--out', default='out/demo', help='output folder (default %(default)s)')
    parser.add_argument('--backend', default='sim', choices=('sim', 'sim_mcu'),
                        help='the robots: simulators, or the bridge on a simulated MCU')
    parser.add_argument('--timeout', type=float, default=170.0,
                        help='give up after this long [s] (default %(default)s)')
    parser.add_argument('--seed', type=int, default=0,
                        help='seed of the simulators (default %(default)s; -1: random)')
    parser.add_argument('--bag-storage', default='sqlite3', choices=('sqlite3', 'mcap'),
                        help="the bag's storage (default %(default)s; mcap for Foxglove)")
    parser.add_argument('--view', action='store_true',
                        help='also the live view of both arms in a browser')
    parser.add_argument('--view-host', default=VIEW_HOST,
                        help='address the view serves on (default %(default)s)')
    parser.add_argument('--view-port', type=int, default=VIEW_PORT,
                        help='port of the view (default %(default)s)')
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    port = ''
    if args.backend == 'sim_mcu':
        port = os.path.join(tempfile.mkdtemp(prefix='inflarm-mcu-'), 'mcu')
    os.environ.update(ros_environment())
    started = time.monotonic()
    knowledge = build_knowledge(out / 'knowledge')
    print(f'[demo] knowledge database of the scenario region built in '
          f'{time.monotonic() - started:.1f} s', flush=True)
    nodes = demo_nodes(Backend(args.backend, port), knowledge, args.seed, out / 'bag',
                       args.bag_storage)
    if args.view:
        view = live_view_node(Backend(args.backend, port), args.view_host, args.view_port)
        nodes += (view,)
        print(f'[demo] live view: {live_view_url(view)}', flush=True)
    print(f'[demo] starting {len(nodes)} nodes (their output: {out / "nodes.log"})', flush=True)
    with open(out / 'nodes.log', 'w') as log:
        group = ProcessGroup(output=log)
        for node in nodes:
            group.start(node.node_name, node.command())
        try:
            mission, finished = run_missions(group, started, args.timeout)
        finally:
            codes = group.stop()
    figures = measure(mission)
    table = summary_table(figures)
    failed = {name: code for name, code in codes.items() if code != 0}
    (out / 'summary.md').write_text(f'# inflarm demo\n\n{table}\n')
    written = plot(mission, figures, out)
    print(f'\n{table}\n')
    print(f'[demo] {time.monotonic() - started:.0f} s; wrote {out / "summary.md"}, '
          + ', '.join(p.name for p in written) + f', {out / "bag"}')
    if failed:
        print(f'[demo] nodes that did not exit cleanly: {failed} (see {out / "nodes.log"})',
              file=sys.stderr)
    if not finished:
        print(f'[demo] stopped after {args.timeout:.0f} s: soft arm {mission.soft_phase!r}, '
              f'inflatable arm {mission.arm_phase!r}', file=sys.stderr)
    return 0 if finished and not failed and targets_met(figures) else 1


def build_knowledge(path: pathlib.Path) -> pathlib.Path:
    """The experiential knowledge database of the scenario's region (section 3.2 of 001)."""
    from inflarm_bringup.knowledge_cli import knowledge_plant
    from inflarm_control.knowledge import KnowledgeGrid, build_knowledge_database

    grid = KnowledgeGrid(origin=KNOWLEDGE_ORIGIN, spacing=0.01, shape=KNOWLEDGE_SHAPE)
    build_knowledge_database(path, grid, plant_factory=knowledge_plant, progress=False).close()
    return path.resolve()


def run_missions(group: ProcessGroup, started: float, timeout_s: float):
    """Spin the mission node until both missions are done, ``timeout_s`` or Ctrl-C."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    stop = []
    previous = {s: signal.signal(s, lambda *_: stop.append(True))
                for s in (signal.SIGINT, signal.SIGTERM)}
    rclpy.init()
    mission = mission_node_class()()
    executor = SingleThreadedExecutor()
    executor.add_node(mission)
    last_report = 0.0
    try:
        while not stop and not mission.done():
            elapsed = time.monotonic() - started
            if elapsed > timeout_s or group.exited():
                break
            executor.spin_once(timeout_sec=0.05)
            mission.step_soft()
            mission.step_arm()
            if elapsed - last_report >= 3.0:
                last_report = elapsed
                print(f'[demo] {elapsed:5.0f} s | soft arm: {mission.soft_phase}'
                      f'{progress_soft(mission)} | inflatable arm: {mission.arm_phase}'
                      f'{progress_arm(mission)}', flush=True)
        done = mission.done()
        if group.exited():
            for name in group.exited():
                print(group.describe(name, f'exited with code {group.processes[name].returncode}'),
                      file=sys.stderr)
        return mission, done
    finally:
        executor.shutdown()
        mission.destroy_node()
        rclpy.try_shutdown()
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def progress_soft(mission) -> str:
    if not mission.ball.values:
        return ''
    end = np.array(mission.ball.values[-1])
    return f' (camera: end at {np.round(end * 1000).astype(int).tolist()} mm)'


def progress_arm(mission) -> str:
    if not mission.forces.values:
        return ''
    force = np.array(mission.forces.values[-1])
    return f' (estimated load {np.linalg.norm(force):.1f} N)'


if __name__ == '__main__':
    sys.exit(main())
