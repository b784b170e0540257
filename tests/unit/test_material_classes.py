"""Material classes and their rules in the world file: both forms, and every rule that cannot
work refused with one line that names it."""
import copy

import pytest
import yaml

from world_description.material_classes import hue_of, in_range
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world, parse_world

CELL = resolve_resource('package://world_description/worlds/pipeline_cell.yaml')


def cell_data():
    with open(CELL, encoding='utf-8') as f:
        return yaml.safe_load(f)


def with_classes(classes, **materials):
    data = cell_data()
    m = {k: v for k, v in data['materials'].items() if k not in ('counts', 'colors')}
    m.update(materials, classes=classes)
    data['materials'] = m
    return data


PAPER_CLASSES = {
    'purple': {'color': [0.5, 0.15, 0.7, 1.0], 'count': 1, 'destination': 'ground_target',
               'route': 'place'},
    'orange': {'color': [1.0, 0.5, 0.05, 1.0], 'count': 6, 'destination': 'pool_floor',
               'route': 'carry'},
    'blue': {'color': [0.1, 0.3, 0.9, 1.0], 'count': 1, 'destination': 'pool_platform',
             'route': 'carry'},
}


def test_the_first_form_gives_the_papers_rules_and_the_camera_the_papers_hues():
    m = load_world(CELL).materials
    rules = {c.name: (c.count, c.destination, c.route) for c in m.classes}
    assert rules == {'purple': (1, 'ground_target', 'place'), 'orange': (6, 'pool_floor', 'carry'),
                     'blue': (1, 'pool_platform', 'carry')}
    # The hues the renderer gives the paper's materials (docs/robot-models.md §5) fall in
    # their classes' ranges, and in no other.
    for name, hue in (('purple', 139), ('orange', 14), ('blue', 112)):
        inside = [c.name for c in m.classes if in_range(hue, c.hue)]
        assert inside == [name]


def test_the_classes_form_says_the_same_as_the_first_form():
    first = load_world(CELL).materials
    second = parse_world(with_classes(copy.deepcopy(PAPER_CLASSES)), 'x.yaml').materials
    assert second.classes == first.classes


def test_a_class_may_have_its_own_size_mass_and_hue():
    classes = copy.deepcopy(PAPER_CLASSES)
    classes['green'] = {'color': [0.1, 0.8, 0.2, 1.0], 'count': 2, 'destination': 'pool_floor',
                        'route': 'carry', 'size': 0.04, 'mass': 0.45, 'hue': [50, 80]}
    m = parse_world(with_classes(classes), 'x.yaml').materials
    green = m.cls('green')
    assert (green.size, green.mass, green.hue) == (0.04, 0.45, (50, 80))
    assert in_range(hue_of(green.color), green.hue)
    assert m.total == 10 and m.largest == 0.05


@pytest.mark.parametrize('change, fragment', [
    (lambda c: c['blue'].pop('destination'), r'classes.blue.destination is required'),
    (lambda c: c['blue'].update(destination='nowhere'), r"blue goes to 'nowhere', which is no "
                                                         r'obstacle'),
    (lambda c: c['blue'].update(route='throw'), r"classes.blue.route must be one of"),
    (lambda c: c['blue'].update(color=[0.5, 0.5, 0.5, 1.0]), r'blue has saturation 0.00.*grey'),
    (lambda c: c['blue'].update(color=[0.1, 0.1, 0.3, 1.0]), r'blue has value 0.30'),
    # Violet (hue 135) beside purple (139): one class would be read as the other.
    (lambda c: c.update(violet={'color': [0.4, 0.1, 0.7, 1.0], 'count': 1,
                                'destination': 'pool_floor', 'route': 'carry'}),
     r'purple and violet have hues 139 and 135.*cannot tell them apart'),
    (lambda c: c['blue'].update(hue=[100, 140]), r'hue ranges of blue .* and purple .* overlap'),
    (lambda c: c['blue'].update(size=0.7), r'blue \(0.7 m\) does not fit on pool_platform'),
    (lambda c: c['blue'].update(count=-1), r'classes.blue.count must be finite and within'),
    (lambda c: c.update({'9x': c.pop('blue')}), r"class name '9x' must be a ROS name"),
    (lambda c: [v.update(count=0) for v in c.values()], r'bring no material at all'),
])
def test_a_rule_that_cannot_work_is_refused_with_one_line(change, fragment):
    classes = copy.deepcopy(PAPER_CLASSES)
    change(classes)
    with pytest.raises(WorldConfigError, match=fragment) as err:
        parse_world(with_classes(classes), 'x.yaml')
    assert '\n' not in str(err.value) and str(err.value).startswith('x.yaml: ')


def test_a_colour_without_a_rule_in_the_first_form_is_refused():
    data = cell_data()
    data['materials']['counts']['green'] = 1
    data['materials']['colors']['green'] = [0.1, 0.8, 0.2, 1.0]
    with pytest.raises(WorldConfigError, match=r"\['green'\]: only .* have rules in this form"):
        parse_world(data, 'x.yaml')


def test_both_forms_at_once_are_refused():
    data = with_classes(copy.deepcopy(PAPER_CLASSES))
    data['materials']['counts'] = {'purple': 1}
    with pytest.raises(WorldConfigError, match='replaces counts and colors'):
        parse_world(data, 'x.yaml')
