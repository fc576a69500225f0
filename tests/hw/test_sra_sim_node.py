"""sra_sim in-process: commands within the chamber limits, rejection of bad ones, the vent."""

import time

import numpy as np
import pytest
import rclpy
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter
from std_msgs.msg import String

from inflarm_hw.nodes.sim_mcu import SimMcuNode
from inflarm_hw.nodes.sra_sim import SraSim
from inflarm_hw.sra_plant import PLANT_PARAMETER_NAMES, SoftArmPlantParams
from inflarm_msgs_json import ChamberPressures, PressureCommand, decode
from inflarm_msgs_json.ros.conversions import to_string_msg
from inflarm_msgs_json.ros.qos import COMMAND_QOS, RELIABLE_QOS
from ros_harness import spin_until


class Rig:
    def __init__(self, executor, **overrides) -> None:
        self.executor = executor
        self.sim = SraSim(context=executor.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node('probe', context=executor.context)
        self.pressures: list[ChamberPressures] = []
        self.probe.create_subscription(String, 'chamber_pressures',
                                       lambda m: self.pressures.append(decode(m.data)),
                                       RELIABLE_QOS)
        self.command_pub = self.probe.create_publisher(String, 'chamber_pressure_command',
                                                       COMMAND_QOS)
        executor.add_node(self.sim)
        executor.add_node(self.probe)
        assert spin_until(executor, lambda: self.command_pub.get_subscription_count() == 1)

    def command(self, chambers: dict) -> None:
        self.command_pub.publish(to_string_msg(PressureCommand(chambers=chambers)))

    def spin(self, seconds: float) -> None:
        spin_until(self.executor, lambda: False, timeout_s=seconds)


def test_an_unknown_chamber_is_rejected_and_the_node_keeps_running(executor):
    rig = Rig(executor)
    rig.command({'B9': 10e3})
    assert spin_until(executor, lambda: 'chamber_pressure_command' in rig.sim.problems.last)
    assert "unknown chambers ['B9']" in rig.sim.problems.last['chamber_pressure_command']
    assert rig.sim.problems.unexpected == 0
    rig.command({'PEA': 10e3})
    assert spin_until(executor, lambda: rig.sim.command[0] == 10e3)


def test_a_pressure_beyond_the_chamber_maximum_is_rejected_whole(executor):
    rig = Rig(executor)
    rig.command({'PEA': 1e300, 'B1': 5e3})
    assert spin_until(executor, lambda: 'chamber_pressure_command' in rig.sim.problems.last)
    assert 'PEA at 1e+300 Pa is outside 0..100000 Pa' in \
        rig.sim.problems.last['chamber_pressure_command']
    np.testing.assert_array_equal(rig.sim.command, 0.0)  # B1 was not applied either
    rig.spin(0.5)
    assert max(rig.pressures[-1].as_dict().values()) == 0.0


def test_a_silent_controller_gets_the_chambers_vented_and_the_timeout_stays_safe(executor):
    rig = Rig(executor, cmd_timeout_s=0.3)
    refused = rig.sim.set_parameters([Parameter('cmd_timeout_s', value=600.0)])[0]
    assert not refused.successful  # minutes are no fail-safe
    rig.command({'PEA': 30e3})
    assert spin_until(executor, lambda: rig.sim.command[0] == 30e3)
    assert spin_until(executor, lambda: rig.sim.vented and rig.sim.command[0] == 0.0,
                      timeout_s=3.0)


def test_a_stall_of_the_simulator_itself_does_not_vent_the_commands_it_has_yet_to_read(executor):
    # measured in a demo on a busy machine: sra_sim ran nothing for 3.1 s, its first step after
    # the stall found the last command read 3 s old and vented, while the controller's commands
    # of those 3 s were queued behind it (the arm dropped 40 mm)
    rig = Rig(executor, cmd_timeout_s=1.0)
    rig.command({'PEA': 30e3})
    assert spin_until(executor, lambda: rig.sim.command[0] == 30e3)
    rig.spin(0.5)
    before = rig.sim.plant.chamber_pressures[0][0]
    for _ in range(8):  # 1.6 s of commands at 5 Hz while the simulator does not run
        time.sleep(0.2)
        rig.command({'PEA': 30e3})
    rig.spin(0.3)
    # the step after the stall integrates it (up to 1 s): vented, the PEA would have emptied
    assert rig.sim.plant.chamber_pressures[0][0] > before
    assert not rig.sim.vented and rig.sim.command[0] == 30e3
    rig.spin(1.5)  # and a controller that really stops still gets the chambers vented
    assert rig.sim.vented and rig.sim.command[0] == 0.0


def test_an_out_of_range_measurement_noise_refuses_to_start_naming_it(ros_context):
    with pytest.raises(InvalidParameterValueException, match='measurement_noise.radius_px'):
        SraSim(context=ros_context, parameter_overrides=[
            Parameter('measurement_noise.radius_px', value=2.0)])


def test_the_stand_in_measurement_uses_the_camera_geometry(executor):
    rig = Rig(executor, **{'measurement_noise.center_px': 0.0,
                           'measurement_noise.radius_px': 0.5, 'camera.enabled': False})
    plant = rig.sim.plant
    assert plant.params.noise_radius_px == 0.5 and plant.params.noise_center_px == 0.0
    error = np.array([plant.measure()[0] - plant.end_point[0] for _ in range(200)])
    # the default camera looks along +y: all the noise is along y (the depth)
    assert np.abs(error[:, 1]).mean() > 10.0 * np.abs(error[:, [0, 2]]).mean()
    refused = rig.sim.set_parameters([Parameter('measurement_noise.center_px', value=-1.0)])[0]
    assert not refused.successful
    assert rig.sim.set_parameters([Parameter('measurement_noise.center_px', value=0.2)])[0] \
        .successful
    assert plant.params.noise_center_px == 0.2


def test_the_plant_parameters_default_to_the_plant_and_load_other_values(ros_context):
    sim = SraSim(context=ros_context, parameter_overrides=[
        Parameter('plant.pea_modulus_pa', value=80e3),
        Parameter('plant.valve_delay_s', value=0.25), Parameter('camera.enabled', value=False)])
    try:
        defaults = SoftArmPlantParams()
        assert sim.get_parameter('plant.bellows_time_constant_s').value == \
            defaults.bellows_time_constant
        assert sim.plant.params.pea_modulus == 80e3 and sim.plant.params.valve_delay == 0.25
        assert sim.plant.params.bellows_modulus == defaults.bellows_modulus
        assert set(PLANT_PARAMETER_NAMES.values()) <= set(sim.params)
    finally:
        sim.destroy_node()


def test_a_plant_value_the_plant_rejects_refuses_to_start_naming_the_parameter(ros_context):
    with pytest.raises(ValueError, match=r"parameter 'plant.bellows_modulus_pa': expected "
                                         r'bellows_modulus > 0, got -1'):
        SraSim(context=ros_context, parameter_overrides=[
            Parameter('plant.bellows_modulus_pa', value=-1.0)])


def test_sim_mcu_takes_the_same_plant_parameters(ros_context):
    # one table for both simulators of the soft arm: an identified plant loads into either
    overrides = [Parameter('plant', value='sra'), Parameter('camera.enabled', value=False)]
    mcu = SimMcuNode(context=ros_context, parameter_overrides=[
        *overrides, Parameter('plant.valve_delay_s', value=0.25)])
    try:
        assert mcu.mcu.sra.params.valve_delay == 0.25
        assert set(PLANT_PARAMETER_NAMES.values()) <= set(mcu.params)
    finally:
        mcu.destroy_node()
    with pytest.raises(ValueError, match=r"parameter 'plant.pea_time_constant_s': expected "
                                         r'pea_time_constant > 0, got 0'):
        SimMcuNode(context=ros_context, parameter_overrides=[
            *overrides, Parameter('plant.pea_time_constant_s', value=0.0)])
