import math

import numpy as np
import pytest
from robotenis_kinematics import description
from robotenis_kinematics.description import DescriptionError
import yaml


def nominal_dict():
    with open(description.config_path('nominal.yaml')) as f:
        return yaml.safe_load(f)


def test_nominal_matches_table1_nominal_column(nominal):
    np.testing.assert_allclose(nominal.a, 0.5)
    np.testing.assert_allclose(nominal.b, 1.0)
    np.testing.assert_allclose(nominal.h, 0.05)
    np.testing.assert_allclose(nominal.H, 0.21)
    np.testing.assert_allclose(np.degrees(nominal.phi), [0, 120, 240])
    # The camera looks along base +x: its optical z axis is the third column.
    np.testing.assert_allclose(nominal.camera_rotation[:, 2], [1, 0, 0])


def test_round_trip(tmp_path, nominal):
    d = nominal.copy()
    d.a[1] = 0.5012
    path = tmp_path / 'robot.yaml'
    description.save(d, path)
    back = description.load(path)
    np.testing.assert_array_equal(back.a, d.a)
    np.testing.assert_array_equal(back.camera_rotation, d.camera_rotation)
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


@pytest.mark.parametrize('edit, key', [
    (lambda d: d.pop('legs'), 'legs: missing key'),
    (lambda d: d['legs'].pop(), 'legs: expected a list of three maps'),
    (lambda d: d['legs'][1].pop('theta0'), 'legs[1].theta0: missing key'),
    (lambda d: d['legs'][2].__setitem__('b', 'long'), 'legs[2].b: expected a number'),
    (lambda d: d['legs'][0].__setitem__('H', math.nan), 'legs[0].H: must be finite'),
    (lambda d: d['legs'][0].__setitem__('a', math.inf), 'legs[0].a: must be finite'),
    (lambda d: d['legs'][0].__setitem__('a', True), 'legs[0].a: expected a number'),
    (lambda d: d['camera'].pop('rotation'), 'camera.rotation: missing key'),
    (lambda d: d['camera'].__setitem__('rotation', [[1, 0, 0], [0, 1, 0]]),
     'camera.rotation: expected 3 rows'),
    (lambda d: d['camera'].__setitem__('rotation', [[2, 0, 0], [0, 1, 0], [0, 0, 1]]),
     'camera.rotation: not a rotation'),
    (lambda d: d['camera'].__setitem__('frame_id', 3), 'camera.frame_id'),
    (lambda d: d.__setitem__('sphere_radius', -0.01), 'sphere_radius: must be positive'),
    (lambda d: d.__setitem__('effects', [{'name': 'warp_drive'}]),
     "effects[0].name: unknown effect 'warp_drive'"),
])
def test_bad_descriptions_name_the_key(edit, key):
    data = nominal_dict()
    edit(data)
    with pytest.raises(DescriptionError, match=key.replace('[', r'\[').replace(']', r'\]')):
        description.from_dict(data)


def test_unreadable_file_is_named(tmp_path):
    bad = tmp_path / 'broken.yaml'
    bad.write_text('legs: [\n')
    with pytest.raises(DescriptionError, match='broken.yaml: not valid YAML'):
        description.load(bad)
    with pytest.raises(DescriptionError, match='cannot read'):
        description.load(tmp_path / 'missing.yaml')
