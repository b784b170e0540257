"""The machines' transition tables (coordinator/pipeline/machine.py): every state has its row,
a transition outside the table is refused (raised in the tests, logged elsewhere), the tables
cover every transition a run makes, and docs/pipeline.md holds their diagrams as printed."""
import copy
import logging

import numpy as np
import pytest
from test_cell_rules import PAPER, FakeCell, run, world

from cell_layout.world_layout import layout_from_world
from coordinator.pipeline import LoaderState, Pipeline, Settings, TransportState
from coordinator.pipeline.loader import LOADER_TRANSITIONS
from coordinator.pipeline.machine import STRICT_ENV, TransitionError, transition_table
from coordinator.pipeline.transport import TRANSPORT_TRANSITIONS
from helpers import ROOT
from studies.pipeline_diagram import diagrams, in_file, main
from trial_record.events import EventKind


def test_every_state_has_a_row_and_only_the_final_state_has_no_way_out():
    for states, table, final in ((LoaderState, LOADER_TRANSITIONS, LoaderState.DONE),
                                 (TransportState, TRANSPORT_TRANSITIONS,
                                  TransportState.DONE)):
        assert set(table) == set(states)
        assert [s for s in states if not table[s]] == [final]
        assert all(final not in table[s] or s in (LoaderState.HOME, TransportState.FOLD,
                                                  TransportState.WAIT_LOAD) for s in states)


def test_a_table_without_a_row_for_a_state_is_refused():
    with pytest.raises(ValueError, match='no row for'):
        transition_table({LoaderState.START: (LoaderState.WAIT,)})


def _pipeline():
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    return Pipeline(layout, FakeCell(layout, []), Settings())


def test_a_transition_outside_the_table_raises_in_the_tests(monkeypatch):
    monkeypatch.setenv(STRICT_ENV, '1')
    p = _pipeline()
    with pytest.raises(TransitionError, match='transport: wait_load -> release'):
        p.transport.enter(TransportState.RELEASE, 0.0, 1.0)
    assert p.transport.state is TransportState.WAIT_LOAD


def test_elsewhere_a_transition_outside_the_table_is_logged_counted_and_made(
        monkeypatch, caplog):
    monkeypatch.delenv(STRICT_ENV)
    p = _pipeline()
    with caplog.at_level(logging.ERROR, logger='coordinator.pipeline'):
        p.loader.enter(LoaderState.PLACE, 3.0, 1.0)
    assert 'loader: start -> place at 3.000 s is not in its transition table' in caplog.text
    assert p.loader.wrong_transitions == [(3.0, LoaderState.START, LoaderState.PLACE)]
    assert p.loader.state is LoaderState.PLACE
    assert p.events[-1].kind is EventKind.STATE and p.events[-1].detail == 'place'


@pytest.mark.parametrize('oranges', [6, 11])          # (the paper's batch; two trips)
def test_a_run_makes_only_the_transitions_of_its_tables_and_each_one_it_reports(oranges):
    classes = copy.deepcopy(PAPER)
    classes['orange']['count'] = oranges
    layout = layout_from_world(world(classes))
    colors = ['orange'] * oranges + ['blue', 'purple']
    cell = FakeCell(layout, [colors[(5 * k) % len(colors)] for k in range(len(colors))])
    p = run(cell)
    assert p.result.status == 'completed', p.result
    seen = {'loader': set(), 'transport': set()}
    last = {'loader': LoaderState.START, 'transport': TransportState.WAIT_LOAD}
    for e in p.events:
        if e.kind is EventKind.STATE:
            state = type(last[e.robot])(e.detail)
            seen[e.robot].add((last[e.robot], state))
            last[e.robot] = state
    for robot, table in (('loader', LOADER_TRANSITIONS), ('transport', TRANSPORT_TRANSITIONS)):
        assert all(b in table[a] for a, b in seen[robot]), seen[robot]
    assert (LoaderState.PICK, LoaderState.PLACE) in seen['loader']
    assert (TransportState.CARRY, TransportState.RELEASE) in seen['transport']
    assert not p.loader.wrong_transitions and not p.transport.wrong_transitions


def test_the_docs_hold_the_diagrams_of_the_tables_as_they_are(tmp_path, capsys):
    assert in_file(ROOT / 'docs' / 'pipeline.md') == diagrams()
    assert main(['--check', str(ROOT / 'docs' / 'pipeline.md')]) == 0
    text = diagrams()
    assert '    wait --> pick' in text and '    carry --> release' in text
    # A table changed without its diagram: the check says so.
    stale = tmp_path / 'pipeline.md'
    stale.write_text(text.replace('    wait --> pick\n', ''))
    assert main(['--check', str(stale)]) == 1
    assert 'pipeline_diagram' in capsys.readouterr().err
    assert np.all([line.startswith(('<!--', 'The', '```', '    ', 'stateDiagram')) or not line
                   for line in text.splitlines()])
