import numpy as np
import pytest
from robotenis_kinematics import delta, effects, observability, synthetic, workspace
from robotenis_kinematics import identification as idf
from scipy import stats

LEVEL = 0.01  # two-sided significance of the chi-square tests


@pytest.fixture
def design(nominal):
    """300 of the paper's calibration poses, 5-10 cm from a singularity."""
    return workspace.boundary_poses(nominal, 300, np.random.default_rng(11))


def test_observation_matrix_matches_finite_differences(table1, design):
    model = synthetic.true_model(table1)
    meas = synthetic.measure(table1, design[:40])
    model = model.with_values(('b1', 'P0x'), model.get(('b1', 'P0x')) + 1e-3)  # off the solution
    names = idf.ALL_PARAMETERS
    J = idf.observation_matrix(model, meas, names)
    U = model.get(names)
    for j, name in enumerate(names):
        h = 1e-6
        plus = idf.constraints(model.with_values(names, U + h * np.eye(len(U))[j]), meas)
        minus = idf.constraints(model.with_values(names, U - h * np.eye(len(U))[j]), meas)
        numeric = np.swapaxes((plus - minus) / (2 * h), 0, 1).reshape(-1)
        assert np.abs(J[:, j] - numeric).max() < 1e-8, name


def test_noise_free_data_are_recovered(nominal, table1, design):
    meas = synthetic.measure(table1, design)
    truth = synthetic.true_model(table1).get(idf.PAPER_PARAMETERS)
    start = idf.initial_model(nominal, meas)
    for solve in (idf.identify, idf.gauss_newton_paper):
        result = solve(start, meas)
        assert result.converged
        assert np.abs(result.U - truth).max() < 1e-9, solve.__name__


def test_errors_agree_with_the_covariance_over_50_seeds(nominal, table1, design):
    """Sum over seeds of e^T Cov^-1 e ~ chi2(50 * 15); residual chi2 ~ chi2(50 * (3K - 15))."""
    truth_model = synthetic.true_model(table1)
    truth = truth_model.get(idf.PAPER_PARAMETERS)
    mahalanobis = residual = dof = 0.0
    seeds = 50
    for seed in range(seeds):
        meas = synthetic.measure(table1, design, rng=np.random.default_rng(1000 + seed))
        result = idf.identify(idf.initial_model(nominal, meas), meas)
        e = result.U - truth
        mahalanobis += e @ np.linalg.solve(result.covariance, e)
        residual += result.chi2
        dof += result.dof
    n = seeds * len(truth)
    assert stats.chi2.ppf(LEVEL / 2, n) < mahalanobis < stats.chi2.ppf(1 - LEVEL / 2, n)
    assert stats.chi2.ppf(LEVEL / 2, dof) < residual < stats.chi2.ppf(1 - LEVEL / 2, dof)


def test_fk_covariance_predicts_the_error_far_from_the_poses_measured(nominal, table1, design):
    """
    Fit 40 poses of one half of the workspace; predict a pose of the other half.

    Its error against the truth, weighted by fk_covariance, summed over 40 seeds ~ chi2(3 * 40).
    """
    near = design[design[:, 0] > 0.05][:40]
    far = design[design[:, 0] < -0.1][:1]
    Theta_far = delta.inverse(table1, far) - table1.theta0
    total, seeds = 0.0, 40
    for seed in range(seeds):
        meas = synthetic.measure(table1, near, rng=np.random.default_rng(2000 + seed))
        result = idf.identify(idf.initial_model(nominal, meas), meas)
        e = idf.predicted_positions(result.model, Theta_far, np.ones((1, 3)))[0] - far[0]
        C = idf.fk_covariance(result, Theta_far)[0]
        total += e @ np.linalg.solve(C, e)
    n = 3 * seeds
    assert stats.chi2.ppf(LEVEL / 2, n) < total < stats.chi2.ppf(1 - LEVEL / 2, n), total


def test_predicted_positions_apply_the_joint_effects_as_fk_does(table1, design):
    """A model's joint effects, compliance among them, move its FK as the description's do."""
    fx = {'backlash': np.array([1e-3, 6e-4, 8e-4]), 'gravity_compliance': np.full(3, 2e-4)}
    desc = table1.copy(effects=[{'name': name, effects.PARAMETERS[name][0]: list(v)}
                                for name, v in fx.items()])
    Theta = delta.inverse(table1, design[:30]) - table1.theta0
    model = idf.Model(table1.copy(), np.zeros(3), fx)
    expected = delta.forward(desc, effects.joint_angles(desc, Theta))
    P = idf.predicted_positions(model, Theta, effects.motion_direction(Theta))
    assert np.abs(P - expected).max() < 1e-12
    assert np.all(np.isfinite(idf.fk_covariance(
        idf.Result(model, ('a1', 'gravity_compliance1'), np.zeros(2), np.eye(2) * 1e-8, 0.0, 0, 0,
                   True), Theta)))


def test_covariance_at_the_truth_is_the_cramer_rao_bound(nominal, table1, design):
    meas = synthetic.measure(table1, design, rng=np.random.default_rng(5))
    result = idf.identify(idf.initial_model(nominal, meas), meas)
    crb = idf.cramer_rao(synthetic.true_model(table1), meas)
    # The estimate's covariance is evaluated at the estimate, a few CRB std away: equal to first
    # order.
    np.testing.assert_allclose(np.sqrt(np.diag(result.covariance)), np.sqrt(np.diag(crb)),
                               rtol=1e-3)


def test_observability_finds_H_minus_h_and_weak_phi(table1, design):
    obs = observability.analyse(synthetic.true_model(table1), synthetic.measure(table1, design))
    assert obs.rank == len(idf.ALL_PARAMETERS) - 3
    pairs = sorted(tuple(sorted(c)) for c in obs.combinations)
    assert pairs == [('H1', 'h1'), ('H2', 'h2'), ('H3', 'h3')]
    assert all(np.isclose(c[a], c[b]) for c in obs.combinations for a, b in [tuple(c)])
    assert set(obs.weak) == {'phi1', 'phi2', 'phi3'}
    assert 'H1 - h1' in observability.format_report(obs)


def test_bad_measurements_are_refused():
    with pytest.raises(ValueError, match='NaN'):
        idf.Measurements([[0.0, np.nan, 0.0]], [[0.0, 0.0, 0.0]], 1e-5, np.eye(3))
    with pytest.raises(ValueError, match=r'\(K, 3\)'):
        idf.Measurements(np.zeros((4, 3)), np.zeros((3, 3)), 1e-5, np.eye(3))


def field_model(model, degree):
    """Return the model with every camera-field term up to ``degree`` present at zero."""
    terms = effects.camera_term_names(degree)
    names = tuple(p for n in terms for p in idf.effect_names(n) if p not in effects.UNSEEN)
    return idf.Model(model.desc, model.P0, {n: np.zeros(3) for n in terms}), names


def noise_residual_correlations(error, r):
    """Return |correlation| of each axis of the error (K, 3) with each leg's residual (3K,)."""
    legs = r.reshape(len(error), 3)
    return np.array([abs(stats.pearsonr(error[:, a], legs[:, i])[0])
                     for a in range(3) for i in range(3)])


def test_adjusted_observations_meet_the_constraints_and_share_no_noise(table1, design):
    """The adjustment's error is uncorrelated with the residuals; the measurements' is not."""
    model = synthetic.true_model(table1)
    clean = synthetic.measure(table1, design)
    meas = synthetic.measure(table1, design, rng=np.random.default_rng(3))
    hat = idf.adjusted(model, meas)
    cov = idf.residual_covariance(meas, idf.partials(model, meas))
    sigma = np.sqrt(np.einsum('kii->ki', cov))
    assert np.abs(idf.constraints(model, hat) / sigma).max() < 1e-3   # Gamma = 0 to first order
    r = idf.whitened_problem(model, meas, ())[0]
    bound = stats.norm.ppf(1 - LEVEL / 18) / np.sqrt(len(meas))    # two-sided, 9 pairs
    assert noise_residual_correlations(meas.Pi - clean.Pi, r).max() > bound
    assert noise_residual_correlations(hat.Pi - clean.Pi, r).max() < bound


@pytest.fixture
def seen_design(nominal):
    """300 boundary poses from which a hand camera sees a point 0.2-0.55 m ahead of it."""
    P = workspace.boundary_poses(nominal, 6000, np.random.default_rng(12))
    x, y, z = ((np.array([0.70, 0.0, 1.35]) - P) @ nominal.camera_rotation).T
    seen = (z > 0.2) & (z < 0.55) & (np.abs(x) < 0.45 * z) & (np.abs(y) < 0.33 * z)
    assert seen.sum() >= 300
    return P[seen][:300]


def test_a_smooth_field_is_not_found_in_pure_noise(nominal, table1, seen_design):
    """
    The score of a degree-2 camera field (26 terms) at the fit follows chi2 on exact-model data.

    With the Jacobian at the adjusted observations the sum over 10 seeds is in chi2(260)'s 99 %
    band; at the measurements it is far above (the shared noise). The fit's chi-square drop
    (identify: the Gauss-Helmert objective) is in the band too.
    """
    score = {'adjusted': 0.0, 'measured': 0.0}
    drop = dof = 0.0
    for seed in range(10):
        meas = synthetic.measure(table1, seen_design, rng=np.random.default_rng(200 + seed))
        plain = idf.identify(idf.initial_model(nominal, meas), meas)
        model, terms = field_model(plain.model, 2)
        names = plain.names + terms
        J_meas = idf.whitened_problem(model, meas, names)[1]
        r, J_hat = idf.whitened_problem(model, meas, names, adjust=True)
        for key, J in (('adjusted', J_hat), ('measured', J_meas)):
            Q = np.linalg.qr(J)[0]
            score[key] += float(np.sum((Q[:, len(plain.names):].T @ r) ** 2))
        drop += plain.chi2 - idf.identify(model, meas, names).chi2
        dof += len(terms)
    low, high = stats.chi2.ppf([LEVEL / 2, 1 - LEVEL / 2], dof)
    assert low < score['adjusted'] < high and score['measured'] > 1.5 * high
    assert low < drop < high
