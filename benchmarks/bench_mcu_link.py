"""Speed of the MCU link and of the bridge's safety core (inflarm_hw).

Prints, with baselines measured in the same run:

- `FrameDecoder.feed` on a stream of STATE frames in 4 KiB reads, per frame [us], against the
  library floor: the same bytes through ``bytes.split``, ``cobs.decode`` and ``zlib.crc32``
  alone (no checks, no messages);
- `encode_frame` of a MotorCommand, per frame [us], against ``struct.pack`` of its payload;
- one bridge cycle of `SafetySupervisor` (``on_state`` + ``output``, eq. (2) included) [us],
  against the cycle period at the default 100 Hz;
- the link load at the defaults (100 Hz commands, 50 Hz STATE, 10 Hz HEARTBEAT and its answer)
  against 921600 baud.

Candidates are timed round-robin (``common.interleaved``); compare the ratios more than the
absolute numbers.

Run: ``source scripts/env.sh && python benchmarks/bench_mcu_link.py [--frames 20000]``
"""

import argparse
import sys
import zlib

from cobs import cobs
from common import Row, interleaved, print_rows
import numpy as np

from inflarm_hw.bridge import BridgeConfig, SafetySupervisor
from inflarm_hw.driver import HEARTBEAT_PERIOD_S, DeviceInfo
from inflarm_hw.mcu_protocol import (
    FrameDecoder,
    Heartbeat,
    MotorCommand,
    MotorMode,
    State,
    ValveCommand,
    encode_frame,
)

BAUD = 921600
CYCLE_S = 1e-2  # the bridge's default 100 Hz


def measure(frames: int, rounds: int) -> dict:
    """Per frame or per cycle [s] of each candidate, and the link loads [B/s]."""
    rng = np.random.default_rng(7)
    states = [State(i, 1, i & 0xFFFF, 0, 0, rng.normal(size=3), rng.normal(size=3),
                    rng.normal(size=3), rng.uniform(0, 1e5, 5), rng.uniform(4e4, 6e4, 2))
              for i in range(frames)]
    stream = b''.join(encode_frame(s, i) for i, s in enumerate(states))
    chunks = [stream[i:i + 4096] for i in range(0, len(stream), 4096)]

    def decode():
        decoder = FrameDecoder()
        for chunk in chunks:
            decoder.feed(chunk)
        assert decoder.stats.frames == frames

    def floor():
        for raw in map(cobs.decode, stream.split(b'\x00')[:-1]):
            zlib.crc32(raw[:-4])

    command = MotorCommand(MotorMode.POSITION, (0.1, 0.6, -1.2), (0.0, 0.1, 0.0))
    supervisor = SafetySupervisor(BridgeConfig(), DeviceInfo(1, 1, 0.25, 3, 5, 2))
    clock = [100.0]
    supervisor.on_pressure_command({'PEA': 20e3, 'B1': 30e3}, clock[0])
    supervisor.on_motor_command(['joint_1', 'joint_2', 'joint_3'], [0.1, 0.6, -1.2], [],
                                clock[0])

    def cycle():
        clock[0] += 1e-4
        state = states[int(clock[0] * 1e4) % len(states)]
        supervisor.on_state(state, clock[0])
        supervisor.output(clock[0], True)
        supervisor.drain_events()

    streams = interleaved({'decode': decode, 'floor': floor}, rounds, number=1)
    calls = interleaved({
        'encode': lambda: encode_frame(command, 7),
        'pack': lambda: command.LAYOUT.pack(1, 0.1, 0.6, -1.2, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0),
        'cycle': cycle,
    }, rounds)
    heartbeat = len(encode_frame(Heartbeat(0), 0)) / HEARTBEAT_PERIOD_S  # and its answer
    tx = 100 * (len(encode_frame(command, 0)) + len(encode_frame(ValveCommand(), 0))) + heartbeat
    rx = 50 * len(encode_frame(states[0], 0)) + heartbeat
    return {'frame_bytes': len(stream) / frames,
            'decode': streams['decode'].median_s / frames,
            'floor': streams['floor'].median_s / frames,
            **{name: t.median_s for name, t in calls.items()},
            'tx': tx, 'rx': rx, 'line': BAUD / 10}  # bytes/s, 8N1


def rows(m: dict) -> list[Row]:
    """The summary rows (no targets: the figures against their floors and the budgets)."""
    return [
        Row('FrameDecoder.feed, per STATE frame', m['decode'] * 1e6, 'us',
            'bytes.split + cobs.decode + zlib.crc32', m['floor'] * 1e6,
            note=f"{m['frame_bytes']:.0f} B frames in 4 KiB reads"),
        Row('encode_frame(MotorCommand)', m['encode'] * 1e6, 'us', 'struct.pack of the payload',
            m['pack'] * 1e6),
        Row('SafetySupervisor cycle (on_state + output)', m['cycle'] * 1e6, 'us',
            'the 100 Hz cycle period', CYCLE_S * 1e6),
        Row('link load, host -> MCU', m['tx'], 'B/s', f'{BAUD} baud, 8N1', m['line'],
            note='100 Hz motor + valve commands, 10 Hz HEARTBEAT'),
        Row('link load, MCU -> host', m['rx'], 'B/s', f'{BAUD} baud, 8N1', m['line'],
            note='50 Hz STATE, 10 Hz HEARTBEAT_ACK'),
    ]


def run(quick: bool) -> list[Row]:
    """Rows of the summary table (--quick: 2,000 frames, 3 rounds)."""
    return rows(measure(2000, 3) if quick else measure(20000, 7))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--frames', type=int, default=20000)
    args = parser.parse_args(argv)
    m = measure(args.frames, 7)
    print(f"decode: {m['decode'] * 1e6:.2f} us/frame ({m['frame_bytes']:.0f} B), library "
          f"floor {m['floor'] * 1e6:.2f} us/frame: x{m['decode'] / m['floor']:.1f}")
    print(f"encode: {m['encode'] * 1e6:.2f} us/frame, struct.pack of the payload "
          f"{m['pack'] * 1e6:.2f} us: x{m['encode'] / m['pack']:.1f}")
    print(f"bridge cycle (on_state + output): {m['cycle'] * 1e6:.0f} us, the 100 Hz period "
          f"{CYCLE_S * 1e6:.0f} us: {m['cycle'] / CYCLE_S * 100:.2f} % of it")
    print(f"link load: host -> MCU {m['tx']:.0f} B/s, MCU -> host {m['rx']:.0f} B/s; {BAUD} baud "
          f"carries {m['line']:.0f} B/s: {m['tx'] / m['line'] * 100:.1f} % and "
          f"{m['rx'] / m['line'] * 100:.1f} %")
    print()
    print_rows('mcu_link', rows(m))
    return 0


if __name__ == '__main__':
    sys.exit(main())
