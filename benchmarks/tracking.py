"""
Benchmark: the tracking tests of section 6.2.2 (Table 5) in simulation, and a baseline.

Runs robotenis_validation.tracking_study (10 tests of 5,000 camera samples per maximum ball speed,
nominal against calibrated description; ``--quick``: 2 tests of 1,000) and prints Table 5's layout
with our numbers beside the paper's. Baseline, same process: the same law without the Kalman
velocity feedforward v_p (pure proportional u_r = -K_p e_r), on 2 tests of 1,000 samples
(``--full-baseline``: as many as the study). Also prints how fast the simulation ran (robot-seconds
per wall second).

``--ros``: the same tests through the ROS nodes instead (robotenis_validation.live_tracking: the
nodes as processes on simulated time, ``--seconds`` counted per speed, default 0.5 and 1.5 m/s),
each beside what tracking_study predicts for that speed, ball and description, computed in this
process: with Table 2's detection noise, and with the live detector's bias and noise. About 3.5
wall seconds per simulated second on 2 cores, plus 20 s per speed for the study (the defaults:
4 minutes).
"""
import argparse
import sys

from robotenis_validation import tracking_setup as tsetup
from robotenis_validation import tracking_study as ts


def robot_seconds(table):
    """Sum the simulated robot time behind a table (s): every run, segment and warm-up included."""
    count, length = tsetup.segments(table.samples, table.setup)
    frames = table.setup.warmup_frames + length + table.setup.latency_frames + 1
    return (len(table.labels) * len(table.speeds) * table.tests * count * frames
            * table.setup.frame_period)


def speed_line(name, table):
    seconds = robot_seconds(table)
    return (f'{name}: {table.wall_time:.1f} s wall for {seconds:.0f} robot-seconds at 1 kHz '
            f'({seconds / table.wall_time:.1f} robot-seconds per second)')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='2 tests of 1,000 samples per speed')
    parser.add_argument('--full-baseline', action='store_true',
                        help='the baseline as large as the study')
    parser.add_argument('--ros', action='store_true',
                        help='through the ROS nodes, beside the study')
    parser.add_argument('--speeds', type=float, nargs='+', default=[0.5, 1.5],
                        help='with --ros: top ball speeds (m/s)')
    parser.add_argument('--seconds', type=float, default=20.0,
                        help='with --ros: simulated seconds counted per speed')
    args = parser.parse_args(argv)
    if args.ros:
        from robotenis_validation import live_tracking
        print('\n'.join(live_tracking.report(args.speeds, args.seconds)))
        return 0
    study = ts.run(quick=args.quick)
    size = ({} if args.full_baseline
            else {'tests': tsetup.QUICK_TESTS, 'samples': tsetup.QUICK_SAMPLES})
    baseline = ts.run(quick=args.quick, setup=tsetup.Setup(feedforward=False), **size)
    print('\n'.join(ts.table_lines(study)))
    print()
    print('baseline, same process: pure proportional u_r = -K_p e_r (no v_p)')
    print('\n'.join(ts.table_lines(baseline)))
    print()
    for name, table in (('study', study), ('baseline', baseline)):
        print(speed_line(name, table))
    return 0


if __name__ == '__main__':
    sys.exit(main())
