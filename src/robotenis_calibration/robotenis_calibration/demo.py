"""`./robotenis demo`: a calibration of the simulated RoboTenis, printed beside the paper's Table 1.

The simulator's truth is Table 1's calibrated column. The demo draws the paper's 300 calibration
poses (5-10 cm from a singularity), lets the simulator measure them with the paper's noise (Table 3
for the camera), identifies the 15 parameters from the nominal start with both solvers, and prints
nominal, identified (with standard deviations) and the paper's values side by side, then the
observability analysis of all 21 parameters.
"""
import argparse
import sys
import time

import numpy as np

from robotenis_kinematics import delta, description, observability, synthetic, workspace
from robotenis_kinematics import identification as idf
from robotenis_sim import truth as sim_truth

# Calibration paper, Table 1 (mm and degrees), in PAPER_PARAMETERS order.
TABLE1_NOMINAL = [500, 1000, 50, 0] * 3 + [0, 0, 750]
TABLE1_CALIBRATED = [500.89, 1002.86, 48.69, 0.316, 500.01, 1001.37, 49.96, 0.844,
                     499.96, 1001.28, 48.68, 0.936, 5.31, 0.31, 743.74]


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
    paper = idf.gauss_newton_paper(start, meas)
    t_gn = time.perf_counter() - t
    print(f'   Levenberg-Marquardt, whitened (default): {result.iterations} iterations, {t_lm * 1e3:.1f} ms, '
          f'chi2/dof = {result.chi2 / result.dof:.3f}')
    print(f'   Gauss-Newton with pseudo-inverse (paper eq. 8): {paper.iterations} iterations, {t_gn * 1e3:.1f} ms')
    print()
    print(parameter_table(idf.PAPER_PARAMETERS, start.get(idf.PAPER_PARAMETERS), result,
                          TABLE1_NOMINAL, TABLE1_CALIBRATED))
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
    return 0


if __name__ == '__main__':
    sys.exit(main())
