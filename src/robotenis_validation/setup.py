from setuptools import find_packages, setup

package_name = 'robotenis_validation'

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
    description="The papers' studies and everything scored against the simulator's truth.",
    license='Apache-2.0',
    # Declaring pytest makes colcon test run pytest; without it unittest runs and finds 0 tests.
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'demo = robotenis_validation.demo:main',
            'report = robotenis_validation.report:main',
        ],
    },
)
