"""
``./robotenis launch``: start a ROS 2 YAML launch file's nodes, one process each.

    ./robotenis launch [FILE] [NAME:=VALUE ...] [--truth F] [--description F] [--sim-time]

FILE is a launch file, or the name of one of robotenis_bringup's (default calibration.launch.yaml:
the simulated robot, the detector, the controller and the calibration service). NAME:=VALUE sets
a launch argument, as ``ros2 launch`` takes them; ``--show-args`` lists them. The options are
shorthands: ``--truth F`` is truth_path:=F, ``--description F`` description_path:=F,
``--sim-time`` sim_time:=true. Node logs go to log/launch/. Exits 0 after Ctrl-C or SIGTERM
when every node ran until then and exited cleanly; 1, naming each, if a node died or exited
non-zero when stopped.
"""
import argparse
import os
import shlex
import sys

from robotenis_bringup import launch_file
from robotenis_bringup.launcher import Launcher

DEFAULT_FILE = 'calibration.launch.yaml'


def parse(argv):
    parser = argparse.ArgumentParser(prog='robotenis launch', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('items', nargs='*', metavar='FILE | NAME:=VALUE')
    parser.add_argument('--truth', help="the simulator's truth file (truth_path:=F)")
    parser.add_argument('--description', help='the robot description the system uses')
    parser.add_argument('--sim-time', action='store_true',
                        help='run on the simulator clock (/clock), simulator and controller '
                             'in lockstep')
    parser.add_argument('--show-args', action='store_true', help="list the file's arguments")
    parser.add_argument('--print', action='store_true', help='print the node commands, start none')
    args = parser.parse_args(argv)
    files = [i for i in args.items if ':=' not in i]
    if len(files) > 1:
        parser.error(f'one launch file at most, got {", ".join(files)}')
    values = dict(i.split(':=', 1) for i in args.items if ':=' in i)
    for key, given in (('truth_path', args.truth), ('description_path', args.description)):
        if given:
            values[key] = os.path.abspath(given)
    if args.sim_time:
        values['sim_time'] = 'true'
    return args, (files or [DEFAULT_FILE])[0], values


def main(argv=None):
    args, name, values = parse(argv)
    top = os.environ.get('ROBOTENIS_TOP', os.getcwd())
    try:
        path = launch_file.find(name)
        if args.show_args:
            for arg, default, text in launch_file.arguments(path):
                print(f"'{arg}': {text}\n    (default: {default!r})")
            return 0
        nodes = launch_file.load(path, values)
    except launch_file.LaunchFileError as e:
        print(f'robotenis launch: {e}', file=sys.stderr)
        return 2
    prefix = os.path.join(top, 'install')
    if args.print:
        for node in nodes:
            print(shlex.join(node.command(prefix)))
        return 0
    launcher = Launcher(nodes, prefix, os.path.join(top, 'log', 'launch'))
    try:
        launcher.start()
    except FileNotFoundError as e:
        print(f'robotenis launch: {e}', file=sys.stderr)
        return 2
    launcher.wait()
    if launcher.failures:
        print(f'robotenis launch: {"; ".join(launcher.failures)}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
