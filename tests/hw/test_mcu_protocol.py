"""The MCU link protocol (inflarm_hw.mcu_protocol): round trips, framing, a fuzzed decoder."""

import pathlib
import struct
import zlib

from cobs import cobs
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from inflarm_hw.mcu_protocol import (
    MAX_ENCODED,
    MESSAGES,
    PROTOCOL_VERSION,
    Fault,
    FaultCode,
    FaultInject,
    FaultKind,
    FrameDecoder,
    Heartbeat,
    HeartbeatAck,
    Hello,
    HelloAck,
    MotorCommand,
    MotorMode,
    State,
    ValveCommand,
    encode_frame,
    seq_newer_or_equal,
)


def f32(values):
    return tuple(np.float32(values).tolist())


EXAMPLES = [
    Hello(PROTOCOL_VERSION, 250),
    HelloAck(PROTOCOL_VERSION, 3, 250, 3, 5, 2),
    Heartbeat(123456789),
    HeartbeatAck(2**32 - 1),
    MotorCommand(MotorMode.POSITION, f32([0.1, 0.6, -1.2]), f32([0.0, 0.5, -0.5])),
    MotorCommand(MotorMode.TORQUE, torque=f32([1.5, -2.0, 0.25])),
    ValveCommand(f32([0.1, 2.0, 3.0, 4.0, 10.0]), f32([0.56, 0.56])),
    State(1000, 0x05, 17, 2, 1, f32([0.0, 0.6, -1.2]), f32([0.1, 0.0, 0.0]),
          f32([-1.0, 3.2, 0.5]), f32([12e3, 0.0, 5e3, 0.0, 30e3]), f32([50e3, 49.9e3])),
    Fault(FaultCode.WATCHDOG, 0, 0.25),
    FaultInject(FaultKind.OVER_PRESSURE, 2, 150e3, 1.5),
]


@pytest.mark.parametrize('message', EXAMPLES, ids=lambda m: type(m).__name__)
def test_every_message_round_trips_through_a_frame(message):
    frame = encode_frame(message, 41)
    assert frame.endswith(b'\x00') and b'\x00' not in frame[:-1]
    decoder = FrameDecoder()
    (decoded,) = decoder.feed(frame)
    assert decoded.seq == 41
    assert decoded.message == message
    assert decoder.stats.frames == 1 and decoder.stats.bad_frames == 0


def test_every_message_type_has_an_example_and_a_fixed_little_endian_layout():
    assert {type(m) for m in EXAMPLES} == set(MESSAGES.values())
    for cls in MESSAGES.values():
        assert cls.LAYOUT.format.startswith('<')
    assert State.LAYOUT.size == 76
    assert MotorCommand.LAYOUT.size == 40
    assert ValveCommand.LAYOUT.size == 28


def test_the_wire_bytes_are_those_the_readme_specifies():
    # header <BBH type, flags, seq; payload; CRC-32 (zlib) of both, <I; then COBS and 0x00
    frame = encode_frame(Heartbeat(0x01020304), 0x0506)
    raw = cobs.decode(frame[:-1])
    assert raw[:4] == bytes([0x03, 0x00, 0x06, 0x05])
    assert raw[4:8] == bytes([0x04, 0x03, 0x02, 0x01])
    assert struct.unpack('<I', raw[8:]) == (zlib.crc32(raw[:8]),)
    assert zlib.crc32(b'123456789') == 0xCBF43926  # the check value quoted in the README


def test_sequence_numbers_wrap_and_gaps_count_as_lost():
    decoder = FrameDecoder()
    stream = b''.join(encode_frame(Heartbeat(i), seq) for i, seq in
                      enumerate([65534, 65535, 0, 3, 4]))
    frames = decoder.feed(stream)
    assert [f.seq for f in frames] == [65534, 65535, 0, 3, 4]
    assert decoder.stats.lost == 2
    assert seq_newer_or_equal(2, 65530) and not seq_newer_or_equal(65530, 2)
    assert seq_newer_or_equal(7, 7)


def test_a_hello_or_hello_ack_starts_the_count_of_lost_frames_afresh():
    decoder = FrameDecoder()
    ack = HelloAck(PROTOCOL_VERSION, 1, 250, 3, 5, 2)
    # an old session's STATE numbers, then a new session from 0; the host's HELLO anywhere
    stream = b''.join(encode_frame(m, seq) for m, seq in [
        (Heartbeat(0), 40000), (ack, 0), (Heartbeat(1), 1), (Hello(), 9), (Heartbeat(2), 12)])
    assert len(decoder.feed(stream)) == 5
    assert decoder.stats.lost == 2  # 10 and 11 only


def test_the_readme_bandwidth_is_that_of_the_frame_sizes():
    """inflarm_hw/README.md "Bandwidth": sizes on the wire and the default link load."""
    from inflarm_hw.driver import HEARTBEAT_PERIOD_S

    size = {type(m).__name__: len(encode_frame(m, 0xFFFF)) for m in EXAMPLES}
    assert all(size[type(m).__name__] == m.LAYOUT.size + 10 for m in EXAMPLES)
    assert (size['MotorCommand'], size['ValveCommand'], size['Heartbeat'], size['State'],
            size['Fault']) == (50, 38, 14, 86, 18)
    heartbeats = size['Heartbeat'] / HEARTBEAT_PERIOD_S  # and as many HEARTBEAT_ACKs
    host = 100 * (size['MotorCommand'] + size['ValveCommand']) + heartbeats
    mcu = 50 * size['State'] + heartbeats
    line = 921600 / 10  # 8N1
    readme = (pathlib.Path(__file__).resolve().parents[2] / 'inflarm_hw' / 'README.md'
              ).read_text()
    text = ' '.join(readme.split())
    assert f'{host:.0f} B/s' in text and f'{mcu:.0f} B/s' in text
    assert f'{host / line * 100:.1f} % and {mcu / line * 100:.1f} % of the line' in text
    assert f'({50 * (size["MotorCommand"] + size["ValveCommand"]) + heartbeats:.0f} B/s' in text


def test_bad_frames_are_counted_by_kind_and_skipped():
    good = encode_frame(Heartbeat(1), 1)
    raw = cobs.decode(good[:-1])
    bad_crc = cobs.encode(raw[:-1] + bytes([raw[-1] ^ 0xFF])) + b'\x00'
    unknown = bytearray(raw[:-4])
    unknown[0] = 0x7F
    unknown_type = cobs.encode(bytes(unknown) + struct.pack('<I', zlib.crc32(unknown))) + b'\x00'
    short = bytearray(raw[:-4])
    short[0] = MotorCommand.TYPE  # a heartbeat-sized payload for a motor command
    wrong_length = cobs.encode(bytes(short) + struct.pack('<I', zlib.crc32(short))) + b'\x00'
    decoder = FrameDecoder()
    stream = (b'\x00\x00' + bad_crc + good + unknown_type + b'\x05ab\x00' + wrong_length
              + b'\x01\x00' + good)
    frames = decoder.feed(stream)
    assert [f.message for f in frames] == [Heartbeat(1), Heartbeat(1)]
    s = decoder.stats
    assert (s.crc_errors, s.unknown_types, s.cobs_errors, s.length_errors) == (1, 1, 1, 2)
    assert s.bad_frames == 5


def test_an_endless_chunk_is_dropped_and_decoding_resumes_after_the_next_delimiter():
    decoder = FrameDecoder()
    for _ in range(20):
        assert decoder.feed(b'\x01' * 100) == []
    assert len(decoder._buffer) <= MAX_ENCODED
    assert decoder.stats.length_errors == 1
    frames = decoder.feed(b'\x01' * 10 + b'\x00' + encode_frame(Hello(), 0))
    assert [f.message for f in frames] == [Hello()]
    assert decoder.stats.length_errors == 1


def test_messages_check_their_fields():
    with pytest.raises(ValueError, match='position of 3 numbers'):
        MotorCommand(MotorMode.POSITION, position=(0.0, 1.0))
    with pytest.raises(ValueError, match=r'mode an integer in \[0, 255\]'):
        MotorCommand(256)
    with pytest.raises(ValueError, match='cannot be packed'):
        MotorCommand(MotorMode.POSITION, position=(1e39, 0.0, 0.0)).pack()
    with pytest.raises(ValueError, match='payload of 76 bytes'):
        State.unpack(b'\x00' * 75)
    # non-finite floats are carried as they are: the receiver decides
    (frame,) = FrameDecoder().feed(encode_frame(ValveCommand((float('nan'),) * 5), 0))
    assert np.isnan(frame.message.chamber_voltage).all()


# --- fuzzing ----------------------------------------------------------------------------------

messages = st.sampled_from(EXAMPLES)
frames = st.builds(encode_frame, messages, st.integers(0, 65535))


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=2000), st.lists(st.integers(1, 64), max_size=40))
def test_arbitrary_bytes_never_crash_the_decoder(data, splits):
    decoder = FrameDecoder()
    position = 0
    for size in splits + [len(data)]:
        for frame in decoder.feed(data[position:position + size]):
            assert type(frame.message) in MESSAGES.values()
        position += size
    assert len(decoder._buffer) <= MAX_ENCODED
    assert decoder.stats.bytes == len(data)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(frames, st.binary(max_size=400)), min_size=1, max_size=12),
       st.integers(1, 97))
def test_the_decoder_resynchronises_on_the_delimiter_after_garbage(pairs, chunk):
    # garbage (longer than any frame, too, at up to 400 bytes) ends at a delimiter: every
    # frame after it comes through, and the garbage decodes to nothing (CRC-32)
    stream = b''.join(garbage + b'\x00' + frame for frame, garbage in pairs)
    decoder = FrameDecoder()
    decoded = []
    for i in range(0, len(stream), chunk):
        decoded += decoder.feed(stream[i:i + chunk])
    assert decoded == [FrameDecoder().feed(frame)[0] for frame, _ in pairs]
    assert decoder.stats.frames == len(pairs)


@settings(max_examples=200, deadline=None)
@given(st.lists(frames, min_size=2, max_size=10), st.data())
def test_a_corrupted_byte_costs_at_most_the_frames_it_touches(stream_frames, data):
    stream = bytearray(b''.join(stream_frames))
    index = data.draw(st.integers(0, len(stream) - 1))
    stream[index] ^= data.draw(st.integers(1, 255))
    decoder = FrameDecoder()
    decoded = decoder.feed(bytes(stream))
    # a flipped byte can merge two frames (a delimiter lost) or split one (a delimiter made):
    # every other frame comes through, and nothing false does (CRC-32)
    assert len(decoded) >= len(stream_frames) - 2
    originals = [FrameDecoder().feed(f)[0] for f in stream_frames]
    assert all(f in originals for f in decoded)
    assert decoder.stats.bad_frames >= 1 or len(decoded) < len(stream_frames)
