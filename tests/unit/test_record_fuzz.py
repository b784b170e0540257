"""Fuzzing (hypothesis) of the records the study tools read back (issue 47): a trial's result
file and the trial record a bag keeps, as a damaged disk, a careless edit or a hostile sender
would leave them. Each is refused with a RecordError or read into a record that every tool
then uses without failing: the report and its plots, a comparison, the CSV row, and a write
that reads back the same. Derandomised: a failure is reproduced by running the test again."""
import copy
import json
import math
import re

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from helpers import REPORT
from studies.recorded import TRIAL_KEY, TrialRecord, bag_metadata
from trial_record.records import RecordError
from trial_record.result import RunInfo, TrialResult
from world_description.resources import resolve_resource
from world_description.world_config import world_data

SETTINGS = settings(derandomize=True, database=None, deadline=None, max_examples=300,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])
CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')
SCENARIO = {'world': str(CELL), 'world_data': world_data(CELL), 'time_step': 1 / 240}
COUNTS = {'results': 0, 'accepted': 0, 'records': 0, 'records accepted': 0}

NUMBERS = st.one_of(
    st.integers(-2 ** 70, 2 ** 70),
    st.sampled_from([0, -1, 1, 2 ** 31, 1e12, -1e12, 1e300, -1e300, 1e308, 5e-324, math.nan,
                     math.inf, -math.inf, 0.5, 8]),
    st.floats(allow_nan=True, allow_infinity=True))
TEXTS = st.one_of(st.text(max_size=12),
                  st.sampled_from(['', '../../evil', 'completed', 'orange', 'x' * 200_000,
                                   'trial_000/../..', '\0', 'lock-step']))
SCALARS = st.one_of(st.none(), st.booleans(), NUMBERS, TEXTS)
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(TEXTS, inner, max_size=4)), max_leaves=12)
# A list nested this deep, written into the record's text where this marker is (Python cannot
# even hold such a value to dump it).
DEEP = st.integers(200, 100_000).map(lambda n: f'\x00DEEP{n}\x00')
_DEEP_TEXT = re.compile(r'"\\u0000DEEP(\d+)\\u0000"')


def _encode(data):
    """A record's JSON text, its deep markers expanded; None if it has no JSON text."""
    try:
        text = json.dumps(data)
    except (ValueError, RecursionError):
        return None
    return _DEEP_TEXT.sub(lambda m: '[' * int(m.group(1)) + ']' * int(m.group(1)), text)


def _result():
    return TrialResult(
        'incomplete', 71.3, scenario_seed=7, belt_speed=0.12, mode='lock-step', total=8,
        delivered=7, handled_verified=7, identified_correct=8, grasp_attempts=9,
        grasp_successes=8, identification_rate=1.0, grasp_success_rate=8 / 9,
        handling_success_rate=7 / 8, parameters={'belt_speed': 0.12},
        materials=[{'id': 1, 'color': 'orange', 'status': 'delivered', 'attempts': 1,
                    'failure': '', 'sim_id': 0},
                   {'id': 2, 'color': 'blue', 'status': 'missed', 'attempts': 2,
                    'failure': 'grasp missed', 'sim_id': 1}],
        not_at_destination=[{'id': 1, 'color': 'blue', 'cause': 'grasp_missed'}],
        identifications=[{'stamp': 1.2, 'color': 'orange', 'material': 1, 'truth_id': 0}],
        final_materials=[{'id': 0, 'color': 'orange', 'position': [1.9, -1.5, 0.03],
                          'at_destination': True}],
        peak_joint_speed={'zu12': {'fraction_of_limit': 0.98, 'joint': 'joint_1',
                                   'time': 24.4}},
        youbot_path=[[0.8, 0.05], [1.2, -0.5], [1.8, -1.5]],
        events=[[0.0, 'belt_started', '', -1, '', ''], [3.1, 'picked', 'zu12', 1, 'orange', ''],
                [71.3, 'finished', '', -1, '', '']],
        states=[[0.0, 'loader', 'pick'], [30.0, 'transport', 'drive'],
                [71.3, 'loader', 'done']],
        scenario=copy.deepcopy(SCENARIO), run=RunInfo(trial=3, code='abc', wall_time=40.0,
                                                      cpu_seconds={'sim_node': 20.0}))


GOOD = _result().to_dict()


def _paths(data, path=()):
    yield path
    if isinstance(data, dict):
        for key, value in data.items():
            if key != 'world_data' or len(path) < 2:
                yield from _paths(value, path + (key,))
    elif isinstance(data, list):
        for i, value in enumerate(data[:3]):
            yield from _paths(value, path + (i,))


PATHS = [p for p in _paths(GOOD) if p]


def _set(data, path, value):
    out = copy.deepcopy(data)
    node = out
    for key in path[:-1]:
        node = node[key]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return out


_DELETE = object()


def _like(draw, old):
    """A value of the same kind as ``old``, anywhere in its kind's range and at its edges:
    what a record that passes the checks may hold (so that the tools run on many)."""
    if isinstance(old, bool):
        return draw(st.booleans())
    if isinstance(old, int):
        return draw(st.one_of(st.integers(-1, 10), st.sampled_from([0, 2 ** 31 - 1, 10 ** 6])))
    if isinstance(old, float):
        return draw(st.one_of(st.floats(-1e5, 1e5), st.sampled_from(
            [0.0, 1.0, 1e-9, 1e5, math.nan, 0.5, 2.0, 1e4, -1e4])))
    if isinstance(old, str):
        return draw(st.one_of(st.text(max_size=30), st.sampled_from(['', 'x' * 10_000])))
    if isinstance(old, list):
        return draw(st.lists(st.sampled_from(old), max_size=200)) if old else []
    return copy.deepcopy(old)


def _mutated(draw, data):
    """``data`` with one to three of its fields (at any depth) replaced by anything, by a
    value of its own kind, or deleted."""
    data = copy.deepcopy(data)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from([p for p in _paths(data) if p]))
        if draw(st.booleans()):
            node = data
            for key in path:
                node = node[key]
            value = _like(draw, node)
        else:
            value = draw(st.one_of(VALUES, DEEP, st.just(_DELETE)))
        try:
            data = _set(data, path, value)
        except (KeyError, IndexError, TypeError):
            pass
    return data


@st.composite
def results(draw):
    """A valid result with one to three of its fields (at any depth) replaced by anything, by
    a value of its own kind, deleted, or a field of its own added; now and then a value that
    is no result at all."""
    if draw(st.integers(0, 19)) == 0:
        return draw(st.one_of(VALUES, DEEP))
    data = _mutated(draw, GOOD)
    if draw(st.integers(0, 9)) == 0:
        data[draw(TEXTS)] = draw(VALUES)
    return data


@pytest.mark.slow
@SETTINGS
@given(data=results())
def test_a_result_read_back_is_refused_or_used_by_every_tool(tmp_path_factory, data):
    from studies.campaign import write_csv
    from studies.compare import compare_campaigns, compare_trials
    from studies.report import write_report
    COUNTS['results'] += 1
    text = _encode(data)
    if text is None:
        event('not even JSON')
        return
    from trial_record.records import parse_json
    try:
        result = TrialResult.from_dict(parse_json(text, 'fuzzed'), 'fuzzed')
    except RecordError as exc:
        assert str(exc).startswith('fuzzed') and '\n' not in str(exc)
        event('refused')
        return
    event('accepted')
    COUNTS['accepted'] += 1
    again = TrialResult.from_dict(json.loads(result.to_json()))
    assert again.differences(result) == []
    assert json.dumps(again.to_dict()['run']) == json.dumps(result.to_dict()['run'])
    out = tmp_path_factory.mktemp('fuzz')
    other = _result()
    write_report([result, other], out, {'note': 'fuzz', 'world': str(CELL),
                                        'sweep': ['belt_speed=0.1,0.2']})
    assert (out / 'report.md').is_file()
    compare_trials(result, other, out, ('a', 'b'))
    compare_campaigns([result], [other], ('a', 'b'))
    write_csv([result, other], out / 'trials.csv')


@st.composite
def trial_records(draw):
    base = json.loads(bag_metadata(4, 7, 0.12, 'abc', SCENARIO, {'belt_speed': 0.12})[TRIAL_KEY])
    if draw(st.integers(0, 9)) == 0:
        return draw(st.one_of(VALUES, DEEP))
    return _mutated(draw, base)


@pytest.mark.slow
@SETTINGS
@given(data=trial_records())
def test_a_bags_trial_record_is_refused_or_safe_to_run(data):
    COUNTS['records'] += 1
    text = _encode(data)
    if text is None:
        return
    try:
        record = TrialRecord.from_json(text, 'fuzzed')
    except RecordError as exc:
        assert str(exc).startswith('fuzzed') and '\n' not in str(exc)
        event('refused')
        return
    event('accepted')
    COUNTS['records accepted'] += 1
    # What names a directory is a number; what runs is a world the reader of worlds takes.
    assert record.trial is None or (isinstance(record.trial, int) and record.trial >= 0)
    assert f'trial_{record.trial or 0:03d}'.isidentifier()
    assert math.isnan(record.belt_speed) or 0.0 <= record.belt_speed <= 2.0
    assert all(isinstance(v, float) and math.isfinite(v) for v in record.parameters.values())
    assert set(record.scenario) <= {'world', 'world_data', 'time_step'}


@pytest.fixture(scope='module', autouse=True)
def _report():
    yield
    REPORT.append(f'record fuzzing: {COUNTS["results"]} result files '
                  f'({COUNTS["accepted"]} accepted, every tool ran on them), '
                  f'{COUNTS["records"]} bag trial records ({COUNTS["records accepted"]} '
                  'accepted); 0 crashes')
