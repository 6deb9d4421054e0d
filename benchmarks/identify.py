"""
Benchmark: identification of 300 poses, 15 parameters, from the nominal start (issue 2).

The paper needed about 5 s. Target: under 20 ms, and faster than scipy.optimize.least_squares on
the same whitened Gauss-Helmert problem (same residuals, same analytic Jacobian) run here in the
same process.
Prints the median of repeated runs and the accuracy of both against the simulated truth.
"""
import time

import numpy as np
from robotenis_kinematics import description, synthetic, workspace
from robotenis_kinematics import identification as idf
from robotenis_sim import truth as sim_truth
from scipy.optimize import least_squares

REPEATS = 20
TARGET_S = 0.020


def median_time(fn, repeats=REPEATS):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), out


def scipy_identify(start, meas, names=idf.PAPER_PARAMETERS):
    """
    Run the same estimator with scipy's least_squares.

    Trust-region reflective, analytic Jacobian.
    """
    U0 = start.get(names)

    def residuals(U):
        return idf.whitened_problem(start.with_values(names, U), meas, names, adjust=True)[0]

    def jacobian(U):
        return idf.whitened_problem(start.with_values(names, U), meas, names, adjust=True)[1]

    return least_squares(residuals, U0, jac=jacobian, x_scale='jac',
                         xtol=1e-12, ftol=1e-12, gtol=1e-12)


def main():
    nominal = description.nominal()
    true_geometry = sim_truth.load().geometry  # scoring only
    rng = np.random.default_rng(2013)
    P = workspace.boundary_poses(nominal, 300, rng)
    meas = synthetic.measure(true_geometry, P, synthetic.NoiseModel(), rng)
    start = idf.initial_model(nominal, meas)
    truth = synthetic.true_model(true_geometry).get(idf.PAPER_PARAMETERS)

    t_ours, ours = median_time(lambda: idf.identify(start, meas))
    t_paper, paper = median_time(lambda: idf.gauss_newton_paper(start, meas))
    t_scipy, ref = median_time(lambda: scipy_identify(start, meas), repeats=5)

    print('identification: 300 poses, 15 parameters, nominal start (median of runs)')
    print(f'  robotenis identify (LM, Gauss-Helmert): {t_ours * 1e3:7.2f} ms  '
          f'{ours.iterations} iterations  '
          f'max |U - truth| {np.abs(ours.U - truth).max() * 1e3:.4f} (mm|mrad)')
    print(f'  paper Gauss-Newton, pseudo-inverse:    {t_paper * 1e3:7.2f} ms  '
          f'{paper.iterations} iterations  '
          f'max |U - truth| {np.abs(paper.U - truth).max() * 1e3:.4f}')
    print(f'  scipy least_squares (baseline):        {t_scipy * 1e3:7.2f} ms  '
          f'{ref.nfev} evaluations  '
          f'max |U - truth| {np.abs(ref.x - truth).max() * 1e3:.4f}')
    print(f'  same minimum as scipy: max |U_ours - U_scipy| = {np.abs(ours.U - ref.x).max():.2e}')
    print(f'speed-up over scipy: {t_scipy / t_ours:.1f}x; paper: about 5 s')
    print(f'target under {TARGET_S * 1e3:.0f} ms and faster than scipy: '
          f"{'MET' if t_ours < TARGET_S and t_ours < t_scipy else 'NOT MET'}")


if __name__ == '__main__':
    main()
