import pytest
from robotenis_kinematics import description


@pytest.fixture
def nominal():
    return description.nominal()


@pytest.fixture
def table1():
    """Table 1's calibrated column: the simulator's default geometry."""
    return description.load(description.config_path('table1_calibrated.yaml'))
