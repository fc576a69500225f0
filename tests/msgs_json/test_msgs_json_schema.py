"""The exported JSON Schemas: checked-in copies match the generated ones and agree with decode."""

import json
from pathlib import Path

from hypothesis import given, settings
import jsonschema
import pytest

import inflarm_msgs_json
from inflarm_msgs_json import MESSAGE_TYPES, Cuboid, MessageError, decode, encode, json_schema
from inflarm_msgs_json.schema_export import main, schema_filename, schema_text
from msgs_json_cases import EXAMPLES, messages, mutated_messages

SCHEMA_DIR = Path(__file__).resolve().parents[2] / 'inflarm_msgs_json' / 'schema'
REGENERATE = 'python -m inflarm_msgs_json.schema_export inflarm_msgs_json/schema'


@pytest.fixture(scope='module')
def validators():
    result = {}
    for name, cls in MESSAGE_TYPES.items():
        schema = json_schema(cls)
        jsonschema.Draft202012Validator.check_schema(schema)
        result[name] = jsonschema.Draft202012Validator(schema)
    return result


def test_checked_in_schemas_match_the_generated_ones():
    expected = {schema_filename(cls) for cls in MESSAGE_TYPES.values()}
    assert {path.name for path in SCHEMA_DIR.glob('*.json')} == expected, REGENERATE
    for cls in MESSAGE_TYPES.values():
        text = (SCHEMA_DIR / schema_filename(cls)).read_text(encoding='utf-8')
        assert text == schema_text(cls), f'{cls.type} schema is stale; run {REGENERATE}'


def test_export_cli_writes_every_schema(tmp_path, capsys):
    assert main([str(tmp_path / 'out')]) == 0
    written = sorted((tmp_path / 'out').iterdir())
    assert [path.name for path in written] == sorted(f'{name}.schema.json' for name in EXAMPLES)
    for path in written:
        schema = json.loads(path.read_text(encoding='utf-8'))
        assert schema['title'] == path.name.removesuffix('.schema.json')
        assert schema['$schema'] == 'https://json-schema.org/draft/2020-12/schema'
    assert capsys.readouterr().out.count('.schema.json') == len(EXAMPLES)


def test_schema_is_derived_from_the_field_specs():
    schema = json_schema(MESSAGE_TYPES['PlanRequest'])
    assert schema['required'] == ['type', 'schema_version', 'frame_id', 'start', 'goal',
                                  'resolution']
    assert schema['additionalProperties'] is False
    assert schema['properties']['type'] == {'const': 'PlanRequest'}
    assert schema['properties']['resolution']['exclusiveMinimum'] == 0
    goal = schema['properties']['goal']
    assert goal['minItems'] == goal['maxItems'] == 3
    pressures = json_schema(MESSAGE_TYPES['ChamberPressures'])['properties']['chambers']
    assert pressures['additionalProperties']['minimum'] == inflarm_msgs_json.VACUUM_GAUGE_PA
    # a nested record has no envelope and its optional field is not required
    cuboid = json_schema(Cuboid)
    assert 'type' not in cuboid['properties'] and cuboid['required'] == ['min', 'max']


@pytest.mark.parametrize('name', sorted(EXAMPLES))
def test_examples_validate(validators, name):
    validators[name].validate(json.loads(encode(EXAMPLES[name])))


def _example_json(name, **changes):
    obj = json.loads(encode(EXAMPLES[name]))
    obj.update(changes)
    return obj


@pytest.mark.parametrize(
    ('name', 'obj'),
    [
        ('ObstacleSet', _example_json('ObstacleSet', alert_margin=-1.0)),
        ('ObstacleSet', _example_json('ObstacleSet', obstacles=[{'min': [0, 0, 0]}])),
        ('ObstacleSet', _example_json('ObstacleSet', extra=1)),
        ('PlanRequest', _example_json('PlanRequest', resolution=0)),
        ('PlanRequest', _example_json('PlanRequest', goal=[0, 0])),
        ('PlanRequest', _example_json('PlanRequest', frame_id='')),
        ('PressureCommand', _example_json('PressureCommand', chambers={})),
        ('PressureCommand', _example_json('PressureCommand', chambers={'B1': -2e5})),
        ('ChamberPressures', _example_json('ChamberPressures', chambers={'': 1.0})),
        ('ControlTask', _example_json('ControlTask', mode='pd')),
        ('ControlTask', _example_json('ControlTask', trial_id=True)),
        ('ControlTask', _example_json('ControlTask', trial_id=0.5)),
        ('TrialReport', _example_json('TrialReport', reach_time=[None, 'x', None])),
        ('TrialReport', _example_json('TrialReport', schema_version=2)),
        ('LinkStatus', _example_json('LinkStatus', type='ObstacleSet')),
        ('LinkStatus', _example_json('LinkStatus', pressure=0)),
    ],
)
def test_invalid_messages_fail_both_schema_and_decode(validators, name, obj):
    assert not validators[name].is_valid(obj)
    with pytest.raises(MessageError):
        decode(json.dumps(obj))


def test_rules_beyond_json_schema_are_documented_gaps(validators):
    # the schema accepts these; decode, which also checks cross-field rules, does not
    flipped = _example_json('ObstacleSet')
    flipped['obstacles'][0]['min'], flipped['obstacles'][0]['max'] = (
        flipped['obstacles'][0]['max'], flipped['obstacles'][0]['min'],
    )  # fmt: skip
    inconsistent = _example_json('LinkStatus', margin=99.0)
    for name, obj in [('ObstacleSet', flipped), ('LinkStatus', inconsistent)]:
        assert validators[name].is_valid(obj)
        with pytest.raises(MessageError):
            decode(json.dumps(obj))


@settings(max_examples=100, deadline=None)
@given(messages)
def test_generated_messages_validate(validators, message):
    validators[message.type].validate(json.loads(encode(message)))


@settings(max_examples=150, deadline=None)
@given(mutated_messages())
def test_whatever_decode_accepts_the_schema_accepts(validators, text):
    try:
        message = decode(text)
    except MessageError:
        return
    validators[message.type].validate(json.loads(text))


def test_schema_of_each_type_rejects_the_other_types(validators):
    for name, validator in validators.items():
        for other, message in EXAMPLES.items():
            obj = json.loads(encode(message))
            assert validator.is_valid(obj) == (name == other)
