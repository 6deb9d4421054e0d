"""
`./robotenis calibrate`: calibrate offline from a bag, or call the running calibration service.

    ./robotenis calibrate BAG_DIR --out RESULT.yaml [--settle S] [--joints A,B,C] [--force]
        any rosbag2 bag (MCAP or SQLite) with /robot_description, /joint_states and
        /sphere/position (rests between /calibration/rest markers, or found from the joint
        states; S: seconds skipped at the start of each rest found that way, default: found from
        the data; A,B,C: the bag's names of the three joints, default motor_1,motor_2,motor_3).
        A result worse than the declared description on the held-out poses is refused unless
        --force; a failed or refused run never replaces an existing RESULT.yaml.
    ./robotenis calibrate --call [--poses N] [--frames N] [--settle S] [--seed N]
                                 [--selection boundary|optimal|discriminating] [--bag PATH]
                                 [--namespace NS]
        calls the calibration service of a running system (0 or absent: the service's defaults)
"""
import argparse
import dataclasses
import signal
import sys

from robotenis_calibration import pipeline, protocol, rests, result


def settings(args):
    """Return the pipeline.Settings of the command line (the node's defaults where not given)."""
    params = rests.RestParameters() if args.settle is None else \
        dataclasses.replace(rests.RestParameters(), settle=args.settle)
    joints = tuple(args.joints.split(',')) if args.joints else pipeline.Settings.joints
    return pipeline.Settings(args.holdout, args.seed, rests=params, joints=joints,
                             force=args.force)


def _interrupt(signum, frame):
    raise KeyboardInterrupt(signal.Signals(signum).name)


def offline(args):
    """
    Calibrate from a bag; exit status 0 on success, 1 with the reason on stderr otherwise.

    SIGTERM and SIGHUP stop it as Ctrl-C does (exit 130), through the pipeline's clean-up: no
    temporary file is left and an existing RESULT.yaml is untouched.
    """
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _interrupt)
    try:
        outcome = pipeline.calibrate_bag(
            args.bag_dir, args.out, settings(args),
            progress=lambda text: print(f'[calibrate] {text}', file=sys.stderr))
    except (pipeline.CalibrationError, ValueError) as e:
        print(f'robotenis calibrate: {e} ({args.out} not written)', file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        print(f'robotenis calibrate: interrupted{f" by {e}" if str(e) else ""} ({args.out} not '
              'written)', file=sys.stderr)
        return 130
    for line in result.summary(outcome.diagnosis):
        print(line)
    if 'next_session' in outcome.description.report:
        print(protocol.next_session_text(outcome.description.report['next_session']))
    print(f'wrote {outcome.result_path} and {outcome.plot_path}')
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis calibrate', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag_dir', nargs='?', help='a rosbag2 bag directory (offline calibration)')
    parser.add_argument('--out', help='RESULT.yaml to write (offline)')
    parser.add_argument('--holdout', type=float, default=pipeline.Settings.holdout_fraction,
                        help='share of poses held out (default 0.3)')
    parser.add_argument('--seed', type=int, default=pipeline.Settings.seed,
                        help='random seed (split; pose selection with --call)')
    parser.add_argument('--settle', type=float, default=None,
                        help='s: settle time (--call) or margin skipped at the start of rests'
                             ' found without markers')
    parser.add_argument('--joints', default='', metavar='A,B,C',
                        help="the bag's names of joints 1, 2, 3 (default motor_1,motor_2,motor_3)")
    parser.add_argument('--force', action='store_true',
                        help='write the result even if it is worse than the declared description')
    parser.add_argument('--call', action='store_true',
                        help='call the calibrate service of a running system')
    parser.add_argument('--poses', type=int, default=0)
    parser.add_argument('--frames', type=int, default=0)
    parser.add_argument('--selection', default='',
                        choices=('boundary', 'optimal', 'discriminating'),
                        help="the session's pose selection (with --call; default: the service's)")
    parser.add_argument('--bag', default='',
                        help='bag path for the recorded session (with --call)')
    parser.add_argument('--namespace', default='', help="the system's namespace (with --call)")
    args = parser.parse_args(argv)
    if args.call and args.settle is not None and not args.settle > 0:
        parser.error(f'--settle with --call must be positive, got {args.settle} (the service '
                     "reads 0 as its own default, the node's settle_time parameter)")
    if args.call:
        from robotenis_calibration import service_client
        return service_client.call(args)
    if not args.bag_dir or not args.out:
        parser.error('offline calibration needs BAG_DIR and --out RESULT.yaml (or use --call)')
    if not 0.0 < args.holdout < 1.0:
        parser.error(f'--holdout must be between 0 and 1, got {args.holdout}')
    if args.settle is not None and args.settle < 0:
        parser.error(f'--settle must not be negative, got {args.settle}')
    if args.joints and len(args.joints.split(',')) != 3:
        parser.error(f'--joints: expected three names separated by commas, got {args.joints!r}')
    return offline(args)


if __name__ == '__main__':
    sys.exit(main())
