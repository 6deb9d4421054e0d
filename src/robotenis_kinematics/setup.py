from glob import glob

from setuptools import find_packages, setup

package_name = 'robotenis_kinematics'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='RoboTenis maintainers',
    maintainer_email='maintainers@robotenis.org',
    description=("Delta robot kinematics in the calibration paper's notation, the robot"
                 ' description, and the identification core (eqs. 1-8).'),
    license='Apache-2.0',
    # Declaring pytest makes colcon test run pytest; without it unittest runs and finds 0 tests.
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'fk = robotenis_kinematics.fk_cli:main',
        ],
    },
)
