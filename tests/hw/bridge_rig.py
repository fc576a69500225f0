"""hw_bridge and sim_mcu as real processes on a pty, and a probe node talking to them over DDS."""

import math
import time

from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.srv import ChangeState, GetState
import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_msgs_json import LinkStatus, PressureCommand, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import COMMAND_QOS, LATCHED_QOS, RELIABLE_QOS
from ros_harness import wait_until

MOTORS = ['joint_1', 'joint_2', 'joint_3']


class Rig:
    """sim_mcu (plant ``plant``) behind ``tmp_path/mcu``, hw_bridge on it (autostart)."""

    def __init__(self, node_processes, executor, tmp_path, plant='both', bridge=None, sim=None,
                 start_bridge=True) -> None:
        self.processes, self.executor = node_processes, executor
        self.link = str(tmp_path / 'mcu')
        self.start_sim(plant, sim)
        self.bridge_parameters = {'port': self.link, 'autostart': True, **(bridge or {})}
        if start_bridge:
            node_processes.start('inflarm_hw', 'hw_bridge', parameters=self.bridge_parameters)
        probe = self.probe = rclpy.create_node('probe', context=executor.context)
        self.statuses, self.joints, self.chambers, self.links, self.diagnostics = \
            [], [], [], [], []
        probe.create_subscription(String, '/hw_bridge/status', lambda m: self.statuses.append(
            (time.monotonic(), decode(m.data))), LATCHED_QOS)
        probe.create_subscription(JointState, 'joint_states', self.joints.append, RELIABLE_QOS)
        probe.create_subscription(String, 'chamber_pressures', lambda m: self.chambers.append(
            decode(m.data).as_dict()), RELIABLE_QOS)
        probe.create_subscription(String, 'link_pressures', lambda m: self.links.append(
            decode(m.data).as_dict()), RELIABLE_QOS)
        probe.create_subscription(DiagnosticArray, 'diagnostics',
                                  lambda m: self.diagnostics.append((time.monotonic(), m)),
                                  RELIABLE_QOS)
        self.motor_pub = probe.create_publisher(JointState, 'motor_position_command',
                                                COMMAND_QOS)
        self.pressure_pub = probe.create_publisher(String, 'chamber_pressure_command',
                                                   COMMAND_QOS)
        self.link_status_pub = probe.create_publisher(String, 'link_status', RELIABLE_QOS)
        # Clients made once, here: a reply to a client that is only milliseconds old can be
        # dropped (rmw_fastrtps waits 100 ms for its reader to match, ros2/rmw_fastrtps#467).
        self.parameter_clients = {
            node: AsyncParameterClient(probe, node) for node in ('sim_mcu', 'hw_bridge')}
        self.clients = {name: probe.create_client(service_type, name) for service_type, name in (
            (Trigger, '/hw_bridge/reset_fault'), (ChangeState, '/hw_bridge/change_state'),
            (GetState, '/hw_bridge/get_state'))}
        executor.add_node(probe)
        self.pressures: dict | None = None
        self.motors: list | None = None
        self.last_command = 0.0

    def start_sim(self, plant='both', sim=None, name='sim_mcu') -> None:
        start = len(self.processes.output())
        self.processes.start('inflarm_hw', 'sim_mcu', name=name, parameters={
            'plant': plant, 'link': self.link, 'seed': 7, **(sim or {})})
        assert wait_until(lambda: 'sim_mcu: serial port' in self.processes.output()[start:],
                          20.0), self.processes.output()

    @property
    def status(self):
        return self.statuses[-1][1] if self.statuses else None

    def chamber(self, name: str) -> float:
        """The latest measured pressure of chamber ``name`` [Pa]; NaN before the first (a
        status can arrive before any chamber_pressures message)."""
        return self.chambers[-1][name] if self.chambers else math.nan

    def run(self, until=lambda: False, timeout_s=10.0, period_s=0.1) -> bool:
        """Spin, sending the current commands every ``period_s``, until ``until()`` or timeout."""
        deadline = time.monotonic() + timeout_s
        while not until():
            now = time.monotonic()
            if now > deadline:
                return False
            if now - self.last_command >= period_s and (self.pressures or self.motors):
                self.send()
            self.executor.spin_once(timeout_sec=0.005)
        return True

    def send(self) -> None:
        if self.pressures:
            self.pressure_pub.publish(to_string_msg(PressureCommand(chambers=self.pressures)))
        if self.motors:
            self.motor_pub.publish(JointState(name=MOTORS, position=list(self.motors)))
        self.last_command = time.monotonic()

    def wait_status(self, predicate, timeout_s=10.0, **kwargs):
        assert self.run(lambda: self.status is not None and predicate(self.status), timeout_s,
                        **kwargs), (self.status, self.processes.output()[-3000:])
        return self.statuses[-1]

    def set_parameters(self, node: str, parameters: list[Parameter]) -> None:
        """Set ``parameters`` of ``node`` (sim_mcu or hw_bridge) at once; they must be accepted."""
        client = self.parameter_clients[node]
        assert client.wait_for_services(timeout_sec=10.0), node
        future = client.set_parameters_atomically(parameters)
        assert self.run(future.done, timeout_s=10.0), f'{node}: no reply'
        assert future.result().result.successful, future.result()

    def inject(self, kind, channel=0, value=0.0, duration_s=0.0) -> None:
        self.set_parameters('sim_mcu', [
            Parameter('fault.channel', value=channel),
            Parameter('fault.value', value=float(value)),
            Parameter('fault.duration_s', value=float(duration_s)),
            Parameter('fault.kind', value=kind)])

    def call(self, name, request, resend_s: float | None = None):
        """The reply to ``request``; a query (``resend_s``) is sent again when no reply came
        within so long. A service that has not yet matched the client's reply reader drops the
        reply (rmw_fastrtps waits for it up to max_blocking_time, 100 ms by default:
        ros2/rmw_fastrtps#390, #704). Transitions are not resent: one must not run twice."""
        client = self.clients[name]
        assert client.wait_for_service(timeout_sec=10.0), name
        deadline = time.monotonic() + 10.0
        while True:
            future = client.call_async(request)
            timeout_s = min(resend_s or math.inf, deadline - time.monotonic())
            if self.run(future.done, timeout_s=timeout_s):
                return future.result()
            client.remove_pending_request(future)
            assert time.monotonic() < deadline, f'{name}: no reply'

    def reset_fault(self) -> Trigger.Response:
        return self.call('/hw_bridge/reset_fault', Trigger.Request())

    def transition(self, transition_id: int) -> bool:
        request = ChangeState.Request()
        request.transition.id = transition_id
        return self.call('/hw_bridge/change_state', request).success

    def lifecycle_state(self) -> str:
        return self.call('/hw_bridge/get_state', GetState.Request(),
                         resend_s=2.0).current_state.label

    def publish_link_status(self, link, moment) -> None:
        self.link_status_pub.publish(to_string_msg(
            LinkStatus.from_moments(link, 50e3, 10.0, moment)))
