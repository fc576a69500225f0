"""Simulated pneumatic soft robot arm (SRA): valves, chambers, walls, segments; batched over arms.

The simulation backend for the SRA of ``001_b59ad71c956a1751`` (sections 2-3): the five ITV2050
proportional valves, the chambers of PEA1&2 (one pressure through the T-pipe) and of bellows
B1-B4, the hyperelastic walls that those pressures stretch, and the arm as three continuum
segments. The model-free PID + ILC controller of section 3 never sees it; the constants are
identified from the paper's work space (section 2.2, Fig 5A) where the paper gives data, and
chosen (with the reason) where it gives none (`SoftArmPlantParams`).

Everything is vectorized over a leading axis of ``n`` independent arms (``n = 1`` for the ROS
node, thousands for building the experiential knowledge database); there is no Python loop over
arms. Pure numpy, no rclpy.

Signal chain per arm and chamber ``c`` (``CHAMBERS`` order: PEA, B1, B2, B3, B4)::

    command [Pa] -> valve voltage (eq. 2) -> transport delay
      -> valve output P_v [Pa] (dead zone 0-4 kPa, range; both in `inflarm_hw.valve`)
      -> chamber: dp/dt = (P_v - p) / tau_c(lambda) - (p + P_atm) dlambda/dt / lambda
      -> wall (Kelvin-Voigt, neo-Hookean): eta_c dlambda/dt = p - mu_c (lambda - lambda^-2)
      -> play operator on lambda (hysteresis)
      -> segments: PEA1 straight, the PBA a constant-curvature arc, PEA2 straight
      -> end point (forward kinematics of the segments)

**Chamber** (isothermal gas, a tube of constant conductance from the valve): the time constant
``tau_c = tau_c0 lambda`` grows with the chamber volume ``V = A lambda L``; the second term is
the gas-structure coupling of section 2.1: a chamber that stretches expands its gas and loses
pressure. **Wall**: the chamber's effective area times its pressure against the wall's
neo-Hookean tension (the material law of the paper's FE model, section 2.2) in the stretch
``lambda`` of the chamber's length, plus a viscous term (Kelvin-Voigt: soft printed walls creep).
At rest ``lambda = 1``; at steady state ``p = mu (lambda - lambda^-2)`` (`wall_stretch`).

**Segments** (constant curvature, Webster & Jones 2010): PEA1 (length ``l = l0 lambda_PEA``)
hangs along +z from the mount; the PBA is an arc of constant length ``L_b`` bent by ``theta``
towards the azimuth ``phi``; PEA2 (the same ``l``, one pressure through the T-pipe) continues
straight along the arc's end tangent. In the bending plane, with ``r`` the distance from the
z axis::

    r = L_b (1 - cos theta) / theta + l sin theta,    z = l + L_b sin theta / theta + l cos theta

The bellows tilt the PBA's lower plate by the difference of their stretches
(``b_x = L_b (lambda_B4 - lambda_B2) / (2 r_b)``, ``b_y`` likewise from B3 - B1 times
``y_bend_ratio``, the vector rotated by ``bend_skew``); the folds' stroke limit saturates the
tilt (``theta_free = theta_max tanh(|b| / theta_max)``: two inflated bellows bend the PBA little
more than one, as an FE model of stroke-limited bellows does), and the weight of PEA2 and the
end, hanging from the PBA, bends it back: ``theta + gamma (l / l0) sin(theta) = theta_free``.

Bend directions follow Fig 4 (`inflarm_model.soft_arm.BELLOWS_PUSH`): B4 bends the end towards
+x, B2 towards -x, B3 towards +y, B1 towards -y. Bending lowers z (Fig 5A's curved envelope).
With all chambers at 0 Pa the arm rests straight at ``(0, 0, 0.604)`` m, the initial point of
the Fig 7 experiment.

`SoftArmPlant.measure` returns the end point as the external camera sees it: noise across the
line of sight from the image centre's error, and larger noise along it from the image radius'
error (`inflarm_model.camera.sphere_position_std`, the camera of `SraCamera`). `NOISE_FREE`
keeps the delay and measures exactly (deterministic trials), `IDEAL` has neither.
"""

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from inflarm_hw.synthetic_camera import SraCamera
from inflarm_hw.valve import ITV2050, ValveModel, pressure_to_voltage, voltage_to_pressure
from inflarm_model.camera import sphere_position_std
from inflarm_model.soft_arm import CHAMBER_MAX_PRESSURE, CHAMBERS

_N_CHAMBERS = len(CHAMBERS)
_BELLOWS = slice(1, _N_CHAMBERS)
# CHAMBERS order: B1 pushes -y, B2 -x, B3 +y, B4 +x (BELLOWS_PUSH)
_B1, _B2, _B3, _B4 = (CHAMBERS.index(b) for b in ('B1', 'B2', 'B3', 'B4'))

P_ATM = 101.325e3
"""Atmospheric pressure [Pa]: chamber pressures are gauge, the gas law needs absolute ones."""


def wall_stretch(pressure: npt.ArrayLike, modulus: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Steady stretch of a chamber wall under pressure: the neo-Hookean law inverted.

    Solves ``p = mu (lambda - lambda^-2)`` for ``lambda >= 1`` (the cubic
    ``lambda^3 - (p / mu) lambda^2 - 1 = 0`` has one real root; Cardano).

    Parameters
    ----------
    pressure : array-like, any shape
        Gauge pressure [Pa]; negative values count as 0.
    modulus : array-like, broadcastable
        ``mu``, the wall's stiffness as a pressure [Pa] (shear modulus times wall section over
        effective area), > 0.

    Returns
    -------
    ndarray, broadcast shape
        ``lambda`` [-].
    """
    s = np.maximum(np.asarray(pressure, dtype=float), 0.0) / modulus
    half_b = -(s ** 3) / 27.0 - 0.5
    root = np.sqrt(half_b * half_b - s ** 6 / 729.0)
    return np.cbrt(-half_b + root) + np.cbrt(-half_b - root) + s / 3.0


def wall_pressure(stretch: npt.ArrayLike, modulus: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Pressure that holds a chamber wall at ``stretch``: ``mu (lambda - lambda^-2)`` [Pa]."""
    lam = np.asarray(stretch, dtype=float)
    return modulus * (lam - lam ** -2)


class PlantParameterError(ValueError):
    """A `SoftArmPlantParams` field out of its range; ``field`` names it (a node maps it to the
    ROS parameter it came from)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class SoftArmPlantParams:
    """Constants of the simulated SRA, each identified from the paper or chosen (with why).

    The paper identifies no plant model; its data are the work space of its nonlinear FE model
    (section 2.2, Fig 5A: X, Y -202..202 mm, Z 574..990 mm under 0-100 kPa), the Fig 7 start
    (0, 0, 604) mm at 0 kPa, Fig 4 (20 kPa visibly bends and stretches the arm), the valves'
    0-4 kPa dead zone (4.3.2) and the qualitative dynamics of 3.3 (the large PEA chamber is
    slow and overshoots; y is the slowest axis). The time constants below are chosen, not
    identified; with them the Fig 7 task's time responses come out near the paper's
    (``inflarm_hw/README.md`` compares them).

    Attributes
    ----------
    pba_length : float
        ``L_b``, length of the PBA between its nylon plates [m]. 0.06 m: chosen (the paper gives
        no dimension; Fig 1B's PBA is short against the PEAs).
    pea_rest_length : float
        ``l0``, length of PEA1 (= PEA2) at 0 Pa [m]. 0.272 m: ``2 l0 + L_b = 0.604`` m, the
        Fig 7 start at 0 kPa.
    pea_modulus : float
        ``mu`` of the PEA wall [Pa]. 73.1 kPa: identified from Z max, ``2 l + L_b = 0.990`` m at
        the chambers' 100 kPa (``lambda = 1.710``, ``100 kPa / (lambda - lambda^-2)``).
    bellows_modulus : float
        ``mu`` of a bellows wall [Pa]. 40 kPa: chosen so that two bellows at the chambers'
        100 kPa reach the stroke limit (Fig 5A's extremes are reached at full pressure) and the
        Fig 7 target needs about 46 and 42 kPa in B3 and B4, inside the learned feedforward's
        90 kPa cap (``PidIlcParams.p_set``).
    bellows_lever : float
        ``r_b``, distance of each bellows' axis from the PBA's axis [m]. 0.03 m: chosen; with
        ``L_b`` a bellows stretch of 1 tilts the plate by ``L_b / (2 r_b) = 1`` rad.
    bend_limit : float
        ``theta_max``, the tilt the bellows' folds allow (stroke limit) [rad]. 0.735 rad:
        identified with ``gravity_moment`` from Fig 5A: X, Y max 202 mm at full length and
        Z min 566 mm at ``l0`` (Fig 5A: 574 mm; one more constraint than constants).
    stroke_sharpness : float
        ``k`` of the stroke limit ``theta_free = |b| / (1 + (|b| / theta_max)^k)^(1/k)`` [-]:
        linear tilt well below the limit, flat at it. 8: chosen; the limit acts on the tilt's
        size, so two inflated bellows bend the PBA no further than one (which Fig 5A's X max
        and Z min together require) and near the limit x and y compete for it.
    gravity_moment : float
        ``gamma``, the weight moment of PEA2 and the end about the PBA at ``l0`` over the PBA's
        bending stiffness [-] (it grows with ``l``): the arm hangs from its mount (3.3), so a
        longer arm bends less and Fig 5A's envelope curves in. 0.45: identified with
        ``bend_limit``.
    y_bend_ratio : float
        Tilt about the x axis (moving the end in y) per bellows stretch, relative to the x tilt
        [-]. 0.9: chosen, not identified. The T-pipe that joins PEA1 and PEA2 (3.1) bridges the
        PBA; running along the B1-B3 (y) line it stiffens bending in y a little; the stroke
        limit keeps Y max at X max.
    bend_skew : float
        Rotation of the bend vector about +z from bellows misalignment [rad]. 0.03 rad (1.7 deg):
        chosen, couples x and y weakly, as on a hand-assembled PBA.
    pea_time_constant, bellows_time_constant : float
        ``tau_c0``: pneumatic time constant of a chamber at rest volume, valve plus tube [s];
        it grows with the volume (``tau_c0 lambda``). 1.0 s for PEA1&2 (two large chambers
        behind one valve, "the large chamber volume of PEA1&2", 3.3) and 0.6 s for a bellows:
        identified from the paper's Fig 7 time responses (with the creep times, below).
    pea_creep_time, bellows_creep_time : float
        Creep time of the wall at small strain, ``eta / (3 mu)`` of the Kelvin-Voigt wall [s];
        the tangent stiffness falls with the stretch (neo-Hookean softening), so a stretched
        wall creeps more slowly. 0.5 s for the PEA, 1.0 s for a bellows: with the chambers'
        time constants and the valve delay they set Fig 7's reach times, and were chosen to
        reproduce them (trial 30 x, z in about 5 s, y in about 8 s, with the controller's
        defaults: ``inflarm_hw/README.md``).
    pea_play, bellows_play : float
        Half-width of the play (backlash) operator on each chamber's stretch [-]: soft-material
        hysteresis. 0.001 each (0.3 mm per PEA, 1 mrad of tilt): chosen below the paper's 5 mm
        accuracy and the camera's noise.
    valve : inflarm_hw.valve.ValveModel
        The five proportional valves (eq. (2), dead zone, range): the ITV2050's 0.005-0.9 MPa
        over 0-10 V and the "dead zone of the proportional valves at 0-4 kPa" (4.3.2).
    valve_delay : float
        Transport delay between a command and the valves' output [s]: a command given at ``t``
        sets the valve outputs from ``t + valve_delay`` on. 0.1 s: the response time class of
        regulators of the ITV2050's size (the prototype's were not characterized), the "various
        unavoidable delays" of 3.1. 0 gives ideal valves.
    max_substep : float
        Largest internal integration step [s]. 0.05 s (4 substeps at 5 Hz): well below the
        fastest time constant (the bellows' 0.6 s).
    camera : inflarm_hw.synthetic_camera.SraCamera
        The external camera whose error `SoftArmPlant.measure` imitates: its pose, focal
        length and ball (the same set-up ``sra_sim`` renders).
    noise_center_px, noise_radius_px : float
        Standard deviations of the ball image's centre (per image axis) and radius [px] behind
        `SoftArmPlant.measure`. 0.12 px and 0.013 px: the errors of ``sra_sim``'s camera +
        ``ball_tracker`` (about 0.1 mm across the line of sight and 0.73 mm median along it at
        1.1-1.2 m, ``inflarm_vision/README.md``; 1.1 mm standard deviation in depth, 0.15 mm
        across). 0 for exact measurements (`NOISE_FREE`).
    """

    pba_length: float = 0.06
    pea_rest_length: float = 0.272
    pea_modulus: float = 73.1e3
    bellows_modulus: float = 40e3
    bellows_lever: float = 0.03
    bend_limit: float = 0.735
    stroke_sharpness: float = 8.0
    gravity_moment: float = 0.45
    y_bend_ratio: float = 0.9
    bend_skew: float = 0.03
    pea_time_constant: float = 1.0
    bellows_time_constant: float = 0.6
    pea_creep_time: float = 0.5
    bellows_creep_time: float = 1.0
    pea_play: float = 0.001
    bellows_play: float = 0.001
    valve: ValveModel = ITV2050
    valve_delay: float = 0.1
    max_substep: float = 0.05
    camera: SraCamera = field(default_factory=SraCamera)
    noise_center_px: float = 0.12
    noise_radius_px: float = 0.013

    def __post_init__(self) -> None:
        if not isinstance(self.valve, ValveModel):
            raise PlantParameterError(
                'valve', f'expected valve a ValveModel, got {type(self.valve).__name__}')
        if not isinstance(self.camera, SraCamera):
            raise PlantParameterError(
                'camera', f'expected camera a SraCamera, got {type(self.camera).__name__}')
        for name, value in vars(self).items():
            if name not in ('valve', 'camera') and not np.isfinite(value):
                raise PlantParameterError(name, f'expected finite {name}, got {value}')
        positive = (
            'pba_length', 'pea_rest_length', 'pea_modulus', 'bellows_modulus', 'bellows_lever',
            'bend_limit', 'stroke_sharpness', 'y_bend_ratio', 'pea_time_constant',
            'bellows_time_constant', 'pea_creep_time', 'bellows_creep_time', 'max_substep')
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise PlantParameterError(name, f'expected {name} > 0, got {getattr(self, name)}')
        non_negative = ('gravity_moment', 'pea_play', 'bellows_play', 'valve_delay',
                        'noise_center_px', 'noise_radius_px')
        for name in non_negative:
            if getattr(self, name) < 0.0:
                raise PlantParameterError(
                    name, f'expected {name} >= 0, got {getattr(self, name)}')
        if self.bend_limit >= 0.5 * np.pi:
            raise PlantParameterError(
                'bend_limit', f'expected bend_limit < pi / 2 rad, got {self.bend_limit}')


# physical SoftArmPlantParams field, unit suffix of its ROS parameter ('' if unitless), description
_PLANT_FIELDS = (
    ('pba_length', 'm', 'length of the PBA between its plates [m]'),
    ('pea_rest_length', 'm', 'length of PEA1 (= PEA2) at 0 Pa [m]'),
    ('pea_modulus', 'pa', 'stiffness mu of the PEA wall, as a pressure [Pa]'),
    ('bellows_modulus', 'pa', 'stiffness mu of a bellows wall, as a pressure [Pa]'),
    ('bellows_lever', 'm', "distance of each bellows' axis from the PBA's axis [m]"),
    ('bend_limit', 'rad', "tilt the bellows' folds allow (stroke limit) [rad]"),
    ('stroke_sharpness', '', 'sharpness k of the stroke limit [-]'),
    ('gravity_moment', '', 'weight moment of PEA2 and the end over the PBA stiffness [-]'),
    ('y_bend_ratio', '', 'tilt about x per bellows stretch relative to the x tilt [-]'),
    ('bend_skew', 'rad', 'rotation of the bend vector about +z [rad]'),
    ('pea_time_constant', 's', 'pneumatic time constant of PEA1&2 at rest volume [s]'),
    ('bellows_time_constant', 's', 'pneumatic time constant of a bellows at rest volume [s]'),
    ('pea_creep_time', 's', 'creep time of the PEA wall at small strain [s]'),
    ('bellows_creep_time', 's', 'creep time of a bellows wall at small strain [s]'),
    ('pea_play', '', 'half-width of the play operator on the PEA stretch [-]'),
    ('bellows_play', '', 'half-width of the play operator on a bellows stretch [-]'),
    ('valve_delay', 's', 'transport delay from a command to the valve outputs [s]'),
    ('max_substep', 's', 'largest internal integration step [s]'),
)
PLANT_PARAMETER_NAMES = {
    field: f"plant.{field}{'_' + unit if unit else ''}" for field, unit, _ in _PLANT_FIELDS}
"""ROS parameter of each physical `SoftArmPlantParams` field (``plant.*``, unit-suffixed): the
names under which ``sra_sim`` takes them and ``inflarm-identify-plant`` writes them."""
PLANT_PARAMETER_DESCRIPTIONS = {field: description for field, _, description in _PLANT_FIELDS}
"""Description of each field in `PLANT_PARAMETER_NAMES`, with its unit."""

NOISE_FREE = SoftArmPlantParams(noise_center_px=0.0, noise_radius_px=0.0)
"""The default plant (valve delay included) with exact measurements: deterministic trials."""

IDEAL = SoftArmPlantParams(valve_delay=0.0, noise_center_px=0.0, noise_radius_px=0.0)
"""Instantaneous valves and exact measurements."""


def _solve_bend(theta_free, gravity):
    """``theta`` with ``theta + gravity sin(theta) = theta_free`` (Newton, monotone for
    ``theta < pi / 2``; 4 steps from ``theta_free / (1 + gravity)`` reach 1e-12 rad)."""
    theta = theta_free / (1.0 + gravity)
    for _ in range(4):
        theta -= (theta + gravity * np.sin(theta) - theta_free) / (1.0 + gravity * np.cos(theta))
    return theta


class SoftArmPlant:
    """``n`` independent simulated SRAs stepped together.

    Parameters
    ----------
    n : int
        Number of arms (leading axis of every state array).
    params : SoftArmPlantParams
        Plant constants.
    rng : numpy.random.Generator, optional
        Source of the measurement noise of `measure` (only used with noise).
    """

    def __init__(
        self,
        n: int = 1,
        params: SoftArmPlantParams = SoftArmPlantParams(),  # noqa: B008 (frozen, immutable)
        rng: np.random.Generator | None = None,
    ) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f'expected n an integer >= 1, got {n!r}')
        self.n = int(n)
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng()
        self.reset()

    @property
    def params(self) -> SoftArmPlantParams:
        """Plant constants; assigning new ones (e.g. another noise level) keeps the state."""
        return self._params

    @params.setter
    def params(self, params: SoftArmPlantParams) -> None:
        if not isinstance(params, SoftArmPlantParams):
            raise ValueError(f'expected params a SoftArmPlantParams, got {type(params).__name__}')
        self._params = p = params
        bellows = np.ones(_N_CHAMBERS - 1)
        self._modulus = np.append(p.pea_modulus, p.bellows_modulus * bellows)
        creep = np.append(p.pea_creep_time, p.bellows_creep_time * bellows)
        self._viscosity = 3.0 * self._modulus * creep  # eta = 3 mu t_creep [Pa s]
        self._tau0 = np.append(p.pea_time_constant, p.bellows_time_constant * bellows)
        self._play = np.append(p.pea_play, p.bellows_play * bellows)
        c, s = np.cos(p.bend_skew), np.sin(p.bend_skew)
        tilt = p.pba_length / (2.0 * p.bellows_lever)
        # stretches (n, 5) -> bend vector (bx, by): B4 - B2 along x, (B3 - B1) y_bend_ratio
        # along y, then rotated by the skew; the PEA column does not bend
        along = np.zeros((_N_CHAMBERS, 2))
        along[_B4, 0], along[_B2, 0] = tilt, -tilt
        along[_B3, 1], along[_B1, 1] = tilt * p.y_bend_ratio, -tilt * p.y_bend_ratio
        self._bend_matrix = along @ np.array([[c, s], [-s, c]])
        camera = p.camera
        self._camera_center = np.asarray(camera.translation_m, dtype=float)
        self._ball_radius = 0.5 * camera.ball_diameter_m
        self._noisy = p.noise_center_px > 0.0 or p.noise_radius_px > 0.0

    # -- state ---------------------------------------------------------------------------------

    def reset(self, end_point: npt.ArrayLike | None = None) -> None:
        """Put every arm at rest, or at steady state holding ``end_point``.

        Parameters
        ----------
        end_point : array-like, shape (3,) or (n, 3), optional
            Point to hold, in ``sra_mount`` [m]. The chambers are set to `holding_pressures`,
            the walls to their steady stretch and the hysteresis centred on it.
            ``None`` (default): all chambers at 0 Pa, straight arm at ``(0, 0, 0.604)`` m.
        """
        n = self.n
        pressures = (np.zeros((n, _N_CHAMBERS)) if end_point is None
                     else self.holding_pressures(end_point))
        self.time = 0.0
        self._pressure = pressures.copy()
        # valve outputs now [Pa], and the commanded ones still in the delay line:
        # (time they reach the valve outputs [s], outputs (n, 5) [Pa]), oldest first
        self._valve_output = pressures.copy()  # the valves have been holding them
        self._pending: list[tuple[float, npt.NDArray[np.float64]]] = []
        self._stretch = wall_stretch(pressures, self._modulus)
        self._stretch_play = self._stretch.copy()

    @property
    def chamber_pressures(self) -> npt.NDArray[np.float64]:
        """Chamber pressures, shape (n, 5), in `CHAMBERS` order [Pa] (a copy)."""
        return self._pressure.copy()

    @property
    def valve_outputs(self) -> npt.NDArray[np.float64]:
        """Pressures the valves deliver now, shape (n, 5), in `CHAMBERS` order [Pa] (a copy):
        the command of ``params.valve_delay`` ago through eq. (2) and the dead zone."""
        return self._valve_output.copy()

    @property
    def stretches(self) -> npt.NDArray[np.float64]:
        """Stretch of every chamber's wall after the hysteresis, shape (n, 5) [-] (a copy)."""
        return self._stretch_play.copy()

    @property
    def end_point(self) -> npt.NDArray[np.float64]:
        """True end point of every arm, shape (n, 3), in ``sra_mount`` [m]."""
        return self._end_point_of(self._stretch_play)

    def measure(self) -> npt.NDArray[np.float64]:
        """End point as the external camera sees it, shape (n, 3) [m].

        `end_point` plus Gaussian noise whose spread across and along the camera's line of
        sight to the ball follows from the image errors ``noise_center_px`` and
        ``noise_radius_px`` (`inflarm_model.camera.sphere_position_std`).
        """
        end = self.end_point
        if not self._noisy:
            return end
        p = self.params
        ray = end - self._camera_center
        distance = np.linalg.norm(ray, axis=-1, keepdims=True)
        ray /= distance
        lateral, depth = sphere_position_std(distance, self._ball_radius, p.camera.focal_px,
                                             p.noise_center_px, p.noise_radius_px)
        w = self.rng.standard_normal((self.n, 3))
        along = np.einsum('ij,ij->i', w, ray)[:, None]
        return end + lateral * w + (depth - lateral) * along * ray

    # -- valves, eq. (2) (inflarm_hw.valve) ----------------------------------------------------

    def valve_voltage(self, pressure: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Control voltage that asks a valve for ``pressure`` [Pa], any shape: eq. (2) inverted,
        clamped to the valve's input range [V] (`inflarm_hw.valve.pressure_to_voltage`)."""
        return pressure_to_voltage(pressure, self.params.valve)

    def valve_pressure(self, voltage: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Output pressure of a valve for a control voltage [V], any shape: eq. (2) plus the
        dead zone [Pa] (`inflarm_hw.valve.voltage_to_pressure`)."""
        return voltage_to_pressure(voltage, self.params.valve)

    # -- kinematics and statics ----------------------------------------------------------------

    def _end_point_of(self, stretch: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """End point (..., 3) of wall stretches (..., 5): the segments' forward kinematics."""
        p = self.params
        ratio = stretch[..., 0]
        l1 = p.pea_rest_length * ratio
        b = (stretch - 1.0) @ self._bend_matrix
        size = np.hypot(b[..., 0], b[..., 1])
        theta_free = size / (1.0 + (size / p.bend_limit) ** p.stroke_sharpness) ** (
            1.0 / p.stroke_sharpness)
        theta = _solve_bend(theta_free, p.gravity_moment * ratio)
        with np.errstate(invalid='ignore', divide='ignore'):
            direction = np.where(size[..., None] > 0.0, b / size[..., None], 0.0)
        # (1 - cos t) / t and sin t / t, finite at t = 0
        half = np.sinc(theta / (2.0 * np.pi))
        arc_r = p.pba_length * 0.5 * theta * half * half
        arc_z = p.pba_length * np.sinc(theta / np.pi)
        r = arc_r + l1 * np.sin(theta)
        z = l1 + arc_z + l1 * np.cos(theta)
        return np.concatenate([r[..., None] * direction, z[..., None]], axis=-1)

    def static_end_point(self, pressures: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """End point at steady state under constant chamber pressures, ignoring hysteresis.

        Parameters
        ----------
        pressures : array-like, shape (5,) or (..., 5)
            Chamber pressures in `CHAMBERS` order [Pa], non-negative.

        Returns
        -------
        end_point : ndarray, shape (3,) or (..., 3)
            In ``sra_mount`` [m]. Steady states reached through the hysteresis lie within the
            play (``pea_play``, ``bellows_play``) of it.
        """
        pr = np.asarray(pressures, dtype=float)
        if pr.ndim == 0 or pr.shape[-1] != _N_CHAMBERS:
            raise ValueError(f'expected pressures of shape (5,) or (..., 5), got {pr.shape}')
        if not np.all(np.isfinite(pr)) or np.any(pr < 0.0):
            raise ValueError(f'expected finite non-negative pressures [Pa], got {pr}')
        return self._end_point_of(wall_stretch(pr, self._modulus))

    def holding_pressures(self, end_point: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Chamber pressures whose static shape is ``end_point`` (inverse of `static_end_point`).

        Only the two bellows of the target's quadrant are inflated (Fig 4); the others are 0.
        The segments' inverse kinematics is solved by bisection on the bend (the in-plane
        residual is monotone in ``theta``), then the bend and the PEA length are turned into
        stretches and those into pressures (`wall_pressure`).

        Parameters
        ----------
        end_point : array-like, shape (3,) or (n, 3)
            Point in ``sra_mount`` [m].

        Returns
        -------
        pressures : ndarray, shape (n, 5)
            In `CHAMBERS` order [Pa].

        Raises
        ------
        ValueError
            If the simulated arm cannot hold the point within the chambers' rating
            (`inflarm_model.soft_arm.CHAMBER_MAX_PRESSURE`): too short, too long or bent too far.
        """
        pt = np.asarray(end_point, dtype=float)
        if pt.shape not in ((3,), (self.n, 3)):
            raise ValueError(f'expected end_point of shape (3,) or ({self.n}, 3), got {pt.shape}')
        if not np.isfinite(pt).all() or np.any(pt[..., 2] <= 0.0):
            raise ValueError(f'expected finite end_point with z > 0 [m], got {pt}')
        pt = np.broadcast_to(pt, (self.n, 3))
        p = self.params
        r = np.hypot(pt[:, 0], pt[:, 1])
        z = pt[:, 2]
        lo, hi = np.zeros(self.n), np.full(self.n, 0.5 * np.pi)
        for _ in range(60):  # r(theta) at this z grows with theta: bisection to 1e-18 rad
            theta = 0.5 * (lo + hi)
            half = np.sinc(theta / (2.0 * np.pi))
            l1 = (z - p.pba_length * np.sinc(theta / np.pi)) / (1.0 + np.cos(theta))
            residual = p.pba_length * 0.5 * theta * half * half + l1 * np.sin(theta) - r
            lo, hi = np.where(residual < 0.0, theta, lo), np.where(residual < 0.0, hi, theta)
        theta = 0.5 * (lo + hi)
        l1 = (z - p.pba_length * np.sinc(theta / np.pi)) / (1.0 + np.cos(theta))
        stretch = np.ones((self.n, _N_CHAMBERS))
        stretch[:, 0] = l1 / p.pea_rest_length
        pressures = np.zeros((self.n, _N_CHAMBERS))
        pressures[:, 0] = wall_pressure(stretch[:, 0], p.pea_modulus)
        if np.any(stretch[:, 0] < 1.0) or np.any(pressures[:, 0] > CHAMBER_MAX_PRESSURE):
            raise ValueError(
                f'end_point needs a PEA length outside the simulated range '
                f'[{p.pea_rest_length:.3f}, '
                f'{p.pea_rest_length * wall_stretch(CHAMBER_MAX_PRESSURE, p.pea_modulus):.3f}]'
                f' m (0-{CHAMBER_MAX_PRESSURE / 1e3:.0f} kPa)')
        theta_free = theta + p.gravity_moment * stretch[:, 0] * np.sin(theta)
        if np.any(theta_free >= p.bend_limit):
            raise ValueError(
                f'end_point needs a bend beyond the simulated stroke limit {p.bend_limit:.3f} rad')
        size = theta_free / (1.0 - (theta_free / p.bend_limit) ** p.stroke_sharpness) ** (
            1.0 / p.stroke_sharpness)
        phi = np.arctan2(pt[:, 1], pt[:, 0])
        b = size[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        c, s = np.cos(p.bend_skew), np.sin(p.bend_skew)
        bx, by = (b @ np.array([[c, s], [-s, c]]).T).T  # undo the skew
        tilt = p.pba_length / (2.0 * p.bellows_lever)
        stretch[:, _B4] += np.maximum(bx, 0.0) / tilt
        stretch[:, _B2] += np.maximum(-bx, 0.0) / tilt
        stretch[:, _B3] += np.maximum(by, 0.0) / (tilt * p.y_bend_ratio)
        stretch[:, _B1] += np.maximum(-by, 0.0) / (tilt * p.y_bend_ratio)
        pressures[:, _BELLOWS] = wall_pressure(stretch[:, _BELLOWS], p.bellows_modulus)
        if np.any(pressures[:, _BELLOWS] > CHAMBER_MAX_PRESSURE):
            raise ValueError(
                f'end_point needs a bend beyond the bellows at {CHAMBER_MAX_PRESSURE / 1e3:.0f} '
                f'kPa')
        return pressures

    # -- dynamics ------------------------------------------------------------------------------
    def step(self, pressure_command: npt.ArrayLike, dt: float) -> None:
        """Apply valve set pressures for ``dt`` seconds.

        Parameters
        ----------
        pressure_command : array-like, shape (n, 5) or (5,)
            Set pressure of each valve in `CHAMBERS` order [Pa] (a (5,) command goes to every
            arm). Turned into valve voltages by eq. (2) (`step_valve_voltages`).
        dt : float
            Duration [s], > 0; integrated in substeps of at most ``params.max_substep``.
        """
        cmd = np.asarray(pressure_command, dtype=float)
        if cmd.shape not in ((self.n, _N_CHAMBERS), (_N_CHAMBERS,)):
            raise ValueError(
                f'expected pressure_command of shape ({self.n}, 5) or (5,), got {cmd.shape}')
        if not np.isfinite(cmd).all():
            raise ValueError('expected finite pressure_command [Pa]')
        self.step_valve_voltages(self.valve_voltage(cmd), dt)

    def step_valve_voltages(self, voltages: npt.ArrayLike, dt: float) -> None:
        """Drive the valves at control voltages for ``dt`` seconds (what an MCU's DACs do).

        Parameters
        ----------
        voltages : array-like, shape (n, 5) or (5,)
            Control voltage of each valve in `CHAMBERS` order [V]. From ``params.valve_delay``
            after now on, each valve delivers eq. (2) of it (clamped to its input range, 0 Pa
            in the dead zone) until the next command arrives, and its chamber's pressure
            follows that output.
        dt : float
            Duration [s], > 0; integrated in substeps of at most ``params.max_substep``.
        """
        u = np.asarray(voltages, dtype=float)
        if u.shape not in ((self.n, _N_CHAMBERS), (_N_CHAMBERS,)):
            raise ValueError(
                f'expected voltages of shape ({self.n}, 5) or (5,), got {u.shape}')
        if not np.isfinite(u).all():
            raise ValueError('expected finite voltages [V]')
        if not (dt > 0.0 and np.isfinite(dt)):
            raise ValueError(f'expected dt > 0 s, got {dt}')
        output = np.broadcast_to(self.valve_pressure(u), self._pressure.shape).copy()
        self._pending.append((self.time + self.params.valve_delay, output))
        # integrate piecewise: the valve outputs change when a command leaves the delay line
        # (times within 1 ns count as equal: steps of dt add up with rounding errors)
        now, end = self.time, self.time + dt
        while True:
            while self._pending and self._pending[0][0] <= now + 1e-9:
                self._valve_output = self._pending.pop(0)[1]
            until = self._pending[0][0] if self._pending else end
            if until >= end - 1e-9:
                self._integrate(end - now)
                break
            self._integrate(until - now)
            now = until
        self.time = end

    def _integrate(self, dt: float) -> None:
        """Advance chambers and walls by ``dt`` [s] under constant valve outputs (module
        docstring: the chamber's gas law, the Kelvin-Voigt wall, the play operator)."""
        p = self.params
        n_sub = max(1, int(np.ceil(dt / p.max_substep - 1e-9)))
        h = dt / n_sub
        target, pressure, stretch = self._valve_output, self._pressure, self._stretch
        for _ in range(n_sub):
            rate = (pressure - wall_pressure(stretch, self._modulus)) / self._viscosity
            fill = -np.expm1(-h / (self._tau0 * stretch))
            pressure += (target - pressure) * fill - h * (pressure + P_ATM) * rate / stretch
            stretch += h * rate
            np.clip(self._stretch_play, stretch - self._play, stretch + self._play,
                    out=self._stretch_play)
