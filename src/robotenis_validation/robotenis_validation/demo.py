"""
`./robotenis demo`: calibrate the simulated RoboTenis, print the result beside the paper's Table 1.

Then run the residual loop on a robot with an effect nobody declared.

Part 1. The simulator's truth is Table 1's calibrated column. The planner draws the paper's
calibration poses (random, 5-10 cm from a singularity) among those where the hand camera should see
the ball; the simulator measures each rest with the paper's noise (Table 3 for the camera). The 15
parameters are identified from the nominal start with both solvers and printed beside Table 1, then
the observability analysis of all 21 parameters.

Part 2. The same robot, now with a backlash in its joints that no description declares, through the
residual loop: it finds and names the effect, and prints the held-out errors before and after. The
result (a calibrated description with its effects and report) and the residual plots go to --out.

Part 3. The whole system through ROS: the nodes (simulated motors and hand camera with the backlash
in their truth, sphere detector, motion controller, calibration service) start as separate
processes on the simulator's clock; the demo calls the Calibrate service as
`./robotenis calibrate --call` would, with a progress bar, and the service records the session to a
bag under --out, finds the rests, averages the detections, identifies and runs the residual loop.
Then the demo scores the answer against the simulator's truth, which only a simulation knows: the
bag calibrated again as the service did, its held-out rests' readings replaced by the truth's
(live_links.holdout_truth_error_mm), for the plain and the final model, and the final model's FK
over the whole workspace. ``--offline`` skips part 3.
"""
import argparse
import glob
import os
import sys
import time

from types import SimpleNamespace

import numpy as np
from robotenis_bringup import launch_file
from robotenis_bringup.launcher import Launcher
from robotenis_calibration import result, service_client
from robotenis_kinematics import delta, description, observability, synthetic
from robotenis_kinematics import identification as idf
from robotenis_sim import scenarios, truth as sim_truth
from robotenis_validation import live_links, paper, study
import yaml


def human(name, value):
    """Return mm for lengths, degrees for angles."""
    return np.degrees(value) if name.startswith('theta') else value * 1e3


def parameter_table(names, fit):
    header = ('param', 'nominal', 'identified +- std', 'Table 1 cal.', 'unit')
    rows = ['%-8s %10s %22s %14s  %s' % header]
    for j, n in enumerate(names):
        if n.startswith('P0'):
            continue  # the camera reference here, not Table 1's home position (see the note below)
        rows.append('%-8s %10.3f %13.4f +- %6.4f %14.3f  %s' % (
            n, paper.TABLE1_NOMINAL[j], human(n, fit.U[j]), human(n, fit.std[j]),
            paper.TABLE1_CALIBRATED[j], 'deg' if n.startswith('theta') else 'mm'))
    return '\n'.join(rows)


def identification(nominal, truth, args):
    """Part 1: identification beside Table 1, and the observability analysis."""
    noise = synthetic.NoiseModel()
    print(f'1. a static session of {args.poses} planned poses '
          '(5-10 cm from a singularity, ball in view); '
          f'noise: resolvers {noise.sigma_resolver:.0e} rad, camera (Table 3) '
          + ', '.join(f'{s * 1e3:.4f}' for s in noise.sigma_camera) + ' mm')
    session, meas, _ = study.static_run(truth, nominal, args.poses, args.seed)
    start = idf.initial_model(nominal, meas)
    t = time.perf_counter()
    fit = idf.identify(start, meas)
    t_lm = time.perf_counter() - t
    t = time.perf_counter()
    paper_fit = idf.gauss_newton_paper(start, meas)
    t_gn = time.perf_counter() - t
    print(f'2. {len(session)} rests measured; '
          'identification of 15 parameters from the nominal start:')
    print(f'   Levenberg-Marquardt, whitened (default): {fit.iterations} iterations, '
          f'{t_lm * 1e3:.1f} ms, '
          f'chi2/dof = {fit.chi2 / fit.dof:.3f}')
    print(f'   Gauss-Newton with pseudo-inverse (paper eq. 8): {paper_fit.iterations} iterations, '
          f'{t_gn * 1e3:.1f} ms')
    print()
    print(parameter_table(idf.PAPER_PARAMETERS, fit))
    legs = [j for j, n in enumerate(idf.PAPER_PARAMETERS) if not n.startswith('P0')]
    truth_U = synthetic.true_model(truth.geometry).get(idf.PAPER_PARAMETERS)[legs]
    e = fit.U[legs] - truth_U
    cov = fit.covariance[np.ix_(legs, legs)]
    print()
    print('Scored against the simulator truth (Table 1 geometry): '
          'Mahalanobis distance of the error %.1f '
          '(chi2 with %d dof: 99 %% below %.1f)' % (e @ np.linalg.solve(cov, e), len(legs), 26.2))
    home = delta.forward(fit.model.desc, fit.model.desc.theta0) * 1e3
    table_home = delta.forward(truth.geometry, truth.geometry.theta0) * 1e3
    print('Home position FK(theta0) of the identified model: (%.2f, %.2f, %.2f) mm.' % tuple(home))
    print('Note: Table 1 lists P0 = (5.31, 0.31, 743.74) mm, '
          'but its own a, b, h, theta0 put home at\n'
          '(%.2f, %.2f, %.2f) mm: the table is not self-consistent in P0.' % tuple(table_home))
    print()
    print(observability.format_report(observability.analyse(fit.model, meas)))


def residual_loop(nominal, truth, args):
    """Part 2: a session on a robot with an undeclared effect, through the residual loop."""
    truth = sim_truth.with_effects(truth, **scenarios.EFFECTS['backlash'])  # what nobody declared
    print('3. residual loop: the robot now has an undeclared effect; '
          'the ball position is known to '
          f'{np.linalg.norm(scenarios.BALL_GUESS_ERROR) * 1e3:.0f} mm')
    t = time.perf_counter()
    session, meas, d = study.static_run(truth, nominal, args.poses, args.seed + 1)
    print(f'   {len(session)} rests measured, {len(d.holdout)} held out; '
          'planning, simulation, identification '
          f'and diagnosis: {(time.perf_counter() - t) * 1e3:.0f} ms')
    for line in result.summary(d):
        print('   ' + line)
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, 'result.yaml')
    description.save(result.calibrated_description(d, nominal), path)
    plot_path = os.path.join(args.out, 'residuals.png')
    result.plot_residuals(d, meas, session.sphere, session.stamps, plot_path)
    print(f'   wrote {path} and residuals.png (try: ./robotenis fk --model {path})')


# Part 4's session: frames per rest and settle (s) after the joints are still. 12 frames: what
# 90-pose live sessions of 30 frames after 0.3 s recommend for the next one (10-14:
# protocol.next_session, printed by the calibration); past 10 frames the rests' error against
# the truth stops falling (z 0.091-0.092 mm std, 30 frames 0.091-0.093: live_links), and the
# first frames after 0.1 s are as good as those after 0.3 s.
LIVE_FRAMES, LIVE_SETTLE = 12, 0.1
# what part 4's robot may hide: the named effects and those outside the library
LIVE_EFFECTS = {**{k: v for k, v in scenarios.EFFECTS.items() if v},
                **{k: v for k, (v, _) in scenarios.OUTSIDE_LIBRARY.items()}}


def ros_session(nominal, truth, args):
    """Part 3: launch the nodes, call /calibrate, print the service's answer; the exit status."""
    robot = sim_truth.with_effects(truth, **LIVE_EFFECTS[args.effect])
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    truth_path = os.path.join(out, 'truth.yaml')
    sim_truth.save(robot, truth_path)
    # what the user tells the calibration node: where the ball roughly is
    params_path = os.path.join(out, 'calibration.params.yaml')
    guess = [float(v) for v in robot.sphere_position + scenarios.BALL_GUESS_ERROR]
    with open(params_path, 'w') as f:
        yaml.safe_dump({'/**/calibration': {'ros__parameters': {'sphere_guess': guess}}}, f)
    bag = os.path.join(out, time.strftime('session-%Y%m%d-%H%M%S'))
    print(f'4. the whole loop through ROS: {args.ros_poses} poses, {args.frames} frames each, '
          f'settle {args.settle} s, the robot hiding {args.effect}; simulated time, the simulator '
          'and the controller in lockstep at 1 kHz')
    top = os.environ.get('ROBOTENIS_TOP', os.getcwd())
    launch_args = {'sim_time': 'true', 'truth_path': truth_path, 'params_file': params_path,
                   'description_path': description.config_path('nominal.yaml'),
                   'bags_dir': out, 'results_dir': out}
    if getattr(args, 'rest_method', None):
        launch_args['rest_method'] = args.rest_method
    nodes = launch_file.load(launch_file.find('calibration.launch.yaml'), launch_args)
    launcher = Launcher(nodes, os.path.join(top, 'install'), os.path.join(top, 'log', 'demo'))
    started = time.perf_counter()
    launcher.start()
    try:
        status = service_client.call(SimpleNamespace(
            poses=args.ros_poses, frames=args.frames, settle=args.settle, seed=args.seed,
            selection=getattr(args, 'selection', ''), bag=bag))
    finally:
        launcher.check()
        launcher.stop()
    print(f'   {time.perf_counter() - started:.0f} s from launch to answer; node logs in '
          f'{top}/log/demo')
    return status


def against_the_truth(args):
    """Part 3's answer scored against the simulator's truth: lines of text."""
    bag = sorted(glob.glob(os.path.join(args.out, 'session-*')))[-1]
    robot = sim_truth.load(os.path.join(args.out, 'truth.yaml'))
    session, d, meas = live_links.calibrated_as_the_service(bag, args.seed)
    sides = live_links.TrueSides.of_bag(bag, robot).at(session.stamps)
    plain, final = (live_links.holdout_truth_error_mm(d, meas, session, robot, r.model, sides)
                    for r in (d.plain, d.final))
    nominal = description.nominal()
    fk = live_links.workspace_error_mm(result.calibrated_description(d, nominal), robot)
    fk_nominal = live_links.workspace_error_mm(nominal, robot)
    return [f"   against the simulator's truth (the bag calibrated again as the service did: "
            f"{', '.join(d.effects) or 'no effect'}): held-out RMS error plain {plain:.3f} mm, "
            f"final {final:.3f} mm (the held-out rests' readings replaced by the truth's);",
            f'   FK over 500 boundary poses of the whole workspace {fk:.3f} mm (nominal '
            f'{fk_nominal:.3f} mm): far from the poses where the camera sees the ball, and with '
            'the offset the fitted ball position takes']


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis demo', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--poses', type=int, default=300)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--out', default='report/demo',
                        help='folder for result.yaml, residuals.png and the bag')
    parser.add_argument('--offline', action='store_true', help='parts 1 and 2 only (no ROS)')
    parser.add_argument('--ros-poses', type=int, default=90,
                        help='poses of the session through ROS')
    parser.add_argument('--frames', type=int, default=LIVE_FRAMES,
                        help='camera frames averaged per pose')
    parser.add_argument('--settle', type=float, default=LIVE_SETTLE,
                        help='settle time at each pose once the joints are still (s)')
    parser.add_argument('--effect', default='backlash', choices=sorted(LIVE_EFFECTS),
                        help='what the simulated robot hides in the session through ROS')
    parser.add_argument('--rest-method',
                        help="the detector's method at rest in the session through ROS (the "
                             "launch argument rest_method; default the detector's own, model; "
                             'conic: the fast one)')
    args = parser.parse_args(argv)
    nominal, truth = description.nominal(), sim_truth.load()
    identification(nominal, truth, args)
    print()
    residual_loop(nominal, truth, args)
    if args.offline:
        return 0
    print()
    status = ros_session(nominal, truth, args)
    if status == 0:
        print('\n'.join(against_the_truth(args)))
    return status


if __name__ == '__main__':
    sys.exit(main())
