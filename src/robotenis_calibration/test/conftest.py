import os
import random

import pytest

from robotenis_kinematics import description


@pytest.fixture
def nominal():
    return description.nominal()


@pytest.fixture
def table1():
    """Table 1's calibrated column (the kinematics package's test geometry)."""
    return description.load(description.config_path('table1_calibrated.yaml'))


@pytest.fixture
def console_script():
    """
    Return the installed path of this package's console script ``name``.

    The test is skipped when the workspace is not built.
    """
    here = os.path.dirname(os.path.realpath(__file__))
    top = os.path.abspath(os.path.join(here, '..', '..', '..'))

    def path(name):
        exe = os.path.join(top, 'install', 'robotenis_calibration', 'lib', 'robotenis_calibration',
                           name)
        if not os.path.exists(exe):
            pytest.skip(f'{exe} is not installed (./robotenis setup)')
        return exe
    return path


@pytest.fixture
def ros_env(monkeypatch):
    """
    Give the test a ROS domain of its own (random id, localhost only).

    The domain serves this process's rclpy and the node processes it starts; the fixture returns
    the environment to start them with.
    """
    monkeypatch.setenv('ROS_DOMAIN_ID', str(random.randint(1, 200)))
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return dict(os.environ)
