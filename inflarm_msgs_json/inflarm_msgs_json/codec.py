"""Encode messages to JSON text and decode JSON text back to messages, strictly.

``decode`` raises only ``MessageError``, whatever the text: invalid JSON, ``NaN``/``Infinity``,
numbers beyond a double, duplicate keys, nesting too deep to parse, a non-object, an unknown type
or schema version, and any missing, unknown or invalid field.
"""

from __future__ import annotations

import json
import math
from typing import Any, TypeVar, overload

from inflarm_msgs_json.spec import MESSAGE_TYPES, Message, MessageError, show

M = TypeVar('M', bound=Message)

_ENVELOPE = ('type', 'schema_version')


def encode(message: Message) -> str:
    """Return the JSON text of a message, envelope first.

    Parameters
    ----------
    message : Message
        Any message instance, e.g. an ``ObstacleSet`` (valid by construction).

    Returns
    -------
    str
        Compact, ASCII-only JSON: ``{"type": ..., "schema_version": ..., <fields>}``.

    Raises
    ------
    TypeError
        If ``message`` is not a message instance (a nested ``Cuboid`` is not one).
    """
    if not isinstance(message, Message):
        raise TypeError(f'expected a message instance, got {type(message).__name__}')
    body = {'type': message.type, 'schema_version': message.schema_version}
    body.update(message._to_json())
    return json.dumps(body, allow_nan=False, separators=(',', ':'))


@overload
def decode(text: str) -> Message: ...


@overload
def decode(text: str, expected: type[M]) -> M: ...


def decode(text: str, expected: type[Message] | None = None) -> Message:
    """Parse and validate JSON text into the message class named by its ``type``.

    Parameters
    ----------
    text : str
        JSON text, e.g. the ``data`` of a ``std_msgs/String``.
    expected : type, optional
        The message class the caller accepts, e.g. ``ObstacleSet``; any other type is an error.

    Returns
    -------
    Message
        An instance of ``expected`` if given, else of the class named by ``type``.

    Raises
    ------
    MessageError
        For any invalid input; its ``path`` names the offending field. Nothing else escapes for
        any ``text``.
    TypeError
        If ``expected`` is not a message class (a programming error, not bad input).
    """
    if expected is not None and expected not in MESSAGE_TYPES.values():
        raise TypeError(f'expected must be a message class, got {expected!r}')
    obj = _parse(text)
    if not isinstance(obj, dict):
        raise MessageError('', f'expected a JSON object, got {show(obj)}')
    if 'type' not in obj:
        raise MessageError('type', 'missing; every message names its type')
    name = obj['type']
    cls = MESSAGE_TYPES.get(name) if isinstance(name, str) else None
    if cls is None:
        known = ', '.join(sorted(MESSAGE_TYPES))
        raise MessageError('type', f'unknown message type {show(name)}; known: {known}')
    if expected is not None and cls is not expected:
        raise MessageError('type', f'expected {expected.type!r}, got {name!r}')
    version = obj.get('schema_version')
    if 'schema_version' not in obj:
        raise MessageError(f'{cls.type}.schema_version', 'missing required field')
    # bool and float compare equal to 1 in Python; only the int itself is the version
    if type(version) is not int or version != cls.schema_version:
        raise MessageError(
            f'{cls.type}.schema_version',
            f'unsupported version {show(version)}; this build reads {cls.schema_version}',
        )
    fields = {key: value for key, value in obj.items() if key not in _ENVELOPE}
    return cls._from_json(fields, cls.type)


def _parse(text: Any) -> Any:
    if not isinstance(text, str):
        raise MessageError('', f'expected JSON text as str, got {type(text).__name__}')
    try:
        return json.loads(
            text,
            parse_constant=_refuse_constant,
            parse_float=_finite_float,
            object_pairs_hook=_unique_keys,
        )
    except MessageError:
        raise
    except (ValueError, RecursionError) as error:
        # JSONDecodeError, ints beyond the digit limit, nesting deeper than the parser can go
        raise MessageError('', f'invalid JSON: {error}') from None


def _refuse_constant(name: str) -> float:
    raise MessageError('', f'invalid JSON: {name} is not a JSON number')


def _finite_float(literal: str) -> float:
    value = float(literal)
    if not math.isfinite(value):  # 1e400 parses to inf
        raise MessageError('', f'invalid JSON: {show(literal)} does not fit a double')
    return value


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    # json.loads would silently keep the last of duplicate keys
    obj: dict[str, Any] = {}
    for key, value in pairs:
        if key in obj:
            raise MessageError('', f'invalid JSON: duplicate key {show(key)}')
        obj[key] = value
    return obj
