"""The code outside the packages (benchmarks, system tests, tools) in the packages' ROS style."""
import os

from ament_flake8.main import main_with_errors
from ament_pep257.main import main as pep257
import pytest

TOP = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDERS = [os.path.join(TOP, name) for name in ('benchmarks', 'test', 'tools')]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    rc, errors = main_with_errors(argv=FOLDERS)
    assert rc == 0, f'{len(errors)} code style errors or warnings:\n' + '\n'.join(errors)


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    assert pep257(argv=FOLDERS) == 0, 'docstring style errors: see the output above'
