"""Each part of the cell's controller is the only writer of what it holds (docs/architecture.md,
"Where each kind of state lives"): no machine writes into a part, into the other machine, or
into a material; a material's fields are written by the book or by the belt model, never by
both. Watched while whole runs of the fake cell go on, with the faults that take the rarer
ways (a missed grasp, a material dropped on the way, a pick out of reach)."""
import sys
from collections import defaultdict

import pytest
from test_pipeline import PAPER, FakeCell, cell_layout, run

from coordinator.pipeline import Settings, clock, core, machine, materials, model, record, robots

# The classes whose objects hold the controller's state, each written only by its own methods
# (a subclass's included), and the run's clock, which the run sets at each tick.
PARTS = (materials.MaterialBook, materials.BeltModel, robots.Arm, robots.CupPlace,
         robots.BaseDrive, record.EventLog, clock.Clock, machine.Machine, core.Pipeline)
ALSO_WRITES = {'Clock': {'Pipeline'}}
MATERIAL_WRITERS = {'MaterialBook', 'BeltModel'}


@pytest.fixture
def writes(monkeypatch):
    """(class of the object written, attribute) -> the classes whose methods wrote it."""
    seen = defaultdict(set)
    for cls in (*PARTS, model.Material):
        def hook(obj, name, value, _set=cls.__setattr__):
            writer = sys._getframe(1).f_locals.get('self')
            seen[(type(obj).__name__, name)].add(
                type(writer).__name__ if writer is not None else sys._getframe(1).f_code.co_name)
            _set(obj, name, value)
        monkeypatch.setattr(cls, '__setattr__', hook)
    return seen


def _own(cls_name):
    """The names of a part's class and its bases: a base's method writes through ``self``."""
    cls = next(c for part in PARTS for c in [part, *part.__subclasses__()]
               if c.__name__ == cls_name)
    return {c.__name__ for c in cls.__mro__}


@pytest.mark.parametrize('faults', [{}, {'grasp_failures': {2: 1}}, {'drop_on_transfer': 3},
                                    {'unreachable': lambda arm, p: arm == 'zu12' and p[2] > 0.5
                                     and p[1] > 0.7}],
                         ids=['clean', 'missed grasp', 'dropped', 'out of reach'])
def test_every_part_is_written_only_by_itself(writes, faults):
    cell = FakeCell(cell_layout(), PAPER, **faults)
    run(cell, Settings(idle_timeout=5.0))
    parts = {(owner, name): by for (owner, name), by in writes.items() if owner != 'Material'}
    assert {owner for owner, _ in parts} >= {'Loader', 'Transport', 'MaterialBook', 'BeltModel',
                                            'Arm', 'YoubotArm', 'CupPlace', 'BaseDrive'}
    strangers = {f'{owner}.{name}': sorted(by - _own(owner) - ALSO_WRITES.get(owner, set()))
                 for (owner, name), by in parts.items()}
    assert {k: v for k, v in strangers.items() if v} == {}


def test_a_materials_fields_have_one_writer_each(writes):
    cell = FakeCell(cell_layout(), PAPER, grasp_failures={2: 1}, drop_on_transfer=3)
    run(cell)
    fields = {name: by - {'Material'} for (owner, name), by in writes.items()
              if owner == 'Material'}
    assert {'status', 'position', 'slot', 'place', 'attempts'} <= set(fields)
    assert {name: by for name, by in fields.items() if not by <= MATERIAL_WRITERS} == {}
    assert {name: by for name, by in fields.items() if len(by) > 1} == {}


def test_the_watch_sees_a_stranger_write(writes):
    """The check itself: a machine that wrote into a material or a part would be seen."""
    cell = FakeCell(cell_layout(), PAPER[:1])
    pipeline = core.Pipeline(cell.layout, cell, Settings())

    class Intruder:
        def write(self, arm, m):
            arm._home = None
            m.status = model.MaterialStatus.FAILED

    Intruder().write(pipeline.loader_arm, model.Material(1, 'orange', None, 0.0, 1))
    assert 'Intruder' in writes[('Arm', '_home')]
    assert 'Intruder' in writes[('Material', 'status')]
