"""Property tests: only MessageError escapes decode; valid messages survive a round trip."""

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inflarm_msgs_json import MESSAGE_TYPES, MessageError, decode, encode
from msgs_json_cases import STRATEGIES, json_values, keys, mutated_messages

FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])

def decode_or_error(text):
    """Decode, accepting a MessageError (which must name its path); anything else fails."""
    try:
        message = decode(text)
    except MessageError as error:
        assert str(error) == (f'{error.path}: {error.reason}' if error.path else error.reason)
        return None
    assert decode(encode(message)) == message  # whatever is accepted is a valid message
    return message


@FUZZ
@given(st.text())
def test_decode_arbitrary_text(text):
    decode_or_error(text)


@FUZZ
@given(json_values)
def test_decode_arbitrary_json_values(value):
    decode_or_error(json.dumps(value))  # allow_nan: NaN and Infinity reach decode too
    decode_or_error(value)  # not text at all, unless a str


@FUZZ
@given(st.sampled_from(sorted(MESSAGE_TYPES)), st.dictionaries(keys, json_values, max_size=4))
def test_decode_envelope_with_arbitrary_fields(name, fields):
    decode_or_error(json.dumps({'type': name, 'schema_version': 1, **fields}))


@FUZZ
@given(mutated_messages())
def test_decode_mutated_valid_messages(text):
    decode_or_error(text)


@settings(max_examples=80, deadline=None)
@given(st.data())
def test_valid_messages_round_trip(data):
    for name, strategy in STRATEGIES.items():
        message = data.draw(strategy, label=name)
        text = encode(message)
        decoded = decode(text, expected=type(message))
        assert decoded == message
        assert encode(decoded) == text  # encoding is deterministic
