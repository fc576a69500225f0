"""trial_runner in-process against a stand-in controller: vent, task, report, next trial."""

import rclpy
from rclpy.parameter import Parameter
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_control.nodes.trial_runner import TrialRunner
from inflarm_msgs_json import ControlTask, TrialReport, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import RELIABLE_QOS
from ros_harness import spin_until


def test_runs_the_configured_trials_venting_between_them(executor):
    runner = TrialRunner(context=executor.context, parameter_overrides=[
        Parameter('trials', value=3), Parameter('settle_time_s', value=0.0),
        Parameter('target', value=[0.05, -0.05, 0.7])])
    controller = rclpy.create_node('pressure_controller', context=executor.context)
    events: list[str] = []
    tasks: list[ControlTask] = []
    report_pub = controller.create_publisher(String, 'trial_report', RELIABLE_QOS)

    def on_vent(request, response):
        events.append('vent')
        response.success = True
        return response

    def on_task(msg: String) -> None:
        task = decode(msg.data, expected=ControlTask)
        tasks.append(task)
        events.append(f'task {task.trial_id}')
        report_pub.publish(to_string_msg(TrialReport(
            trial_index=task.trial_id, rmse=(0.01, 0.01, 0.01), reach_time=(1.0, None, 2.0))))

    controller.create_service(Trigger, '~/vent', on_vent)
    controller.create_subscription(String, 'control_task', on_task, RELIABLE_QOS)
    executor.add_node(runner)
    executor.add_node(controller)

    assert spin_until(executor, lambda: runner.phase == 'done', timeout_s=20.0), events
    assert events == ['vent', 'task 0', 'vent', 'task 1', 'vent', 'task 2']
    assert all(t.target == (0.05, -0.05, 0.7) and t.mode == 'pid_ilc' for t in tasks)
