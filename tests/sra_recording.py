"""Recordings of the simulated soft arm for the identification tests: a plant run on random
valve steps, as a `PlantRecording` and as a real rosbag2 bag with sra_sim's topics."""

import pathlib

import numpy as np

from inflarm_hw.bag import BagWriter, serialize, typestore
from inflarm_hw.sra_identification import PlantRecording
from inflarm_hw.sra_plant import SoftArmPlant, SoftArmPlantParams
from inflarm_model.soft_arm import CHAMBERS
from inflarm_msgs_json import ChamberPressures, PressureCommand, encode

BAG_START_NS = 1_700_000_000 * 10**9
STRING = 'std_msgs/msg/String'
POINT_STAMPED = 'geometry_msgs/msg/PointStamped'


def plant_run(params: SoftArmPlantParams, duration_s: float, seed: int,
              pressure_noise_pa: float = 0.0) -> tuple[PlantRecording, np.ndarray]:
    """A recording of ``params`` on random valve steps, from rest: commands and chamber
    pressures (plus Gaussian noise of ``pressure_noise_pa``) at 10 Hz, the measured end point
    (`SoftArmPlant.measure`) at 5 Hz, sra_sim's rates; and the true end points (q, 3)."""
    rng = np.random.default_rng(seed)
    plant = SoftArmPlant(1, params, rng=np.random.default_rng(seed + 1))
    dt = 0.1
    command = np.zeros(5)
    change_at = 0.5
    times, commands, pressures, position_times, positions, truth = [], [], [], [], [], []
    for k in range(int(round(duration_s / dt))):
        t = k * dt
        times.append(t)
        pressures.append(plant.chamber_pressures[0] + rng.normal(0.0, pressure_noise_pa, 5))
        if k % 2 == 0:
            position_times.append(t)
            positions.append(plant.measure()[0])
            truth.append(plant.end_point[0])
        if t >= change_at:  # each valve on (5-60 kPa) or vented, for 1-2.5 s
            command = np.where(rng.random(5) < 0.6, rng.uniform(5e3, 60e3, 5), 0.0)
            change_at = t + rng.uniform(1.0, 2.5)
        commands.append(command.copy())
        plant.step(command, dt)
    recording = PlantRecording(np.array(times), np.array(commands), np.array(times),
                               np.array(pressures), np.array(position_times),
                               np.array(positions))
    return recording, np.array(truth)


def _point(t_ns: int, point) -> bytes:
    types = typestore().types
    header = types['std_msgs/msg/Header'](
        stamp=types['builtin_interfaces/msg/Time'](sec=t_ns // 10**9, nanosec=t_ns % 10**9),
        frame_id='sra_mount')
    msg = types[POINT_STAMPED](header=header, point=types['geometry_msgs/msg/Point'](
        x=float(point[0]), y=float(point[1]), z=float(point[2])))
    return serialize(msg, POINT_STAMPED)


def _string(text: str) -> bytes:
    return serialize(typestore().types[STRING](data=text), STRING)


def write_run_bag(path: pathlib.Path, recording: PlantRecording, truth: np.ndarray | None = None,
                  topics: tuple[str, ...] = ('chamber_pressure_command', 'chamber_pressures',
                                             'ball_position', 'end_point_truth')) -> None:
    """``recording`` as a bag with the topics sra_sim subscribes and publishes (those of
    ``topics``), on record times ``BAG_START_NS`` + the recording's times."""
    def stamp(t: float) -> int:
        return BAG_START_NS + int(round(t * 1e9))

    with BagWriter(path) as bag:
        if 'chamber_pressure_command' in topics:
            bag.add_topic('chamber_pressure_command', STRING)
            for t, command in zip(recording.command_times, recording.commands, strict=True):
                bag.write('chamber_pressure_command', stamp(t), _string(encode(PressureCommand(
                    chambers=dict(zip(CHAMBERS, command.tolist(), strict=True))))))
        if 'chamber_pressures' in topics:
            bag.add_topic('chamber_pressures', STRING)
            for t, pressures in zip(recording.pressure_times, recording.pressures, strict=True):
                bag.write('chamber_pressures', stamp(t), _string(encode(ChamberPressures(
                    chambers=dict(zip(CHAMBERS, pressures.tolist(), strict=True))))))
        for topic, points in (('ball_position', recording.positions), ('end_point_truth', truth)):
            if topic in topics and points is not None:
                bag.add_topic(topic, POINT_STAMPED)
                for t, point in zip(recording.position_times, points, strict=True):
                    bag.write(topic, stamp(t), _point(stamp(t), point))
