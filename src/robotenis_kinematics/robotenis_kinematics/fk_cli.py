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
    """Return the readings (N, 3) of CSV lines and their line numbers; ValueError if one is bad."""
    rows, numbers = [], []
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
        numbers.append(number)
    return np.array(rows, dtype=float).reshape(-1, 3), numbers


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis fk', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--model', required=True,
                        help='robot description YAML (nominal or calibrated)')
    args = parser.parse_args(argv)
    try:
        desc = description.load(args.model)
        Theta, lines = parse_rows(sys.stdin)
    except (description.DescriptionError, ValueError) as e:
        print(f'robotenis fk: {e}', file=sys.stderr)
        return 2
    P = positions(desc, Theta)
    for x, y, z in P:
        sys.stdout.write(f'{x:.9f},{y:.9f},{z:.9f}\n')
    failed = [str(n) for n, p in zip(lines, P) if not np.all(np.isfinite(p))]
    if failed:
        print(f'robotenis fk: no forward kinematics for line(s) {", ".join(failed)} (the '
              'forearms cannot close at those readings): printed as nan', file=sys.stderr)
        return 1
    return 0


def positions(desc, Theta):
    """Return where the effector is, (N, 3), for readings in visit order; NaN where FK has none."""
    try:
        return delta.forward(desc, effects.joint_angles(desc, Theta))
    except ValueError:
        pass
    # some rows have no assembly: solve them one by one, each after the rows visited before it
    # (its motion direction)
    out = np.full((len(Theta), 3), np.nan)
    for k in range(len(Theta)):
        try:
            out[k] = delta.forward(desc, effects.joint_angles(desc, Theta[:k + 1])[-1])
        except ValueError:
            pass
    return out


if __name__ == '__main__':
    sys.exit(main())
