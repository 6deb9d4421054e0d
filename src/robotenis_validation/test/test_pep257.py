# The package's docstrings, as ros2/examples checks them (ament_pep257's ROS convention).
from ament_pep257.main import main
import pytest


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    assert main(argv=['.', 'test']) == 0, 'docstring style errors: see the output above'
