"""`./robotenis demo`: a calibration of the simulated RoboTenis, printed beside the paper's Table 1,
then the residual loop on a robot with an effect nobody declared.

Part 1. The simulator's truth is Table 1's calibrated column. The demo draws the paper's 300
calibration poses (5-10 cm from a singularity), lets the simulator measure them with the paper's
noise (Table 3 for the camera), identifies the 15 parameters from the nominal start with both
solvers, and prints nominal, identified (with standard deviations) and the paper's values side by
side, then the observability analysis of all 21 parameters.

Part 2. The same robot, now with a backlash in its joints that no description declares. A static
session (the poses the camera can see, in visit order) is fitted with the plain model, the residual
loop finds and names the effect, and the held-out errors before and after are printed. The result
(a calibrated description with its effects and report) and the residual plots go to --out.
"""
import argparse
import os
import sys
import time

import numpy as np

from robotenis_calibration import diagnosis, paper, poses, result
from robotenis_calibration.study import EFFECTS as STUDY
from robotenis_calibration.session import Session
from robotenis_kinematics import delta, description, observability, synthetic, workspace
from robotenis_kinematics import identification as idf
from robotenis_sim import static_session
from robotenis_sim import truth as sim_truth


def human(name, value):
    """mm for lengths, degrees for angles."""
    return np.degrees(value) if name.startswith('theta') else value * 1e3


def parameter_table(names, nominal, result, paper_nominal, paper_calibrated):
    rows = ['%-8s %10s %22s %10s %12s' % ('param', 'nominal', 'identified +- std', 'Table 1', 'Table 1 cal.')]
    for j, n in enumerate(names):
        unit = 'deg' if n.startswith('theta') else 'mm'
        rows.append('%-8s %10.3f %13.4f +- %6.4f %10.3f %12.3f  %s' % (
            n, human(n, nominal[j]), human(n, result.U[j]), human(n, result.std[j]),
            paper_nominal[j], paper_calibrated[j], unit))
    return '\n'.join(rows)


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis demo', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--poses', type=int, default=300)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--out', default='report/demo', help='folder for result.yaml and residuals.png')
    args = parser.parse_args(argv)

    nominal = description.nominal()
    truth = sim_truth.load()
    rng = np.random.default_rng(args.seed)
    noise = synthetic.NoiseModel()
    print(f'1. {args.poses} calibration poses, 5-10 cm from a singularity (paper, section 5.1)')
    P = workspace.boundary_poses(nominal, args.poses, rng)
    print('2. the simulator measures them: resolver noise %.0e rad, camera noise (Table 3) %s mm'
          % (noise.sigma_resolver, ', '.join(f'{s * 1e3:.4f}' for s in noise.sigma_camera)))
    meas = synthetic.measure(truth.geometry, P, noise, rng)
    start = idf.initial_model(nominal, meas)
    print('3. identification from the nominal start')
    t = time.perf_counter()
    result = idf.identify(start, meas)
    t_lm = time.perf_counter() - t
    t = time.perf_counter()
    paper_fit = idf.gauss_newton_paper(start, meas)
    t_gn = time.perf_counter() - t
    print(f'   Levenberg-Marquardt, whitened (default): {result.iterations} iterations, {t_lm * 1e3:.1f} ms, '
          f'chi2/dof = {result.chi2 / result.dof:.3f}')
    print(f'   Gauss-Newton with pseudo-inverse (paper eq. 8): {paper_fit.iterations} iterations, {t_gn * 1e3:.1f} ms')
    print()
    print(parameter_table(idf.PAPER_PARAMETERS, start.get(idf.PAPER_PARAMETERS), result,
                          paper.TABLE1_NOMINAL, paper.TABLE1_CALIBRATED))
    true_model = synthetic.true_model(truth.geometry)
    e = result.U - true_model.get(idf.PAPER_PARAMETERS)
    print()
    print('Scored against the simulator truth (Table 1 geometry): max |error| %.4f mm (lengths), %.5f deg (angles);'
          % (np.abs(e[[j for j, n in enumerate(idf.PAPER_PARAMETERS) if not n.startswith('theta')]]).max() * 1e3,
             np.degrees(np.abs(e[[j for j, n in enumerate(idf.PAPER_PARAMETERS) if n.startswith('theta')]]).max())))
    print('Mahalanobis distance of the error: %.1f (chi2 with 15 dof: 95%% below 25.0)'
          % (e @ np.linalg.solve(result.covariance, e)))
    home = delta.forward(truth.geometry, truth.geometry.theta0) * 1e3
    print('Note: P0 here is the home position FK(theta0). Table 1 lists P0 = (5.31, 0.31, 743.74) mm, but its own\n'
          'a, b, h, theta0 put home at (%.2f, %.2f, %.2f) mm: the table is not self-consistent in P0.' % tuple(home))
    print()
    print(observability.format_report(observability.analyse(result.model, meas)))
    print()
    residual_loop(nominal, truth, rng, args)
    return 0


def residual_loop(nominal, truth, rng, args):
    """Part 2: a session on a robot with an undeclared effect, through the residual loop."""
    truth = sim_truth.with_effects(truth, **STUDY['backlash'])  # what nobody declared
    guess = truth.sphere_position + np.array([0.03, -0.02, 0.02])  # the user's rough ball position
    print(f'4. residual loop: the robot now has an undeclared effect; ball guessed at {guess} m')
    P = poses.boundary(nominal, guess, args.poses, rng)
    Theta, sigma, sphere, cov, kept = static_session.run(truth, nominal, P, synthetic.NoiseModel(), rng)
    print(f'   {len(P)} poses planned, {len(kept)} measured (ball in view), 30 % held out')
    session = Session(nominal, Theta, sigma, sphere, cov, 8.0 * np.arange(len(kept)))
    meas = session.measurements()
    t = time.perf_counter()
    d = diagnosis.run(nominal, meas, session.sphere, session.stamps, seed=args.seed,
                      progress=lambda text: print('   ' + text))
    print(f'   identification and diagnosis: {(time.perf_counter() - t) * 1e3:.0f} ms')
    for line in result.summary(d):
        print('   ' + line)
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, 'result.yaml')
    description.save(result.calibrated_description(d, nominal), path)
    result.plot_residuals(d, meas, session.sphere, session.stamps, os.path.join(args.out, 'residuals.png'))
    print(f'   wrote {path} and residuals.png (try: ./robotenis fk --model {path})')


if __name__ == '__main__':
    sys.exit(main())
