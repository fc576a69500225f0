"""Repeats one control task as a series of learning trials, as in section 3.3 of 001_...

Each cycle vents the arm through the pressure controller (``~/vent``: every chamber at 0 Pa, so
the arm returns to rest and the trial's outputs start at 0 kPa, eq. 3), waits
``settle_time_s``, then runs trial ``i`` to ``target`` in ``mode``; the controller reports each
trial and this node logs the per-axis reach time and RMSE, trial after trial.

Subscribes:
    trial_report (std_msgs/String: TrialReport JSON, RELIABLE_QOS)
Publishes:
    control_task (std_msgs/String: ControlTask JSON, RELIABLE_QOS)
Calls:
    pressure_controller/vent (std_srvs/Trigger)
Parameters:
    target (double[3], read-only): target point [m] in ``frame_id``.
    trials (int, read-only): number of trials to run.
    mode (string, read-only): 'pid' or 'pid_ilc'.
    settle_time_s (double): rest between venting and the next trial [s], node clock.
    report_timeout_s (double): start the cycle again when a report is this late [s], node
        clock (simulated time with ``use_sim_time``).
    frame_id (string, read-only).
"""

from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_msgs_json import ControlTask, TrialReport
from inflarm_msgs_json.ros.conversions import from_string_msg, to_string_msg
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import RELIABLE_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node

PARAMETERS = (
    Parameter('target', [0.100, 0.110, 0.670], 'target point [m] (Fig 7)', read_only=True),
    Parameter('trials', 30, 'number of trials', range=(1, 10000), read_only=True),
    Parameter('mode', 'pid_ilc', "'pid' or 'pid_ilc'", read_only=True),
    Parameter('settle_time_s', 8.0, 'rest after venting, before the next trial [s]',
              range=(0.0, 600.0)),
    Parameter('report_timeout_s', 120.0, 'restart the cycle when a report is this late [s]',
              range=(1.0, 3600.0)),
    Parameter('frame_id', 'sra_mount', 'frame of the target', read_only=True),
)


class TrialRunner(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('trial_runner', **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        p = self.params
        # Validated once at startup: a bad parameter stops the node with its reason.
        self.task = ControlTask(frame_id=p['frame_id'], target=tuple(p['target']),
                                mode=p['mode'], trial_id=0)
        self.trial = 0
        self.phase = 'vent'  # vent -> settle -> run -> vent ...; 'done' at the end
        self.phase_since = self.get_clock().now()  # the node clock: simulated time too
        self.task_pub = self.create_publisher(
            String, 'control_task', RELIABLE_QOS,
            event_callbacks=publisher_events(self, 'control_task'))
        self.create_guarded_subscription(String, 'trial_report', self.on_report, RELIABLE_QOS)
        self.vent_client = self.create_client(Trigger, 'pressure_controller/vent')
        self.create_guarded_timer(0.2, self.tick)
        self.get_logger().info(f"ready: {p['trials']} {p['mode']} trials to {p['target']}")

    def enter(self, phase: str) -> None:
        self.phase = phase
        self.phase_since = self.get_clock().now()

    def tick(self) -> None:
        in_phase = (self.get_clock().now() - self.phase_since).nanoseconds * 1e-9
        if self.phase == 'vent' and self.vent_client.service_is_ready():
            self.vent_client.call_async(Trigger.Request())
            self.enter('settle')
        elif self.phase == 'settle' and in_phase >= self.params['settle_time_s']:
            self.task_pub.publish(to_string_msg(ControlTask(
                frame_id=self.task.frame_id, target=self.task.target, mode=self.task.mode,
                trial_id=self.trial)))
            self.enter('run')
        elif self.phase == 'run' and in_phase >= self.params['report_timeout_s']:
            self.get_logger().warning(
                f'no report of trial {self.trial} after {in_phase:.0f} s: starting it again')
            self.enter('vent')

    def on_report(self, msg: String) -> None:
        report = from_string_msg(msg, expected=TrialReport)
        if self.phase != 'run' or report.trial_index != self.trial:
            return
        reach = ', '.join('--' if t is None else f'{t:.1f}' for t in report.reach_time)
        rmse = ', '.join(f'{e * 1000:.1f}' for e in report.rmse)
        self.get_logger().info(
            f'trial {self.trial}: reach time x, y, z [s] = {reach}; RMSE [mm] = {rmse}')
        self.trial += 1
        if self.trial == self.params['trials']:
            self.get_logger().info('all trials done')
            self.enter('done')
        else:
            self.enter('vent')


def main(args: list[str] | None = None) -> None:
    spin_node(TrialRunner, args)


if __name__ == '__main__':
    main()
