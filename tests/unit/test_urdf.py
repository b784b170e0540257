"""The mini robot description: parts, joints, plausible inertia, loadable by PyBullet and
pinocchio."""
import xml.etree.ElementTree as ET

import numpy as np
import pybullet
import pytest

from robot_description import urdf_path

URDF = urdf_path('mini_robot')
ROOT = ET.parse(URDF).getroot()


def _joint(name):
    return ROOT.find(f"joint[@name='{name}']")


def test_the_reports_four_revolute_joints():
    moving = {j.get('name'): j.get('type') for j in ROOT.findall('joint')
              if j.get('type') != 'fixed'}
    assert moving == {'left_wheel_joint': 'continuous', 'right_wheel_joint': 'continuous',
                      'caster_swivel_joint': 'continuous', 'caster_wheel_joint': 'continuous'}
    assert _joint('caster_swivel_joint').find('axis').get('xyz') == '0 0 1'


def test_the_reports_parts_and_a_camera():
    links = {link.get('name') for link in ROOT.findall('link')}
    assert {'base_link', 'front_plate', 'left_wheel', 'right_wheel', 'caster_bracket',
            'caster_cover', 'caster_wheel', 'left_servo', 'right_servo', 'camera_link',
            'camera_optical_frame'} <= links


def test_wheel_radius_and_separation():
    for side, sign in (('left', 1), ('right', -1)):
        cyl = ROOT.find(f"link[@name='{side}_wheel']/collision/geometry/cylinder")
        assert float(cyl.get('radius')) == 0.03
        y = float(_joint(f'{side}_wheel_joint').find('origin').get('xyz').split()[1])
        assert y == pytest.approx(sign * 0.0565)


def _solid_inertia(geometry, mass):
    box, cyl = geometry.find('box'), geometry.find('cylinder')
    if box is not None:
        x, y, z = map(float, box.get('size').split())
        return np.array([y * y + z * z, x * x + z * z, x * x + y * y]) * mass / 12
    r, h = float(cyl.get('radius')), float(cyl.get('length'))
    side = mass * (3 * r * r + h * h) / 12
    return np.array([side, mass * r * r / 2, side])  # our cylinders lie along y


@pytest.mark.parametrize('link', [link for link in ROOT.findall('link')],
                         ids=lambda link: link.get('name'))
def test_inertia_is_physical_and_matches_the_shape(link):
    inertial = link.find('inertial')
    assert inertial is not None, 'PyBullet gives a link without <inertial> a mass of 1 kg'
    mass = float(inertial.find('mass').get('value'))
    i = inertial.find('inertia')
    diag = np.array([float(i.get(k)) for k in ('ixx', 'iyy', 'izz')])
    assert mass > 0 and (diag > 0).all()
    assert all(float(i.get(k)) == 0.0 for k in ('ixy', 'ixz', 'iyz'))
    # Triangle inequality of principal moments.
    assert diag[0] + diag[1] >= diag[2] and diag[1] + diag[2] >= diag[0]
    assert diag[0] + diag[2] >= diag[1]
    geometry = link.find('visual/geometry')
    if geometry is not None and mass > 1e-3:
        assert diag == pytest.approx(_solid_inertia(geometry, mass), rel=0.01)


def test_total_mass_is_that_of_a_small_robot():
    total = sum(float(m.get('value')) for m in ROOT.iter('mass'))
    assert 0.2 < total < 1.0


def test_pybullet_loads_it_with_the_files_inertia():
    cid = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(str(URDF), flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
                                 physicsClientId=cid)
        masses = [pybullet.getDynamicsInfo(body, j, physicsClientId=cid)[0]
                  for j in range(-1, pybullet.getNumJoints(body, physicsClientId=cid))]
        expected = sum(float(m.get('value')) for m in ROOT.iter('mass'))
        assert sum(masses) == pytest.approx(expected, rel=1e-6)
        inertia = pybullet.getDynamicsInfo(body, -1, physicsClientId=cid)[2]
        declared = ROOT.find("link[@name='base_link']/inertial/inertia")
        assert inertia == pytest.approx([float(declared.get(k)) for k in ('ixx', 'iyy', 'izz')],
                                        rel=1e-6)
    finally:
        pybullet.disconnect(cid)


def test_pinocchio_loads_it():
    pin = pytest.importorskip('pinocchio')
    # A mobile base: a free-flyer root, so base_link's own mass is part of the model.
    model = pin.buildModelFromUrdf(str(URDF), pin.JointModelFreeFlyer())
    names = [model.names[i] for i in range(1, model.njoints)]
    assert sorted(names) == ['caster_swivel_joint', 'caster_wheel_joint', 'left_wheel_joint',
                             'right_wheel_joint', 'root_joint']
    data = model.createData()
    total = pin.computeTotalMass(model, data)
    assert total == pytest.approx(sum(float(m.get('value')) for m in ROOT.iter('mass')))
    assert model.existFrame('camera_optical_frame')
