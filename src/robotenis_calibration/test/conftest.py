import os

import pytest

from robotenis_kinematics import description


@pytest.fixture
def nominal():
    return description.nominal()


@pytest.fixture
def table1():
    """Table 1's calibrated column (the kinematics package's test geometry)."""
    here = os.path.dirname(os.path.abspath(__file__))
    return description.load(os.path.join(here, '..', '..', 'robotenis_kinematics', 'test', 'table1_calibrated.yaml'))
