"""The inflarm JSON messages: a frozen dataclass per type, each field declared once with its kind.

SI units throughout (m, Pa, s, N m); vectors are ``(x, y, z)`` tuples of floats. Constructing a
message validates it and normalises its values (ints to floats, lists and numpy arrays to tuples,
dicts to Cuboids), so an invalid message cannot exist; ``decode`` builds messages through the same
constructors.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from inflarm_msgs_json.spec import (
    Array,
    Choice,
    Integer,
    Map,
    Message,
    MessageError,
    Nested,
    Nullable,
    Number,
    Record,
    Text,
    field_spec,
)

#: Lowest gauge pressure a chamber can hold: absolute vacuum at standard atmosphere [Pa].
VACUUM_GAUGE_PA = -101325.0

#: Tolerance of LinkStatus.margin against wrinkling_moment - moment, relative to the larger moment
#: (absolute below 1 N m): room for rounding, none for a stale or mismatched margin.
MARGIN_TOLERANCE = 1e-9

FINITE = Number()
NONNEGATIVE = Number(minimum=0.0)
POSITIVE = Number(minimum=0.0, exclusive=True)
COUNT = Integer(minimum=0)
NAME = Text()
VEC3 = Array(FINITE, length=3)

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Cuboid(Record):
    """Axis-aligned box given by its two extreme corners; not a message by itself.

    min <= max on every axis (a flat box is allowed).
    """

    min: Vec3 = field_spec(VEC3, 'corner with the smallest coordinates [m]')
    max: Vec3 = field_spec(VEC3, 'corner with the largest coordinates [m]')
    name: str = field_spec(Text(allow_empty=True), 'label for logs and markers', default='')

    def _check_invariants(self, path: str) -> None:
        for axis, low, high in zip('xyz', self.min, self.max, strict=True):
            if low > high:
                raise MessageError(path, f'expected min <= max, got {axis}: {low!r} > {high!r}')


@dataclass(frozen=True)
class ObstacleSet(Message):
    """Obstacles around the arm, as axis-aligned boxes."""

    frame_id: str = field_spec(NAME, 'frame the boxes are expressed in')
    alert_margin: float = field_spec(
        NONNEGATIVE, 'clearance to a box below which the arm raises an alert [m]'
    )
    obstacles: tuple[Cuboid, ...] = field_spec(Array(Nested(Cuboid)), 'the boxes; may be empty')


@dataclass(frozen=True)
class PlanRequest(Message):
    """Request for a collision-free path of the tip from start to goal."""

    frame_id: str = field_spec(NAME, 'frame of start and goal')
    start: Vec3 = field_spec(VEC3, 'tip position to start from [m]')
    goal: Vec3 = field_spec(VEC3, 'tip position to reach [m]')
    resolution: float = field_spec(POSITIVE, 'planning grid cell size [m]')


PLAN_STATUSES = ('planned', 'no_path', 'rejected')


@dataclass(frozen=True)
class PlanOutcome(Message):
    """Outcome of one plan request: the planned path's figures, or why there is none.

    ``status`` is ``'planned'`` (a path was published), ``'no_path'`` (none exists; ``reason``
    says which check failed) or ``'rejected'`` (the request itself was invalid). ``reason`` is
    empty unless the status is ``'no_path'``; the figures are 0 unless it is ``'planned'``.
    """

    status: str = field_spec(Choice(PLAN_STATUSES), "'planned', 'no_path' or 'rejected'")
    reason: str = field_spec(
        Text(allow_empty=True),
        "why there is no path, e.g. 'start_blocked' or 'no_connection'; '' otherwise",
    )
    message: str = field_spec(Text(allow_empty=True), 'what happened, for people and logs')
    start: Vec3 = field_spec(VEC3, 'requested start [m]')
    goal: Vec3 = field_spec(VEC3, 'requested goal [m]')
    waypoints: int = field_spec(COUNT, 'poses in the published path')
    length: float = field_spec(NONNEGATIVE, 'length of the published path [m]')
    duration: float = field_spec(NONNEGATIVE, 'time the path is parameterized to take [s]')
    planning_time: float = field_spec(NONNEGATIVE, 'wall time spent planning [s]')

    def _check_invariants(self, path: str) -> None:
        if (self.status == 'no_path') != bool(self.reason):
            raise MessageError(
                f'{path}.reason',
                f"expected a reason exactly when status is 'no_path', got status "
                f'{self.status!r} and reason {self.reason!r}',
            )
        if self.status == 'planned' and self.waypoints == 0:
            raise MessageError(f'{path}.waypoints', "expected waypoints > 0 when 'planned'")
        if self.status != 'planned' and (self.waypoints or self.length or self.duration):
            raise MessageError(
                f'{path}.waypoints', f'expected no path figures when {self.status!r}')


@dataclass(frozen=True)
class _ChamberPressureMap(Message, abstract=True):
    """Gauge pressure per chamber, shared by commanded and measured pressures."""

    chambers: tuple[tuple[str, float], ...] = field_spec(
        Map(Number(minimum=VACUUM_GAUGE_PA)),
        'gauge pressure by chamber name, at least one chamber, not below vacuum [Pa]',
    )

    def as_dict(self) -> dict[str, float]:
        """Return the pressures as a new ``{chamber name: gauge pressure [Pa]}`` dict."""
        return dict(self.chambers)


@dataclass(frozen=True)
class PressureCommand(_ChamberPressureMap):
    """Commanded gauge pressure per chamber.

    ``chambers`` is built from a mapping such as ``{'B1': 12000.0}`` and stored as (name, value)
    pairs sorted by name; ``as_dict()`` gives the mapping back.
    """


@dataclass(frozen=True)
class ChamberPressures(_ChamberPressureMap):
    """Measured gauge pressure per chamber.

    ``chambers`` is built from a mapping such as ``{'B1': 11950.0}`` and stored as (name, value)
    pairs sorted by name; ``as_dict()`` gives the mapping back.
    """


@dataclass(frozen=True)
class LinkPressures(Message):
    """Measured gauge pressure per inflated link of the inflatable arm.

    ``links`` is built from a mapping such as ``{'link_1': 50010.0}`` and stored as (name,
    value) pairs sorted by name; ``as_dict()`` gives the mapping back.
    """

    links: tuple[tuple[str, float], ...] = field_spec(
        Map(Number(minimum=VACUUM_GAUGE_PA)),
        "gauge pressure by link name ('link_1', 'link_2'), at least one, not below vacuum [Pa]",
    )

    def as_dict(self) -> dict[str, float]:
        """Return the pressures as a new ``{link name: gauge pressure [Pa]}`` dict."""
        return dict(self.links)


#: HardwareStatus.state: the lifecycle state of the bridge.
BRIDGE_STATES = ('unconfigured', 'inactive', 'active', 'finalized')
#: HardwareStatus.link: the serial link to the MCU.
LINK_STATES = ('closed', 'handshake', 'connected', 'lost')
#: HardwareStatus.motors: what the motors are told; 'none' when the MCU has none.
MOTOR_OUTPUTS = ('none', 'follow', 'hold', 'zero_torque')
#: HardwareStatus.valves: what the valves are told; 'none' when the MCU has none.
VALVE_OUTPUTS = ('none', 'follow', 'safe')


@dataclass(frozen=True)
class HardwareStatus(Message):
    """State of a hardware bridge: its outputs, the MCU link, faults and its reaction time."""

    state: str = field_spec(Choice(BRIDGE_STATES), 'lifecycle state of the bridge')
    link: str = field_spec(Choice(LINK_STATES), 'serial link to the MCU')
    motors: str = field_spec(
        Choice(MOTOR_OUTPUTS), "motor output: following commands, or a safe 'hold' or zero torque"
    )
    valves: str = field_spec(
        Choice(VALVE_OUTPUTS), "valve output: following commands, or the configured 'safe' one"
    )
    faults: tuple[str, ...] = field_spec(Array(NAME), 'active faults, latched ones included')
    latched: tuple[str, ...] = field_spec(
        Array(NAME), 'faults that hold the safe output until reset (a subset of faults)'
    )
    reason: str = field_spec(
        Text(allow_empty=True), 'why an output is safe; empty while both follow commands'
    )
    safe_latency: float | None = field_spec(
        Nullable(NONNEGATIVE),
        'last measured time from detecting a fault or timeout to the MCU confirming the safe '
        'output, null if none yet [s]',
    )
    clamped: int = field_spec(COUNT, 'commands clamped to a limit since start')
    rejected: int = field_spec(COUNT, 'commands rejected since start')
    bad_frames: int = field_spec(COUNT, 'bad frames received from the MCU since start')

    def _check_invariants(self, path: str) -> None:
        extra = sorted(set(self.latched) - set(self.faults))
        if extra:
            raise MessageError(f'{path}.latched', f'expected a subset of faults, got {extra}')


@dataclass(frozen=True)
class ControlTask(Message):
    """Task for the tip controller: reach a target, in one trial of a series."""

    frame_id: str = field_spec(NAME, 'frame of the target')
    target: Vec3 = field_spec(VEC3, 'tip position to reach [m]')
    mode: str = field_spec(
        Choice(('pid', 'pid_ilc')), "'pid', or 'pid_ilc' to learn from trial to trial"
    )
    trial_id: int = field_spec(COUNT, 'trial number, from 0')


@dataclass(frozen=True)
class TrialReport(Message):
    """Outcome of one control trial, per axis x, y, z."""

    trial_index: int = field_spec(COUNT, 'trial number, from 0')
    rmse: Vec3 = field_spec(Array(NONNEGATIVE, length=3), 'tracking RMS error per axis [m]')
    reach_time: tuple[float | None, float | None, float | None] = field_spec(
        Array(Nullable(NONNEGATIVE), length=3),
        'time to reach the target per axis, null if not reached [s]',
    )


#: Where inflarm nodes publish their `CallbackRecord`s (parameter ``callback_log``).
CALLBACK_LOG_TOPIC = '/callback_log'


@dataclass(frozen=True)
class PublishedMessage(Record):
    """A message a callback published, named as `CallbackRecord` names the one it took; not a
    message by itself."""

    topic: str = field_spec(NAME, "the resolved topic, e.g. '/link_status'")
    stamp_ns: int | None = field_spec(
        Nullable(COUNT), 'its header stamp [ns]; null without one'
    )
    digest: int | None = field_spec(
        Nullable(COUNT), 'CRC-32 of the text of a std_msgs/String; null otherwise'
    )


@dataclass(frozen=True)
class CallbackRecord(Message):
    """One callback a node ran: what ``inflarm-bag-regression`` replays, in this order."""

    node: str = field_spec(NAME, "the node's fully qualified name, e.g. '/load_estimator'")
    callback: str = field_spec(
        NAME, "a subscription's resolved topic, e.g. '/joint_states', or 'timer <name>'"
    )
    time_ns: int = field_spec(COUNT, "the node's clock when the callback began [ns]")
    stamp_ns: int | None = field_spec(
        Nullable(COUNT), 'the header stamp of the message taken [ns]; null without one'
    )
    digest: int | None = field_spec(
        Nullable(COUNT), 'CRC-32 of the text of a std_msgs/String taken; null otherwise'
    )
    published: tuple[PublishedMessage, ...] = field_spec(
        Array(Nested(PublishedMessage)),
        'the messages it published with a stamp or a text, in order', default=()
    )


@dataclass(frozen=True)
class LinkStatus(Message):
    """Wrinkling safety of one inflated link: how far its bending moment is from wrinkling.

    Build it with ``LinkStatus.from_moments`` to have the margin computed.
    """

    link: str = field_spec(NAME, "link name, e.g. 'link_1'")
    pressure: float = field_spec(POSITIVE, 'link pressure [Pa]')
    wrinkling_moment: float = field_spec(
        NONNEGATIVE, 'bending moment at which the wall wrinkles [N m]'
    )
    moment: float = field_spec(NONNEGATIVE, 'magnitude of the current bending moment [N m]')
    margin: float = field_spec(
        FINITE, 'wrinkling_moment - moment; negative once the link wrinkles [N m]'
    )

    @classmethod
    def from_moments(
        cls, link: str, pressure: float, wrinkling_moment: float, moment: float
    ) -> LinkStatus:
        """Build a status with ``margin = wrinkling_moment - moment``.

        Parameters
        ----------
        link : str
            Link name, e.g. ``'link_1'``.
        pressure : float
            Link pressure [Pa], > 0.
        wrinkling_moment : float
            Bending moment at which the wall wrinkles [N m], >= 0.
        moment : float
            Magnitude of the current bending moment [N m], >= 0.

        Returns
        -------
        LinkStatus

        Raises
        ------
        MessageError
            If an argument is invalid; the error names the field.
        """
        try:
            margin: Any = wrinkling_moment - moment
        except (TypeError, ValueError):
            margin = None  # the field checks, which run before margin's, name the bad argument
        return cls(link, pressure, wrinkling_moment, moment, margin)

    def _check_invariants(self, path: str) -> None:
        expected = self.wrinkling_moment - self.moment
        tolerance = MARGIN_TOLERANCE * max(1.0, self.wrinkling_moment, self.moment)
        if abs(self.margin - expected) > tolerance:
            raise MessageError(
                f'{path}.margin',
                f'expected wrinkling_moment - moment = {expected!r}, got {self.margin!r}',
            )
