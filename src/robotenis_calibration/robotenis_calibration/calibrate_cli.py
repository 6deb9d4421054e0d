"""
`./robotenis calibrate`: calibrate offline from a bag, or call the running calibration service.

    ./robotenis calibrate BAG_DIR --out RESULT.yaml [--settle S]
        any rosbag2 bag with /robot_description, /joint_states and /sphere/position (rests between
        /calibration/rest markers, or found from the joint states; S: seconds skipped at the start
        of each rest found that way, default 0.5)
    ./robotenis calibrate --call [--poses N] [--frames N] [--settle S] [--seed N]
                                 [--selection boundary|optimal] [--bag PATH] [--namespace NS]
        calls the calibration service of a running system (0 or absent: the service's defaults)
"""
import argparse
import dataclasses
import sys

from robotenis_calibration import pipeline, rests, result


def offline(args):
    """Calibrate from a bag; exit status 0 on success, 1 with the reason on stderr otherwise."""
    params = rests.RestParameters() if args.settle is None else \
        dataclasses.replace(rests.RestParameters(), settle=args.settle)
    try:
        outcome = pipeline.calibrate_bag(
            args.bag_dir, args.out, args.holdout, args.seed, params,
            progress=lambda text: print(f'[calibrate] {text}', file=sys.stderr),
            detector_floor=tuple(args.detector_floor))
    except (pipeline.CalibrationError, ValueError) as e:
        print(f'robotenis calibrate: {e} ({args.out} not written)', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f'robotenis calibrate: interrupted ({args.out} not written)', file=sys.stderr)
        return 130
    for line in result.summary(outcome.diagnosis):
        print(line)
    print(f'wrote {outcome.result_path} and {outcome.plot_path}')
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis calibrate', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag_dir', nargs='?', help='a rosbag2 bag directory (offline calibration)')
    parser.add_argument('--out', help='RESULT.yaml to write (offline)')
    parser.add_argument('--holdout', type=float, default=0.3,
                        help='share of poses held out (default 0.3)')
    parser.add_argument('--seed', type=int, default=0,
                        help='random seed (split; pose selection with --call)')
    parser.add_argument('--settle', type=float, default=None,
                        help='s: settle time (--call) or margin skipped at the start of rests'
                             ' found without markers')
    parser.add_argument('--detector-floor', type=float, nargs=2, default=(0.0, 0.0),
                        metavar=('LATERAL', 'DEPTH'),
                        help="the detector's systematic error, fractions of the range"
                             " (this project's: 5e-4 3e-3)")
    parser.add_argument('--call', action='store_true',
                        help='call the calibrate service of a running system')
    parser.add_argument('--poses', type=int, default=0)
    parser.add_argument('--frames', type=int, default=0)
    parser.add_argument('--selection', default='boundary', choices=('boundary', 'optimal'))
    parser.add_argument('--bag', default='',
                        help='bag path for the recorded session (with --call)')
    parser.add_argument('--namespace', default='', help="the system's namespace (with --call)")
    args = parser.parse_args(argv)
    if args.call:
        from robotenis_calibration import service_client
        return service_client.call(args)
    if not args.bag_dir or not args.out:
        parser.error('offline calibration needs BAG_DIR and --out RESULT.yaml (or use --call)')
    if not 0.0 < args.holdout < 1.0:
        parser.error(f'--holdout must be between 0 and 1, got {args.holdout}')
    if args.settle is not None and args.settle < 0:
        parser.error(f'--settle must not be negative, got {args.settle}')
    return offline(args)


if __name__ == '__main__':
    sys.exit(main())
