"""Round trips, construction and rejection of every inflarm JSON message, without ROS."""

import copy
import dataclasses
import json
import pickle
import re

import numpy as np
import pytest

import inflarm_msgs_json
from inflarm_msgs_json import (
    MESSAGE_TYPES,
    ChamberPressures,
    ControlTask,
    Cuboid,
    LinkStatus,
    MessageError,
    ObstacleSet,
    PlanOutcome,
    PlanRequest,
    PressureCommand,
    TrialReport,
    decode,
    encode,
)
from msgs_json_cases import EXAMPLES

# --- round trips and the envelope ---------------------------------------------------------------


def test_examples_cover_every_message_type():
    assert set(EXAMPLES) == set(MESSAGE_TYPES) == {
        'ObstacleSet', 'PlanRequest', 'PlanOutcome', 'PressureCommand', 'ChamberPressures',
        'ControlTask', 'TrialReport', 'LinkStatus', 'LinkPressures', 'HardwareStatus',
            'CallbackRecord',
    }  # fmt: skip


@pytest.mark.parametrize('name', sorted(EXAMPLES))
def test_round_trip(name):
    message = EXAMPLES[name]
    decoded = decode(encode(message))
    assert type(decoded) is type(message)
    assert decoded == message
    assert decode(encode(message), expected=type(message)) == message


@pytest.mark.parametrize('name', sorted(EXAMPLES))
def test_encoded_text_has_the_envelope_first(name):
    message = EXAMPLES[name]
    obj = json.loads(encode(message))
    assert list(obj)[:2] == ['type', 'schema_version']
    assert obj['type'] == name == type(message).type
    assert obj['schema_version'] == 1 == type(message).schema_version


def test_decode_hand_written_obstacle_set():
    text = """{"type": "ObstacleSet", "schema_version": 1, "frame_id": "world",
               "alert_margin": 0, "obstacles": [
                   {"min": [0, 0, 0], "max": [1, 2.5, 3], "name": "table"},
                   {"min": [-1, -1, -1], "max": [-0.5, -0.5, -0.5]}]}"""
    message = decode(text, expected=ObstacleSet)
    assert message.frame_id == 'world'
    assert message.alert_margin == 0.0 and isinstance(message.alert_margin, float)
    assert message.obstacles == (
        Cuboid(min=(0.0, 0.0, 0.0), max=(1.0, 2.5, 3.0), name='table'),
        Cuboid(min=(-1.0, -1.0, -1.0), max=(-0.5, -0.5, -0.5), name=''),
    )


def test_pressure_map_json_form_and_access():
    text = '{"type": "PressureCommand", "schema_version": 1, "chambers": {"B2": -5e3, "B1": 12e3}}'
    command = decode(text)
    assert isinstance(command, PressureCommand)
    assert command.as_dict() == {'B1': 12000.0, 'B2': -5000.0}
    assert json.loads(encode(command))['chambers'] == {'B1': 12000.0, 'B2': -5000.0}
    # equality does not depend on insertion order; commanded and measured never compare equal
    assert command == PressureCommand({'B1': 12000.0, 'B2': -5000.0})
    assert command != ChamberPressures({'B1': 12000.0, 'B2': -5000.0})
    # as_dict hands out a copy: mutating it cannot change the message
    command.as_dict()['B1'] = 0.0
    assert command.as_dict()['B1'] == 12000.0
    # the stored pairs can be passed back in
    assert PressureCommand(command.chambers) == command


def test_trial_report_null_reach_time():
    report = decode(
        '{"type": "TrialReport", "schema_version": 1, "trial_index": 2,'
        ' "rmse": [0.001, 0.002, 0.003], "reach_time": [null, 2.5, null]}'
    )
    assert report == TrialReport(2, (0.001, 0.002, 0.003), (None, 2.5, None))
    assert json.loads(encode(report))['reach_time'] == [None, 2.5, None]


def test_link_status_from_moments_computes_the_margin():
    status = LinkStatus.from_moments('link_2', 40000.0, 3.0, 3.5)
    assert status.margin == pytest.approx(-0.5)  # past wrinkling: a negative margin is valid
    assert decode(encode(status)) == status


# --- construction -------------------------------------------------------------------------------


def test_construction_normalises_values():
    task = ControlTask('base_link', np.array([0.1, 0.2, 0.3]), 'pid', np.int64(2))
    assert task.target == (0.1, 0.2, 0.3)
    assert all(type(x) is float for x in task.target)
    assert type(task.trial_id) is int
    request = PlanRequest('base_link', [0, 0, 1], (1, 2, 3), 1)
    assert request.start == (0.0, 0.0, 1.0) and type(request.resolution) is float
    obstacles = ObstacleSet('w', 0.1, [Cuboid((0, 0, 0), (1, 1, 1))])
    assert isinstance(obstacles.obstacles, tuple)


def test_messages_are_frozen_and_hashable():
    message = EXAMPLES['ObstacleSet']
    with pytest.raises(dataclasses.FrozenInstanceError):
        message.alert_margin = -1.0
    assert hash(message) == hash(copy.deepcopy(message))
    assert len(set(EXAMPLES.values())) == len(EXAMPLES)


def test_replace_validates():
    with pytest.raises(MessageError, match=r'^PlanRequest\.resolution: '):
        dataclasses.replace(EXAMPLES['PlanRequest'], resolution=0.0)


@pytest.mark.parametrize(
    ('build', 'path'),
    [
        (lambda: Cuboid((1, 0, 0), (0, 1, 1)), 'Cuboid'),
        (lambda: Cuboid((0, 0, 0), (1, 1, float('nan'))), 'Cuboid.max[2]'),
        (lambda: Cuboid((0, 0, 0), (1, 1)), 'Cuboid.max'),
        (lambda: Cuboid((0, 0, 0), (1, 1, 1), None), 'Cuboid.name'),
        (lambda: ObstacleSet('', 0.1, ()), 'ObstacleSet.frame_id'),
        (lambda: ObstacleSet('w', 0.1, (Cuboid((0, 0, 0), (1, 1, 1)), 'box')), 'ObstacleSet.obstacles[1]'),  # noqa: E501
        (lambda: PlanRequest('w', (0, 0, 0), (1, 1, 1), float('inf')), 'PlanRequest.resolution'),
        (lambda: PlanRequest('w', (0, 0, 0), (1, 1, 1), 10**400), 'PlanRequest.resolution'),
        (lambda: PlanRequest('w', (0, 0, 0), (1, 1, 1), 10**5000), 'PlanRequest.resolution'),
        (lambda: PlanRequest('w', 'abc', (1, 1, 1), 0.1), 'PlanRequest.start'),
        (lambda: PlanRequest('w', np.zeros((3, 1)), (1, 1, 1), 0.1), 'PlanRequest.start[0]'),
        (lambda: PressureCommand({}), 'PressureCommand.chambers'),
        (lambda: PressureCommand((('B1', 1.0), ('B1', 2.0))), "PressureCommand.chambers['B1']"),
        (lambda: PressureCommand({3: 1.0}), 'PressureCommand.chambers[3]'),
        (lambda: ChamberPressures({'B1': -101325.5}), "ChamberPressures.chambers['B1']"),
        (lambda: ControlTask('w', (0, 0, 0), 'pid', -1), 'ControlTask.trial_id'),
        (lambda: ControlTask('w', (0, 0, 0), 'PID', 0), 'ControlTask.mode'),
        (lambda: TrialReport(0, (0, -1e-9, 0), (None, None, None)), 'TrialReport.rmse[1]'),
        (lambda: LinkStatus('link_1', 1e5, 2.0, 0.5, 1.4), 'LinkStatus.margin'),
        (lambda: LinkStatus.from_moments('link_1', 1e5, 'a', 0.5), 'LinkStatus.wrinkling_moment'),
        (lambda: LinkStatus.from_moments('link_1', 1e5, 2.0, [1.0]), 'LinkStatus.moment'),
        (lambda: LinkStatus.from_moments('link_1', 0.0, 2.0, 1.0), 'LinkStatus.pressure'),
        (lambda: PlanOutcome('done', '', '', (0, 0, 1), (0, 1, 1), 1, 0.1, 1.0, 0.0), 'PlanOutcome.status'),  # noqa: E501
        (lambda: PlanOutcome('no_path', '', '', (0, 0, 1), (0, 1, 1), 0, 0.0, 0.0, 0.0), 'PlanOutcome.reason'),  # noqa: E501
        (lambda: PlanOutcome('planned', 'x', '', (0, 0, 1), (0, 1, 1), 3, 0.1, 1.0, 0.0), 'PlanOutcome.reason'),  # noqa: E501
        (lambda: PlanOutcome('planned', '', '', (0, 0, 1), (0, 1, 1), 0, 0.0, 0.0, 0.0), 'PlanOutcome.waypoints'),  # noqa: E501
        (lambda: PlanOutcome('rejected', '', '', (0, 0, 1), (0, 1, 1), 2, 0.0, 0.0, 0.0), 'PlanOutcome.waypoints'),  # noqa: E501
        (lambda: PlanOutcome('planned', '', '', (0, 0, 1), (0, 1, 1), 2, -0.1, 1.0, 0.0), 'PlanOutcome.length'),  # noqa: E501
    ],
)
def test_invalid_construction_raises_naming_the_field(build, path):
    with pytest.raises(MessageError, match='^' + re.escape(path) + ': ') as error:
        build()
    assert error.value.path == path


def test_link_status_margin_tolerance_scales_with_the_moments():
    # 1e-9 relative to the larger moment: rounding passes, a real discrepancy does not
    LinkStatus('link_1', 1e5, 1e6, 0.0, 1e6 * (1 + 5e-10))
    with pytest.raises(MessageError, match=r'^LinkStatus\.margin: '):
        LinkStatus('link_1', 1e5, 1e6, 0.0, 1e6 * (1 + 5e-9))
    LinkStatus('link_1', 1e5, 0.5, 0.25, 0.25 + 5e-10)  # absolute below 1 N m
    with pytest.raises(MessageError, match=r'^LinkStatus\.margin: '):
        LinkStatus('link_1', 1e5, 0.5, 0.25, 0.25 + 5e-9)


# --- decode rejections --------------------------------------------------------------------------

OBSTACLES = {
    'type': 'ObstacleSet',
    'schema_version': 1,
    'frame_id': 'world',
    'alert_margin': 0.1,
    'obstacles': [
        {'min': [0, 0, 0], 'max': [1, 1, 1]},
        {'min': [0, 0, 0], 'max': [1, 1, 1], 'name': 'b'},
        {'min': [0, 0, 0], 'max': [1, 1, 1]},
    ],
}


def _obstacles_with(path, value=None, *, delete=False):
    obj = copy.deepcopy(OBSTACLES)
    *parents, last = path
    target = obj
    for key in parents:
        target = target[key]
    if delete:
        del target[last]
    else:
        target[last] = value
    return json.dumps(obj)


def _example_with(name, **changes):
    obj = json.loads(encode(EXAMPLES[name]))
    obj.update(changes)
    return json.dumps(obj)


@pytest.mark.parametrize(
    ('text', 'path', 'reason'),
    [
        # the field path names the culprit, down into nested objects and arrays
        (_obstacles_with(['obstacles', 2, 'max'], [1, 2]), 'ObstacleSet.obstacles[2].max',
         'expected 3 finite numbers, got [1, 2]'),
        (_obstacles_with(['obstacles', 0, 'min', 1], 'a'), 'ObstacleSet.obstacles[0].min[1]',
         None),
        (_obstacles_with(['obstacles', 1, 'min'], [2, 0, 0]), 'ObstacleSet.obstacles[1]',
         'min <= max'),
        (_obstacles_with(['obstacles', 1, 'name'], 7), 'ObstacleSet.obstacles[1].name', None),
        (_obstacles_with(['obstacles', 0], [0, 1]), 'ObstacleSet.obstacles[0]', None),
        (_obstacles_with(['obstacles'], {}), 'ObstacleSet.obstacles', None),
        # missing and unknown fields
        (_obstacles_with(['frame_id'], delete=True), 'ObstacleSet.frame_id', 'missing'),
        (_obstacles_with(['obstacles', 1, 'max'], delete=True), 'ObstacleSet.obstacles[1].max',
         'missing'),
        (_obstacles_with(['colour'], 'red'), 'ObstacleSet', "unknown field 'colour'"),
        (_obstacles_with(['obstacles', 0, 'type'], 'Cuboid'), 'ObstacleSet.obstacles[0]',
         "unknown field 'type'"),
        # wrong types: bool is not a number, a float is not an int, a number is not a string
        (_obstacles_with(['alert_margin'], True), 'ObstacleSet.alert_margin', None),
        (_obstacles_with(['alert_margin'], '0.1'), 'ObstacleSet.alert_margin', None),
        (_obstacles_with(['alert_margin'], None), 'ObstacleSet.alert_margin', None),
        (_obstacles_with(['frame_id'], 5), 'ObstacleSet.frame_id', None),
        (_example_with('ControlTask', trial_id=1.0), 'ControlTask.trial_id', None),
        (_example_with('ControlTask', trial_id=False), 'ControlTask.trial_id', None),
        (_example_with('TrialReport', trial_index='3'), 'TrialReport.trial_index', None),
        (_example_with('ControlTask', target=[0, True, 0]), 'ControlTask.target[1]', None),
        # bounds
        (_obstacles_with(['alert_margin'], -0.01), 'ObstacleSet.alert_margin', '>= 0'),
        (_obstacles_with(['frame_id'], ''), 'ObstacleSet.frame_id', 'non-empty'),
        (_example_with('PlanRequest', resolution=0), 'PlanRequest.resolution', '> 0'),
        (_example_with('PlanRequest', resolution=-0.01), 'PlanRequest.resolution', '> 0'),
        (_example_with('ControlTask', trial_id=-1), 'ControlTask.trial_id', '>= 0'),
        (_example_with('ControlTask', mode='ilc'), 'ControlTask.mode', "'pid', 'pid_ilc'"),
        (_example_with('TrialReport', rmse=[0, 0, -1]), 'TrialReport.rmse[2]', '>= 0'),
        (_example_with('TrialReport', reach_time=[None, -1, None]), 'TrialReport.reach_time[1]',
         'or null'),
        (_example_with('TrialReport', reach_time=[None, None]), 'TrialReport.reach_time', None),
        (_example_with('LinkStatus', pressure=0), 'LinkStatus.pressure', '> 0'),
        (_example_with('LinkStatus', moment=-0.5, margin=3.0), 'LinkStatus.moment', '>= 0'),
        (_example_with('LinkStatus', margin=1.0), 'LinkStatus.margin',
         'wrinkling_moment - moment'),
        (_example_with('LinkStatus', link=''), 'LinkStatus.link', None),
        # pressure maps: non-empty, named, not below vacuum, a JSON object
        (_example_with('PressureCommand', chambers={}), 'PressureCommand.chambers', None),
        (_example_with('PressureCommand', chambers={'B1': 0, 'B2': -101326}),
         "PressureCommand.chambers['B2']", '-101325'),
        (_example_with('ChamberPressures', chambers={'': 0}), "ChamberPressures.chambers['']",
         'non-empty'),
        (_example_with('ChamberPressures', chambers={'B1': '1'}),
         "ChamberPressures.chambers['B1']", None),
        (_example_with('PressureCommand', chambers=[['B1', 1.0]]), 'PressureCommand.chambers',
         None),
        # numbers JSON or a double cannot hold
        (_obstacles_with(['alert_margin'], 10**400), 'ObstacleSet.alert_margin', None),
        (_obstacles_with(['alert_margin'], 'X').replace('"X"', '1e400'), '', 'double'),
        (_obstacles_with(['alert_margin'], 'X').replace('"X"', 'NaN'), '', 'NaN'),
        (_obstacles_with(['alert_margin'], 'X').replace('"X"', '-Infinity'), '', 'Infinity'),
        (_obstacles_with(['alert_margin'], 'X').replace('"X"', '9' * 5000), '', 'invalid JSON'),
        # the envelope
        (_obstacles_with(['type'], 'Obstacles'), 'type', "unknown message type 'Obstacles'"),
        (_obstacles_with(['type'], 'Cuboid'), 'type', 'unknown message type'),
        (_obstacles_with(['type'], ['ObstacleSet']), 'type', 'unknown message type'),
        (_obstacles_with(['type'], delete=True), 'type', 'missing'),
        (_obstacles_with(['schema_version'], 2), 'ObstacleSet.schema_version', 'version 2'),
        (_obstacles_with(['schema_version'], 1.0), 'ObstacleSet.schema_version', None),
        (_obstacles_with(['schema_version'], True), 'ObstacleSet.schema_version', None),
        (_obstacles_with(['schema_version'], '1'), 'ObstacleSet.schema_version', None),
        (_obstacles_with(['schema_version'], delete=True), 'ObstacleSet.schema_version',
         'missing'),
        # not a message at all
        ('[]', '', 'expected a JSON object'),
        ('"ObstacleSet"', '', 'expected a JSON object'),
        ('null', '', 'expected a JSON object'),
        ('', '', 'invalid JSON'),
        ('{"type": "ObstacleSet",', '', 'invalid JSON'),
        ('{"type": "ObstacleSet"} trailing', '', 'invalid JSON'),
        ('{"type": "ObstacleSet", "type": "PlanRequest"}', '', "duplicate key 'type'"),
        ('[' * 100_000 + ']' * 100_000, '', 'invalid JSON'),
        ('{"a":' * 50_000 + '1' + '}' * 50_000, '', 'invalid JSON'),
    ],
)
def test_decode_rejects_naming_the_path(text, path, reason):
    with pytest.raises(MessageError) as error:
        decode(text)
    assert error.value.path == path
    assert str(error.value).startswith(f'{path}: ' if path else '')
    if reason is not None:
        assert reason in error.value.reason


@pytest.mark.parametrize('value', [b'{}', None, 3, {'type': 'ObstacleSet'}, ['x']])
def test_decode_rejects_non_str(value):
    with pytest.raises(MessageError, match='expected JSON text as str') as error:
        decode(value)
    assert error.value.path == ''


def test_decode_expected_type():
    text = encode(EXAMPLES['PlanRequest'])
    assert decode(text, expected=PlanRequest) == EXAMPLES['PlanRequest']
    with pytest.raises(MessageError, match=r"^type: expected 'ObstacleSet', got 'PlanRequest'$"):
        decode(text, expected=ObstacleSet)
    # a mismatched type is refused before its fields are looked at
    with pytest.raises(MessageError, match=r'^type: '):
        decode(json.dumps({'type': 'PlanRequest', 'schema_version': 1}), expected=ObstacleSet)


@pytest.mark.parametrize('expected', [Cuboid, dict, 'ObstacleSet', inflarm_msgs_json.Message])
def test_decode_expected_must_be_a_message_class(expected):
    with pytest.raises(TypeError, match='message class'):
        decode(encode(EXAMPLES['ObstacleSet']), expected=expected)


def test_encode_refuses_non_messages():
    with pytest.raises(TypeError, match='Cuboid'):
        encode(Cuboid((0, 0, 0), (1, 1, 1)))
    with pytest.raises(TypeError, match='dict'):
        encode({'type': 'ObstacleSet'})


def test_error_is_a_value_error_and_pickles():
    with pytest.raises(ValueError, match='PlanRequest.resolution') as error:
        decode(_example_with('PlanRequest', resolution=0))
    copy_ = pickle.loads(pickle.dumps(error.value))
    assert (copy_.path, copy_.reason, str(copy_)) == (
        error.value.path, error.value.reason, str(error.value),
    )  # fmt: skip


def test_error_message_shows_huge_values_briefly():
    with pytest.raises(MessageError) as error:
        decode(_obstacles_with(['frame_id'], ['x' * 10_000] * 1000))
    assert len(str(error.value)) < 200


def test_hardware_status_latched_faults_are_active_faults():
    from inflarm_msgs_json import HardwareStatus
    with pytest.raises(MessageError, match=r"HardwareStatus.latched: expected a subset of faults, "
                                           r"got \['frozen_sensor'\]"):
        HardwareStatus('active', 'connected', 'hold', 'safe', ('over_pressure',),
                       ('frozen_sensor',), '', None, 0, 0, 0)
