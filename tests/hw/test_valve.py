"""Eq. (2) of 001_... in inflarm_hw.valve: pressure <-> voltage, dead zone, range, no ROS."""


from hypothesis import given
from hypothesis import strategies as st
import numpy as np
import pytest

from inflarm_hw.valve import (
    ITV2050,
    ValveModel,
    pressure_to_voltage,
    valve_output,
    voltage_to_pressure,
)


def test_the_itv2050_defaults_follow_eq2():
    assert (ITV2050.voltage_min, ITV2050.voltage_max) == (0.0, 10.0)
    assert (ITV2050.pressure_min, ITV2050.pressure_max) == (5e3, 900e3)
    # P_out = u_p / (U_max - U_min) (P_max - P_min)
    u = np.array([0.0, 1.0, 5.0, 10.0])
    np.testing.assert_allclose(voltage_to_pressure(u), [0.0, 89.5e3, 447.5e3, 895e3])
    np.testing.assert_allclose(pressure_to_voltage([89.5e3, 447.5e3]), [1.0, 5.0])


def test_voltages_are_clamped_to_the_valve_input_range():
    np.testing.assert_allclose(pressure_to_voltage([-20e3, 0.0, 2e6]), [0.0, 0.0, 10.0])
    np.testing.assert_allclose(voltage_to_pressure([-3.0, 12.0]), [0.0, 895e3])


def test_the_dead_zone_exhausts():
    np.testing.assert_allclose(valve_output([3.99e3, 4.0e3, 20e3]), [0.0, 4.0e3, 20e3])
    wide = ValveModel(dead_zone=10e3)
    np.testing.assert_allclose(valve_output([9e3, 11e3], wide), [0.0, 11e3])


def test_another_valve_range():
    valve = ValveModel(voltage_min=1.0, voltage_max=5.0, pressure_min=0.0, pressure_max=200e3,
                       dead_zone=0.0)
    np.testing.assert_allclose(pressure_to_voltage([0.0, 100e3, 200e3], valve), [1.0, 3.0, 5.0])
    np.testing.assert_allclose(voltage_to_pressure([0.0, 3.0, 6.0], valve), [0.0, 100e3, 200e3])


@given(st.floats(min_value=ITV2050.dead_zone, max_value=ITV2050.full_scale))
def test_the_round_trip_is_exact_inside_the_range(p):
    assert valve_output(p) == pytest.approx(p, rel=1e-12, abs=1e-9)


def test_shapes_are_kept():
    p = np.full((2, 5), 30e3)
    assert pressure_to_voltage(p).shape == (2, 5)
    assert voltage_to_pressure(3.0).shape == ()


@pytest.mark.parametrize(('call', 'message'), [
    (lambda: pressure_to_voltage([1.0, np.nan]), r'finite p \[Pa\]'),
    (lambda: pressure_to_voltage(np.inf), r'finite p \[Pa\]'),
    (lambda: voltage_to_pressure(np.nan), r'finite u \[V\]'),
    (lambda: ValveModel(voltage_max=0.0), 'voltage_max > voltage_min'),
    (lambda: ValveModel(pressure_min=1e6), 'pressure_max > pressure_min'),
    (lambda: ValveModel(dead_zone=-1.0), 'dead_zone >= 0'),
    (lambda: ValveModel(pressure_max=np.nan), 'finite pressure_max'),
])
def test_bad_input_is_rejected(call, message):
    with pytest.raises(ValueError, match=message):
        call()
