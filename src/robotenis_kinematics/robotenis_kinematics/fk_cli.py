"""
`./robotenis fk --model FILE`: resolver readings on stdin to effector positions on stdout.

Input: CSV rows ``Theta1,Theta2,Theta3`` (rad, increments from home), in the order the robot
visited them (effects such as backlash depend on that order); blank lines and lines starting with
'#' are skipped. Output: one ``x,y,z`` row (m, base frame) per input row, applying everything the
model file holds: its geometry and its effects.
"""
import argparse
import sys

import numpy as np

from robotenis_kinematics import delta, description, effects


def parse_rows(lines):
    """(N, 3) readings from CSV lines; ValueError names the first bad line."""
    rows = []
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text or text.startswith('#'):
            continue
        fields = text.split(',')
        try:
            values = [float(f) for f in fields]
        except ValueError:
            raise ValueError(f'line {number}: not three numbers: {text!r}') from None
        if len(values) != 3 or not np.all(np.isfinite(values)):
            raise ValueError(f'line {number}: expected three finite numbers, got {text!r}')
        rows.append(values)
    return np.array(rows, dtype=float).reshape(-1, 3)


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis fk', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--model', required=True,
                        help='robot description YAML (nominal or calibrated)')
    args = parser.parse_args(argv)
    try:
        desc = description.load(args.model)
        Theta = parse_rows(sys.stdin)
        P = delta.forward(desc, effects.joint_angles(desc, Theta))
    except (description.DescriptionError, ValueError) as e:
        print(f'robotenis fk: {e}', file=sys.stderr)
        return 2
    for x, y, z in P:
        sys.stdout.write(f'{x:.9f},{y:.9f},{z:.9f}\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
