"""``inflarm-identify-plant``: the soft-arm plant's constants identified from a recorded bag.

Usage::

    inflarm-identify-plant BAG --out plant.yaml [--command-topic chamber_pressure_command]
                           [--pressure-topic chamber_pressures] [--position-topic ball_position]
                           [--pressure-std 1000] [--position-std 0.001]

Reads from the rosbag2 bag BAG (sqlite3 or MCAP, as ``bag_recorder`` writes) the valve commands
(``PressureCommand`` JSON in std_msgs/String; a chamber not named keeps its command, as in
``sra_sim``), the measured chamber pressures (``ChamberPressures`` JSON) and the measured end
point (geometry_msgs/PointStamped: ``ball_position``, or ``end_point_truth`` with
``--position-topic``), all on the bag's record time. The recording must start with the arm at
rest (every chamber at 0 Pa). `inflarm_hw.sra_identification.identify_plant` fits the plant's
valve delay, time constants, moduli and creep times by least squares, replaying the plant on
the recorded commands. Prints the fitted values with their standard errors and the replay's RMS
error per chamber and per axis, and writes them as a ROS params file::

    sra_sim:
      ros__parameters:
        plant.valve_delay_s: 0.1
        ...

which ``ros2 run inflarm_hw sra_sim --ros-args --params-file plant.yaml`` loads.

Exit status: 0 on success; 1 when the fit does not converge (nothing written) or the file
cannot be written; 2 on bad arguments or a bag that cannot be identified from (unreadable, a
needed topic missing or of another type, too short, not starting at rest, NaN in a sample),
with a message naming what was wrong.
"""

import argparse
from collections.abc import Sequence
import sys

import numpy as np

from inflarm_hw.bag import bag_info, deserialize, normalize_topic, read_messages
from inflarm_hw.sra_identification import (
    IDENTIFIED_FIELDS,
    PlantIdentification,
    PlantRecording,
    identify_plant,
)
from inflarm_hw.sra_plant import PLANT_PARAMETER_NAMES, SoftArmPlantParams
from inflarm_model.soft_arm import CHAMBERS
from inflarm_msgs_json import ChamberPressures, MessageError, PressureCommand, decode
from inflarm_msgs_json.cli import positive_float, run_command

PROG = 'inflarm-identify-plant'
STRING = 'std_msgs/msg/String'
POINT_STAMPED = 'geometry_msgs/msg/PointStamped'
NODE_NAME = 'sra_sim'  # the params file is keyed by the node that loads it
MIN_DURATION_S = 5.0  # several of the slowest time constants (PEA, 1 s) and delays
MIN_SAMPLES = 20  # per measured series: well above the 7 fitted constants
REST_PRESSURE_PA = 2e3  # a first pressure sample above this: the arm was not at rest


class RecordingError(ValueError):
    """The bag cannot be identified from; the message says why."""


def build_parser() -> argparse.ArgumentParser:
    """Command-line parser of ``inflarm-identify-plant``."""
    parser = argparse.ArgumentParser(
        prog=PROG, description="Identify the soft arm's valve delay, time constants, moduli "
                               'and creep times from a recorded bag, and write them as an '
                               'sra_sim params file.')
    parser.add_argument('bag', help='rosbag2 directory (sqlite3 or MCAP)')
    parser.add_argument('--out', required=True, metavar='YAML',
                        help='ROS params file to write (sra_sim: ros__parameters: plant.*)')
    parser.add_argument('--command-topic', default='chamber_pressure_command',
                        help='valve commands, PressureCommand JSON (default: %(default)s)')
    parser.add_argument('--pressure-topic', default='chamber_pressures',
                        help='measured chamber pressures, ChamberPressures JSON '
                             '(default: %(default)s)')
    parser.add_argument('--position-topic', default='ball_position',
                        help='measured end point, PointStamped (default: %(default)s; '
                             'end_point_truth for the true one)')
    parser.add_argument('--pressure-std', type=positive_float, default=1e3, metavar='PA',
                        help='expected pressure measurement error [Pa], the weight of the '
                             'pressure residuals (default: %(default)s)')
    parser.add_argument('--position-std', type=positive_float, default=1e-3, metavar='M',
                        help='expected end point measurement error [m], the weight of the '
                             'position residuals (default: %(default)s)')
    return parser


def _check_topic(info, topic: str, msgtype: str) -> str:
    name = normalize_topic(topic)
    if name not in info.topics:
        raise RecordingError(f'the bag has no {name} ({msgtype}); it holds {sorted(info.topics)}')
    if info.topics[name].msgtype != msgtype:
        raise RecordingError(f'{name} holds {info.topics[name].msgtype}, expected {msgtype}')
    return name


def read_recording(bag: str, command_topic: str, pressure_topic: str,
                   position_topic: str) -> PlantRecording:
    """The commands, chamber pressures and end points of ``bag`` on its record time [s].

    Raises
    ------
    RecordingError
        When a topic is missing or of another type, a message is not what its topic carries,
        or a sample holds NaN (naming the topic).
    ValueError
        When ``bag`` is not a readable bag.
    """
    info = bag_info(bag)
    topics = {_check_topic(info, command_topic, STRING): 'command',
              _check_topic(info, pressure_topic, STRING): 'pressure',
              _check_topic(info, position_topic, POINT_STAMPED): 'position'}
    series: dict[str, tuple[list, list]] = {kind: ([], []) for kind in topics.values()}
    command = np.zeros(len(CHAMBERS))
    for message in read_messages(bag, list(topics)):
        kind = topics[message.topic]
        msg = deserialize(message.data, message.msgtype)
        try:
            if kind == 'command':  # a chamber not named keeps its command (sra_sim)
                for chamber, value in decode(msg.data, expected=PressureCommand).as_dict() \
                        .items():
                    command[CHAMBERS.index(chamber)] = value
                value = command.copy()
            elif kind == 'pressure':
                pressures = decode(msg.data, expected=ChamberPressures).as_dict()
                missing = [c for c in CHAMBERS if c not in pressures]
                if missing:
                    raise RecordingError(f'{message.topic}: a sample lacks chambers {missing}')
                value = [pressures[c] for c in CHAMBERS]
            else:
                value = [msg.point.x, msg.point.y, msg.point.z]
        except MessageError as error:
            raise RecordingError(f'{message.topic}: {error}') from error
        if not np.isfinite(value).all():
            raise RecordingError(f'{message.topic}: a sample holds NaN or an infinity at '
                               f't = {(message.timestamp_ns - info.start_ns) * 1e-9:.3f} s')
        series[kind][0].append((message.timestamp_ns - info.start_ns) * 1e-9)
        series[kind][1].append(value)
    widths = {'command': len(CHAMBERS), 'pressure': len(CHAMBERS), 'position': 3}
    arrays = {kind: (np.array(t, dtype=float), np.array(v, dtype=float).reshape(-1, widths[kind]))
              for kind, (t, v) in series.items()}
    return PlantRecording(*arrays['command'], *arrays['pressure'], *arrays['position'])


def check_identifiable(recording: PlantRecording, topics: dict[str, str]) -> None:
    """Raise `RecordingError` when ``recording`` is too short or does not start at rest.

    ``topics`` names the topic of each series ('command', 'pressure', 'position').
    """
    for kind, samples in (('pressure', recording.pressures), ('position', recording.positions)):
        if len(samples) < MIN_SAMPLES:
            raise RecordingError(f'too short to identify: {len(samples)} samples on '
                               f'{topics[kind]}, at least {MIN_SAMPLES} needed')
    if recording.duration < MIN_DURATION_S:
        raise RecordingError(f'too short to identify: {recording.duration:.1f} s recorded, at '
                           f'least {MIN_DURATION_S:.0f} s needed')
    if not np.any(recording.commands > 0.0):
        raise RecordingError(
            f'nothing to identify: no chamber was commanded on {topics["command"]}')
    if np.any(recording.pressures[0] > REST_PRESSURE_PA):
        raise RecordingError(
            f'the recording does not start at rest: {topics["pressure"]} first reads '
            f'{np.round(recording.pressures[0] / 1e3, 1).tolist()} kPa ({", ".join(CHAMBERS)});'
            ' record from a vented arm')


def _yaml_float(value: float) -> str:
    """A float as YAML reads it back as a float (a bare ``100000`` would be an integer)."""
    return np.format_float_positional(value, precision=6, unique=False, fractional=False,
                                      trim='0')


def params_yaml(identification: PlantIdentification, bag: str) -> str:
    """The identified constants as an ``sra_sim`` ROS params file, the fit in comments."""
    lines = [f'# {PROG}: the soft-arm plant identified from {bag}',
             '# replay RMS error per axis x, y, z: '
             + ', '.join(f'{v * 1e3:.2f}' for v in identification.position_rms) + ' mm',
             '# replay RMS error per chamber ' + ', '.join(CHAMBERS) + ': '
             + ', '.join(f'{v:.0f}' for v in identification.pressure_rms) + ' Pa',
             f'{NODE_NAME}:', '  ros__parameters:']
    for field, value, error in zip(identification.fields, identification.values,
                                   identification.standard_errors, strict=True):
        lines.append(f'    {PLANT_PARAMETER_NAMES[field]}: {_yaml_float(value)}'
                     f'  # +- {_yaml_float(error)} (1 sigma)')
    return '\n'.join(lines) + '\n'


def report(identification: PlantIdentification, initial: SoftArmPlantParams) -> str:
    """The fit as text: each constant with its standard error, then the replay's RMS errors."""
    rows = []
    for field, value, error in zip(identification.fields, identification.values,
                                   identification.standard_errors, strict=True):
        rows.append(f'  {PLANT_PARAMETER_NAMES[field]:32s} {value:12.6g} +- {error:.3g}'
                    f'   (initial {getattr(initial, field):.6g})')
    pressure = ', '.join(f'{c} {v / 1e3:.2f}' for c, v in
                         zip(CHAMBERS, identification.pressure_rms, strict=True))
    position = ', '.join(f'{a} {v * 1e3:.2f}' for a, v in
                         zip('xyz', identification.position_rms, strict=True))
    return '\n'.join([
        f'fitted in {identification.evaluations} evaluations: {identification.message}', *rows,
        f'replay RMS error: end point {position} mm; chamber pressure {pressure} kPa'])


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; returns the exit status (0 ok, 1 no convergence or unwritable output,
    2 bad arguments or a bag that cannot be identified from)."""
    return run_command(build_parser(), argv, _identify)


def _identify(args: argparse.Namespace) -> int:
    topics = {'command': normalize_topic(args.command_topic),
              'pressure': normalize_topic(args.pressure_topic),
              'position': normalize_topic(args.position_topic)}
    try:
        recording = read_recording(args.bag, topics['command'], topics['pressure'],
                                   topics['position'])
        check_identifiable(recording, topics)
    except ValueError as exc:  # RecordingError, an unreadable bag, NaN (PlantRecording)
        print(f'{PROG}: error: {args.bag}: {exc}', file=sys.stderr)
        return 2
    initial = SoftArmPlantParams()
    identification = identify_plant(recording, initial, IDENTIFIED_FIELDS,
                                    pressure_std=args.pressure_std,
                                    position_std=args.position_std)
    print(report(identification, initial))
    if not identification.converged:
        print(f'{PROG}: error: the fit did not converge; {args.out} not written',
              file=sys.stderr)
        return 1
    try:
        with open(args.out, 'w', encoding='utf-8') as handle:
            handle.write(params_yaml(identification, args.bag))
    except OSError as exc:
        print(f'{PROG}: error: cannot write {args.out}: {exc}', file=sys.stderr)
        return 1
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
