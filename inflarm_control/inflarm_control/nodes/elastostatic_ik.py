"""Elastostatic inverse kinematics: motor set points whose deflected tip reaches the target
(Fig 6, eqs 8-9 of 000_...): the links' deflection under the tip load is compensated.

A ``tip_target`` is solved at once and commanded; a ``tip_trajectory`` (poses stamped with the
times they are due) is integrated with eq. 9 from the current motor angles and streamed at
``command_rate_hz``. The load is the latest ``estimated_wrench`` or a configured one.

Subscribes:
    tip_target (geometry_msgs/PointStamped, COMMAND_QOS): tip position to reach [m].
    tip_trajectory (nav_msgs/Path, RELIABLE_QOS): timed tip positions [m].
    joint_states (sensor_msgs/JointState, SENSOR_QOS): current joint_1..joint_3 angles.
    estimated_wrench (geometry_msgs/WrenchStamped, RELIABLE_QOS): tip load [N].
Publishes:
    motor_position_command (sensor_msgs/JointState, COMMAND_QOS): joint_1..joint_3 [rad].
Parameters:
    arm.* (inflarm_model.nodes.arm_parameters): geometry, stiffness, link pressure.
    load.source (string): 'estimated' or 'configured'.
    load.force_n (double[3]): the configured tip load [N].
    gain_per_s (double): K of eq. 9 [1/s].
    method (string, read-only): 'effective' (exact motor-to-tip map) or 'paper' (J_m^#).
    command_rate_hz (double, read-only): trajectory streaming rate.
    frame_id (string, read-only): base frame of targets.
"""

import math
import time

from geometry_msgs.msg import PointStamped, WrenchStamped
from nav_msgs.msg import Path
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.time import Time
from sensor_msgs.msg import JointState

from inflarm_control.elastostatic_ik import TrackingResult, solve_ik, track_trajectory
from inflarm_model.kinematics import FlexibleArm
from inflarm_model.nodes.arm_parameters import (
    ARM_PARAMETERS,
    arm_from_parameters,
    check_arm_parameters,
)
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import (
    COMMAND_QOS,
    RELIABLE_QOS,
    SENSOR_QOS,
    publisher_events,
    subscription_events,
)
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = ARM_PARAMETERS + (
    Parameter('load.source', 'estimated',
              "'estimated' (latest estimated_wrench) or 'configured' (load.force_n)"),
    Parameter('load.force_n', [0.0, 10.0, -15.0], 'configured tip load [N], base frame'),
    Parameter('gain_per_s', 5.0, 'K of eq. 9 [1/s]', range=(0.0, 1000.0)),
    Parameter('method', 'effective',
              "'effective' (exact motor-to-tip map) or 'paper' (J_m^# of eq. 8)", read_only=True),
    Parameter('command_rate_hz', 50.0, 'trajectory streaming rate [Hz]', range=(1.0, 1000.0),
              read_only=True),
    Parameter('frame_id', 'base_link', 'base frame of targets', read_only=True),
)
MOTORS = FlexibleArm.MOTOR_JOINT_NAMES
# Eq. 9 is integrated with explicit Euler, stable for dt * K < 1: paths are resampled (linearly)
# so that dt * K stays at most this.
MAX_EULER_STEP = 0.25


def resample(times: np.ndarray, x_d: np.ndarray, max_dt: float):
    """Linear interpolation of the waypoints ``x_d`` (N, 3) at ``times`` onto steps of at
    most ``max_dt``, keeping every original time."""
    pieces = [np.linspace(a, b, int(np.ceil((b - a) / max_dt)) + 1)[:-1]
              for a, b in zip(times[:-1], times[1:], strict=True)]
    fine = np.concatenate(pieces + [times[-1:]])
    return fine, np.stack([np.interp(fine, times, x_d[:, i]) for i in range(3)], axis=1)


def check_ik_parameters(values: dict) -> str | None:
    problem = check_arm_parameters(values)
    if problem is None and values.get('load.source', 'estimated') not in ('estimated',
                                                                          'configured'):
        problem = f"load.source must be 'estimated' or 'configured', got {values['load.source']}"
    force = values.get('load.force_n')
    if problem is None and force is not None and (
            len(force) != 3 or not all(math.isfinite(v) for v in force)):
        problem = f'load.force_n must be 3 finite numbers, got {list(force)}'
    if problem is None and values.get('method', 'effective') not in ('effective', 'paper'):
        problem = f"method must be 'effective' or 'paper', got {values['method']}"
    return problem


class ElastostaticIk(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('elastostatic_ik', **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        problem = check_ik_parameters(self.params)
        if problem is not None:
            raise ValueError(problem)
        self.arm = arm_from_parameters(self.params)
        self.q_m: np.ndarray | None = None
        self.estimated_force: np.ndarray | None = None
        self.trajectory: TrackingResult | None = None
        self.trajectory_start = 0.0  # monotonic time of the trajectory's first waypoint

        for topic, kind, callback, qos in (
                ('tip_target', PointStamped, self.on_target, COMMAND_QOS),
                ('tip_trajectory', Path, self.on_trajectory, RELIABLE_QOS),
                ('joint_states', JointState, self.on_joint_states, SENSOR_QOS),
                ('estimated_wrench', WrenchStamped, self.on_wrench, RELIABLE_QOS)):
            self.create_subscription(kind, topic, callback, qos,
                                     event_callbacks=subscription_events(self, topic))
        self.command_pub = self.create_publisher(
            JointState, 'motor_position_command', COMMAND_QOS,
            event_callbacks=publisher_events(self, 'motor_position_command'))
        self.create_timer(1.0 / self.params['command_rate_hz'], self.stream)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(
            lambda parameters: self.params.update({q.name: q.value for q in parameters}))
        self.get_logger().info(f"ready: load from {self.params['load.source']}")

    def on_set_parameters(self, parameters) -> SetParametersResult:
        problem = check_ik_parameters({q.name: q.value for q in parameters})
        return SetParametersResult(successful=problem is None, reason=problem or '')

    # -- inputs --------------------------------------------------------------------------------

    def on_joint_states(self, msg: JointState) -> None:
        index = {name: i for i, name in enumerate(msg.name)}
        if all(name in index for name in MOTORS) and len(msg.position) == len(msg.name):
            q_m = np.array([msg.position[index[name]] for name in MOTORS])
            if np.isfinite(q_m).all():
                self.q_m = q_m
                return
        self.get_logger().warning(
            f'joint_states ignored: expected finite positions of {list(MOTORS)}',
            throttle_duration_sec=2.0)

    def on_wrench(self, msg: WrenchStamped) -> None:
        force = np.array([msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z])
        if np.isfinite(force).all():
            self.estimated_force = force

    def load(self) -> np.ndarray:
        """The tip load to compensate; ValueError (with the reason) when there is none."""
        if self.params['load.source'] == 'configured':
            return np.array(self.params['load.force_n'])
        if self.estimated_force is None:
            raise ValueError('no estimated_wrench received yet')
        return self.estimated_force

    def check_frame(self, frame_id: str) -> None:
        if frame_id != self.params['frame_id']:
            raise ValueError(f"frame_id '{frame_id}' is not '{self.params['frame_id']}'")

    def on_target(self, msg: PointStamped) -> None:
        target = np.array([msg.point.x, msg.point.y, msg.point.z])
        try:
            self.check_frame(msg.header.frame_id)
            if self.q_m is None:
                raise ValueError('no joint_states received yet')
            q_m = solve_ik(self.arm, target, self.load(), self.params['arm.spring_stiffness'],
                           self.q_m)
        except ValueError as err:
            self.get_logger().error(f'tip_target {target.tolist()} rejected: {err}')
            return
        self.trajectory = None
        self.publish_command(q_m)
        self.get_logger().info(
            f'tip_target {np.round(target, 4).tolist()}: motors {np.round(q_m, 4).tolist()}')

    def on_trajectory(self, msg: Path) -> None:
        try:
            if len(msg.poses) < 2:
                raise ValueError(f'expected at least 2 poses, got {len(msg.poses)}')
            self.check_frame(msg.header.frame_id)
            if self.q_m is None:
                raise ValueError('no joint_states received yet')
            stamps = np.array([Time.from_msg(p.header.stamp).nanoseconds for p in msg.poses])
            times = (stamps - stamps[0]) * 1e-9
            if not (np.diff(times) > 0.0).all():
                raise ValueError('pose stamps must increase strictly: they give the times')
            x_d = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                            for p in msg.poses])
            times, x_d = resample(times, x_d, MAX_EULER_STEP / max(self.params['gain_per_s'],
                                                                   1e-9))
            v_d = np.gradient(x_d, times, axis=0)
            result = track_trajectory(
                self.arm, times, x_d, v_d, self.load(), self.params['arm.spring_stiffness'],
                self.q_m, self.params['gain_per_s'], method=self.params['method'])
        except ValueError as err:
            self.get_logger().error(f'tip_trajectory rejected: {err}')
            return
        # The first waypoint is due at the path's first stamp; late paths start now.
        delay = (stamps[0] - self.get_clock().now().nanoseconds) * 1e-9
        self.trajectory = result
        self.trajectory_start = time.monotonic() + max(delay, 0.0)
        self.get_logger().info(
            f'tip_trajectory of {len(times)} poses over {times[-1]:.2f} s: model tip error '
            f'at most {result.tip_error.max() * 1000:.3f} mm')

    # -- output --------------------------------------------------------------------------------

    def stream(self) -> None:
        if self.trajectory is None:
            return
        elapsed = time.monotonic() - self.trajectory_start
        if elapsed < 0.0:
            return
        i = int(np.searchsorted(self.trajectory.times, elapsed, side='right')) - 1
        self.publish_command(self.trajectory.q_m[i])
        if i == len(self.trajectory.times) - 1:
            self.trajectory = None  # the last set point stays commanded

    def publish_command(self, q_m: np.ndarray) -> None:
        msg = JointState(name=list(MOTORS), position=q_m.tolist())
        msg.header.stamp = self.get_clock().now().to_msg()
        self.command_pub.publish(msg)


def main(args: list[str] | None = None) -> None:
    spin_node(ElastostaticIk, args)


if __name__ == '__main__':
    main()
