"""A recorded trial read from its bag alone (studies/recorded.py): what ran from the bag's
metadata, how it went from the coordinator's last state; and what a bag that cannot say is
told."""
import pytest
from rclpy.serialization import serialize_message
from sim_interfaces.msg import PipelineState

from recording.bag_writer import BagWriter
from studies.recorded import (
    STATE_TOPIC,
    TRIAL_KEY,
    RecordError,
    bag_metadata,
    load_trial,
    result_from_bag,
)
from trial_record.result import RunInfo, TrialResult
from world_description.resources import resolve_resource
from world_description.world_config import world_data

SCENARIO = {'world': 'cell.yaml', 'time_step': 1 / 240,
            'world_data': world_data(resolve_resource(
                'package://world_description/worlds/pipeline_cell.yaml'))}


def _result():
    return TrialResult('completed', 25.1, scenario_seed=5, belt_speed=0.12, total=3,
                       events=[[0.0, 'belt_started', '', -1, '', '']],
                       run=RunInfo(code='abc', wall_time=3.0))


def _bag(tmp_path, custom, states):
    writer = BagWriter(tmp_path, 'bag', 'mcap', custom_data=custom)
    writer.add_topic(STATE_TOPIC, 'sim_interfaces/msg/PipelineState')
    for i, text in enumerate(states):
        writer.write(STATE_TOPIC, i, serialize_message(
            PipelineState(status='running' if not text else 'completed', result_json=text)))
    writer.close()
    return writer.path


def test_a_bag_alone_says_what_ran_and_how_it_went(tmp_path):
    original = _result()
    custom = bag_metadata(4, 5, 0.12, 'abc', SCENARIO, {'belt_speed': 0.12})
    bag = _bag(tmp_path, custom, ['', '', original.to_json(), ''])
    kept = result_from_bag(bag)
    assert kept.differences(original) == ['parameters']
    assert kept.parameters == {'belt_speed': 0.12}
    assert kept.scenario == SCENARIO and list(kept.scenario) == list(SCENARIO)
    assert kept.trial == 4 and kept.run.code == 'abc'
    assert load_trial(bag) == (kept, bag)


def test_a_bag_that_cannot_say_is_told(tmp_path):
    result = _result().to_json()
    with pytest.raises(RecordError, match=f'no {TRIAL_KEY} in custom_data'):
        result_from_bag(_bag(tmp_path / 'old', {}, [result]))
    # A run stopped before its end: what ran is known, how it went is not.
    cut = result_from_bag(_bag(tmp_path / 'cut', bag_metadata(2, 5, 0.12, 'abc', SCENARIO),
                               ['', '']))
    assert cut.status == 'interrupted' and 'did not end while it was recorded' in cut.message
    assert (cut.trial, cut.scenario_seed, cut.belt_speed, cut.scenario) == (2, 5, 0.12,
                                                                           SCENARIO)
    with pytest.raises(RecordError, match='a JSON object was expected'):
        result_from_bag(_bag(tmp_path / 'odd', {TRIAL_KEY: '[1]'}, [result]))
    with pytest.raises(RecordError, match='not a readable rosbag2 bag'):
        bad = tmp_path / 'bad'
        bad.mkdir()
        (bad / 'metadata.yaml').write_text('rosbag2_bagfile_information: {version: 9}\n')
        result_from_bag(bad)
    with pytest.raises(RecordError, match='does not exist'):
        load_trial(tmp_path / 'nowhere')
