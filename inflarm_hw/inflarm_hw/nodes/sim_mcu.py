"""Simulated MCU on a pseudo-terminal, with the simulated robots behind it.

The MCU link protocol (`inflarm_hw.mcu_protocol`) on a serial line, in front of the simulated
inflatable arm and/or soft arm (`inflarm_hw.sim_mcu`), so that ``hw_bridge`` runs the same code
in simulation as on hardware. At start it opens a new pty and prints its path on stdout as
``sim_mcu: serial port /dev/pts/N`` (and makes the symlink ``link`` to it when set); with
``device`` set it uses that tty instead (e.g. one end of ``socat -d -d pty,raw,echo=0
pty,raw,echo=0``). Only what an MCU cannot know goes on ROS topics: the true arm state and the
external camera's images of the soft arm's end (the simulated world's sensors beside the MCU;
the same camera as ``sra_sim``'s, ``inflarm_hw.nodes.camera_publisher``), so that
``ball_tracker`` closes the soft arm's loop on either backend.

Publishes:
    tip_position_truth (geometry_msgs/PointStamped, SENSOR_QOS): true inflatable-arm tip [m].
    spring_states_truth (sensor_msgs/JointState, SENSOR_QOS): true spring deflections [rad]
        and torques [N m].
    end_point_truth (geometry_msgs/PointStamped, SENSOR_QOS): true soft-arm end point [m].
    ball_position (geometry_msgs/PointStamped, SENSOR_QOS): the true end point plus the
        camera's error (`inflarm_hw.sra_plant.SoftArmPlant.measure`: ``measurement_noise.*``
        of the ball's image, through the ``camera.*`` geometry), a stand-in for camera +
        tracker, only when
        ``publish_ball_position`` is true (default false, as for ``sra_sim``).
    camera/image_raw (sensor_msgs/Image, bgr8), camera/camera_info (sensor_msgs/CameraInfo),
        SENSOR_QOS: the simulated camera's view of the yellow ball at the soft arm's true end
        point, at ``camera_rate_hz``, with the soft arm (plant 'sra' or 'both'), when
        ``camera.enabled`` and while someone subscribes; with ``camera.transport``
        compressed, JPEG on camera/image_raw/compressed (sensor_msgs/CompressedImage) instead
        of camera/image_raw.
Parameters:
    plant (string, read-only): 'arm', 'sra' or 'both'.
    device, link (string, read-only): the tty to use, or the symlink to make to the new pty.
    rate_hz (double, read-only): physics and State report rate (each step integrates the
        wall-clock time since the previous one, ``inflarm_hw.realtime``); io_rate_hz: line poll
        rate.
    protocol_version (int, read-only): the protocol it speaks (test an incompatible MCU).
    watchdog_default_s (double, read-only): command watchdog when HELLO asks for 0.
    arm.* (inflarm_model.nodes.arm_parameters), tip_force_n (runtime),
        initial_motor_positions_rad, motor.*, noise.position_rad, noise.effort_nm,
        wrinkling: the inflatable arm, as for arm_sim.
    noise.pressure_pa (double, read-only): pressure sensor noise.
    measurement_noise.center_px, measurement_noise.radius_px, camera_rate_hz, truth_rate_hz,
        publish_ball_position (default false): the stand-in measurement's image errors [px],
        the camera rate and the truth topics.
    plant.* (double, read-only): the soft arm's physical constants, as for ``sra_sim``
        (``plant.valve_delay_s`` among them; an identified plant loads with --params-file).
    camera.* : the simulated camera, as for ``sra_sim`` (camera.transport, raw or
        compressed, and camera.jpeg_quality among them).
    arm_frame_id, sra_frame_id (string, read-only); seed (int, read-only).
    fault.kind (string: '', clear, drop_bytes, corrupt_crc, silent, stick_sensor,
        over_pressure), fault.channel (int), fault.value (double), fault.duration_s (double):
        setting fault.kind injects the fault with the current channel, value and duration:
        set them atomically, or fault.kind last.
"""

import time

from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState

from inflarm_hw.mcu_protocol import PROTOCOL_VERSION, FaultKind
from inflarm_hw.nodes.camera_publisher import (
    CAMERA_PARAMETERS,
    CameraPublisher,
)
from inflarm_hw.nodes.plant_parameters import (
    ARM_PLANT_PARAMETERS,
    SRA_PLANT_PARAMETERS,
    apply_arm_plant_parameter,
    arm_plant_from_parameters,
    check_arm_plant_parameters,
    sra_plant_from_parameters,
)
from inflarm_hw.realtime import ElapsedSteps
from inflarm_hw.sim_mcu import McuPort, SimMcu, SimMcuParams
from inflarm_hw.sra_plant import SoftArmPlant, SoftArmPlantParams
from inflarm_model.kinematics import FlexibleArm
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import SENSOR_QOS
from inflarm_msgs_json.ros.spin import spin_node

PLANTS = ('arm', 'sra', 'both')
_SRA = SoftArmPlantParams()
FAULT_KINDS = {kind.name.lower(): kind for kind in FaultKind}
PARAMETERS = ARM_PLANT_PARAMETERS + (
    Parameter('plant', 'both', "simulated robots behind the MCU: 'arm', 'sra' or 'both'",
              read_only=True),
    Parameter('device', '', "tty to use as the MCU's UART; '' opens a new pty", read_only=True),
    Parameter('link', '', 'with a new pty: make this symlink to it', read_only=True),
    Parameter('rate_hz', 50.0, 'physics and State report rate [Hz]', range=(5.0, 500.0),
              read_only=True),
    Parameter('io_rate_hz', 200.0, 'serial line poll rate [Hz]', range=(10.0, 2000.0),
              read_only=True),
    Parameter('protocol_version', PROTOCOL_VERSION, 'MCU link protocol version it speaks',
              range=(0, 65535), read_only=True),
    Parameter('watchdog_default_s', 0.25, 'command watchdog when HELLO asks for 0 [s]',
              range=(0.02, 2.0), read_only=True),
    Parameter('noise.pressure_pa', 20.0, 'pressure sensor noise (std) [Pa]',
              range=(0.0, 10000.0), read_only=True),
    Parameter('measurement_noise.center_px', _SRA.noise_center_px,
              "std of the ball image's centre behind the stand-in ball_position [px]",
              range=(0.0, 5.0), read_only=True),
    Parameter('measurement_noise.radius_px', _SRA.noise_radius_px,
              "std of the ball image's radius behind the stand-in ball_position [px]",
              range=(0.0, 1.0), read_only=True),
    Parameter('camera_rate_hz', 5.0, 'simulated camera rate [Hz] (paper: about 5 Hz)',
              range=(0.1, 100.0), read_only=True),
    Parameter('truth_rate_hz', 10.0, 'rate of the truth topics [Hz]', range=(0.1, 500.0),
              read_only=True),
    Parameter('publish_ball_position', False,
              'publish the true end point plus noise on ball_position (a stand-in for the '
              'camera and ball_tracker)', read_only=True),
    Parameter('arm_frame_id', 'base_link', 'frame of the inflatable arm', read_only=True),
    Parameter('sra_frame_id', 'sra_mount', 'frame of the soft arm', read_only=True),
    Parameter('seed', -1, 'noise seed, -1 for a random one', range=(-1, 2**31 - 1),
              read_only=True),
    Parameter('fault.kind', '', f"inject a fault: one of {sorted(FAULT_KINDS)}, '' for none"),
    Parameter('fault.channel', 0, 'pressure channel of the fault (0-4 PEA, B1..B4; 5-6 '
              'link_1, link_2)', range=(0, 6)),
    Parameter('fault.value', 0.0, 'share of bytes or frames (0-1), or pressure [Pa]'),
    Parameter('fault.duration_s', 0.0, 'how long the fault lasts [s]; 0: until cleared',
              range=(0.0, 3600.0)),
) + SRA_PLANT_PARAMETERS + CAMERA_PARAMETERS


def check_parameters(p: dict) -> None:
    """Raise ``ValueError`` naming the first invalid value among the parameter values ``p``."""
    problem = check_arm_plant_parameters(p)
    if problem is not None:
        raise ValueError(problem)
    if p.get('plant', 'both') not in PLANTS:
        raise ValueError(f"plant must be one of {list(PLANTS)}, got '{p['plant']}'")
    kind = p.get('fault.kind', '')
    if kind and kind not in FAULT_KINDS:
        raise ValueError(f"fault.kind must be '' or one of {sorted(FAULT_KINDS)}, got '{kind}'")


class SimMcuNode(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('sim_mcu', **kwargs)
        self.params = p = declare_parameters(self, PARAMETERS, check=check_parameters,
                                             on_set=self.on_parameters_set)
        check_parameters(p)
        seed = p['seed']
        rng = np.random.default_rng(None if seed < 0 else seed)
        arm = sra = None
        if p['plant'] in ('arm', 'both'):
            arm = arm_plant_from_parameters(p, rng)
        if p['plant'] in ('sra', 'both'):
            sra = SoftArmPlant(1, sra_plant_from_parameters(p), rng)
        self.mcu = SimMcu(arm, sra, p['arm.link_pressure_pa'], SimMcuParams(
            protocol_version=p['protocol_version'], default_watchdog_s=p['watchdog_default_s'],
            pressure_noise_pa=p['noise.pressure_pa']), rng)
        self.camera = None
        if sra is not None and p['camera.enabled']:
            # before the port: building the renderer takes a while, and a bridge may send
            # HELLO as soon as the port is printed
            self.camera = CameraPublisher(self, p, lambda: self.mcu.sra.end_point[0],
                                          None if seed < 0 else seed)
        self.port = McuPort(p['device'], p['link'])
        print(f'sim_mcu: serial port {self.port.path}', flush=True)

        self.tip_pub = self.spring_pub = self.end_pub = self.ball_pub = None
        if arm is not None:
            self.tip_pub = self.create_publisher(PointStamped, 'tip_position_truth', SENSOR_QOS)
            self.spring_pub = self.create_publisher(JointState, 'spring_states_truth',
                                                    SENSOR_QOS)
        if sra is not None:
            self.end_pub = self.create_publisher(PointStamped, 'end_point_truth', SENSOR_QOS)
            if p['publish_ball_position']:
                self.ball_pub = self.create_publisher(PointStamped, 'ball_position', SENSOR_QOS)
                self.create_guarded_timer(1.0 / p['camera_rate_hz'], self.publish_camera)
        self.dt = 1.0 / p['rate_hz']
        self.elapsed = ElapsedSteps(max_step_s=1.0)  # physics keep pace with the wall clock
        self.create_guarded_timer(1.0 / p['io_rate_hz'], self.poll)
        self.create_guarded_timer(self.dt, self.step)
        self.create_guarded_timer(1.0 / p['truth_rate_hz'], self.publish_truth)
        self.get_logger().info(
            f"ready: simulated MCU ({p['plant']}) on {self.port.path}"
            + (f' (link {p["link"]})' if p['link'] else '') + f", {p['rate_hz']} Hz")

    def on_parameters_set(self, changed: dict) -> None:
        for name, value in changed.items():
            change = (None if self.mcu.arm is None
                      else apply_arm_plant_parameter(self.mcu.arm, name, value))
            if change is not None:
                self.get_logger().info(change)
        if 'fault.kind' in changed and self.params['fault.kind']:
            p = self.params
            try:
                self.mcu.inject(FAULT_KINDS[p['fault.kind']], p['fault.channel'],
                                p['fault.value'], p['fault.duration_s'], time.monotonic())
            except ValueError as err:
                self.get_logger().error(f'fault not injected: {err}')
                return
            self.get_logger().warning(
                f"fault injected: {p['fault.kind']} (channel {p['fault.channel']}, value "
                f"{p['fault.value']:g}, {p['fault.duration_s']:g} s)")

    def poll(self) -> None:
        data = self.port.read()
        if data:
            self.port.write(self.mcu.receive(data, time.monotonic()))

    def step(self) -> None:
        # the line first, as an MCU reads it: after a stall of this process its timers run
        # before the poll, and the watchdog would trip on commands waiting in the pty
        self.poll()
        dt = self.elapsed()
        if dt > 0.0:
            self.port.write(self.mcu.step(dt, time.monotonic()))

    def point(self, point, frame_id: str) -> PointStamped:
        msg = PointStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = frame_id
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in point)
        return msg

    def publish_truth(self) -> None:
        state = self.mcu.arm_state
        if self.tip_pub is not None and state is not None:
            self.tip_pub.publish(self.point(state.tip_position, self.params['arm_frame_id']))
            springs = JointState(name=list(FlexibleArm.SPRING_JOINT_NAMES),
                                 position=state.q_k.tolist(),
                                 effort=(self.mcu.arm.stiffness * state.q_k).tolist())
            springs.header.stamp = self.get_clock().now().to_msg()
            self.spring_pub.publish(springs)
        if self.end_pub is not None:
            self.end_pub.publish(self.point(self.mcu.sra.end_point[0],
                                            self.params['sra_frame_id']))

    def publish_camera(self) -> None:
        self.ball_pub.publish(self.point(self.mcu.sra.measure()[0], self.params['sra_frame_id']))

    def destroy_node(self) -> None:
        self.port.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    spin_node(SimMcuNode, args)


if __name__ == '__main__':
    main()
