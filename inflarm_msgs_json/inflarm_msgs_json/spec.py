"""Field kinds, the message base classes and the one error: the machinery behind ``messages``.

Each message field is declared once, as ``name: hint = field_spec(KIND, 'doc [unit]')``. Its kind
validates and normalises a value (at construction, which also serves ``decode``), converts it to
JSON, and describes itself as JSON Schema, so the checks and the published schemas cannot disagree.
Cross-field rules that JSON Schema cannot express (a box's min <= max, a margin that must equal a
difference) live in one ``_check_invariants`` method of the class concerned.
"""

from __future__ import annotations

from collections.abc import Mapping
import dataclasses
import math
import numbers
import reprlib
from types import MappingProxyType
from typing import Any, ClassVar

JSON_SCHEMA_DIALECT = 'https://json-schema.org/draft/2020-12/schema'


class MessageError(ValueError):
    """An invalid message: bad JSON text, unknown type or version, or a bad field.

    Parameters
    ----------
    path : str
        Where the problem is, e.g. ``'ObstacleSet.obstacles[2].max'``; ``'type'`` for the
        envelope's type, ``''`` for the text as a whole.
    reason : str
        What is wrong, e.g. ``'expected 3 finite numbers, got [1, 2]'``.
    """

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(path, reason)  # both in args, so the error pickles across processes
        self.path = path
        self.reason = reason

    def __str__(self) -> str:
        return f'{self.path}: {self.reason}' if self.path else self.reason


class _ShortRepr(reprlib.Repr):
    def repr_int(self, x: int, level: int) -> str:
        # repr() of an int beyond 4300 digits raises ValueError; never let an error message fail
        if x.bit_length() > 256:
            return f'<int of about {int(x.bit_length() * math.log10(2)) + 1} digits>'
        return super().repr_int(x, level)


_SHORT_REPR = _ShortRepr()
_SHORT_REPR.maxlevel = 3  # bounded depth: deeply nested input cannot recurse here
_SHORT_REPR.maxstring = 40
_SHORT_REPR.maxother = 40


def show(value: Any) -> str:
    """Return a short, always-computable repr of an offending value for error messages."""
    text = _SHORT_REPR.repr(value)
    return text if len(text) <= 80 else text[:76] + ' ...'


# --- field kinds -------------------------------------------------------------------------------


class Kind:
    """How one field is validated and normalised, converted to JSON, and described as a schema.

    ``check`` accepts the JSON form and the Python form of a value (they differ only where
    JSON cannot carry the Python one: tuples, nested dataclasses) and returns the stored form.
    """

    what = 'a value'  # singular, for 'expected ...' messages
    plural = 'values'  # for arrays: 'expected 3 finite numbers'

    def check(self, value: Any, path: str) -> Any:
        raise NotImplementedError

    def to_json(self, value: Any) -> Any:
        return value

    def schema(self) -> dict[str, Any]:
        raise NotImplementedError

    def _fail(self, value: Any, path: str) -> MessageError:
        return MessageError(path, f'expected {self.what}, got {show(value)}')


@dataclasses.dataclass(frozen=True)
class Number(Kind):
    """A finite float (ints accepted, bools not), optionally bounded below."""

    minimum: float | None = None
    exclusive: bool = False

    @property
    def _bound(self) -> str:
        if self.minimum is None:
            return ''
        return f' {">" if self.exclusive else ">="} {self.minimum:g}'

    @property
    def what(self) -> str:
        return f'a finite number{self._bound}'

    @property
    def plural(self) -> str:
        return f'finite numbers{self._bound}'

    def check(self, value: Any, path: str) -> float:
        if isinstance(value, numbers.Real) and not isinstance(value, bool):
            try:
                x = float(value)
            except OverflowError:  # an int like 10**400 has no float
                x = math.inf
            if math.isfinite(x) and (
                self.minimum is None
                or x > self.minimum
                or (x == self.minimum and not self.exclusive)
            ):
                return x
        raise self._fail(value, path)

    def schema(self) -> dict[str, Any]:
        schema: dict[str, Any] = {'type': 'number'}
        if self.minimum is not None:
            schema['exclusiveMinimum' if self.exclusive else 'minimum'] = self.minimum
        return schema


@dataclasses.dataclass(frozen=True)
class Integer(Kind):
    """An int (not a bool, not a float with an integral value) >= ``minimum``."""

    minimum: int = 0

    @property
    def what(self) -> str:
        return f'an integer >= {self.minimum}'

    @property
    def plural(self) -> str:
        return f'integers >= {self.minimum}'

    def check(self, value: Any, path: str) -> int:
        if (
            isinstance(value, numbers.Integral)
            and not isinstance(value, bool)
            and value >= self.minimum
        ):
            return int(value)
        raise self._fail(value, path)

    def schema(self) -> dict[str, Any]:
        return {'type': 'integer', 'minimum': self.minimum}


@dataclasses.dataclass(frozen=True)
class Text(Kind):
    """A string, non-empty unless ``allow_empty``."""

    allow_empty: bool = False

    @property
    def what(self) -> str:
        return 'a string' if self.allow_empty else 'a non-empty string'

    @property
    def plural(self) -> str:
        return 'strings' if self.allow_empty else 'non-empty strings'

    def check(self, value: Any, path: str) -> str:
        if isinstance(value, str) and (value or self.allow_empty):
            return str(value)
        raise self._fail(value, path)

    def schema(self) -> dict[str, Any]:
        return {'type': 'string'} if self.allow_empty else {'type': 'string', 'minLength': 1}


@dataclasses.dataclass(frozen=True)
class Choice(Kind):
    """One of a fixed set of strings."""

    options: tuple[str, ...]

    @property
    def what(self) -> str:
        return 'one of ' + ', '.join(repr(option) for option in self.options)

    def check(self, value: Any, path: str) -> str:
        if isinstance(value, str) and value in self.options:
            return str(value)
        raise self._fail(value, path)

    def schema(self) -> dict[str, Any]:
        return {'enum': list(self.options)}


@dataclasses.dataclass(frozen=True)
class Nullable(Kind):
    """``inner`` or None (JSON null)."""

    inner: Kind

    @property
    def what(self) -> str:
        return f'{self.inner.what} or null'

    @property
    def plural(self) -> str:
        return f'{self.inner.plural} or nulls'

    def check(self, value: Any, path: str) -> Any:
        if value is None:
            return None
        try:
            return self.inner.check(value, path)
        except MessageError:
            raise self._fail(value, path) from None

    def to_json(self, value: Any) -> Any:
        return None if value is None else self.inner.to_json(value)

    def schema(self) -> dict[str, Any]:
        return {'anyOf': [self.inner.schema(), {'type': 'null'}]}


@dataclasses.dataclass(frozen=True)
class Array(Kind):
    """A list of ``item``, of exactly ``length`` items when given; stored as a tuple."""

    item: Kind
    length: int | None = None

    @property
    def what(self) -> str:
        if self.length is None:
            return f'a list of {self.item.plural}'
        return f'{self.length} {self.item.plural}'

    def check(self, value: Any, path: str) -> tuple[Any, ...]:
        if not isinstance(value, list | tuple | str) and hasattr(value, 'tolist'):
            value = value.tolist()  # numpy arrays from the cores, without importing numpy
        if not isinstance(value, list | tuple) or (
            self.length is not None and len(value) != self.length
        ):
            raise self._fail(value, path)
        return tuple(self.item.check(item, f'{path}[{i}]') for i, item in enumerate(value))

    def to_json(self, value: tuple[Any, ...]) -> list[Any]:
        return [self.item.to_json(item) for item in value]

    def schema(self) -> dict[str, Any]:
        schema: dict[str, Any] = {'type': 'array', 'items': self.item.schema()}
        if self.length is not None:
            schema['minItems'] = schema['maxItems'] = self.length
        return schema


@dataclasses.dataclass(frozen=True)
class Nested(Kind):
    """A nested record: an instance of ``record``, or its JSON object (no envelope)."""

    record: type[Record]

    @property
    def what(self) -> str:
        return f'a {self.record.__name__} object'

    @property
    def plural(self) -> str:
        return f'{self.record.__name__} objects'

    def check(self, value: Any, path: str) -> Record:
        if isinstance(value, self.record):
            return value  # valid by construction
        return self.record._from_json(value, path)

    def to_json(self, value: Record) -> dict[str, Any]:
        return value._to_json()

    def schema(self) -> dict[str, Any]:
        return self.record._object_schema()


@dataclasses.dataclass(frozen=True)
class Map(Kind):
    """A JSON object from non-empty names to ``value``, with at least ``min_items`` entries.

    Stored as a tuple of ``(name, value)`` pairs sorted by name, so it is immutable and hashable,
    and equality and encoding do not depend on insertion order. Accepts a mapping, or that
    tuple of pairs (so stored values can be passed back in); a JSON list of pairs is refused.
    """

    value: Kind
    min_items: int = 1

    _KEY = Text()

    @property
    def what(self) -> str:
        return f'an object of at least {self.min_items} name: value entries'

    def check(self, value: Any, path: str) -> tuple[tuple[str, Any], ...]:
        if isinstance(value, Mapping):
            pairs = list(value.items())
        elif isinstance(value, tuple) and all(
            isinstance(pair, tuple) and len(pair) == 2 for pair in value
        ):
            pairs = list(value)
        else:
            raise self._fail(value, path)
        if len(pairs) < self.min_items:
            raise self._fail(value, path)
        checked = {}
        for key, item in pairs:
            key_path = f'{path}[{show(key)}]'
            key = self._KEY.check(key, key_path)
            if key in checked:
                raise MessageError(key_path, 'duplicate name')
            checked[key] = self.value.check(item, key_path)
        return tuple(sorted(checked.items()))

    def to_json(self, value: tuple[tuple[str, Any], ...]) -> dict[str, Any]:
        return {key: self.value.to_json(item) for key, item in value}

    def schema(self) -> dict[str, Any]:
        return {
            'type': 'object',
            'minProperties': self.min_items,
            'propertyNames': {'minLength': 1},
            'additionalProperties': self.value.schema(),
        }


def field_spec(kind: Kind, doc: str, default: Any = dataclasses.MISSING) -> Any:
    """Declare a message field.

    Parameters
    ----------
    kind : Kind
        How the field is validated, encoded and described in the schema.
    doc : str
        One line saying what the field is, with its unit, e.g. ``'grid cell size [m]'``.
    default : optional
        Value used when the field is omitted (from the constructor and from JSON).

    Returns
    -------
    dataclasses.Field
        For use as the field's default in a ``@dataclass(frozen=True)`` body.
    """
    return dataclasses.field(default=default, metadata={'kind': kind, 'doc': doc})


# --- base classes ------------------------------------------------------------------------------


class Record:
    """Base of the message dataclasses: every field is checked against its kind at construction.

    Subclasses are ``@dataclass(frozen=True)`` with fields declared by ``field_spec``; an invalid
    instance cannot exist.
    """

    def __post_init__(self) -> None:
        path = type(self).__name__
        for field in dataclasses.fields(self):
            value = field.metadata['kind'].check(getattr(self, field.name), f'{path}.{field.name}')
            object.__setattr__(self, field.name, value)  # frozen: store the normalised value
        self._check_invariants(path)

    def _check_invariants(self, path: str) -> None:
        """Check cross-field rules JSON Schema cannot express; raise MessageError at ``path``."""

    @classmethod
    def _from_json(cls, obj: Any, path: str) -> Record:
        if not isinstance(obj, Mapping):
            raise MessageError(path, f'expected a {cls.__name__} object, got {show(obj)}')
        fields = dataclasses.fields(cls)
        names = [field.name for field in fields]
        for key in obj:
            if key not in names:
                raise MessageError(path, f'unknown field {show(key)}; fields: {", ".join(names)}')
        for field in fields:
            if field.name not in obj and field.default is dataclasses.MISSING:
                raise MessageError(f'{path}.{field.name}', 'missing required field')
        try:
            return cls(**obj)
        except MessageError as error:
            # __post_init__ roots its paths at the class name; re-root them where obj sits
            tail = error.path.removeprefix(cls.__name__)
            raise MessageError(path + tail, error.reason) from None

    def _to_json(self) -> dict[str, Any]:
        return {
            field.name: field.metadata['kind'].to_json(getattr(self, field.name))
            for field in dataclasses.fields(self)
        }

    @classmethod
    def _object_schema(cls) -> dict[str, Any]:
        properties = {}
        for field in dataclasses.fields(cls):
            prop = {'description': field.metadata['doc'], **field.metadata['kind'].schema()}
            if field.default is not dataclasses.MISSING:
                prop['default'] = field.default
            properties[field.name] = prop
        required = [f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING]
        return {
            'type': 'object',
            'properties': properties,
            'required': required,
            'additionalProperties': False,
        }


_MESSAGE_TYPES: dict[str, type[Message]] = {}

#: Every top-level message class by its ``type`` name (read-only).
MESSAGE_TYPES: Mapping[str, type[Message]] = MappingProxyType(_MESSAGE_TYPES)


class Message(Record):
    """Base of the top-level messages, sent as ``{"type": ..., "schema_version": ..., fields}``.

    A concrete subclass is registered under its class name, which is its ``type``; pass
    ``abstract=True`` in the class statement for a shared base that is not itself a message.
    """

    type: ClassVar[str]
    schema_version: ClassVar[int] = 1

    def __init_subclass__(cls, abstract: bool = False, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if abstract:
            return
        if cls.__name__ in _MESSAGE_TYPES:
            raise TypeError(f'message type {cls.__name__!r} is defined twice')
        cls.type = cls.__name__
        _MESSAGE_TYPES[cls.type] = cls


def json_schema(cls: type[Record]) -> dict[str, Any]:
    """Return the JSON Schema (draft 2020-12) of a message class, derived from its field specs.

    Parameters
    ----------
    cls : type
        A message class such as ``ObstacleSet``; for a nested record such as ``Cuboid`` the
        schema of its bare object (no envelope) is returned.

    Returns
    -------
    dict
        The schema. It cannot express cross-field rules (a box's min <= max, LinkStatus's margin),
        nor that numbers must fit a double, that integer fields refuse ``1.0`` and that keys are
        unique; ``decode`` checks those too, so it accepts a subset of what the schema accepts.
    """
    body = cls._object_schema()
    if issubclass(cls, Message):
        body['properties'] = {
            'type': {'const': cls.type},
            'schema_version': {'const': cls.schema_version},
            **body['properties'],
        }
        body['required'] = ['type', 'schema_version', *body['required']]
    doc = (cls.__doc__ or '').strip().split('\n\n')[0]
    return {
        '$schema': JSON_SCHEMA_DIALECT,
        'title': cls.__name__,
        'description': ' '.join(doc.split()),
        **body,
    }
