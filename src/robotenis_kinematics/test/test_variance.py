"""The REML floor: its score and information are right, and it finds a floor the data carry."""
import numpy as np
import pytest
from robotenis_kinematics import delta, description, effects, synthetic, variance, workspace
from robotenis_kinematics import identification as idf
from scipy import stats
import scipy.linalg

BALL, CAMERA_OFFSET = np.array([0.70, 0.0, 1.35]), np.array([0.10, 0.0, 0.03])
FLOOR = {'camera_y': (0.02e-3) ** 2, 'camera_z': (0.05e-3) ** 2,
         'camera_z_range': (0.05e-3) ** 2, 'resolver': (1e-5) ** 2}


@pytest.fixture(scope='module')
def session():
    """Noise-free rests of Table 1's robot seeing the ball, increments as a session makes them."""
    truth = description.load(description.config_path('table1_calibrated.yaml'))
    R = truth.camera_rotation
    P = workspace.boundary_poses(description.nominal(), 4000, np.random.default_rng(0))
    s = (BALL - P - CAMERA_OFFSET) @ R
    seen = (s[:, 2] > 0.2) & (s[:, 2] < 0.55) & (np.abs(s[:, 0]) < 0.45 * s[:, 2]) \
        & (np.abs(s[:, 1]) < 0.33 * s[:, 2])
    P, s = P[seen][:240], s[seen][:240]
    noise = synthetic.NoiseModel()
    return idf.Measurements(delta.inverse(truth, P) - truth.theta0, -s @ R.T,
                            np.full(3, noise.sigma_resolver), noise.cov_Pi(R)), R


def draw(meas, R, floor, rng):
    """Measurements with the frames' noise and the floor drawn; covariances the frames' only."""
    wide = variance.Floor(floor).widen(meas, R)
    Pi = meas.Pi + np.array([rng.multivariate_normal(np.zeros(3), c) for c in wide.cov_Pi])
    Theta = meas.Theta + rng.normal(size=meas.Theta.shape) * wide.sigma_Theta
    return idf.Measurements(Theta, Pi, meas.sigma_Theta, meas.cov_Pi)


def test_score_and_information_are_the_restricted_likelihoods(session):
    """The score is the likelihood's gradient; the information is 1/2 tr(P G_j P G_l) dense."""
    meas, R = session
    sample = draw(meas, R, FLOOR, np.random.default_rng(1)).subset(np.arange(40))
    fit = idf.identify(idf.initial_model(description.nominal(), sample), sample)
    V0, B, S, r, J = variance._blocks(fit.model, sample, idf.PAPER_PARAMETERS,
                                      variance.COMPONENTS)
    B = B / np.sqrt(S @ (S.T @ np.einsum('kti,kti->t', B, B) / len(sample)))[None, :, None]
    phi = np.linspace(0.05, 0.2, len(variance.COMPONENTS))
    score, information, _ = variance._score_and_information(V0, B, S, r, J, phi)
    h = 1e-6 * phi
    for j in range(len(phi)):
        up, down = (variance._score_and_information(V0, B, S, r, J, phi + sign * h[j] * np.eye(
            len(phi))[j])[2] for sign in (1, -1))
        assert (up - down) / (2 * h[j]) == pytest.approx(score[j], rel=1e-5)
    V = V0 + np.einsum('kti,ktj,t->kij', B, B, S @ phi)
    W = np.linalg.inv(scipy.linalg.block_diag(*V))
    Jd = J.reshape(-1, J.shape[2])
    P = W - W @ Jd @ np.linalg.inv(Jd.T @ W @ Jd) @ Jd.T @ W
    G = [scipy.linalg.block_diag(*np.einsum('kti,ktj,t->kij', B, B, S[:, j]))
         for j in range(len(phi))]
    dense = np.array([[0.5 * np.trace(P @ a @ P @ b) for b in G] for a in G])
    np.testing.assert_allclose(information, dense, rtol=1e-8)


def test_the_floor_found_predicts_held_out_rests_and_its_large_components(session):
    """
    Check the floor on rests it was not fitted on, and the components far from zero.

    Fitted on 160 rests, the model and floor give the other 80 a chi-square that follows
    chi2(240) (with the fit's own error in their predictive covariance; summed over 12 seeds:
    chi2(2880), two-sided 1 %; without the floor it is seven times larger). The large components
    scatter about the drawn ones as their standard errors say: the mean of 12 z-scores within
    3 / sqrt(12). (Small components share what they
    explain with their neighbours near the boundary at zero: only their sum is well determined.)
    """
    meas, R = session
    chi2, dof, z = 0.0, 0, {'camera_z': [], 'camera_z_range': []}
    train, held = np.arange(160), np.arange(160, 240)
    for seed in range(12):
        sample = draw(meas, R, FLOOR, np.random.default_rng(100 + seed))
        fit, floor = variance.identify(idf.initial_model(description.nominal(), sample.subset(
            train)), sample.subset(train))
        widened = floor.widen(sample.subset(held), R)
        r, Jh = idf.whitened_problem(fit.model, widened, fit.names)
        predictive = np.eye(len(r)) + Jh @ fit.covariance @ Jh.T     # the fit's own error too
        chi2, dof = chi2 + r @ np.linalg.solve(predictive, r), dof + len(r)
        for name in z:
            z[name].append((floor.variances[name] - FLOOR[name]) / floor.std[name])
    assert stats.chi2.ppf(0.005, dof) < chi2 < stats.chi2.ppf(0.995, dof), (chi2, dof)
    for name, values in z.items():
        assert abs(np.mean(values)) < 3 / np.sqrt(len(values)), (name, values)


def test_the_range_components_grow_as_an_error_in_pixels_does():
    """
    An outline's error of e px is z e / f sideways and z^2 e / (f R) deep: twice as far, 2x and 4x.

    The widened covariance of a rest at 2 z_ref carries 4x the lateral components' variance and
    16x the depth component's that it carries at z_ref (camera rotation the identity, so the
    optical axes are the base axes), and the result file says so.
    """
    floor = variance.Floor({'camera_x_range': 1e-10, 'camera_z_range': 2e-10})
    z_ref = effects.CAMERA_REFERENCE_RANGE
    meas = idf.Measurements(np.zeros((2, 3)), np.array([[0, 0, -z_ref], [0, 0, -2 * z_ref]]),
                            np.zeros(3), np.zeros((2, 3, 3)))
    added = np.diagonal(floor.widen(meas, np.eye(3)).cov_Pi, axis1=1, axis2=2)[:, [0, 2]]
    np.testing.assert_allclose(added[1] / added[0], [4.0, 16.0])
    written = floor.as_dict()
    assert written['camera_x_range']['times'] == f'(z / {z_ref} m)^2'
    assert written['camera_z_range']['times'] == f'(z / {z_ref} m)^4'
