"""
ROS 2 YAML launch files, read as ``ros2 launch`` reads them, into the node processes to start.

``ros2 launch`` is not among the ROS 2 wheels on PyPI, so this module reads the same files for
``./robotenis launch``: one description of the system for both kinds of user. It reads the part of
the launch_yaml format that this project's launch files use, and refuses anything else by name:

* ``arg`` (``name``, ``default``, ``description``), ``let`` (``name``, ``value``);
* ``include`` (``file``, ``arg``: a list of ``name``/``value``). Launch arguments are global, as
  in Jazzy's launch: the command line sets them first, an ``arg`` gives its default only to one not
  set yet, an include sets those it passes before reading its file, and what the included file sets
  stays set after it;
* ``node`` (``pkg``, ``exec``, ``name``, ``namespace``, ``param``: ``name``/``value`` pairs or
  ``from`` a parameter file, ``remap``: ``from``/``to`` pairs, ``output`` is accepted and ignored);
* ``if`` / ``unless`` on any of them ("true", "false", "1" or "0" once substituted);
* substitutions ``$(var NAME)``, ``$(find-pkg-share PACKAGE)``, ``$(env NAME [DEFAULT])`` and
  ``$(dirname)`` (the folder of the file being read).

A parameter value is typed as launch_ros types it: a YAML number, bool, string or list is taken
as it is (a quoted '4.0' stays a string), and text with a substitution is read as YAML once
substituted ("$(var rate)" giving 0.5 is a float, 4 an integer, true a bool, [1.0, 2.0] a list),
so a float parameter must be written 4.0, not 4. Unlike ros2 launch, which ignores them, an
argument given that no file declares is refused (a typo would otherwise go unnoticed).
"""
from dataclasses import dataclass, field
import os
import re

import yaml

SHARE = 'robotenis_bringup'
ENTITY_KEYS = {
    'arg': {'name', 'default', 'description'},
    'let': {'name', 'value'},
    'include': {'file', 'arg'},
    'node': {'pkg', 'exec', 'name', 'namespace', 'param', 'remap', 'output'},
}
CONDITIONS = {'if', 'unless'}
SUBSTITUTION = re.compile(r'\$\(([a-z-]+)((?:\s+[^()\s]+)*)\s*\)')


class LaunchFileError(ValueError):
    """A launch file that cannot be read; the message names the file and the entry."""


@dataclass
class NodeSpec:
    """One node process: package and executable, ROS name, parameters and remappings."""

    name: str
    package: str
    executable: str
    namespace: str = ''
    param_files: list = field(default_factory=list)
    parameters: dict = field(default_factory=dict)
    remaps: list = field(default_factory=list)

    def command(self, prefix):
        """Return the command line, the executable found under ``prefix`` as ros2 run finds it."""
        exe = os.path.join(prefix, self.package, 'lib', self.package, self.executable)
        args = [exe, '--ros-args', '-r', f'__node:={self.name}']
        if self.namespace:
            args += ['-r', f'__ns:=/{self.namespace.strip("/")}']
        for path in self.param_files:
            args += ['--params-file', path]
        for key, value in self.parameters.items():
            args += ['-p', f'{key}:={encode(value)}']
        for source, target in self.remaps:
            args += ['-r', f'{source}:={target}']
        return args


def encode(value):
    """Return a parameter value as the YAML text that ``--ros-args -p name:=TEXT`` reads."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10 ** 6)
    return text.strip().removesuffix('\n...').strip()


def share_directory(package):
    """Return the share folder of an installed package (ament index)."""
    from ament_index_python.packages import get_package_share_directory
    return get_package_share_directory(package)


def find(name):
    """Return the path of a launch file: ``name`` if it exists, else one of this package's."""
    if os.path.exists(name):
        return os.path.abspath(name)
    path = os.path.join(share_directory(SHARE), 'launch', name)
    if not os.path.exists(path):
        shipped = sorted(os.listdir(os.path.dirname(path)))
        raise LaunchFileError(f'no launch file {name!r} (shipped: {", ".join(shipped)})')
    return path


def load(path, args=None):
    """
    Read a launch file with launch arguments ``args`` ({name: text}); return its nodes.

    Raises
    ------
    LaunchFileError
        naming the file and the entry that cannot be read, a required argument not given, or an
        argument given that the file does not declare.

    """
    given = {k: str(v) for k, v in (args or {}).items()}
    context = {'file': os.path.abspath(path), 'vars': dict(given), 'declared': set()}
    nodes = _read(context)
    unknown = sorted(set(given) - context['declared'])
    if unknown:
        raise LaunchFileError(f'{path}: no launch argument {", ".join(unknown)} '
                              f'(declared: {", ".join(sorted(context["declared"]))})')
    return nodes


def override(nodes, parameters):
    """Set parameters {node name: {name: value}} of the nodes loaded, over the launch file's."""
    for node in nodes:
        node.parameters.update(parameters.get(node.name, {}))


def arguments(path):
    """Return the (name, default, description) of the arguments a launch file declares."""
    return [(e['arg']['name'], e['arg'].get('default'), e['arg'].get('description', ''))
            for e in _entities(os.path.abspath(path)) if 'arg' in e]


def _entities(path):
    try:
        with open(path) as f:
            data = yaml.safe_load(f)
    except (OSError, yaml.YAMLError) as e:
        raise LaunchFileError(f'{path}: {e}') from None
    if not isinstance(data, dict) or not isinstance(data.get('launch'), list):
        raise LaunchFileError(f'{path}: expected a map with a "launch" list')
    return data['launch']


def _read(context):
    nodes = []
    for i, entity in enumerate(_entities(context['file'])):
        where = f'{context["file"]}: launch[{i}]'
        kind, body = _entity(entity, where)
        if not _active(body, context, where):
            continue
        if kind == 'arg':
            _declare(body, context, where)
        elif kind == 'let':
            context['vars'][body['name']] = _text(body['value'], context, where)
        elif kind == 'include':
            nodes += _include(body, context, where)
        else:
            nodes.append(_node(body, context, where))
    return nodes


def _entity(entity, where):
    """(kind, body) of one launch entry, its keys checked."""
    if not isinstance(entity, dict) or len(entity) != 1:
        raise LaunchFileError(f'{where}: expected one of {", ".join(ENTITY_KEYS)}')
    (kind, body), = entity.items()
    if kind not in ENTITY_KEYS or not isinstance(body, dict):
        raise LaunchFileError(f'{where}: {kind!r} is not one of {", ".join(ENTITY_KEYS)}')
    unknown = set(body) - ENTITY_KEYS[kind] - CONDITIONS
    if unknown:
        raise LaunchFileError(f'{where}: {kind} has no key {", ".join(sorted(unknown))}')
    return kind, body


def _active(body, context, where):
    """Whether an entry's ``if`` / ``unless`` condition lets it run."""
    active = True
    for key, wanted in (('if', True), ('unless', False)):
        if key in body:
            text = _text(body[key], context, where).strip().lower()
            if text not in ('true', 'false', '1', '0'):
                raise LaunchFileError(f'{where}: {key} must be true or false, got {text!r}')
            active = active and (text in ('true', '1')) == wanted
    return active


def _declare(body, context, where):
    name = body.get('name')
    context['declared'].add(name)
    if name not in context['vars']:
        if 'default' not in body:
            raise LaunchFileError(f'{where}: launch argument {name!r} is required '
                                  f'(give {name}:=...)')
        context['vars'][name] = _text(body['default'], context, where)


def _include(body, context, where):
    path = _text(body['file'], context, where)
    passed = {a['name']: _text(a['value'], context, where) for a in body.get('arg') or []}
    if not os.path.exists(path):
        raise LaunchFileError(f'{where}: included file {path} does not exist')
    context['vars'].update(passed)
    inner = {**context, 'file': os.path.abspath(path)}     # the same arguments and declarations
    return _read(inner)


def _node(body, context, where):
    for key in ('pkg', 'exec'):
        if key not in body:
            raise LaunchFileError(f'{where}: node without {key!r}')
    spec = NodeSpec(name=_text(body.get('name', body['exec']), context, where),
                    package=_text(body['pkg'], context, where),
                    executable=_text(body['exec'], context, where),
                    namespace=_text(body.get('namespace', ''), context, where))
    for item in body.get('param') or []:
        if 'from' in item:
            spec.param_files.append(_text(item['from'], context, where))
        elif 'name' in item and 'value' in item:
            spec.parameters[item['name']] = _typed(item['value'], context, where)
        else:
            raise LaunchFileError(f'{where}: a param needs name and value, or from')
    for item in body.get('remap') or []:
        spec.remaps.append((_text(item['from'], context, where),
                            _text(item['to'], context, where)))
    return spec


def _typed(value, context, where):
    """Return a parameter value typed as launch_ros types it (see the module docstring)."""
    if isinstance(value, list):
        return [_typed(v, context, where) for v in value]
    if not isinstance(value, str) or not SUBSTITUTION.search(value):
        return value
    text = _text(value, context, where)
    try:
        typed = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    return text if typed is None or isinstance(typed, dict) else typed


def _text(value, context, where):
    """Return a value with its substitutions replaced, as text."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    text = str(value)

    def replace(match):
        kind, words = match.group(1), match.group(2).split()
        if kind == 'var' and len(words) == 1:
            if words[0] not in context['vars']:
                raise LaunchFileError(f'{where}: $(var {words[0]}) is not a launch argument')
            return context['vars'][words[0]]
        if kind == 'find-pkg-share' and len(words) == 1:
            return share_directory(words[0])
        if kind == 'env' and len(words) in (1, 2):
            return os.environ.get(words[0], words[1] if len(words) == 2 else '')
        if kind == 'dirname' and not words:
            return os.path.dirname(context['file'])
        raise LaunchFileError(f'{where}: unknown substitution {match.group(0)}')
    return SUBSTITUTION.sub(replace, text)
