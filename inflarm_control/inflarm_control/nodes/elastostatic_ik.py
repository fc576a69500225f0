"""Elastostatic inverse kinematics: motor set points whose deflected tip reaches the target
(Fig 6, eqs 8-9 of 000_...): the links' deflection under the tip load is compensated.

A ``tip_target`` is solved at once; a ``tip_trajectory`` (poses stamped with the times they
are due, or from 0 for "from now") is integrated with eq. 9 from the current motor angles on a
worker thread (`inflarm_msgs_json.ros.worker`: the longest paths take seconds), while the
set point keeps streaming; one solved late is joined where it is due by then, one overtaken
by a newer target or trajectory is dropped. Either is checked whole before
anything is commanded: every motor angle within the joint limits, the model's deflected tip
within ``max_tip_error_m`` of every waypoint (an unreachable path fails here), the path no
longer than ``max_duration_s``. The set point is streamed at ``command_rate_hz``, interpolated
between the integration steps, with the motor velocities of eq. 9 as a feed-forward (so that
position-controlled motors do not lag the path); after a trajectory it is held (re-sent, zero
velocity) so that the motors' command watchdog stays fed. The load is the latest
``estimated_wrench`` or a configured one.

Subscribes:
    tip_target (geometry_msgs/PointStamped, COMMAND_QOS): tip position to reach [m].
    tip_trajectory (nav_msgs/Path, RELIABLE_QOS): timed tip positions [m], at most
        ``max_poses`` poses over at most ``max_duration_s``.
    joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): current joint_1..joint_3 angles.
    estimated_wrench (geometry_msgs/WrenchStamped, RELIABLE_QOS): tip load [N], in the base
        frame or in the ``tip`` frame; a tip-frame wrench is turned into the base frame with the
        estimated pose of the same stamp (``estimated_joint_states``).
    estimated_joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): the estimator's deflected
        pose, all 7 joints.
Publishes:
    motor_position_command (sensor_msgs/JointState, COMMAND_QOS): joint_1..joint_3 positions
        [rad] and velocities [rad/s] (feed-forward).
Parameters:
    arm.* (inflarm_model.nodes.arm_parameters): geometry, stiffness, link pressure.
    load.source (string): 'estimated' or 'configured'.
    load.force_n (double[3]): the configured tip load [N].
    gain_per_s (double): K of eq. 9 [1/s].
    max_tip_error_m (double): largest model tip error accepted along a path [m].
    max_duration_s (double), max_poses (int): bounds of an accepted trajectory.
    method (string, read-only): 'effective' (exact motor-to-tip map) or 'paper' (J_m^#).
    command_rate_hz (double, read-only): streaming rate.
    frame_id (string, read-only): base frame of targets.
    tip_frame_id (string, read-only): frame of a tip-frame wrench.
"""

from collections import OrderedDict
from dataclasses import dataclass
import math

from geometry_msgs.msg import PointStamped, WrenchStamped
from nav_msgs.msg import Path
import numpy as np
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
from inflarm_model.ros_conversions import joint_arrays, joint_state
from inflarm_model.urdf import TIP_LINK, check_joint_positions
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import COMMAND_QOS, JOINT_STATE_QOS, RELIABLE_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node
from inflarm_msgs_json.ros.worker import LatestJobWorker

PARAMETERS = ARM_PARAMETERS + (
    Parameter('load.source', 'estimated',
              "'estimated' (latest estimated_wrench) or 'configured' (load.force_n)"),
    Parameter('load.force_n', [0.0, 10.0, -15.0], 'configured tip load [N], base frame'),
    Parameter('gain_per_s', 5.0, 'K of eq. 9 [1/s]', range=(0.01, 100.0)),
    Parameter('max_tip_error_m', 0.01,
              'largest model tip error accepted along a trajectory [m]', range=(1e-6, 0.1)),
    Parameter('max_duration_s', 600.0, 'longest trajectory accepted [s]', range=(0.1, 3600.0)),
    Parameter('max_poses', 10000, 'most poses accepted in a trajectory', range=(2, 100000)),
    Parameter('method', 'effective',
              "'effective' (exact motor-to-tip map) or 'paper' (J_m^# of eq. 8)", read_only=True),
    Parameter('command_rate_hz', 50.0, 'set point streaming rate [Hz]', range=(1.0, 1000.0),
              read_only=True),
    Parameter('frame_id', 'base_link', 'base frame of targets', read_only=True),
    Parameter('tip_frame_id', TIP_LINK, 'frame of a tip-frame estimated_wrench', read_only=True),
)
MOTORS = FlexibleArm.MOTOR_JOINT_NAMES
# Eq. 9 is integrated with explicit Euler, stable for dt * K < 1: paths are resampled (linearly)
# so that dt * K stays at most this.
MAX_EULER_STEP = 0.25
POSES_KEPT = 50  # estimated poses kept to turn tip-frame wrenches of the same stamp


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


STOP_WAIT_S = 1.0  # how long a stop waits for an integration under way


@dataclass(frozen=True)
class TrajectoryJob:
    """A checked ``tip_trajectory``, resampled, with what its integration starts from."""

    command: int  # number of the command it answers: a newer command drops it
    start_ns: int | None  # when its first pose is due [ns]; None: when it is solved
    times: np.ndarray
    x_d: np.ndarray
    v_d: np.ndarray
    force: np.ndarray
    q_m: np.ndarray
    settings: dict


def check_motor_path(q_m: np.ndarray) -> None:
    """InputError naming the first set point outside the joint limits."""
    for i, row in enumerate(np.atleast_2d(q_m)):
        try:
            check_joint_positions(MOTORS, row)
        except ValueError as error:
            raise InputError('joint limit', f'set point {i}: {error}') from error


class ElastostaticIk(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('elastostatic_ik', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, check=check_ik_parameters)
        problem = check_ik_parameters(self.params)
        if problem is not None:
            raise ValueError(problem)
        self.arm = arm_from_parameters(self.params)
        self.q_m: np.ndarray | None = None
        self.estimated_force: np.ndarray | None = None
        self.poses: OrderedDict[int, np.ndarray] = OrderedDict()  # stamp [ns] -> q (7,)
        self.pending_wrench: WrenchStamped | None = None  # tip frame, waiting for its pose
        self.trajectory: TrackingResult | None = None
        self.trajectory_velocity: np.ndarray | None = None  # dq_m of each step [rad/s]
        self.commands = 0  # targets and trajectories received, the newest wins
        self.worker = LatestJobWorker('elastostatic_ik trajectory', self.integrate)
        self.trajectory_start_ns = 0  # node clock time of the trajectory's first waypoint
        self.set_point: np.ndarray | None = None  # last commanded, re-sent while idle

        for topic, kind, callback, qos in (
                ('tip_target', PointStamped, self.on_target, COMMAND_QOS),
                ('tip_trajectory', Path, self.on_trajectory, RELIABLE_QOS),
                ('joint_states', JointState, self.on_joint_states, JOINT_STATE_QOS),
                ('estimated_wrench', WrenchStamped, self.on_wrench, RELIABLE_QOS),
                ('estimated_joint_states', JointState, self.on_estimated_pose,
                 JOINT_STATE_QOS)):
            self.create_guarded_subscription(kind, topic, callback, qos)
        self.command_pub = self.create_publisher(
            JointState, 'motor_position_command', COMMAND_QOS,
            event_callbacks=publisher_events(self, 'motor_position_command'))
        self.create_guarded_timer(1.0 / self.params['command_rate_hz'], self.stream)
        self.get_logger().info(f"ready: load from {self.params['load.source']}")

    # -- inputs --------------------------------------------------------------------------------

    def on_joint_states(self, msg: JointState) -> None:
        self.q_m = joint_arrays(msg, MOTORS)['position']

    def on_estimated_pose(self, msg: JointState) -> None:
        q = joint_arrays(msg, FlexibleArm.JOINT_NAMES)['position']
        self.poses[Time.from_msg(msg.header.stamp).nanoseconds] = q
        while len(self.poses) > POSES_KEPT:
            self.poses.popitem(last=False)
        if self.pending_wrench is not None:
            self.on_wrench(self.pending_wrench)

    def on_wrench(self, msg: WrenchStamped) -> None:
        force = np.array([msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z])
        if not np.isfinite(force).all():
            raise InputError('not finite', f'force {force.tolist()} N')
        frame = msg.header.frame_id
        if frame == self.params['tip_frame_id']:
            q = self.poses.get(Time.from_msg(msg.header.stamp).nanoseconds)
            if q is None:  # its pose is on its way: use it when it comes
                self.pending_wrench = msg
                return
            force = self.arm.fk(q)[:3, :3] @ force  # tip frame -> base frame
        elif frame != self.params['frame_id']:
            raise InputError('frame', f"frame_id '{frame}' is neither "
                                      f"'{self.params['frame_id']}' nor "
                                      f"'{self.params['tip_frame_id']}'")
        self.pending_wrench = None
        self.estimated_force = force

    def load(self) -> np.ndarray:
        """The tip load to compensate; ValueError (with the reason) when there is none."""
        if self.params['load.source'] == 'configured':
            return np.array(self.params['load.force_n'])
        if self.estimated_force is None:
            raise InputError('no load', 'no estimated_wrench received yet')
        return self.estimated_force

    def check_frame(self, frame_id: str) -> None:
        if frame_id != self.params['frame_id']:
            raise InputError('frame', f"frame_id '{frame_id}' is not '{self.params['frame_id']}'")

    def current_motors(self) -> np.ndarray:
        if self.q_m is None:
            raise InputError('no joint states', 'no joint_states received yet')
        return self.q_m

    def on_target(self, msg: PointStamped) -> None:
        target = np.array([msg.point.x, msg.point.y, msg.point.z])
        self.check_frame(msg.header.frame_id)
        q_m = solve_ik(self.arm, target, self.load(), self.params['arm.spring_stiffness'],
                       self.current_motors())
        check_motor_path(q_m)
        self.commands += 1
        self.trajectory = None
        self.publish_command(q_m)
        self.get_logger().info(
            f'tip_target {np.round(target, 4).tolist()}: motors {np.round(q_m, 4).tolist()}')

    def on_trajectory(self, msg: Path) -> None:
        p = self.params
        if not 2 <= len(msg.poses) <= p['max_poses']:
            raise InputError('pose count', f"expected 2 to {p['max_poses']} poses, got "
                                           f'{len(msg.poses)}')
        self.check_frame(msg.header.frame_id)
        stamps = np.array([Time.from_msg(ps.header.stamp).nanoseconds for ps in msg.poses])
        times = (stamps - stamps[0]) * 1e-9
        if not (np.diff(times) > 0.0).all():
            raise InputError('stamps', 'pose stamps must increase strictly: they give the times')
        if times[-1] > p['max_duration_s']:
            raise InputError('duration', f'the path lasts {times[-1]:.6g} s, over max_duration_s'
                                         f" = {p['max_duration_s']} s")
        x_d = np.array([[ps.pose.position.x, ps.pose.position.y, ps.pose.position.z]
                        for ps in msg.poses])
        if not np.isfinite(x_d).all():
            raise InputError('not finite', 'the path has non-finite positions')
        times, x_d = resample(times, x_d, MAX_EULER_STEP / p['gain_per_s'])
        force, q_m = self.load(), self.current_motors()
        self.commands += 1
        # Each waypoint is due at its stamp, as a JointTrajectoryController reads a trajectory;
        # stamps from 0 are relative: the path starts when it is solved.
        self.worker.submit(TrajectoryJob(
            self.commands, int(stamps[0]) if stamps[0] > 0 else None, times, x_d,
            np.gradient(x_d, times, axis=0), force, q_m, dict(p)))

    def integrate(self, job: TrajectoryJob) -> tuple[TrajectoryJob, TrackingResult]:
        """Eq. 9 along the job's path, checked whole (worker thread)."""
        p = job.settings
        result = track_trajectory(
            self.arm, job.times, job.x_d, job.v_d, job.force, p['arm.spring_stiffness'],
            job.q_m, p['gain_per_s'], method=p['method'])
        check_motor_path(result.q_m)
        worst = int(np.argmax(result.tip_error))
        if result.tip_error[worst] > p['max_tip_error_m']:
            raise InputError(
                'tip error', f'the model tip strays {result.tip_error[worst]:.4g} m from '
                f"waypoint {job.x_d[worst].round(4).tolist()} at {job.times[worst]:.3g} s (over "
                f"max_tip_error_m = {p['max_tip_error_m']} m): out of reach or too fast")
        return job, result

    def on_integrated(self, done: tuple[TrajectoryJob, TrackingResult]) -> None:
        """Start streaming an integrated trajectory (executor thread)."""
        job, result = done
        if job.command != self.commands:
            self.get_logger().info('tip_trajectory dropped: a newer command replaced it')
            return
        # a path solved late is joined where it is due now, so the arm is not late all along it
        now_ns = self.callback_time().nanoseconds
        start_ns = now_ns if job.start_ns is None else job.start_ns
        late_s = (now_ns - start_ns) * 1e-9
        if late_s >= job.times[-1]:
            raise InputError('late', f'the path ended {late_s - job.times[-1]:.3g} s before it '
                                     'was solved: nothing of it is due any more')
        self.trajectory = result
        # Eq. 9 was integrated by explicit Euler: each step's motor velocity is its difference.
        self.trajectory_velocity = np.vstack([np.diff(result.q_m, axis=0)
                                              / np.diff(result.times)[:, None], np.zeros(3)])
        self.trajectory_start_ns = start_ns
        self.get_logger().info(
            f'tip_trajectory of {len(job.times)} poses over {job.times[-1]:.2f} s: model tip '
            f'error at most {result.tip_error.max() * 1000:.3f} mm')

    # -- output --------------------------------------------------------------------------------

    def stream(self) -> None:
        for done in self.worker.results():
            try:
                if isinstance(done, Exception):
                    raise done  # what the integration raised
                self.on_integrated(done)
            except ValueError as error:
                self.problems.reject('tip_trajectory', error)
            except Exception as error:  # noqa: BLE001 (the stream must go on)
                self.problems.bug('tip_trajectory', error)
        if self.trajectory is None:
            if self.set_point is not None:
                self.publish_command(self.set_point)
            return
        elapsed = (self.callback_time().nanoseconds - self.trajectory_start_ns) * 1e-9
        if elapsed < 0.0:
            return
        times = self.trajectory.times
        i = int(np.searchsorted(times, elapsed, side='right')) - 1
        if i >= len(times) - 1:
            last = self.trajectory.q_m[-1]
            self.trajectory = None  # the last set point stays commanded
            self.publish_command(last)
            return
        velocity = self.trajectory_velocity[i]
        self.publish_command(self.trajectory.q_m[i] + (elapsed - times[i]) * velocity, velocity)

    def publish_command(self, q_m: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Command ``q_m`` with a velocity feed-forward (zero when holding)."""
        self.set_point = q_m
        self.command_pub.publish(joint_state(
            MOTORS, self.callback_time().to_msg(), position=q_m,
            velocity=np.zeros(3) if velocity is None else velocity))


    def destroy_node(self) -> None:
        self.worker.close(STOP_WAIT_S)
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(ElastostaticIk, args)


if __name__ == '__main__':
    main()
