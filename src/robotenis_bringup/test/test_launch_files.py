"""
Every shipped launch file and parameter file names nodes and parameters that exist.

A node's parameters are those of its module's table (``PARAMETERS``, robotenis_ros.node), found
through the package's console script; a value must have the declared type (rclpy refuses an
integer for a float parameter at start-up, and so would the node).
"""
import glob
import importlib
from importlib import metadata
import os

import pytest
from robotenis_bringup import launch_file
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
LAUNCH_FILES = sorted(glob.glob(os.path.join(HERE, '..', 'launch', '*.launch.yaml')))
PARAM_FILES = sorted(glob.glob(os.path.join(HERE, '..', 'config', '*.params.yaml')))
BUILT_IN = {'use_sim_time': (False, 'every node')}
ARGUMENTS = [{}, {'sim_time': 'true'}, {'namespace': 'robot1'}, {'sim': 'false'}]


def table(package, executable):
    """Return the parameter table of the node module behind a package's console script."""
    scripts = {e.name: e.value for e in metadata.distribution(package).entry_points
               if e.group == 'console_scripts'}
    assert executable in scripts, f'{package} has no console script {executable!r}'
    module = importlib.import_module(scripts[executable].split(':')[0])
    return {**BUILT_IN, **module.PARAMETERS}


def same_type(value, default):
    """Whether rclpy would take ``value`` for a parameter declared with ``default``."""
    if isinstance(default, list):
        return isinstance(value, list) and all(same_type(v, default[0]) for v in value)
    if isinstance(default, (bool, float, str)):
        return type(value) is type(default)
    return isinstance(default, int) and type(value) is int


def check(node_name, parameters, known, where):
    for name, value in parameters.items():
        assert name in known, f'{where}: {node_name} has no parameter {name!r}'
        assert same_type(value, known[name][0]), \
            f'{where}: {node_name}.{name} = {value!r}, declared as {known[name][0]!r}'


def loadable(path):
    """Return the argument sets among ARGUMENTS that a launch file accepts."""
    names = {a for a, _, _ in launch_file.arguments(path)}
    return [args for args in ARGUMENTS if set(args) <= names]


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=os.path.basename)
def test_every_node_and_parameter_of_a_launch_file_exists(path):
    for args in loadable(path):
        nodes = launch_file.load(path, args)
        assert nodes, f'{path} {args}: starts no node'
        for node in nodes:
            check(node.name, node.parameters, table(node.package, node.executable),
                  f'{os.path.basename(path)} {args}')
            for file in node.param_files:
                assert os.path.exists(file), f'{path}: {node.name} reads {file}, not there'
            if args.get('namespace'):
                assert node.namespace == args['namespace']


@pytest.mark.parametrize('path', PARAM_FILES, ids=os.path.basename)
def test_every_parameter_file_names_nodes_that_exist_and_their_parameters(path):
    nodes = {n.name: n for f in LAUNCH_FILES for n in launch_file.load(f, loadable(f)[0])}
    with open(path) as f:
        data = yaml.safe_load(f)
    for key, section in data.items():
        name = key.split('/')[-1]
        assert key in (name, f'/{name}', f'/**/{name}'), f'{path}: unexpected node key {key!r}'
        assert name in nodes, f'{path}: no launch file starts a node {name!r}'
        check(name, section['ros__parameters'], table(nodes[name].package, nodes[name].executable),
              os.path.basename(path))


def test_the_product_nodes_carry_no_simulator_fact():
    """The ball's position reaches the calibration node from the launch configuration only."""
    known = table('robotenis_calibration', 'calibration')
    guess = known['sphere_guess'][0]
    assert all(v != v for v in guess), f'sphere_guess defaults to {guess}, a position'


def test_sim_time_puts_the_simulator_and_the_visual_loop_in_lockstep():
    path = launch_file.find('tracking.launch.yaml')
    nodes = {n.name: n.parameters for n in launch_file.load(path, {'sim_time': 'true'})}
    assert nodes['sim_motors']['lockstep'] is True and nodes['hand_camera']['tick_on_effector']
    assert nodes['motion_controller']['tick_on_joint_states'] is True
    assert nodes['sim_motors']['camera_rate'] == 120.0
    # the tracking loop at real time at most, as the ball flies; a session as fast as it can
    assert nodes['sim_motors']['speed'] == 1.0
    calibration = {n.name: n.parameters
                   for n in launch_file.load(launch_file.find('calibration.launch.yaml'),
                                             {'sim_time': 'true'})}
    assert 'pbvs_tracker' not in calibration and calibration['sim_motors']['camera_rate'] == 120.0
    assert calibration['sim_motors']['speed'] == 0.0
    # a calibration session waits for the detector at rest; the tracking loop for its commands
    assert calibration['sim_motors']['visual_answer'] == 'detection'
    assert calibration['sim_motors']['visual_rest_speed'] > 0
    # beside a busy process the detector's fits at rest answered later than 1 s of wall time
    assert calibration['sim_motors']['visual_timeout'] >= 5.0
    # the frames the simulator may run ahead at rest fit in the detector's queue
    ahead = calibration['sim_motors']['visual_delay'] * calibration['sim_motors']['camera_rate']
    assert calibration['sphere_detector']['image_queue'] > ahead
    samples_ahead = calibration['sim_motors']['visual_delay'] * 250      # 4 ms truth samples
    assert calibration['hand_camera']['effector_queue'] > samples_ahead
    assert nodes['hand_camera']['effector_queue'] == 10    # the tracking loop wants the newest
    assert nodes['sim_motors']['visual_answer'] == 'command'
    # the tracked ball stands still in the image: no slow fit at rest inside the 1/120 s loop
    assert nodes['sphere_detector']['rest_method'] == 'conic'
    assert nodes['sphere_detector']['search_interval'] == 0.0  # a lost ball searched every frame
    assert nodes['sim_motors']['visual_timeout'] >= 1.0    # a stall of 0.14 s kept the loop
    real = launch_file.load(launch_file.find('calibration.launch.yaml'), {'sim': 'false'})
    assert {n.name for n in real} == {'sphere_detector', 'motion_controller', 'calibration'}


@pytest.mark.parametrize('argument, package, executable, parameter', [
    ('rest_method', 'robotenis_vision', 'sphere_detector', 'rest_method'),
    ('search_interval', 'robotenis_vision', 'sphere_detector', 'search_interval'),
    ('image_queue', 'robotenis_vision', 'sphere_detector', 'image_queue'),
    ('effector_queue', 'robotenis_sim', 'hand_camera', 'effector_queue'),
    ('visual_answer', 'robotenis_sim', 'sim_motors', 'visual_answer'),
    ('visual_delay', 'robotenis_sim', 'sim_motors', 'visual_delay'),
    ('visual_timeout', 'robotenis_sim', 'sim_motors', 'visual_timeout'),
    ('visual_rest_speed', 'robotenis_sim', 'sim_motors', 'visual_rest_speed')])
def test_arguments_passed_on_to_a_node_default_to_its_own(argument, package, executable,
                                                          parameter):
    """A launch argument that only passes a node parameter on must default to the node's."""
    own = table(package, executable)[parameter][0]
    for path in LAUNCH_FILES:
        defaults = {name: default for name, default, _ in launch_file.arguments(path)}
        if argument in defaults:
            assert yaml.safe_load(str(defaults[argument])) == own, f'{path}: {argument}'
