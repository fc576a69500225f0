"""Hardware bridge to the MCU: a lifecycle node in front of the serial driver, fail-safe.

The same topics as the simulators (``arm_sim``, ``sra_sim``), so the rest of the system does not
know which it talks to. The lifecycle follows ros2_control's hardware components: configure opens
the port and checks the MCU's protocol version (`inflarm_hw.driver`), activate lets the outputs
follow the commands, and deactivate, cleanup, shutdown and error all command the safe output
first (motors hold or zero torque, chamber valves to the safe pressure). Every safety rule lives
in `inflarm_hw.bridge` (README: "Hardware bridge"). With ``autostart`` the node configures and
activates itself, retrying configure until the MCU answers (no lifecycle manager needed).

Subscribes (from configure on):
    motor_position_command (sensor_msgs/JointState, COMMAND_QOS): targets [rad] of some of
        joint_1..joint_3 by name, optional velocity feed-forward [rad/s].
    chamber_pressure_command (std_msgs/String: PressureCommand JSON, COMMAND_QOS): set
        pressures [Pa] of some of PEA, B1..B4; unnamed chambers keep theirs.
    link_status (std_msgs/String: LinkStatus JSON, RELIABLE_QOS): bending moment per link,
        from load_estimator, for the wrinkling check.
Publishes (for the channels the MCU has, from configure on, one message per MCU report):
    joint_states (sensor_msgs/JointState, JOINT_STATE_QOS): joint_1..joint_3 positions [rad],
        velocities [rad/s], and in ``effort`` the torque each motor applies to its joint [N m]
        (ros2_control convention; the negative of the load torque tau_m of eq. 6 of 000_...).
    chamber_pressures (std_msgs/String: ChamberPressures JSON, RELIABLE_QOS): measured [Pa].
    link_pressures (std_msgs/String: LinkPressures JSON, RELIABLE_QOS): measured [Pa].
    ~/status (std_msgs/String: HardwareStatus JSON, LATCHED_QOS): outputs, link, faults; on
        every change, and at least once a second while configured. Without an MCU
        (unconfigured, finalized) link 'closed', outputs 'none', and after a failed configure
        the fault 'configure_failed' with the reason; published at start and after every
        transition and configure attempt (autostart: every autostart_retry_s).
    diagnostics (diagnostic_msgs/DiagnosticArray, RELIABLE_QOS): about 1 Hz, always.
Services:
    ~/reset_fault (std_srvs/Trigger): clear the latched faults once their cause is gone.
    lifecycle_msgs services (~/change_state, ~/get_state, ...), from rclpy's LifecycleNode.
Parameters (read at configure unless noted; the limits' ranges are safe ranges):
    port (string): serial device, e.g. the pty (or its symlink) of sim_mcu.
    baudrate (int), rate_hz (double): line speed; read/write cycle rate.
    autostart (bool, read-only), autostart_retry_s (double, read-only).
    handshake_timeout_s, link_timeout_s, mcu_watchdog_s, reconnect_period_s (double).
    cmd_timeout_s (double): command watchdog.
    limits.* (double, double[3]): joint limits, slew, chamber and link pressure limits and
        trip levels, frozen-sensor time.
    safe_output.motors (string: hold | zero_torque), safe_output.chamber_pressure_pa,
        safe_output.link_fault_pressure_pa (double).
    wrinkle.margin, wrinkle.status_timeout_s (double).
    valve.* (double, read-only): eq. 2 range and dead zone of the valves.
    arm.link_pressure_pa (double[2], runtime): link set points; arm.link_radius_m (read-only).
"""

import time

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from inflarm_hw.bridge import LINKS, MOTORS, BridgeConfig, SafetySupervisor
from inflarm_hw.driver import (
    HEARTBEAT_PERIOD_S,
    DriverConfig,
    LinkState,
    McuDriver,
    McuError,
)
from inflarm_hw.valve import ValveModel
from inflarm_model.nodes.arm_parameters import ARM_PARAMETERS
from inflarm_model.soft_arm import CHAMBER_MAX_PRESSURE, CHAMBERS
from inflarm_model.urdf import JOINT_LIMITS
from inflarm_msgs_json import (
    ChamberPressures,
    HardwareStatus,
    LinkPressures,
    LinkStatus,
    MessageError,
    PressureCommand,
)
from inflarm_msgs_json.ros.conversions import from_string_msg, to_string_msg
from inflarm_msgs_json.ros.diagnostics import ERROR, OK, WARN, DiagnosticsPublisher
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import (
    COMMAND_QOS,
    JOINT_STATE_QOS,
    LATCHED_QOS,
    RELIABLE_QOS,
    publisher_events,
)
from inflarm_msgs_json.ros.spin import spin_node

_ARM = {p.name: p for p in ARM_PARAMETERS}
PARAMETERS = (
    Parameter('port', '', 'serial device of the MCU (sim_mcu prints its pty) [read at '
              'configure]'),
    Parameter('baudrate', 921600, 'serial line speed [bit/s]', range=(9600, 12000000)),
    Parameter('rate_hz', 100.0, 'read/write cycle rate [Hz]', range=(10.0, 1000.0),
              read_only=True),
    Parameter('autostart', False, 'configure and activate at start, retrying configure (node '
              'default false: wait for a lifecycle manager; the launcher sets true)',
              read_only=True),
    Parameter('autostart_retry_s', 0.5, 'autostart: retry configure this often [s]',
              range=(0.05, 10.0), read_only=True),
    Parameter('handshake_timeout_s', 0.5, 'longest wait for the MCU to answer HELLO [s]',
              range=(0.01, 5.0)),
    Parameter('link_timeout_s', 0.25, 'link lost after this long without a valid frame [s]',
              range=(0.02, 2.0)),
    Parameter('mcu_watchdog_s', 0.25, "the MCU's own command watchdog, set at the handshake "
              '[s]', range=(0.02, 2.0)),
    Parameter('reconnect_period_s', 0.5, 'after a link loss, try to reconnect this often [s]',
              range=(0.05, 10.0)),
    Parameter('cmd_timeout_s', 1.0, 'safe output after this long without a command [s]',
              range=(0.05, 2.0)),
    Parameter('limits.position_min_rad', [JOINT_LIMITS[m][0] for m in MOTORS],
              'lower joint limits of joint_1..joint_3 [rad]; commands below are rejected'),
    Parameter('limits.position_max_rad', [JOINT_LIMITS[m][1] for m in MOTORS],
              'upper joint limits of joint_1..joint_3 [rad]; commands above are rejected'),
    Parameter('limits.max_velocity_rad_s', 1.0, 'motor slew limit and largest feed-forward '
              '[rad/s]', range=(0.01, 10.0)),
    Parameter('limits.chamber_pressure_max_pa', CHAMBER_MAX_PRESSURE, 'chamber rating: a '
              'command with a set point outside [0, this] is rejected whole [Pa]',
              range=(1000.0, 500000.0)),
    Parameter('limits.chamber_over_pressure_pa', 130000.0, 'a chamber reading above this '
              'vents and latches over_pressure [Pa]', range=(1000.0, 600000.0)),
    Parameter('limits.link_pressure_min_pa', 10000.0, 'lowest link set point [Pa]',
              range=(0.0, 100000.0)),
    Parameter('limits.link_pressure_max_pa', 60000.0, 'highest link set point [Pa]',
              range=(1000.0, 100000.0)),
    Parameter('limits.link_over_pressure_pa', 70000.0, 'a link reading above this vents and '
              'latches over_pressure [Pa]', range=(1000.0, 150000.0)),
    Parameter('limits.pressure_rate_pa_s', 500000.0, 'slew limit of every pressure set point '
              '[Pa/s]', range=(1000.0, 5000000.0)),
    Parameter('limits.frozen_sensor_s', 0.5, 'a pressure reading unchanged this long latches '
              'frozen_sensor [s]; 0: off', range=(0.0, 10.0)),
    Parameter('safe_output.motors', 'hold', "safe motor output: 'hold' or 'zero_torque'"),
    Parameter('safe_output.chamber_pressure_pa', 0.0, 'chamber set point while safe [Pa] '
              '(0: vent)', range=(0.0, 500000.0)),
    Parameter('safe_output.link_fault_pressure_pa', 0.0, 'link set point on a link sensor '
              'fault [Pa] (0: vent); other safe outputs keep the links inflated',
              range=(0.0, 100000.0)),
    Parameter('wrinkle.margin', 0.2, 'warn below (1 + margin) x the wrinkle-safe link pressure',
              range=(0.0, 1.0)),
    Parameter('wrinkle.status_timeout_s', 1.0, 'ignore link_status older than this [s]',
              range=(0.01, 10.0)),
    Parameter('valve.voltage_min_v', 0.0, 'U_min of eq. 2 [V]', range=(-10.0, 10.0),
              read_only=True),
    Parameter('valve.voltage_max_v', 10.0, 'U_max of eq. 2 [V]', range=(0.1, 24.0),
              read_only=True),
    Parameter('valve.pressure_min_pa', 5000.0, 'P_min of eq. 2 [Pa] (ITV2050: 0.005 MPa)',
              range=(0.0, 1e7), read_only=True),
    Parameter('valve.pressure_max_pa', 900000.0, 'P_max of eq. 2 [Pa] (ITV2050: 0.9 MPa)',
              range=(1000.0, 1e7), read_only=True),
    Parameter('valve.dead_zone_pa', 4000.0, 'valve outputs below this are 0 [Pa] (4 kPa)',
              range=(0.0, 100000.0), read_only=True),
    _ARM['arm.link_pressure_pa'],
    _ARM['arm.link_radius_m'],
)
# The parameters read at configure (all but those applied at runtime or read-only).
_RUNTIME = {'arm.link_pressure_pa'}


def bridge_config(p: dict) -> BridgeConfig:
    """The safety configuration the parameter values ``p`` describe; ``ValueError`` if unsafe
    or inconsistent (the message names the value)."""
    valve = ValveModel(p['valve.voltage_min_v'], p['valve.voltage_max_v'],
                       p['valve.pressure_min_pa'], p['valve.pressure_max_pa'],
                       p['valve.dead_zone_pa'])
    return BridgeConfig(
        cmd_timeout_s=p['cmd_timeout_s'],
        position_min=tuple(p['limits.position_min_rad']),
        position_max=tuple(p['limits.position_max_rad']),
        max_velocity=p['limits.max_velocity_rad_s'],
        chamber_pressure_max=p['limits.chamber_pressure_max_pa'],
        chamber_over_pressure=p['limits.chamber_over_pressure_pa'],
        link_pressure=tuple(p['arm.link_pressure_pa']),
        link_pressure_min=p['limits.link_pressure_min_pa'],
        link_pressure_max=p['limits.link_pressure_max_pa'],
        link_over_pressure=p['limits.link_over_pressure_pa'],
        pressure_rate=p['limits.pressure_rate_pa_s'],
        safe_motors=p['safe_output.motors'],
        safe_chamber_pressure=p['safe_output.chamber_pressure_pa'],
        link_fault_pressure=p['safe_output.link_fault_pressure_pa'],
        frozen_sensor_s=p['limits.frozen_sensor_s'],
        wrinkle_margin=p['wrinkle.margin'],
        wrinkle_status_timeout_s=p['wrinkle.status_timeout_s'],
        link_radius=p['arm.link_radius_m'],
        chamber_valve=valve, link_valve=valve)


def driver_config(p: dict) -> DriverConfig:
    """The driver configuration of the parameter values ``p``; ``ValueError`` if invalid."""
    if not p['port']:
        raise ValueError('port is not set: pass the MCU serial device, e.g. -p port:=/dev/pts/5')
    return DriverConfig(p['port'], p['baudrate'], p['handshake_timeout_s'], p['link_timeout_s'],
                        p['mcu_watchdog_s'])


def check_bridge_parameters(p: dict) -> None:
    """Raise ValueError naming the first bad parameter (the driver's only with a ``port``)."""
    bridge_config(p)
    if p['port']:
        driver_config(p)


class HwBridge(GuardedCallbacks, LifecycleNode):

    def __init__(self, **kwargs) -> None:
        super().__init__('hw_bridge', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, check=check_bridge_parameters,
                                         on_set=self.on_parameters_set)
        check_bridge_parameters(self.params)  # bad values fail at start, naming the parameter
        self.lifecycle = 'unconfigured'
        self.driver: McuDriver | None = None
        self.supervisor: SafetySupervisor | None = None
        self._entities: list = []
        self._timer = None
        self._next_reconnect = 0.0
        self._last_heartbeat = 0.0
        self._last_status = None
        self._last_status_time = 0.0
        self._configure_error: str | None = None  # why the last configure failed
        self.status_pub = self.create_publisher(String, '~/status', LATCHED_QOS)
        self.diagnostics = DiagnosticsPublisher(self, self.diagnostic_status)
        self.create_guarded_service(Trigger, '~/reset_fault', self.on_reset_fault)
        self._autostart = None
        if self.params['autostart']:
            self._autostart = self.create_guarded_timer(self.params['autostart_retry_s'],
                                                        self.try_autostart)
        self.publish_status(force=True)
        self.get_logger().info(
            f"ready: unconfigured, port '{self.params['port']}'"
            + (', autostart' if self.params['autostart'] else ''))

    # -- parameters -----------------------------------------------------------------------------

    def on_parameters_set(self, changed: dict) -> None:
        for name, value in changed.items():
            if name == 'arm.link_pressure_pa' and self.supervisor is not None:
                self.supervisor.set_link_pressure(value)
                self.get_logger().info(f'link set points now {list(value)} Pa')
            elif name not in _RUNTIME:
                self.get_logger().info(f'{name} takes effect at the next configure')

    # -- lifecycle ------------------------------------------------------------------------------

    def try_autostart(self) -> None:
        if self.lifecycle == 'unconfigured':
            self.trigger_configure()
        if self.lifecycle == 'inactive':
            self.trigger_activate()
        if self.lifecycle != 'unconfigured':
            self._autostart.cancel()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            config = bridge_config(self.params)
            driver = McuDriver(driver_config(self.params))
            info = driver.open()
        except (ValueError, McuError) as err:
            self.problems.warn('configure', f'configure failed: {err}')
            self._configure_error = str(err)
            self.publish_status()  # on a change of the reason, and once a second
            return TransitionCallbackReturn.FAILURE
        self._configure_error = None
        self.driver = driver
        self.supervisor = SafetySupervisor(config, info)
        self._make_entities(info)
        self._timer = self.create_guarded_timer(1.0 / self.params['rate_hz'], self.cycle)
        self.lifecycle = 'inactive'
        self.get_logger().info(
            f"configured: MCU on {self.params['port']}, protocol {info.protocol_version}, "
            f'firmware {info.firmware_version}, watchdog {info.watchdog_s * 1000:.0f} ms, '
            f'{info.n_motors} motors, {info.n_chambers} chamber valves, {info.n_links} link '
            'valves; outputs safe until activated')
        self.publish_status(force=True)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.lifecycle = 'active'
        self.get_logger().info('active: outputs follow fresh commands')
        self.publish_status(force=True)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.lifecycle = 'inactive'
        self.write_safe('deactivate')
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.release('cleanup')
        self.lifecycle = 'unconfigured'
        self.publish_status(force=True)
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.release('shutdown')
        self.lifecycle = 'finalized'
        self.publish_status(force=True)
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.get_logger().error(f'error in a transition from {state.label}: safe output, port '
                                'closed')
        self.release('error')
        self.lifecycle = 'unconfigured'
        self.publish_status(force=True)
        return TransitionCallbackReturn.SUCCESS

    def destroy_node(self) -> None:
        self.release('node destroyed')
        super().destroy_node()

    def write_safe(self, why: str) -> None:
        """Command the safe output now (motors hold or zero torque, valves safe)."""
        driver, supervisor = self.driver, self.supervisor
        if driver is None or supervisor is None:
            return
        if driver.state is not LinkState.CONNECTED:
            self.get_logger().warning(f'{why}: the MCU is not connected; its watchdog makes '
                                      'the outputs safe')
            return
        try:
            supervisor.sent(driver.write(supervisor.output(time.monotonic(), enabled=False)))
            self.get_logger().info(f'{why}: safe output commanded')
        except McuError as err:
            self.get_logger().warning(f'{why}: safe output not sent ({err}); the MCU watchdog '
                                      'makes the outputs safe')
        self.log_events()

    def release(self, why: str) -> None:
        """Safe output, then close the port and drop the topics."""
        self.write_safe(why)
        if self.driver is not None:
            self.driver.close()
        self.driver = self.supervisor = None
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        for destroy, entity in self._entities:
            destroy(entity)
        self._entities = []

    def _make_entities(self, info) -> None:
        self.joint_pub = self.chamber_pub = self.link_pub = None
        entities = []
        if info.n_motors:
            self.joint_pub = self.create_publisher(
                JointState, 'joint_states', JOINT_STATE_QOS,
                event_callbacks=publisher_events(self, 'joint_states'))
            entities += [(self.destroy_publisher, self.joint_pub),
                         (self.destroy_subscription, self.create_guarded_subscription(
                             JointState, 'motor_position_command', self.on_motor_command,
                             COMMAND_QOS))]
        if info.n_links:
            self.link_pub = self.create_publisher(
                String, 'link_pressures', RELIABLE_QOS,
                event_callbacks=publisher_events(self, 'link_pressures'))
            entities += [(self.destroy_publisher, self.link_pub),
                         (self.destroy_subscription, self.create_guarded_subscription(
                             String, 'link_status', self.on_link_status, RELIABLE_QOS))]
        if info.n_chambers:
            self.chamber_pub = self.create_publisher(
                String, 'chamber_pressures', RELIABLE_QOS,
                event_callbacks=publisher_events(self, 'chamber_pressures'))
            entities += [(self.destroy_publisher, self.chamber_pub),
                         (self.destroy_subscription, self.create_guarded_subscription(
                             String, 'chamber_pressure_command', self.on_pressure_command,
                             COMMAND_QOS))]
        self._entities = entities

    # -- inputs ---------------------------------------------------------------------------------

    def on_motor_command(self, msg: JointState) -> None:
        if self.supervisor is None:
            return
        try:  # a rejected command raises: the guard reports it under the topic
            self.supervisor.on_motor_command(msg.name, msg.position, msg.velocity,
                                             time.monotonic())
        finally:
            self.log_events()

    def on_pressure_command(self, msg: String) -> None:
        if self.supervisor is None:
            return
        try:
            command = from_string_msg(msg, expected=PressureCommand).as_dict()
        except MessageError:
            self.supervisor.rejected += 1
            raise
        self.supervisor.on_pressure_command(command, time.monotonic())

    def on_link_status(self, msg: String) -> None:
        if self.supervisor is None:
            return
        status = from_string_msg(msg, expected=LinkStatus)
        self.supervisor.on_link_status(status, time.monotonic())

    def on_reset_fault(self, request, response):
        if self.supervisor is None:
            response.success, response.message = False, f'not configured ({self.lifecycle})'
        else:
            response.success, response.message = self.supervisor.reset_faults(time.monotonic())
        self.get_logger().info(f'reset_fault: {response.message}')
        self.log_events()
        self.publish_status(force=True)
        return response

    # -- the read/write cycle ------------------------------------------------------------------

    def cycle(self) -> None:
        driver, supervisor = self.driver, self.supervisor
        if driver is None or supervisor is None:
            return
        now = time.monotonic()
        if driver.state is LinkState.CLOSED:
            if now < self._next_reconnect:
                supervisor.output(now, enabled=False)  # what the MCU's watchdog does now
                self.log_events()
                self.publish_status()
                return
            try:
                driver.connect()
            except McuError as err:
                self._lost(str(err), now)
                return
        handshaking = driver.state is LinkState.HANDSHAKE
        try:
            reading = driver.read()
            if handshaking and driver.state is LinkState.CONNECTED:
                supervisor.on_link_restored(driver.info, now)
            if driver.state is LinkState.CONNECTED:
                if reading.state is not None:
                    supervisor.on_state(reading.state, now)
                    self.publish_state(reading.state)
                for fault in reading.faults:
                    supervisor.on_mcu_fault(fault)
                supervisor.sent(driver.write(supervisor.output(
                    now, enabled=self.lifecycle == 'active')))
                if now - self._last_heartbeat >= HEARTBEAT_PERIOD_S:
                    self._last_heartbeat = now
                    driver.heartbeat()
        except (McuError, ValueError) as err:
            self._lost(str(err), now)
        self.log_events()
        self.publish_status()

    def _lost(self, reason: str, now: float) -> None:
        self.driver.close()
        self.supervisor.on_link_lost(reason, now)
        self.supervisor.output(now, enabled=False)  # not written: the link is down
        self._next_reconnect = now + self.params['reconnect_period_s']
        self.log_events()
        self.publish_status()

    def publish_state(self, state) -> None:
        stamp = self.get_clock().now().to_msg()
        if self.joint_pub is not None:
            msg = JointState(name=list(MOTORS), position=list(state.motor_position),
                             velocity=list(state.motor_velocity),
                             effort=list(state.motor_torque))
            msg.header.stamp = stamp
            self.joint_pub.publish(msg)
        try:
            if self.chamber_pub is not None:
                self.chamber_pub.publish(to_string_msg(ChamberPressures(
                    chambers=dict(zip(CHAMBERS, state.chamber_pressure, strict=True)))))
            if self.link_pub is not None:
                self.link_pub.publish(to_string_msg(LinkPressures(
                    links=dict(zip(LINKS, state.link_pressure, strict=True)))))
        except MessageError as err:  # a non-finite reading (latched as sensor_invalid)
            self.problems.warn('state', f'pressures not published: {err}', kind='not finite')

    # -- reporting ------------------------------------------------------------------------------

    def log_events(self) -> None:
        """Log the supervisor's events: warnings throttled per kind, state changes at once."""
        if self.supervisor is None:
            return
        for event in self.supervisor.drain_events():
            if event.level == 'warning':
                self.problems.warn('safety', event.message, kind=event.kind)
            elif event.level == 'error':  # one call site per severity (rclpy requires it)
                self.get_logger().error(event.message)
            else:
                self.get_logger().info(event.message)

    def current_status(self) -> HardwareStatus:
        supervisor = self.supervisor
        if supervisor is None:  # no MCU: unconfigured (configure failing?) or finalized
            error = self._configure_error
            return HardwareStatus(
                state=self.lifecycle, link='closed', motors='none', valves='none',
                faults=('configure_failed',) if error else (), latched=(),
                reason=f'configure failed: {error}' if error else f'{self.lifecycle}: no MCU',
                safe_latency=None, clamped=0, rejected=0, bad_frames=0)
        link = 'lost' if supervisor.link_lost is not None else self.driver.state.value
        return supervisor.status(self.lifecycle, link, self.driver.stats.bad_frames)

    def publish_status(self, force: bool = False) -> None:
        status = self.current_status()
        now = time.monotonic()
        key = (status.state, status.link, status.motors, status.valves, status.faults,
               status.latched, status.reason, status.safe_latency)
        if force or key != self._last_status or now - self._last_status_time >= 1.0:
            self._last_status, self._last_status_time = key, now
            self.status_pub.publish(to_string_msg(status))

    def diagnostic_status(self) -> list[DiagnosticStatus]:
        status = self.current_status()
        diagnostic = DiagnosticStatus(name='hw_bridge: MCU link', hardware_id=self.params['port'])
        if self.supervisor is None:
            diagnostic.level = WARN
            diagnostic.message = status.reason
        else:
            faults = self.supervisor.faults
            safe = status.motors not in ('follow', 'none') or status.valves == 'safe'
            diagnostic.level = (ERROR if faults else WARN if safe and status.state == 'active'
                                else OK)
            diagnostic.message = (f'{status.state}, link {status.link}, motors {status.motors},'
                                  f' valves {status.valves}'
                                  + (f': {status.reason}' if status.reason else ''))
            driver, stats = self.driver, self.driver.stats
            values = {
                'faults': '; '.join(f'{k}: {v}' for k, v in sorted(faults.items())) or 'none',
                'safe_latency_ms': 'none' if status.safe_latency is None
                else f'{status.safe_latency * 1000:.1f}',
                'frames_received': stats.frames, 'bad_frames': stats.bad_frames,
                'crc_errors': stats.crc_errors, 'frames_lost': stats.lost,
                'frames_sent': driver.tx_frames, 'tx_dropped': driver.tx_dropped,
                'rtt_ms': 'none' if driver.rtt_s is None else f'{driver.rtt_s * 1000:.1f}',
                'commands_clamped': status.clamped, 'commands_rejected': status.rejected,
            }
            if self.supervisor.state is not None:
                values['mcu_rx_errors'] = self.supervisor.state.rx_errors
                values['mcu_status'] = f'0x{self.supervisor.state.status:02x}'
            diagnostic.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return [diagnostic]


def main(args: list[str] | None = None) -> None:
    spin_node(HwBridge, args)


if __name__ == '__main__':
    main()
