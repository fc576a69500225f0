"""Simulated pneumatic soft robot arm (SRA) behind its valves and MCU: the default plant.

Subscribes:
    chamber_pressure_command (std_msgs/String: PressureCommand JSON, COMMAND_QOS): valve set
        pressures [Pa] by chamber name (PEA, B1..B4); chambers not named keep their command.
Publishes:
    chamber_pressures (std_msgs/String: ChamberPressures JSON, RELIABLE_QOS): measured [Pa].
    end_point_truth (geometry_msgs/PointStamped, SENSOR_QOS): true end point [m], for evaluation.
    ball_position (geometry_msgs/PointStamped, SENSOR_QOS): the true end point plus the
        camera's error (`inflarm_hw.sra_plant.SoftArmPlant.measure`: ``measurement_noise.*``
        of the ball's image, through the ``camera.*`` geometry), a stand-in for camera +
        tracker, only when
        ``publish_ball_position`` is true (default false: ``ball_tracker`` measures the ball
        in the camera images).
    camera/image_raw (sensor_msgs/Image, bgr8), camera/camera_info (sensor_msgs/CameraInfo),
        SENSOR_QOS: the simulated external camera's view of the yellow ball at the true end
        point, at ``camera_rate_hz``, when ``camera.enabled`` and while someone subscribes
        (``inflarm_hw.nodes.camera_publisher``); with ``camera.transport`` compressed, JPEG
        on camera/image_raw/compressed (sensor_msgs/CompressedImage) instead of
        camera/image_raw.
Parameters:
    physics_rate_hz, state_rate_hz, camera_rate_hz (double): simulation, state and camera rates;
        each physics step integrates the wall-clock time since the previous one
        (``inflarm_hw.realtime``), so simulated time keeps pace with the controller's.
    publish_ball_position (bool, read-only): publish the stand-in measurement on
        ``ball_position`` (default false).
    measurement_noise.center_px, measurement_noise.radius_px (double): the image errors behind
        it [px] (`inflarm_hw.sra_plant.SoftArmPlantParams`): depth noise along the camera's line
        of sight larger than across it.
    plant.* (double, read-only): the plant's physical constants, one per
        `inflarm_hw.sra_plant.SoftArmPlantParams` field, named with its unit by
        `inflarm_hw.sra_plant.PLANT_PARAMETER_NAMES` (``plant.pea_modulus_pa``,
        ``plant.valve_delay_s``, ...), defaults those of `SoftArmPlantParams`: ``--params-file
        plant.yaml`` loads an identified plant (``inflarm-identify-plant``). A value the plant
        rejects stops the start with a message naming the parameter.
    cmd_timeout_s (double, 0.05-5): without a command for this long the MCU vents every chamber.
    max_chamber_pressure_pa (double, read-only): commands above this are rejected whole.
    frame_id (string, read-only): frame of the points (the paper's mount frame, z down PEA1).
    seed (int, read-only): noise seed, -1 for a random one.
    camera.* : the simulated camera (``inflarm_hw.nodes.camera_publisher.CAMERA_PARAMETERS``),
        among them camera.transport (string, read-only: raw or compressed) and
        camera.jpeg_quality (int, 1-100).
"""

import dataclasses
import time

from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from std_msgs.msg import String

from inflarm_hw.nodes.camera_publisher import CAMERA_PARAMETERS, CameraPublisher
from inflarm_hw.nodes.plant_parameters import SRA_PLANT_PARAMETERS, sra_plant_from_parameters
from inflarm_hw.realtime import ElapsedSteps
from inflarm_hw.sra_plant import SoftArmPlant, SoftArmPlantParams
from inflarm_model.soft_arm import CHAMBER_MAX_PRESSURE, CHAMBERS, check_chamber_pressures
from inflarm_msgs_json import ChamberPressures, PressureCommand
from inflarm_msgs_json.ros.conversions import from_string_msg, to_string_msg
from inflarm_msgs_json.ros.node import GuardedCallbacks
from inflarm_msgs_json.ros.parameters import Parameter, declare_parameters
from inflarm_msgs_json.ros.qos import COMMAND_QOS, RELIABLE_QOS, SENSOR_QOS, publisher_events
from inflarm_msgs_json.ros.spin import spin_node

_PLANT = SoftArmPlantParams()
PARAMETERS = (
    Parameter('physics_rate_hz', 50.0, 'simulation step rate [Hz]', range=(1.0, 1000.0),
              read_only=True),
    Parameter('state_rate_hz', 10.0, 'chamber pressure and true end point rate [Hz]',
              range=(0.1, 1000.0), read_only=True),
    Parameter('camera_rate_hz', 5.0, 'simulated camera rate [Hz] (paper: about 5 Hz)',
              range=(0.1, 100.0), read_only=True),
    Parameter('publish_ball_position', False,
              'publish the true end point plus noise on ball_position (a stand-in for the '
              'camera and ball_tracker)', read_only=True),
    Parameter('measurement_noise.center_px', _PLANT.noise_center_px,
              "std of the ball image's centre behind the stand-in ball_position [px]",
              range=(0.0, 5.0)),
    Parameter('measurement_noise.radius_px', _PLANT.noise_radius_px,
              "std of the ball image's radius behind the stand-in ball_position [px]",
              range=(0.0, 1.0)),
    Parameter('cmd_timeout_s', 2.0, 'vent every chamber after this long without a command [s]',
              range=(0.05, 5.0)),
    Parameter('max_chamber_pressure_pa', CHAMBER_MAX_PRESSURE,
              'commands above this chamber pressure are rejected [Pa]', range=(1e3, 900e3),
              read_only=True),
    Parameter('frame_id', 'sra_mount', 'frame of the published points', read_only=True),
    Parameter('seed', -1, 'noise seed, -1 for a random one', range=(-1, 2**31 - 1),
              read_only=True),
) + SRA_PLANT_PARAMETERS + CAMERA_PARAMETERS


class SraSim(GuardedCallbacks, Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('sra_sim', **kwargs)
        self.params = declare_parameters(self, PARAMETERS, on_set=self.on_parameters_set)
        seed = self.params['seed']
        self.plant = SoftArmPlant(
            n=1, params=sra_plant_from_parameters(self.params),
            rng=np.random.default_rng(None if seed < 0 else seed))
        self.command = np.zeros(len(CHAMBERS))
        self.last_command_time = self.last_step_time = time.monotonic()
        self.vented = True

        self.create_guarded_subscription(
            String, 'chamber_pressure_command', self.on_command, COMMAND_QOS)
        self.pressures_pub = self.create_publisher(
            String, 'chamber_pressures', RELIABLE_QOS,
            event_callbacks=publisher_events(self, 'chamber_pressures'))
        self.truth_pub = self.create_publisher(PointStamped, 'end_point_truth', SENSOR_QOS)
        self.ball_pub = None
        if self.params['publish_ball_position']:
            self.ball_pub = self.create_publisher(PointStamped, 'ball_position', SENSOR_QOS)
            self.create_guarded_timer(1.0 / self.params['camera_rate_hz'],
                                      self.publish_measurement)
        self.dt = 1.0 / self.params['physics_rate_hz']
        # physics follow the wall clock: a late step (behind a rendered frame) integrates the
        # time that really passed
        self.elapsed = ElapsedSteps(max_step_s=1.0)
        self.create_guarded_timer(self.dt, self.step)
        self.create_guarded_timer(1.0 / self.params['state_rate_hz'], self.publish_state)
        self.camera = None
        if self.params['camera.enabled']:
            self.camera = CameraPublisher(self, self.params, lambda: self.plant.end_point[0],
                                          None if seed < 0 else seed)
        self.get_logger().info(
            f"ready: SRA at rest, {self.params['physics_rate_hz']} Hz physics, chambers "
            f"{', '.join(CHAMBERS)}")

    def on_parameters_set(self, changed: dict) -> None:
        for name, value in changed.items():
            if name.startswith('measurement_noise.'):
                field = {'measurement_noise.center_px': 'noise_center_px',
                         'measurement_noise.radius_px': 'noise_radius_px'}[name]
                self.plant.params = dataclasses.replace(self.plant.params, **{field: value})

    def on_command(self, msg: String) -> None:
        command = check_chamber_pressures(
            from_string_msg(msg, expected=PressureCommand).as_dict(),
            self.params['max_chamber_pressure_pa'])
        for name, pressure in command.items():
            self.command[CHAMBERS.index(name)] = pressure
        self.last_command_time = time.monotonic()
        if self.vented:
            self.vented = False
            self.get_logger().info('commands received: valves follow them')

    def step(self) -> None:
        # Fail safe like the MCU: a silent controller gets every chamber vented. Not on the
        # first step after a stall of this process (its timers run before its subscriptions):
        # the commands that came meanwhile are still queued, and an MCU would have read them.
        now = time.monotonic()
        stalled = now - self.last_step_time > 5.0 * self.dt
        self.last_step_time = now
        if (not self.vented and not stalled
                and now - self.last_command_time > self.params['cmd_timeout_s']):
            self.command[:] = 0.0
            self.vented = True
            self.get_logger().warning(
                f"no chamber_pressure_command for {self.params['cmd_timeout_s']} s: "
                'venting every chamber')
        dt = self.elapsed()
        if dt > 0.0:
            self.plant.step(self.command, dt)

    def point_msg(self, point: np.ndarray) -> PointStamped:
        msg = PointStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.params['frame_id']
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in point)
        return msg

    def publish_state(self) -> None:
        pressures = dict(zip(CHAMBERS, self.plant.chamber_pressures[0].tolist(), strict=True))
        self.pressures_pub.publish(to_string_msg(ChamberPressures(chambers=pressures)))
        self.truth_pub.publish(self.point_msg(self.plant.end_point[0]))

    def publish_measurement(self) -> None:
        self.ball_pub.publish(self.point_msg(self.plant.measure()[0]))


def main(args: list[str] | None = None) -> None:
    spin_node(SraSim, args)


if __name__ == '__main__':
    main()
