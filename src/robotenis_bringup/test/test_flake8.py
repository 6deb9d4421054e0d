# The package's code style, as ros2/examples checks it (ament_flake8's ROS configuration).
from ament_flake8.main import main_with_errors
import pytest


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    rc, errors = main_with_errors(argv=[])
    assert rc == 0, f'{len(errors)} code style errors or warnings:\n' + '\n'.join(errors)
