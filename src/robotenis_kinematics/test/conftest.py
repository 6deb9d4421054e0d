import os

import pytest

from robotenis_kinematics import description

HERE = os.path.dirname(os.path.abspath(__file__))


@pytest.fixture
def nominal():
    return description.nominal()


@pytest.fixture
def table1():
    """Table 1's calibrated column: a known geometry to generate data from and score against."""
    return description.load(description.config_path('table1_calibrated.yaml'))
