from setuptools import find_packages, setup

package_name = 'robotenis_calibration'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='RoboTenis maintainers',
    maintainer_email='maintainers@robotenis.org',
    description=('The calibration service, rosbag2 sessions, and the residual loop that finds'
                 ' what the model lacks.'),
    license='Apache-2.0',
    # Declaring pytest makes colcon test run pytest; without it unittest runs and finds 0 tests.
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'calibrate = robotenis_calibration.calibrate_cli:main',
            'replay = robotenis_calibration.replay:main',
            'calibration = robotenis_calibration.calibration_node:main',
        ],
    },
)
