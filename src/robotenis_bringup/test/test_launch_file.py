"""The launch file reader on files written here: arguments, includes, conditions, substitutions."""
import textwrap

import pytest
from robotenis_bringup import launch_file
from robotenis_bringup.launch_file import LaunchFileError


def write(folder, name, text):
    path = folder / name
    path.write_text(textwrap.dedent(text))
    return path


@pytest.fixture
def files(tmp_path, monkeypatch):
    monkeypatch.setenv('ROBOTENIS_TEST_VALUE', 'from-env')
    write(tmp_path, 'inner.launch.yaml', """
        launch:
        - arg: {name: rate, default: '100.0'}
        - arg: {name: fast, default: 'false'}
        - arg: {name: ns, default: ''}
        - node:
            pkg: p
            exec: e
            name: inner
            namespace: $(var ns)
            param:
            - from: $(dirname)/p.yaml
            - {name: rate, value: $(var rate)}
            - {name: count, value: 4}
            - {name: quoted, value: '4.0'}
            - {name: fast, value: $(var fast)}
            - {name: guess, value: [0.5, '$(var rate)']}
            - {name: label, value: $(env ROBOTENIS_TEST_VALUE)}
            remap:
            - {from: a, to: b}
        - node: {pkg: p, exec: slow, if: $(var fast), unless: 'false'}
        """)
    return write(tmp_path, 'outer.launch.yaml', """
        launch:
        - arg: {name: fast, default: 'true', description: go fast}
        - let: {name: rate, value: '250.0'}
        - include:
            file: $(dirname)/inner.launch.yaml
            arg:
            - {name: rate, value: $(var rate)}
            - {name: fast, value: $(var fast)}
        - node: {pkg: q, exec: other, unless: $(var fast), param: [{name: ns, value: $(var ns)}]}
        """)


def test_arguments_includes_conditions_and_typed_values(files):
    inner, slow = launch_file.load(files)
    assert (inner.name, inner.package, inner.executable) == ('inner', 'p', 'e')
    assert inner.namespace == ''
    assert inner.parameters == {'rate': 250.0, 'count': 4, 'quoted': '4.0', 'fast': True,
                                'guess': [0.5, 250.0], 'label': 'from-env'}
    assert inner.param_files == [str(files.parent / 'p.yaml')] and inner.remaps == [('a', 'b')]
    assert slow.name == 'slow'                       # no name: the executable's
    nodes = launch_file.load(files, {'fast': 'false', 'ns': 'robot1'})
    assert [n.name for n in nodes] == ['inner', 'other']
    assert nodes[0].namespace == 'robot1' and nodes[0].parameters['fast'] is False
    # arguments are global, as in Jazzy: the included file's ns is seen after the include
    assert nodes[1].parameters == {'ns': 'robot1'}
    assert launch_file.arguments(files) == [('fast', 'true', 'go fast')]


def test_the_command_line_of_a_node():
    node = launch_file.NodeSpec('n', 'p', 'e', 'robot1', ['/f.yaml'], {'s': '', 'x': 1.0},
                                [('a', 'b')])
    assert node.command('/ws/install') == [
        '/ws/install/p/lib/p/e', '--ros-args', '-r', '__node:=n', '-r', '__ns:=/robot1',
        '--params-file', '/f.yaml', '-p', "s:=''", '-p', 'x:=1.0', '-r', 'a:=b']


@pytest.mark.parametrize('text, message', [
    ('launch:\n- arg: {name: x}\n', "'x' is required"),
    ('launch:\n- node: {pkg: p, exec: e, params: []}\n', 'node has no key params'),
    ('launch:\n- group: {}\n', "'group' is not one of"),
    ('launch:\n- node: {pkg: p, exec: e, name: $(var nope)}\n', r'\$\(var nope\) is not'),
    ('launch:\n- node: {pkg: p, exec: e, if: maybe}\n', 'if must be true or false'),
    ('launch:\n- node: {pkg: p, exec: e, name: $(command ls)}\n', 'unknown substitution'),
    ('launch:\n- node: {exec: e}\n', "node without 'pkg'"),
    ('nodes: []\n', 'expected a map with a "launch" list'),
])
def test_what_cannot_be_read_is_named(tmp_path, text, message):
    path = write(tmp_path, 'bad.launch.yaml', text)
    with pytest.raises(LaunchFileError, match=message):
        launch_file.load(path)


def test_an_argument_the_file_does_not_declare_is_refused(files):
    with pytest.raises(LaunchFileError, match='no launch argument speed'):
        launch_file.load(files, {'speed': '2'})
    assert launch_file.load(files, {'rate': '1.0'})   # declared by the included file
