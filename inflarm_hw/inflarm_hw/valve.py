"""Proportional pressure valves (SMC ITV2050 class): set pressure <-> control voltage, eq. (2).

The one implementation of eq. (2) of 001_b59ad71c956a1751 in the suite: the hardware bridge
turns pressure set points into valve voltages with `pressure_to_voltage`, and the simulated
valves (`inflarm_hw.sra_plant`, the simulated MCU) turn voltages back into output pressures with
`voltage_to_pressure`. Volts exist only here, in the bridge and in the MCU: every topic carries
pascals.

Eq. (2) as the paper writes it::

    P_out = u_p / (U_max - U_min) * (P_max - P_min)

with ``u_p`` measured from ``U_min`` (``U_min = 0`` for the ITV2050's 0-10 V input), so full
scale is ``P_max - P_min`` (895 kPa for the default 5-900 kPa range). Output pressures below the
dead zone (0-4 kPa in 4.3.2) are 0: the valve exhausts. The valve's range is not a chamber's
rating: a bellows rated for 100 kPa sits behind a 900 kPa valve, so the chamber limit is set
separately (the bridge's ``limits.*`` parameters).
"""

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class ValveModel:
    """The configured range of one kind of proportional valve.

    Attributes
    ----------
    voltage_min, voltage_max : float
        ``U_min``, ``U_max`` of eq. (2): the control input range [V].
    pressure_min, pressure_max : float
        ``P_min``, ``P_max`` of eq. (2): the valve's controllable set-pressure range [Pa].
    dead_zone : float
        Output pressures below this are 0 Pa (the valve exhausts) [Pa].
    """

    voltage_min: float = 0.0
    voltage_max: float = 10.0
    pressure_min: float = 5e3
    pressure_max: float = 900e3
    dead_zone: float = 4e3

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not np.isfinite(value):
                raise ValueError(f'expected finite {name}, got {value}')
        if not self.voltage_max > self.voltage_min:
            raise ValueError(f'expected voltage_max > voltage_min, got {self.voltage_max} V '
                             f'<= {self.voltage_min} V')
        if not self.pressure_max > self.pressure_min >= 0.0:
            raise ValueError(f'expected pressure_max > pressure_min >= 0 Pa, got '
                             f'{self.pressure_min} Pa and {self.pressure_max} Pa')
        if self.dead_zone < 0.0:
            raise ValueError(f'expected dead_zone >= 0 Pa, got {self.dead_zone}')

    @property
    def gain(self) -> float:
        """Slope of eq. (2) [Pa/V]."""
        return (self.pressure_max - self.pressure_min) / (self.voltage_max - self.voltage_min)

    @property
    def full_scale(self) -> float:
        """Output pressure at ``voltage_max`` [Pa] (``pressure_max - pressure_min``)."""
        return self.pressure_max - self.pressure_min


#: SMC ITV2050: 0.005-0.9 MPa over 0-10 V, dead zone 0-4 kPa (4.3.2 of 001_...).
ITV2050 = ValveModel()


def _finite(name: str, value: npt.ArrayLike, unit: str) -> npt.NDArray[np.float64]:
    array = np.asarray(value, dtype=float)
    if not np.isfinite(array).all():
        raise ValueError(f'expected finite {name} [{unit}], got {array.tolist()}')
    return array


def pressure_to_voltage(
    p: npt.ArrayLike, valve: ValveModel = ITV2050
) -> npt.NDArray[np.float64]:
    """Control voltage that asks a valve for the set pressure ``p``: eq. (2) inverted.

    Parameters
    ----------
    p : array-like, any shape
        Set gauge pressure [Pa]. Negative values ask for 0 V (exhaust).
    valve : ValveModel
        The valve's range (default `ITV2050`).

    Returns
    -------
    ndarray, shape of ``p``
        ``u_p = U_min + p (U_max - U_min) / (P_max - P_min)``, clamped to
        ``[U_min, U_max]`` [V].

    Raises
    ------
    ValueError
        If ``p`` holds NaN or an infinity.
    """
    pressure = _finite('p', p, 'Pa')
    return np.clip(valve.voltage_min + pressure / valve.gain, valve.voltage_min,
                   valve.voltage_max)


def voltage_to_pressure(
    u: npt.ArrayLike, valve: ValveModel = ITV2050
) -> npt.NDArray[np.float64]:
    """Output pressure of a valve driven at ``u``: eq. (2) with the dead zone.

    Parameters
    ----------
    u : array-like, any shape
        Control voltage [V], clamped to ``[U_min, U_max]`` first.
    valve : ValveModel
        The valve's range (default `ITV2050`).

    Returns
    -------
    ndarray, shape of ``u``
        ``P_out = (u_p - U_min) / (U_max - U_min) (P_max - P_min)``, and 0 where that is below
        ``valve.dead_zone`` [Pa].

    Raises
    ------
    ValueError
        If ``u`` holds NaN or an infinity.
    """
    voltage = np.clip(_finite('u', u, 'V'), valve.voltage_min, valve.voltage_max)
    pressure = (voltage - valve.voltage_min) * valve.gain
    return np.where(pressure < valve.dead_zone, 0.0, pressure)


def valve_output(p: npt.ArrayLike, valve: ValveModel = ITV2050) -> npt.NDArray[np.float64]:
    """Pressure a valve delivers for the set pressure ``p`` [Pa]: eq. (2) both ways.

    ``voltage_to_pressure(pressure_to_voltage(p))``: ``p`` itself inside the valve's range,
    0 in the dead zone and below, ``valve.full_scale`` above.
    """
    return voltage_to_pressure(pressure_to_voltage(p, valve), valve)
