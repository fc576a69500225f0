"""trial_runner in-process against a stand-in controller: vent, task, report, next trial."""

import rclpy
from rclpy.parameter import Parameter
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
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


def test_the_settle_time_is_measured_on_the_node_clock(executor):
    # simulated time at half the wall clock's rate: the rest after venting must last
    # settle_time_s of *simulated* time (a paused or slow simulation rests as long in its time)
    settle_s = 2.0
    runner = TrialRunner(context=executor.context, parameter_overrides=[
        Parameter('trials', value=1), Parameter('settle_time_s', value=settle_s),
        Parameter('use_sim_time', value=True)])
    controller = rclpy.create_node('pressure_controller', context=executor.context)
    clock_pub = controller.create_publisher(Clock, '/clock', 10)
    sim_ns = [1_000_000_000_000]
    sim_at: dict[str, float] = {}

    def tick() -> None:
        sim_ns[0] += 25_000_000  # 25 ms every 50 ms
        clock_pub.publish(Clock(clock=Time(nanoseconds=sim_ns[0]).to_msg()))

    def on_vent(request, response):
        sim_at.setdefault('vent', sim_ns[0] * 1e-9)
        response.success = True
        return response

    controller.create_timer(0.05, tick)
    controller.create_service(Trigger, '~/vent', on_vent)
    controller.create_subscription(
        String, 'control_task', lambda msg: sim_at.setdefault('task', sim_ns[0] * 1e-9),
        RELIABLE_QOS)
    executor.add_node(runner)
    executor.add_node(controller)

    assert spin_until(executor, lambda: 'task' in sim_at, timeout_s=30.0), sim_at
    # the runner decides at its 0.2 s ticks; the vent's stamp may trail its call by a tick
    assert sim_at['task'] - sim_at['vent'] >= settle_s - 0.1, sim_at
