from glob import glob

from setuptools import find_packages, setup

package_name = 'robotenis_vision'

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
    description='Measuring the calibration sphere from hand-camera images (paper section 5) '
                'and the sphere_detector node.',
    license='Apache-2.0',
    # Declaring pytest makes colcon test run pytest; without it unittest runs and finds 0 tests.
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'sphere_detector = robotenis_vision.sphere_detector_node:main',
            'detect = robotenis_vision.detect_cli:main',
        ],
    },
)
