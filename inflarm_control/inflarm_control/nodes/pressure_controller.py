"""PID + iterative learning control of the soft arm's chamber pressures (Fig 6 of 001_...).

A trial drives the ball on the arm's end from where it is to a target at ``rate_hz``: every step
takes the latest ball position, runs the three axis controllers and publishes the valve set
pressures. After ``trial_duration_s`` the trial's outputs become the ILC memory of that target
(seeding the next ``pid_ilc`` trial to it), a TrialReport is published, and the last pressures
are held. Without a memory, a ``pid_ilc`` task is seeded from the experiential knowledge database
(when one is configured). Trials drive the bellows by the paper's quadrant rule, the scheme the
ILC memories and the knowledge database were learned with.

A planned path (section 4.2) is followed by `inflarm_control.path_following.PathFollower`: a
reference moving along it at up to ``path.speed_mps`` that waits for the arm (it slows down
from ``path.slow_error_m`` and stops at ``path.stop_error_m`` of error), the knowledge
database's holding pressures at the waypoints as feedforward (``knowledge.holding_pressure``;
PI alone without a database or where it has no knowledge), and a PI per axis (``path.kp``,
``path.ki``) from the pressures held when the path arrives (no jump). After its end the path's
last waypoint is held, under control, until the next task, path, ``~/stop`` or ``~/vent``.
While following, every bellows pair is driven antagonistically around ``path.bellows_preload_pa``
(``pid_ilc`` module docstring): no bellows exhausts as the end crosses an axis. While the
measured end is inside an alert region of the latest ``obstacles`` (each box grown by the set's
``alert_margin``), the follower pulls its target towards the region's border with
``path.repulsion_gain`` (section 4.3.2; `PathFollower` module docstring).

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

import math
import os

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_control.knowledge import KnowledgeDatabase, holding_pressure, seed_memory
from inflarm_control.path_following import PathFollower, PathFollowingParams
from inflarm_control.pid_ilc import PidIlcController, PidIlcParams
from inflarm_control.trial_metrics import TrialMetrics
from inflarm_model.alert_regions import regions_of
from inflarm_model.soft_arm import CHAMBERS, Workspace, check_in_workspace
from inflarm_msgs_json import ControlTask, ObstacleSet, PressureCommand, TrialReport
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
              "share of the trial's final PID correction kept in the memory, per axis",
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
    Parameter('knowledge_db_path', '', 'experiential knowledge database seeding new pid_ilc '
              'tasks; empty: none', read_only=True),
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


def task_key(target: np.ndarray) -> tuple[int, int, int]:
    """ILC memories are kept per target, to the millimetre."""
    return tuple(int(v) for v in np.round(np.asarray(target) * 1000.0))


def grown(workspace: Workspace, margin: float) -> Workspace:
    """``workspace`` grown by ``margin`` [m] on every side."""
    return Workspace(f'{workspace.name}, grown by {margin} m', workspace.x_max + margin,
                     workspace.y_max + margin, workspace.z_min - margin,
                     workspace.z_max + margin)


class PressureController(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('pressure_controller', **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        p = self.params
        self.core_params = PidIlcParams(
            kp=tuple(p['gains.kp']), ki=tuple(p['gains.ki']), kd=tuple(p['gains.kd']),
            p_set=tuple(p['limits.p_set_pa']), p_max=tuple(p['limits.p_max_pa']),
            rate_hz=p['rate_hz'], learning_gain=tuple(p['learning.gain']),
            learning_lead_steps=tuple(p['learning.lead_steps']),
            learning_filter_steps=p['learning.filter_steps'],
            learning_dead_band=p['learning.dead_band_m'],
            learning_feedback_gain=tuple(p['learning.feedback_gain']),
            quadrant_bellows=tuple(tuple(q.split(',')) for q in p['quadrant_bellows']))
        self.controller = PidIlcController(n=1, params=self.core_params)
        self.follower = PathFollower(path_following_params(p, self.core_params))
        self.dt = 1.0 / p['rate_hz']
        self.memories = self.load_memories(p['ilc_memory_path'])
        self.knowledge = (KnowledgeDatabase.open(p['knowledge_db_path'])
                          if p['knowledge_db_path'] else None)
        self.measurable = grown(self.core_params.workspace, p['workspace_margin_m'])

        self.position: np.ndarray | None = None
        self.position_time_ns: int | None = None  # node clock
        self.task: ControlTask | None = None
        self.trial_active = False
        self.trial_steps = 0
        self.metrics: TrialMetrics | None = None
        self.following = False  # a path is being followed (or its end held)
        self.command: np.ndarray | None = None  # last published set pressures, held when idle

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
        self.create_guarded_timer(self.dt, self.step)
        self.get_logger().info(
            f"ready: {p['rate_hz']} Hz, {len(self.memories)} ILC memories, knowledge database "
            f"{'loaded' if self.knowledge is not None else 'none'}")

    # -- inputs --------------------------------------------------------------------------------

    def check_frame(self, frame_id: str) -> None:
        if frame_id != self.params['frame_id']:
            raise InputError('frame', f"frame_id '{frame_id}' is not '{self.params['frame_id']}'")

    def on_ball_position(self, msg: PointStamped) -> None:
        point = np.array([msg.point.x, msg.point.y, msg.point.z])
        self.check_frame(msg.header.frame_id)
        check_in_workspace(point, self.measurable, 'ball_position')
        self.position = point
        self.position_time_ns = self.get_clock().now().nanoseconds

    def on_control_task(self, msg: String) -> None:
        task = from_string_msg(msg, expected=ControlTask)
        self.check_frame(task.frame_id)
        self.following = False
        self.start_task(task)

    def on_obstacles(self, msg: String) -> None:
        obstacles = from_string_msg(msg, expected=ObstacleSet)
        self.check_frame(obstacles.frame_id)
        self.follower.set_alert_regions(regions_of(obstacles))
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
        check_in_workspace(waypoints, self.core_params.workspace, 'waypoint')
        if self.position is None:
            raise InputError('path', 'path rejected: no ball_position received yet')
        feedforward, source = None, 'PI alone'
        if self.knowledge is not None:
            try:
                feedforward = np.array([holding_pressure(self.knowledge, w) for w in waypoints])
                source = 'knowledge database feedforward'
            except (KeyError, ValueError) as err:
                self.problems.warn('path', f'no knowledge along the path ({err}): PI alone',
                                   kind='no knowledge')
        held = np.zeros(len(CHAMBERS)) if self.command is None else self.command
        self.abort_trial()
        self.follower.start(waypoints, self.position, held, feedforward)
        self.following = True
        self.get_logger().info(f'following a path of {len(waypoints)} waypoints, '
                               f'{self.follower.length:.3f} m ({source})')

    # -- trials --------------------------------------------------------------------------------

    def start_task(self, task: ControlTask) -> bool:
        """Start a trial of ``task`` from the current position, its outputs starting at the
        held pressures; False (logged) if it can't."""
        if self.position is None:
            self.get_logger().error(
                f'task to {list(task.target)} rejected: no ball_position received yet')
            return False
        target = np.array(task.target)
        memory, source = None, 'PID alone'
        if task.mode == 'pid_ilc' and task_key(target) in self.memories:
            memory, source = self.memories[task_key(target)], 'ILC memory'
        elif task.mode == 'pid_ilc' and self.knowledge is not None:
            try:
                memory, source = seed_memory(self.knowledge, target), 'knowledge database'
            except (KeyError, ValueError) as err:
                self.get_logger().warning(f'no knowledge for this task: {err}')
        initial_output = np.zeros(len(CHAMBERS)) if self.command is None else self.command
        try:
            self.controller.start_trial(self.position, target, memory,
                                        initial_output=initial_output)
        except ValueError as err:
            self.get_logger().error(f'task to {list(task.target)} rejected: {err}')
            return False
        self.task = task
        self.trial_active = True
        self.trial_steps = 0
        self.metrics = TrialMetrics(target, self.params['reach_tolerance_m'])
        self.get_logger().info(f'trial {task.trial_id} ({task.mode}, {source}) to '
                               f'{np.round(target, 4).tolist()}')
        return True

    def step(self) -> None:
        if self.following:
            self.step_path()
            return
        if not self.trial_active:
            if self.command is not None:
                self.publish_command(self.command)  # hold: the MCU vents a silent controller
            return
        fresh = self.fresh_position()
        position = self.position if fresh else np.full(3, np.nan)
        command = self.controller.step(position[None, :], self.dt, valid=[fresh])[0]
        self.publish_command(command)
        self.trial_steps += 1
        elapsed = self.trial_steps * self.dt
        if fresh:
            self.metrics.add(self.position, elapsed)
        if elapsed >= self.params['trial_duration_s']:
            self.finish_trial()

    def fresh_position(self) -> bool:
        """Whether the latest ball position is recent enough to act on (warns if not)."""
        fresh = (self.position_time_ns is not None
                 and (self.get_clock().now().nanoseconds - self.position_time_ns) * 1e-9
                 <= self.params['measurement_timeout_s'])
        if not fresh:
            self.problems.warn('step', 'no fresh ball_position: holding the pressures, '
                                       'not learning', kind='stale')
        return fresh

    def step_path(self) -> None:
        was_at_end = self.follower.at_end
        fresh = self.fresh_position()
        self.publish_command(self.follower.step(self.position, self.dt, valid=fresh))
        if self.follower.at_end and not was_at_end:
            self.get_logger().info('path followed to its end; holding its last waypoint')

    def finish_trial(self) -> None:
        memory = self.controller.finish_trial()[0]
        self.trial_active = False
        self.memories[task_key(self.controller.target[0])] = memory
        self.save_memories()
        rmse = self.metrics.rmse[0]
        reach = [None if math.isinf(t) else float(t) for t in self.metrics.reach_time[0]]
        report = TrialReport(trial_index=self.task.trial_id, rmse=tuple(np.nan_to_num(rmse)),
                             reach_time=tuple(reach))
        self.report_pub.publish(to_string_msg(report))
        self.get_logger().info(
            f'trial {self.task.trial_id} done: RMSE {np.round(rmse * 1000, 1).tolist()} mm, '
            f'reach time {reach} s; holding')

    def publish_command(self, command: np.ndarray) -> None:
        self.command = command
        chambers = dict(zip(CHAMBERS, command.tolist(), strict=True))
        self.command_pub.publish(to_string_msg(PressureCommand(chambers=chambers)))

    # -- services ------------------------------------------------------------------------------

    def on_start_trial(self, request, response):
        if self.task is None:
            response.success, response.message = False, 'no task yet: publish a control_task'
            return response
        task = ControlTask(frame_id=self.task.frame_id, target=self.task.target,
                           mode=self.task.mode, trial_id=self.task.trial_id + 1)
        self.following = False
        response.success = self.start_task(task)
        response.message = f'trial {task.trial_id} started' if response.success else 'rejected'
        return response

    def abort_trial(self) -> None:
        if self.trial_active:
            self.controller.finish_trial()  # discarded: an aborted trial teaches nothing
            self.trial_active = False
        self.following = False

    def on_stop(self, request, response):
        self.abort_trial()
        response.success, response.message = True, 'stopped; holding the last pressures'
        self.get_logger().info(response.message)
        return response

    def on_vent(self, request, response):
        self.abort_trial()
        self.publish_command(np.zeros(len(CHAMBERS)))
        response.success, response.message = True, 'venting every chamber'
        self.get_logger().info(response.message)
        return response

    def on_reset_learning(self, request, response):
        count = len(self.memories)
        self.memories.clear()
        self.save_memories()
        response.success, response.message = True, f'forgot {count} ILC memories'
        self.get_logger().info(response.message)
        return response

    # -- ILC memory file -----------------------------------------------------------------------

    def load_memories(self, path: str) -> dict[tuple[int, int, int], np.ndarray]:
        if not path or not os.path.exists(path):
            return {}
        try:
            with np.load(path) as data:
                keys, memories = data['targets_mm'], data['memories']
            shape = (len(keys), self.core_params.memory_steps, len(CHAMBERS))
            if keys.shape != (len(keys), 3) or memories.shape != shape:
                raise ValueError(f'arrays of shape {keys.shape} and {memories.shape}')
        except (OSError, KeyError, ValueError) as err:
            raise ValueError(f"ilc_memory_path '{path}' is not an ILC memory file: {err}") from err
        return {tuple(int(v) for v in key): memory for key, memory in zip(keys, memories,
                                                                           strict=True)}

    def save_memories(self) -> None:
        path = self.params['ilc_memory_path']
        if not path:
            return
        shape = (0, self.core_params.memory_steps, len(CHAMBERS))
        keys = np.array(list(self.memories), dtype=np.int64).reshape(-1, 3)
        memories = np.array(list(self.memories.values())).reshape(-1, *shape[1:])
        tmp = path + '.tmp.npz'
        np.savez(tmp, targets_mm=keys, memories=memories)
        os.replace(tmp, path)  # atomic: a crash never leaves half a file


def main(args: list[str] | None = None) -> None:
    spin_node(PressureController, args)


if __name__ == '__main__':
    main()
