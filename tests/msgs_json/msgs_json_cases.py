"""Shared test data for inflarm_msgs_json: hand-written examples and hypothesis strategies."""

import json

from hypothesis import strategies as st

from inflarm_msgs_json import (
    MESSAGE_TYPES,
    CallbackRecord,
    ChamberPressures,
    ControlTask,
    Cuboid,
    HardwareStatus,
    LinkPressures,
    LinkStatus,
    ObstacleSet,
    PlanOutcome,
    PlanRequest,
    PressureCommand,
    TrialReport,
    encode,
)

# One valid instance per message type, written by hand (not produced by the code under test).
EXAMPLES = {
    'ObstacleSet': ObstacleSet(
        frame_id='base_link',
        alert_margin=0.05,
        obstacles=(
            Cuboid((0.2, -0.1, 0.0), (0.3, 0.1, 0.4), 'box'),
            Cuboid((-0.5, -0.5, -0.01), (0.5, 0.5, 0.0)),
            Cuboid((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 'point'),
        ),
    ),
    'PlanRequest': PlanRequest('base_link', (0.0, 0.0, 0.35), (0.2, -0.1, 0.3), 0.01),
    'PlanOutcome': PlanOutcome(
        'no_path', 'start_blocked', 'start is inside an alert region', (0.0, 0.13, 0.71),
        (0.13, 0.0, 0.73), 0, 0.0, 0.0, 0.0125),
    'PressureCommand': PressureCommand({'B1': 12000.0, 'B2': -5000.0, 'A': 0.0}),
    'ChamberPressures': ChamberPressures({'B1': 11950.5, 'B2': -101325.0}),
    'ControlTask': ControlTask('base_link', (0.1, 0.2, 0.3), 'pid_ilc', 4),
    'TrialReport': TrialReport(3, (0.004, 0.0, 0.012), (1.25, None, 0.0)),
    'LinkStatus': LinkStatus('link_1', 35000.0, 2.5, 0.75, 1.75),
    'LinkPressures': LinkPressures({'link_1': 50010.5, 'link_2': 49990.0}),
    'CallbackRecord': CallbackRecord('/load_estimator', '/joint_states', 1764968400123456789,
                                     1764968400120000000, None),
    'HardwareStatus': HardwareStatus(
        'active', 'connected', 'hold', 'safe', ('over_pressure', 'link_lost'),
        ('over_pressure',), 'over_pressure: B1 at 131000 Pa', 0.023, 2, 1, 0),
}

finite = st.floats(allow_nan=False, allow_infinity=False) | st.integers(-(10**6), 10**6)
nonnegative = st.floats(min_value=0.0, allow_infinity=False) | st.integers(0, 10**6)
positive = st.floats(min_value=0.0, exclude_min=True, allow_infinity=False)
vec3 = st.tuples(finite, finite, finite)
names = st.text(min_size=1, max_size=12)
counts = st.integers(min_value=0, max_value=2**70)
modes = st.sampled_from(['pid', 'pid_ilc'])
gauge_pressures = st.dictionaries(
    names, st.floats(min_value=-101325.0, max_value=1e7), min_size=1, max_size=5
)


@st.composite
def cuboids(draw):
    a, b = draw(vec3), draw(vec3)
    low = tuple(min(p, q) for p, q in zip(a, b, strict=True))
    high = tuple(max(p, q) for p, q in zip(a, b, strict=True))
    return Cuboid(low, high, draw(st.text(max_size=8)))


STRATEGIES = {
    'ObstacleSet': st.builds(
        ObstacleSet, names, nonnegative, st.lists(cuboids(), max_size=4).map(tuple)
    ),
    'PlanRequest': st.builds(PlanRequest, names, vec3, vec3, positive),
    'PlanOutcome': st.one_of(
        st.builds(PlanOutcome, st.just('planned'), st.just(''), st.text(max_size=8), vec3, vec3,
                  st.integers(1, 10**4), nonnegative, nonnegative, nonnegative),
        st.builds(PlanOutcome, st.just('no_path'), names, st.text(max_size=8), vec3, vec3,
                  st.just(0), st.just(0.0), st.just(0.0), nonnegative),
        st.builds(PlanOutcome, st.just('rejected'), st.just(''), st.text(max_size=8), vec3,
                  vec3, st.just(0), st.just(0.0), st.just(0.0), nonnegative),
    ),
    'PressureCommand': st.builds(PressureCommand, gauge_pressures),
    'ChamberPressures': st.builds(ChamberPressures, gauge_pressures),
    'ControlTask': st.builds(ControlTask, names, vec3, modes, counts),
    'TrialReport': st.builds(
        TrialReport,
        counts,
        st.tuples(nonnegative, nonnegative, nonnegative),
        st.tuples(*[st.none() | nonnegative] * 3),
    ),
    'LinkStatus': st.builds(LinkStatus.from_moments, names, positive, nonnegative, nonnegative),
    'LinkPressures': st.builds(LinkPressures, gauge_pressures),
    'CallbackRecord': st.builds(CallbackRecord, names, names, counts, st.none() | counts,
                                st.none() | counts),
    'HardwareStatus': st.lists(names, max_size=4, unique=True).flatmap(
        lambda faults: st.builds(
            HardwareStatus,
            st.sampled_from(['unconfigured', 'inactive', 'active', 'finalized']),
            st.sampled_from(['closed', 'handshake', 'connected', 'lost']),
            st.sampled_from(['none', 'follow', 'hold', 'zero_torque']),
            st.sampled_from(['none', 'follow', 'safe']),
            st.just(tuple(faults)),
            st.lists(st.sampled_from(faults), unique=True).map(tuple) if faults
            else st.just(()),
            st.text(max_size=20),
            st.none() | nonnegative,
            counts, counts, counts)),
}

messages = st.one_of(*STRATEGIES.values())

# Arbitrary JSON, with keys and values biased towards real ones so that mutated or made-up
# messages get past the envelope into field validation.
FIELD_NAMES = sorted(
    {'type', 'schema_version', 'min', 'max', 'name'}
    | {name for cls in MESSAGE_TYPES.values() for name in cls.__dataclass_fields__}
)
keys = st.sampled_from(FIELD_NAMES) | st.text(max_size=6)
scalars = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.integers(min_value=-(10**400), max_value=10**400)  # beyond a double
    | st.floats()  # includes nan, inf and -0.0
    | st.sampled_from([1e308, -1e308, 5e-324, -101325.0, -101325.5, 0.0])
    | st.text(max_size=8)
    | st.sampled_from([*sorted(MESSAGE_TYPES), 'pid', 'pid_ilc', 'Cuboid', 'planned', 'no_path'])
)
json_values = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(keys, children, max_size=5),
    max_leaves=10,
)


def _locations(obj, path=()):
    """Yield the path (tuple of keys and indices) of every value below the root of ``obj``."""
    if isinstance(obj, dict):
        items = obj.items()
    elif isinstance(obj, list):
        items = enumerate(obj)
    else:
        return
    for key, value in items:
        yield (*path, key)
        yield from _locations(value, (*path, key))


def _at(obj, path):
    for key in path:
        obj = obj[key]
    return obj


@st.composite
def mutated_messages(draw):
    """JSON text of a valid message with one value replaced or removed, or one key added."""
    obj = json.loads(encode(draw(messages)))
    locations = list(_locations(obj))
    action = draw(st.sampled_from(['replace', 'remove', 'add']))
    if action == 'add':
        objects = [()] + [path for path in locations if isinstance(_at(obj, path), dict)]
        _at(obj, draw(st.sampled_from(objects)))[draw(keys)] = draw(json_values)
    else:
        path = draw(st.sampled_from(locations))
        parent = _at(obj, path[:-1])
        if action == 'replace':
            parent[path[-1]] = draw(json_values)
        else:
            del parent[path[-1]]
    return json.dumps(obj)  # allow_nan: NaN and Infinity tokens reach decode too
