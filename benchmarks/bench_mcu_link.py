"""Speed of the MCU link and of the bridge's safety core (inflarm_hw).

Prints, with baselines measured in the same run:

- `FrameDecoder.feed` on a stream of STATE frames in 4 KiB reads, per frame [us], against the
  library floor: the same bytes through ``bytes.split``, ``cobs.decode`` and ``zlib.crc32``
  alone (no checks, no messages);
- `encode_frame` of a MotorCommand, per frame [us], against ``struct.pack`` of its payload;
- one bridge cycle of `SafetySupervisor` (``on_state`` + ``output``, eq. (2) included) [us],
  against the cycle period at the default 100 Hz;
- the link load at the defaults (100 Hz commands, 50 Hz STATE) against 921600 baud.

Per-call figures are the best of 5 repeats, so other load on the machine inflates them less;
compare the ratios more than the absolute numbers.

Run: ``source scripts/env.sh && python benchmarks/bench_mcu_link.py [--frames 20000]``
"""

import argparse
import timeit
import zlib

from cobs import cobs
import numpy as np

from inflarm_hw.bridge import BridgeConfig, SafetySupervisor
from inflarm_hw.driver import DeviceInfo
from inflarm_hw.mcu_protocol import (
    FrameDecoder,
    MotorCommand,
    MotorMode,
    State,
    ValveCommand,
    encode_frame,
)


def best(statement, number: int) -> float:
    """Best of 5 repeats, seconds per call."""
    return min(timeit.repeat(statement, number=number, repeat=5)) / number


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--frames', type=int, default=20000)
    args = parser.parse_args()
    rng = np.random.default_rng(7)

    states = [State(i, 1, i & 0xFFFF, 0, 0, rng.normal(size=3), rng.normal(size=3),
                    rng.normal(size=3), rng.uniform(0, 1e5, 5), rng.uniform(4e4, 6e4, 2))
              for i in range(args.frames)]
    stream = b''.join(encode_frame(s, i) for i, s in enumerate(states))
    chunks = [stream[i:i + 4096] for i in range(0, len(stream), 4096)]

    def decode():
        decoder = FrameDecoder()
        for chunk in chunks:
            decoder.feed(chunk)
        assert decoder.stats.frames == args.frames

    def floor():
        for raw in map(cobs.decode, stream.split(b'\x00')[:-1]):
            zlib.crc32(raw[:-4])

    t_decode = best(decode, 1) / args.frames
    t_floor = best(floor, 1) / args.frames
    print(f'decode: {t_decode * 1e6:.2f} us/frame ({len(stream) / args.frames:.0f} B), library '
          f'floor {t_floor * 1e6:.2f} us/frame: x{t_decode / t_floor:.1f}')

    command = MotorCommand(MotorMode.POSITION, (0.1, 0.6, -1.2), (0.0, 0.1, 0.0))
    t_encode = best(lambda: encode_frame(command, 7), 20000)
    t_pack = best(lambda: command.LAYOUT.pack(1, 0.1, 0.6, -1.2, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0),
                  20000)
    print(f'encode: {t_encode * 1e6:.2f} us/frame, struct.pack of the payload '
          f'{t_pack * 1e6:.2f} us: x{t_encode / t_pack:.1f}')

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

    t_cycle = best(cycle, 2000)
    print(f'bridge cycle (on_state + output): {t_cycle * 1e6:.0f} us, the 100 Hz period '
          f'10000 us: {t_cycle / 1e-2 * 100:.2f} % of it')

    tx = 100 * (len(encode_frame(command, 0)) + len(encode_frame(ValveCommand(), 0)))
    rx = 50 * len(encode_frame(states[0], 0))
    line = 921600 / 10  # bytes/s, 8N1
    print(f'link load: host -> MCU {tx} B/s, MCU -> host {rx} B/s; 921600 baud carries '
          f'{line:.0f} B/s: {tx / line * 100:.1f} % and {rx / line * 100:.1f} %')


if __name__ == '__main__':
    main()
