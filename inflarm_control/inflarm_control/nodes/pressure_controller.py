"""PID + iterative learning control of the soft arm's chamber pressures (Fig 6 of 001_...).

The ROS adapter of `inflarm_control.pressure_control.PressureControlSession`: trials from
``control_task`` at ``rate_hz``, each seeded by the target's ILC memory or the experiential
knowledge database (``pid_ilc``), learning its memory when it ends, then holding its last
pressures; planned paths followed by `inflarm_control.path_following.PathFollower` (a
reference moving at up to ``path.speed_mps`` that waits for the arm, the knowledge database's
holding pressures as feedforward, a PI per axis, bellows pairs driven antagonistically around
``path.bellows_preload_pa``, repulsion from the alert regions of ``obstacles`` with
``path.repulsion_gain``), their last waypoint then held until the next task, path,
``~/stop`` or ``~/vent``. Trials drive the bellows by the paper's quadrant rule, the scheme the
ILC memories and the knowledge database were learned with.

Subscribes:
    ball_position (geometry_msgs/PointStamped, SENSOR_QOS): measured end point [m]; a point
        outside the work space grown by ``workspace_margin_m`` is a bad measurement, rejected
        (it reaches neither a report nor the ILC memory).
    control_task (std_msgs/String: ControlTask JSON, RELIABLE_QOS): start a trial.
    planned_path (nav_msgs/Path, LATCHED_QOS): follow this path (at most ``max_waypoints``
        waypoints, each in the work space; pose stamps are not used: the arm sets the pace),
        then hold its last waypoint.
    obstacles (std_msgs/String: ObstacleSet JSON, LATCHED_QOS): boxes in ``frame_id`` and their
        alert margin; the alert regions the path follower repels the end from (the latest set
        replaces the previous one; a rejected one leaves it in force).
Publishes:
    chamber_pressure_command (std_msgs/String: PressureCommand JSON, COMMAND_QOS) [Pa].
    trial_report (std_msgs/String: TrialReport JSON, RELIABLE_QOS): per-axis RMSE, reach time
        (of trials; a path has none).
Services (std_srvs/Trigger):
    ~/start_trial: repeat the last task as the next trial.
    ~/stop: end the current trial without learning; the last pressures are held.
    ~/vent: end the current trial without learning and vent every chamber (0 Pa, held): the
        arm returns to rest, where the paper's trials start (eq. 3: outputs start at 0 kPa).
    ~/reset_learning: forget every ILC memory (and the memory file).
Parameters:
    rate_hz, gains.kp/ki/kd, limits.p_set_pa, limits.p_max_pa, learning.*, quadrant_bellows,
        path.bellows_preload_pa (read-only),
    path.kp, path.ki (read-only), path.speed_mps, path.slow_error_m, path.stop_error_m,
        path.feedforward_lead_s, path.feedforward_dead_zone_pa, path.repulsion_gain (read-only),
    trial_duration_s, measurement_timeout_s, reach_tolerance_m,
    workspace_margin_m, max_waypoints, ilc_memory_path, knowledge_db_path (read-only),
    frame_id (read-only).
Times (trial steps, measurement freshness) are on the node clock, so that a replay under
``use_sim_time`` runs the same steps.
"""

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_control.knowledge import KnowledgeDatabase
from inflarm_control.path_following import PathFollowingParams
from inflarm_control.pid_ilc import PidIlcParams
from inflarm_control.pressure_control import PressureControlSession, SessionStep, TrialLimits
from inflarm_model.alert_regions import regions_of
from inflarm_model.soft_arm import CHAMBERS
from inflarm_msgs_json import ControlTask, ObstacleSet, PressureCommand
from inflarm_msgs_json.ros.conversions import from_string_msg, to_string_msg
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.problems import InputError
from inflarm_msgs_json.ros.qos import (
    COMMAND_QOS,
    LATCHED_QOS,
    RELIABLE_QOS,
    SENSOR_QOS,
    publisher_events,
)
from inflarm_msgs_json.ros.spin import spin_node

_DEFAULTS = PidIlcParams()
_PATH_DEFAULTS = PathFollowingParams()
PARAMETERS = (
    Parameter('rate_hz', _DEFAULTS.rate_hz, 'control rate [Hz] (paper: about 5 Hz)',
              range=(0.5, 100.0), read_only=True),
    Parameter('gains.kp', list(_DEFAULTS.kp), 'K_P of eq. 1 per axis x, y, z [Pa/m]',
              read_only=True),
    Parameter('gains.ki', list(_DEFAULTS.ki), 'K_I of eq. 1 per axis [Pa/(m s)]', read_only=True),
    Parameter('gains.kd', list(_DEFAULTS.kd), 'K_D of eq. 1 per axis [Pa s/m]', read_only=True),
    Parameter('limits.p_set_pa', list(_DEFAULTS.p_set),
              'P_set of eq. 4 per axis: cap of the learned feedforward [Pa]', read_only=True),
    Parameter('limits.p_max_pa', list(_DEFAULTS.p_max),
              f"valve output limit per chamber {', '.join(CHAMBERS)} [Pa]", read_only=True),
    Parameter('learning.gain', list(_DEFAULTS.learning_gain),
              'ILC update gain L per axis [Pa/m] (inflarm_control/README.md)', read_only=True),
    Parameter('learning.lead_steps', list(_DEFAULTS.learning_lead_steps),
              'ILC phase lead per axis [control steps]', read_only=True),
    Parameter('learning.filter_steps', _DEFAULTS.learning_filter_steps,
              'moving-average length of the ILC update [steps]', range=(1, 50), read_only=True),
    Parameter('learning.dead_band_m', _DEFAULTS.learning_dead_band,
              'errors below this teach nothing [m]', range=(0.0, 0.1), read_only=True),
    Parameter('learning.feedback_gain', list(_DEFAULTS.learning_feedback_gain),
              'share of what the PID added after the memory (its last entry held) kept in the '
              'memory, per axis',
              read_only=True),
    Parameter('quadrant_bellows', [','.join(pair) for pair in _DEFAULTS.quadrant_bellows],
              "bellows driving x,y in quadrants 1-4 (Fig 4: 'B4,B3', 'B2,B3', 'B2,B1', 'B4,B1')",
              read_only=True),
    Parameter('path.bellows_preload_pa', _PATH_DEFAULTS.bellows_preload,
              'path following: common pressure of each bellows pair, driven antagonistically '
              "[Pa]; 0: the paper's quadrant rule", range=(0.0, 50e3), read_only=True),
    Parameter('path.kp', list(_PATH_DEFAULTS.kp), 'path following: proportional gain per axis '
              '[Pa/m]', read_only=True),
    Parameter('path.ki', list(_PATH_DEFAULTS.ki), 'path following: integral gain per axis '
              '[Pa/(m s)]', read_only=True),
    Parameter('path.speed_mps', _PATH_DEFAULTS.speed,
              'top speed of the reference along a path [m/s]', range=(1e-4, 0.1),
              read_only=True),
    Parameter('path.slow_error_m', _PATH_DEFAULTS.slow_error,
              'the reference slows down beyond this distance from the end [m]',
              range=(0.0, 0.1), read_only=True),
    Parameter('path.stop_error_m', _PATH_DEFAULTS.stop_error,
              'the reference waits at this distance from the end (> path.slow_error_m) [m]',
              range=(1e-4, 0.2), read_only=True),
    Parameter('path.feedforward_lead_s', _PATH_DEFAULTS.feedforward_lead,
              'the feedforward is taken this far ahead of the reference [s]',
              range=(0.0, 10.0), read_only=True),
    Parameter('path.feedforward_dead_zone_pa', _PATH_DEFAULTS.feedforward_dead_zone,
              "the knowledge's x and y holding outputs shrink by this much: the valves' dead "
              'zone, which the preloaded bellows never enter [Pa]',
              range=(0.0, 50e3), read_only=True),
    Parameter('path.repulsion_gain', _PATH_DEFAULTS.repulsion_gain,
              'path following: while the end is in an alert region of the obstacles, the target '
              'is (reference + k nearest border point) / (1 + k) (section 4.3.2); 0: no '
              'repulsion', range=(0.0, 10.0), read_only=True),
    Parameter('trial_duration_s', 20.0, 'length of a trial [s]', range=(1.0, 600.0)),
    Parameter('measurement_timeout_s', 0.5,
              'a ball position older than this is a vision dropout: hold, do not learn [s]',
              range=(0.05, 10.0)),
    Parameter('reach_tolerance_m', 0.005, 'per-axis tolerance for the reach time [m]',
              range=(1e-4, 0.1)),
    Parameter('workspace_margin_m', 0.05,
              'ball positions farther than this outside the work space are rejected [m]',
              range=(0.0, 0.5), read_only=True),
    Parameter('max_waypoints', 10000, 'most waypoints accepted in a planned_path',
              range=(1, 1000000)),
    Parameter('ilc_memory_path', '', 'file keeping the ILC memories across runs (.npz); empty: '
              'in memory only', read_only=True),
    Parameter('knowledge_db_path', '', 'experiential knowledge database (a directory) seeding '
              'new pid_ilc tasks; empty: none', read_only=True),
    Parameter('frame_id', 'sra_mount', 'frame of targets and measurements', read_only=True),
)


def path_following_params(p: dict, core: PidIlcParams) -> PathFollowingParams:
    """The path follower's parameters from the node's (``path.*``) and the trials' limits."""
    return PathFollowingParams(
        kp=tuple(p['path.kp']), ki=tuple(p['path.ki']),
        bellows_preload=p['path.bellows_preload_pa'], p_max=core.p_max, speed=p['path.speed_mps'],
        slow_error=p['path.slow_error_m'], stop_error=p['path.stop_error_m'],
        feedforward_lead=p['path.feedforward_lead_s'],
        feedforward_dead_zone=p['path.feedforward_dead_zone_pa'],
        repulsion_gain=p['path.repulsion_gain'], workspace=core.workspace)


def trial_limits(p: dict) -> TrialLimits:
    """The trials' runtime limits from the node's parameters."""
    return TrialLimits(trial_duration=p['trial_duration_s'],
                       measurement_timeout=p['measurement_timeout_s'],
                       reach_tolerance=p['reach_tolerance_m'])


class PressureController(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('pressure_controller', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, on_set=self.on_parameters_set)
        p = self.params
        core = PidIlcParams(
            kp=tuple(p['gains.kp']), ki=tuple(p['gains.ki']), kd=tuple(p['gains.kd']),
            p_set=tuple(p['limits.p_set_pa']), p_max=tuple(p['limits.p_max_pa']),
            rate_hz=p['rate_hz'], learning_gain=tuple(p['learning.gain']),
            learning_lead_steps=tuple(p['learning.lead_steps']),
            learning_filter_steps=p['learning.filter_steps'],
            learning_dead_band=p['learning.dead_band_m'],
            learning_feedback_gain=tuple(p['learning.feedback_gain']),
            quadrant_bellows=tuple(tuple(q.split(',')) for q in p['quadrant_bellows']))
        self.session = PressureControlSession(
            core, path_following_params(p, core), trial_limits(p), p['workspace_margin_m'],
            memory_path=p['ilc_memory_path'] or None,
            knowledge=(KnowledgeDatabase.open(p['knowledge_db_path'])
                       if p['knowledge_db_path'] else None))

        self.create_guarded_subscription(
            PointStamped, 'ball_position', self.on_ball_position, SENSOR_QOS)
        self.create_guarded_subscription(
            String, 'control_task', self.on_control_task, RELIABLE_QOS)
        self.create_guarded_subscription(Path, 'planned_path', self.on_planned_path, LATCHED_QOS)
        self.create_guarded_subscription(String, 'obstacles', self.on_obstacles, LATCHED_QOS)
        self.command_pub = self.create_publisher(
            String, 'chamber_pressure_command', COMMAND_QOS,
            event_callbacks=publisher_events(self, 'chamber_pressure_command'))
        self.report_pub = self.create_publisher(
            String, 'trial_report', RELIABLE_QOS,
            event_callbacks=publisher_events(self, 'trial_report'))
        self.create_guarded_service(Trigger, '~/start_trial', self.on_start_trial)
        self.create_guarded_service(Trigger, '~/stop', self.on_stop)
        self.create_guarded_service(Trigger, '~/vent', self.on_vent)
        self.create_guarded_service(Trigger, '~/reset_learning', self.on_reset_learning)
        self.create_guarded_timer(self.session.dt, self.step)
        self.get_logger().info(
            f"ready: {p['rate_hz']} Hz, {len(self.session.memories)} ILC memories, knowledge "
            f"database {'loaded' if self.session.knowledge is not None else 'none'}")

    def on_parameters_set(self, changed: dict) -> None:
        self.session.limits = trial_limits(self.params)

    def now_ns(self) -> int:
        return self.callback_time().nanoseconds

    # -- inputs --------------------------------------------------------------------------------

    def check_frame(self, frame_id: str) -> None:
        if frame_id != self.params['frame_id']:
            raise InputError('frame', f"frame_id '{frame_id}' is not '{self.params['frame_id']}'")

    def on_ball_position(self, msg: PointStamped) -> None:
        self.check_frame(msg.header.frame_id)
        self.session.measure((msg.point.x, msg.point.y, msg.point.z), self.now_ns())

    def on_control_task(self, msg: String) -> None:
        task = from_string_msg(msg, expected=ControlTask)
        self.check_frame(task.frame_id)
        self.start_task(task)

    def on_obstacles(self, msg: String) -> None:
        obstacles = from_string_msg(msg, expected=ObstacleSet)
        self.check_frame(obstacles.frame_id)
        self.session.set_alert_regions(regions_of(obstacles))
        gain = self.params['path.repulsion_gain']
        self.get_logger().info(
            f'{len(obstacles.obstacles)} obstacles: repelling from their alert regions '
            f'(margin {obstacles.alert_margin:.3f} m, gain {gain:g})', throttle_duration_sec=1.0)

    def on_planned_path(self, msg: Path) -> None:
        if not 1 <= len(msg.poses) <= self.params['max_waypoints']:
            raise InputError('waypoint count', f"expected 1 to {self.params['max_waypoints']} "
                                               f'poses, got {len(msg.poses)}')
        self.check_frame(msg.header.frame_id)
        waypoints = np.array([[ps.pose.position.x, ps.pose.position.y, ps.pose.position.z]
                              for ps in msg.poses])
        source, problem = self.session.follow(waypoints)
        if problem:
            self.problems.warn('path', problem, kind='no knowledge')
        self.get_logger().info(f'following a path of {len(waypoints)} waypoints, '
                               f'{self.session.follower.length:.3f} m ({source})')

    # -- trials --------------------------------------------------------------------------------

    def start_task(self, task: ControlTask) -> bool:
        """Start a trial of ``task``; False (logged) if it can't."""
        try:
            source, problem = self.session.start_task(task)
        except ValueError as err:
            self.get_logger().error(str(err))
            return False
        self.log_trial_start(task, source, problem)
        return True

    def log_trial_start(self, task: ControlTask, source: str, problem: str | None) -> None:
        if problem:
            self.get_logger().warning(problem)
        self.get_logger().info(f'trial {task.trial_id} ({task.mode}, {source}) to '
                               f'{np.round(task.target, 4).tolist()}')

    def step(self) -> None:
        result: SessionStep = self.session.step(self.now_ns())
        if result.stale:
            self.problems.warn('step', 'no fresh ball_position: holding the pressures, '
                                       'not learning', kind='stale')
        if result.command is not None:
            self.publish_command(result.command)
        if result.path_end:
            self.get_logger().info('path followed to its end; holding its last waypoint')
        if result.report is not None:
            report = result.report
            self.report_pub.publish(to_string_msg(report))
            self.get_logger().info(
                f'trial {report.trial_index} done: RMSE '
                f'{np.round(np.array(report.rmse) * 1000, 1).tolist()} mm, reach time '
                f'{list(report.reach_time)} s; holding')

    def publish_command(self, command: np.ndarray) -> None:
        chambers = dict(zip(CHAMBERS, command.tolist(), strict=True))
        self.command_pub.publish(to_string_msg(PressureCommand(chambers=chambers)))

    # -- services ------------------------------------------------------------------------------

    def on_start_trial(self, request, response):
        try:
            task, source, problem = self.session.repeat_task()
        except ValueError as err:
            response.success, response.message = False, str(err)
            return response
        self.log_trial_start(task, source, problem)
        response.success, response.message = True, f'trial {task.trial_id} started'
        return response

    def on_stop(self, request, response):
        self.session.stop()
        response.success, response.message = True, 'stopped; holding the last pressures'
        self.get_logger().info(response.message)
        return response

    def on_vent(self, request, response):
        self.publish_command(self.session.vent())
        response.success, response.message = True, 'venting every chamber'
        self.get_logger().info(response.message)
        return response

    def on_reset_learning(self, request, response):
        count = self.session.reset_learning()
        response.success, response.message = True, f'forgot {count} ILC memories'
        self.get_logger().info(response.message)
        return response


def main(args: list[str] | None = None) -> None:
    spin_node(PressureController, args)


if __name__ == '__main__':
    main()
