"""
The residual loop: find what the model lacks, add it, and prove it helped on held-out poses.

1. Fit the paper's 15 parameters on the training poses; hold the rest out.
2. Test the residuals: their chi-square against the propagated noise (size), and, for every
   candidate effect, a score (Lagrange multiplier) test: with Q_c an orthonormal basis of the
   candidate's whitened columns after the current model's columns are projected out, the statistic
   |Q_c^T r_w|^2 follows chi2(q) when the effect is absent.
3. Take the most significant candidate (Bonferroni over the candidates left), keeping only its
   parameters that are identifiable together with the rest (their projected columns must not
   vanish: H_i beside h_i does), and refit.
4. Keep it only if the fit improves significantly (likelihood ratio, chi2(q)) and the held-out
   poses do too (one-sided paired t-test of their per-pose chi-square contributions, before against
   after); repeat until no candidate is significant.
5. If the residuals are still too large, a generic fallback tests their correlation with what could
   explain them (joint angle, motion direction, gravity torque, image position, time) and flags it.

All tests run at the significance level ``ALPHA`` (per decision, Bonferroni-corrected where several
candidates compete), so on data with no effect the loop claims one in about ALPHA of sessions.
"""
from dataclasses import dataclass, field

import numpy as np
from robotenis_kinematics import delta, effects
from robotenis_kinematics import identification as idf
from scipy import stats

ALPHA = 0.01
CANDIDATES = ('joint_scale', 'base_geometry', 'hand_eye_rotation', 'backlash',
              'gravity_compliance')
FEATURES = ('joint angle', 'joint angle squared', 'motion direction', 'gravity torque', 'range',
            'image x', 'image y', 'time')


def candidate_parameters(name):
    """Parameter names a candidate proposes (before the identifiability check)."""
    if name == 'base_geometry':
        return ('H1', 'H2', 'H3', 'phi1', 'phi2', 'phi3')
    return idf.effect_names(name)


@dataclass
class CandidateTest:
    """Score test of one candidate against the current model's residuals."""

    name: str
    parameters: tuple        # identifiable together with the current model
    dropped: tuple           # proposed but not identifiable (e.g. H_i beside h_i)
    statistic: float
    dof: int
    p_value: float
    # Wilson-Hilferty normal score of the statistic: ranks candidates where p underflows.
    z: float


@dataclass
class Step:
    """One round of the loop."""

    tests: list
    chosen: str = None
    kept: bool = False
    chi2_before: float = 0.0
    chi2_after: float = 0.0
    lr_p_value: float = 1.0
    holdout_p_value: float = 1.0
    reason: str = ''


@dataclass
class Diagnosis:
    """Everything the loop found."""

    plain: idf.Result
    final: idf.Result
    effects: list
    steps: list
    train: np.ndarray
    holdout: np.ndarray
    size_test: dict
    errors_mm: dict                 # held-out RMS 3D error per model: nominal, plain, final
    holdout_chi2: dict
    fallback: list = field(default_factory=list)


def with_candidate(model, name):
    """Return the model with a candidate's parameters present at zero effect."""
    if effects.is_effect(name) and name not in model.effects:
        return idf.Model(model.desc, model.P0, {**model.effects, name: np.zeros(3)})
    return model


def score_test(result, meas, name, rtol=1e-6):
    """Score test of candidate ``name`` at the fitted ``result`` (see the module docstring)."""
    proposed = tuple(n for n in candidate_parameters(name) if n not in result.names)
    model = with_candidate(result.model, name)
    r_w, J_w = idf.whitened_problem(model, meas, result.names + proposed)
    p = len(result.names)
    Q, _ = np.linalg.qr(J_w[:, :p])
    Jc = J_w[:, p:]
    perp = Jc - Q @ (Q.T @ Jc)
    keep, basis = [], np.zeros((len(r_w), 0))
    # Gram-Schmidt in order: a column that adds nothing is dropped.
    for j, n in enumerate(proposed):
        v = perp[:, j] - basis @ (basis.T @ perp[:, j])
        if np.linalg.norm(v) > rtol * np.linalg.norm(Jc[:, j]):
            keep.append(n)
            basis = np.column_stack([basis, v / np.linalg.norm(v)])
    dropped = tuple(n for n in proposed if n not in keep)
    stat = float(np.sum((basis.T @ r_w) ** 2))
    q = len(keep)
    if not q:
        return CandidateTest(name, (), dropped, 0.0, 0, 1.0, -np.inf)
    return CandidateTest(name, tuple(keep), dropped, stat, q, float(stats.chi2.sf(stat, q)),
                         wilson_hilferty(stat, q))


def wilson_hilferty(x, k):
    """
    Return the normal score of a chi2(k) value x; monotone in p.

    z = ((x/k)^(1/3) - 1 + 2/(9k)) / sqrt(2/(9k)).
    """
    return float(((x / k) ** (1 / 3) - 1 + 2 / (9 * k)) / np.sqrt(2 / (9 * k)))


def pose_chi2(model, meas):
    """Per-pose chi-square contributions Gamma_k^T Sigma_k^-1 Gamma_k (K,) of a model."""
    r_w = idf.whitened_problem(model, meas, ())[0]
    return np.sum(r_w.reshape(-1, 3) ** 2, axis=1)


def position_errors(model, meas):
    """
    Return the 3D distance (K,), m, between the effector positions of the model and the camera.

    That is, between where the model puts the effector (FK of its arm angles) and where the camera
    saw it (P0 + Pi_k).
    """
    Pi = effects.camera_increments(model.effects, meas.Pi, model.desc.camera_rotation)
    P_seen = model.P0 + Pi
    theta, _ = effects.model_joint_angles(model.desc, model.effects, meas.Theta, meas.direction,
                                          P_seen)
    return np.linalg.norm(delta.forward(model.desc, theta) - P_seen, axis=1)


def split(K, holdout_fraction, rng):
    """Random train / held-out split of K poses; both sorted (visit order kept)."""
    order = rng.permutation(K)
    n_hold = int(round(holdout_fraction * K))
    return np.sort(order[n_hold:]), np.sort(order[:n_hold])


def correlations(model, meas, features):
    """Correlation of each leg's whitened residual with each feature: [(feature, leg, r, p)]."""
    r_w = idf.whitened_problem(model, meas, ())[0].reshape(-1, 3)
    out = []
    for fname, values in features.items():
        for leg in range(3):
            f = values[:, leg] if values.ndim == 2 else values
            if np.ptp(f) == 0:
                continue
            r, p = stats.pearsonr(f, r_w[:, leg])
            out.append((fname, leg + 1, float(r), float(p)))
    return out


def residual_features(model, meas, sphere, stamps):
    """Return what a residual may correlate with, per pose (and per joint where it applies)."""
    theta = model.desc.theta0 + meas.Theta
    P = model.P0 + meas.Pi
    return {
        'joint angle': theta,
        'joint angle squared': theta ** 2,
        'motion direction': meas.direction,
        'gravity torque': effects.gravity_torque(model.desc, P, theta),
        'image x': sphere[:, 0] / sphere[:, 2],
        'image y': sphere[:, 1] / sphere[:, 2],
        'range': sphere[:, 2],          # the detector's depth error grows with it
        'time': np.asarray(stamps, dtype=float),
    }


def run(declared, meas, sphere, stamps, holdout_fraction=0.3, seed=0, alpha=ALPHA, progress=None):
    """
    Run the residual loop on one session (see the module docstring).

    Parameters
    ----------
    declared : RobotDescription
        The description the session ran with (the nominal start).
    meas : Measurements
        All rests, in visit order (Session.measurements()).
    sphere, stamps : numpy.ndarray
        (K, 3) camera-frame sphere centres and (K,) rest times, for the fallback.
    holdout_fraction : float
        Share of the rests held out.
    seed : int
        Seed of the random train / held-out split.
    alpha : float
        Significance level of the tests.
    progress : callable or None
        Called with a line of text as the loop goes.

    """
    rng = np.random.default_rng(seed)
    train, hold = split(len(meas), holdout_fraction, rng)
    m_train, m_hold = meas.subset(train), meas.subset(hold)
    say = progress or (lambda text: None)

    start = idf.initial_model(declared, m_train)
    nominal = idf.identify(start, m_train, ('P0x', 'P0y', 'P0z'))
    say('fitting the plain 15-parameter model')
    plain = idf.identify(start, m_train)
    current, steps, found = plain, [], []
    remaining = list(CANDIDATES)
    while remaining:
        tests = [score_test(current, m_train, name) for name in remaining]
        best = max(tests, key=lambda t: t.z)
        step = Step(tests, best.name, chi2_before=current.chi2)
        steps.append(step)
        if best.p_value >= alpha / len(tests):
            step.reason = f'no candidate significant (smallest p = {best.p_value:.3g})'
            break
        say(f'adding {best.name} ({", ".join(best.parameters)})')
        trial = idf.identify(with_candidate(current.model, best.name), m_train,
                             current.names + best.parameters)
        step.chi2_after = trial.chi2
        step.lr_p_value = float(stats.chi2.sf(current.chi2 - trial.chi2, best.dof))
        before, after = pose_chi2(current.model, m_hold), pose_chi2(trial.model, m_hold)
        step.holdout_p_value = float(stats.ttest_rel(before, after, alternative='greater').pvalue)
        remaining.remove(best.name)
        if step.lr_p_value < alpha and step.holdout_p_value < alpha:
            step.kept, step.reason = True, 'fit and held-out poses improved significantly'
            current = trial
            found.append(best.name)
        else:
            step.reason = 'rejected: no significant improvement ' + \
                ('on the held-out poses' if step.lr_p_value < alpha else 'of the fit')
    size = {'chi2': current.chi2, 'dof': current.dof,
            'p_value': float(stats.chi2.sf(current.chi2, current.dof)),
            'plain_chi2': plain.chi2, 'plain_p_value': float(stats.chi2.sf(plain.chi2, plain.dof))}
    fallback = []
    if size['p_value'] < alpha:
        feats = residual_features(current.model, m_train, sphere[train], np.asarray(stamps)[train])
        tests = correlations(current.model, m_train, feats)
        fallback = sorted((t for t in tests if t[3] < alpha / len(tests)), key=lambda t: t[3])
    errors = {name: float(np.sqrt(np.mean(position_errors(r.model, m_hold) ** 2)) * 1e3)
              for name, r in (('nominal', nominal), ('plain', plain), ('final', current))}
    holdout_chi2 = {name: float(np.sum(pose_chi2(r.model, m_hold)))
                    for name, r in (('nominal', nominal), ('plain', plain), ('final', current))}
    return Diagnosis(plain, current, found, steps, train, hold, size, errors, holdout_chi2,
                     fallback)
