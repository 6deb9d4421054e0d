"""
The residual loop: find what the model lacks, add it, and prove it helped on held-out poses.

1. Fit the paper's 15 parameters on the training poses together with the rests' error floor
   (robotenis_kinematics.variance: what each rest gets wrong beyond its frames' spread, learned by
   REML); hold the other poses out.
2. Test the residuals for every candidate: the named effects (``NAMED``) and the two generic ones
   (``GENERIC``: harmonics in each joint's angle, a polynomial field of the camera's coordinates,
   for effects no library names), with a score (Lagrange multiplier) test: with Q_c an orthonormal
   basis of the candidate's whitened columns after the current model's columns are projected out,
   |Q_c^T r_w|^2 follows chi2(q) when the effect is absent. The Jacobian is taken at the
   observations adjusted to the current fit (``identification.adjusted``), whose error is
   uncorrelated with the residuals: at the measurements it shares their noise, and a smooth
   field's columns, once the model's are projected out, would be mostly that noise. A generic
   candidate's size (the harmonics' orders, the field's coefficients) is chosen first by K-fold
   cross-validation on the training poses only, never on the held-out ones.
3. Take the most significant named candidate if one is significant (Bonferroni over the
   candidates left), else the most significant generic one, keeping only its parameters that are
   identifiable together with the rest (H_i beside h_i is not), and refit.
4. Keep it only if the fit improves significantly (likelihood ratio, chi2(q), at the current
   floor) and the held-out poses confirm it (``holdout_confirmation``: their residuals under
   the model before move as the model after predicts, beyond their noise). A named effect is
   then confronted with the generic ones (encompassing score tests: does each add to the
   other?): it is claimed only if no generic model adds to it; if a generic adds and the name
   adds nothing to the generic, the generic stands and the name is dropped (a library effect
   that explains a part of an unknown one is not that effect); if each adds to the other, the
   generic stands and the name must still add on top of it in a later round to be claimed.
   It is then confronted with the other significant named effects in the same way: a rival
   that adds to it where it adds nothing to the rival explains more and is claimed instead (if
   it improves the held-out poses, and after it has met the generic ones as the first did; if
   a generic explains it, that generic or, unconfirmed, the first stands); a rival that
   neither adds to it nor gains from it is the
   same explanation on these poses, and is reported beside the claim as indistinguishable
   (``Step.equivalent``), not silently lost to a score a fraction higher. After each effect
   kept the floor is learned again; repeat until no candidate is left significant.
5. The held-out poses then test the whole model and floor: their chi-square against chi2(3K)
   (with the fitted parameters' own error in the predictive covariance). If it is too large, a
   fallback tests the residuals' correlation with what could explain them (joint angle, motion
   direction, gravity torque, image position, range, time) and flags it.

Every decision runs at the significance level ``ALPHA`` (Bonferroni-corrected where candidates
compete) and needs three tests to pass, so on data with no effect the loop claims one in far fewer
than ALPHA of the sessions.
"""
from dataclasses import dataclass, field
import functools

import numpy as np
from robotenis_kinematics import delta, effects, variance, workspace
from robotenis_kinematics import identification as idf
from scipy.special import chdtrc, chdtri, ndtr, stdtr

ALPHA = 0.01
WORKSPACE_POSES = 200    # boundary poses over which the fit's FK uncertainty is reported
NAMED = ('joint_scale', 'base_geometry', 'hand_eye_rotation', 'backlash', 'gravity_compliance')
GENERIC = ('joint_harmonics', 'camera_field')
CANDIDATES = NAMED + GENERIC
ORDERS = tuple(range(1, 9))     # harmonics of a joint's angle a short series may pick
MAX_ORDERS = 4                  # the series' length at most
DEGREE = 3                      # of the camera field's monomials a field may pick from
MAX_FIELD_TERMS = 6             # the field's coefficients at most
FOLDS = 5
FEATURES = ('joint angle', 'joint angle squared', 'motion direction', 'gravity torque', 'range',
            'image x', 'image y', 'time')


def generic_terms(name, size):
    """
    Return the effect terms of a generic candidate.

    ``size``: the harmonics' orders (a tuple); the camera field's degree, or the parameters
    chosen (a tuple of names such as 'camera_w3').
    """
    if name == 'joint_harmonics':
        return effects.joint_term_names(size)
    if isinstance(size, tuple):
        return tuple(dict.fromkeys(p[:-1] for p in size))
    return effects.camera_term_names(size)


def candidate_parameters(name, size=None):
    """Return the parameter names a candidate proposes (before the identifiability check)."""
    if name == 'base_geometry':
        # phi1 stays as declared: it sets the base frame's yaw (x along leg 1). Free, it turns the
        # whole robot about z, which to the hand camera is its own turn about z (the rotation
        # vector's z of hand_eye_rotation) with the ball moved: no pose tells them apart.
        return ('H1', 'H2', 'H3', 'phi2', 'phi3')
    if name == 'camera_field' and isinstance(size, tuple):
        return size
    if name in GENERIC:
        return tuple(p for term in generic_terms(name, size) for p in idf.effect_names(term)
                     if p not in effects.UNSEEN)
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
    size: object = None      # a generic candidate's orders or parameters, by cross-validation


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
    generic_p_value: float = None   # p of the generic rivals adding to the named effect
    # named effects these poses cannot tell from the chosen one: (name, p that it adds to the
    # chosen one, p that the chosen one adds to it)
    equivalent: list = field(default_factory=list)


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
    floor: variance.Floor = None    # the rests' error floor learned with the final model
    fallback: list = field(default_factory=list)
    sizes: dict = field(default_factory=dict)     # generic effect -> orders or parameters kept
    correlates: dict = field(default_factory=dict)  # generic effect -> generic_correlations

    @property
    def indistinguishable(self):
        """Return {effect claimed: [named effects these poses cannot tell from it]}."""
        return {step.chosen: [name for name, _, _ in step.equivalent]
                for step in self.steps if step.kept and step.equivalent}

    @functools.cached_property
    def workspace_fk_std_mm(self):
        """
        Return the RMS and largest standard deviation (mm) of the final fit's FK, workspace-wide.

        At WORKSPACE_POSES boundary poses of the fitted geometry (a fixed draw), from the fit's
        own covariance (identification.fk_covariance): how far from the poses it measured the
        calibration can be trusted, which needs no truth. A session whose poses cover little of
        the workspace, or whose rests err by more than their frames show, reads large here
        however small its held-out error. Returns (rms, largest, poses): poses where the final
        model cannot assemble the robot (its joint effects, extrapolated to the boundary, put the
        arms where the forearms do not meet) are left out of both; with none left, inf.
        """
        desc = self.final.model.desc
        P = workspace.boundary_poses(desc, WORKSPACE_POSES, np.random.default_rng(0))
        Theta = delta.inverse(desc, P) - desc.theta0
        C = assembled_fk_covariance(self.final, Theta, effects.motion_direction(Theta))
        if not len(C):
            return np.inf, np.inf, 0
        sd = np.sqrt(np.trace(C, axis1=1, axis2=2))
        return float(np.sqrt(np.mean(sd ** 2)) * 1e3), float(sd.max() * 1e3), len(C)


def assembled_fk_covariance(result, Theta, direction):
    """Return identification.fk_covariance (n, 3, 3) at the poses the fit's model assembles."""
    try:
        return idf.fk_covariance(result, Theta, direction)
    except ValueError:              # some poses it cannot assemble: each of the others alone
        out = []
        for k in range(len(Theta)):
            try:
                out.append(idf.fk_covariance(result, Theta[k:k + 1], direction[k:k + 1])[0])
            except ValueError:
                continue
        return np.reshape(out, (-1, 3, 3))


def with_candidate(model, name, size=None):
    """Return the model with a candidate's terms present at zero effect."""
    terms = generic_terms(name, size) if name in GENERIC else (name,)
    fresh = {t: np.zeros(3) for t in terms if effects.is_effect(t) and t not in model.effects}
    return idf.Model(model.desc, model.P0, {**model.effects, **fresh}) if fresh else model


def candidate_problem(result, meas, name, size=None):
    """
    Return (proposed names, r_w, J_w) at the current fit with the candidate's terms at zero.

    Both in the Gauss-Helmert form (at the adjusted observations, see the module docstring); the
    Jacobian holds the fit's parameters, then the candidate's.
    """
    proposed = tuple(n for n in candidate_parameters(name, size) if n not in result.names)
    model = with_candidate(result.model, name, size)
    r_w, J_w = idf.whitened_problem(model, meas, result.names + proposed, adjust=True)
    return proposed, r_w, J_w


def identifiable(J, p, rtol=1e-6):
    """
    Return (kept column indices beyond the first p, orthonormal basis of what they add).

    Gram-Schmidt in order on J's columns after the first p are projected out: a column that adds
    less than ``rtol`` of its norm depends on the others and is dropped.
    """
    Q, _ = np.linalg.qr(J[:, :p])
    C = J[:, p:]
    perp = C - Q @ (Q.T @ C)
    keep, basis = [], np.zeros((len(C), 0))
    for j in range(C.shape[1]):
        v = perp[:, j] - basis @ (basis.T @ perp[:, j])
        v = v - basis @ (basis.T @ v)        # twice: orthogonal to working precision
        size = np.linalg.norm(v)
        if size > rtol * np.linalg.norm(C[:, j]):
            keep.append(j)
            basis = np.column_stack([basis, v / size])
    return keep, basis


def score_test(result, meas, name, size=None):
    """Score test of candidate ``name`` at the fitted ``result`` (see the module docstring)."""
    proposed, r_w, J_w = candidate_problem(result, meas, name, size)
    keep, basis = identifiable(J_w, len(result.names))
    kept = tuple(proposed[j] for j in keep)
    dropped = tuple(n for n in proposed if n not in kept)
    stat = float(np.sum((basis.T @ r_w) ** 2))
    q = len(kept)
    if not q:
        return CandidateTest(name, (), dropped, 0.0, 0, 1.0, -np.inf, size)
    return CandidateTest(name, kept, dropped, stat, q, float(chdtrc(q, stat)),
                         wilson_hilferty(stat, q), size)


def wilson_hilferty(x, k):
    """
    Return the normal score of a chi2(k) value x, monotone in its p-value.

    ((x / k)^(1/3) - 1 + 2 / (9 k)) / sqrt(2 / (9 k)).
    """
    return float(((x / k) ** (1 / 3) - 1 + 2 / (9 * k)) / np.sqrt(2 / (9 * k)))


def cross_validated_size(result, meas, name, rng, folds=FOLDS):
    """
    Return the size of a generic candidate that predicts left-out training rests best, or None.

    Linearised at the current fit: a size's whitened residuals are fitted on the current
    parameters and the candidate's terms with one fold of the rests left out, and the left-out
    fold predicted. Both generic candidates grow by forward selection, one item at a time: the
    joint harmonics an order (its cos and sin on every joint, at most
    MAX_ORDERS), the camera field one coefficient of a monomial up to DEGREE along one optical
    axis (at most MAX_FIELD_TERMS), while the gain beats what chance gives the best of the items
    left (``_forward_selection``). A sparse field matters: a full linear field is nearly a change
    of the robot's own geometry, so every coefficient it needs not costs kinematic accuracy that
    the camera cannot see. None (no term) wins unless a size predicts better.
    """
    largest = ORDERS if name == 'joint_harmonics' else DEGREE
    proposed, r_w, J_w = candidate_problem(result, meas, name, largest)
    p = len(result.names)
    cv = _FoldedProblem(r_w, J_w, np.repeat(rng.permutation(len(meas)) % folds, 3), folds)
    if name == 'joint_harmonics':
        pool, most = ORDERS, MAX_ORDERS
    else:
        pool, most = proposed, MAX_FIELD_TERMS

    def columns(size):
        # identifiable within this size only: over a joint's short range of angle the whole
        # pool is nearly dependent, and checking it in order would drop a high order's sine
        extra = [p + proposed.index(n) for n in candidate_parameters(name, size)
                 if n in proposed] if size else []
        keep = identifiable(J_w[:, list(range(p)) + extra], p)[0]
        return list(range(p)) + [extra[j] for j in keep]

    chosen = _forward_selection(pool, most, lambda size: cv.error(columns(size)),
                                lambda n: len(columns((n,))) - p)
    return chosen or None


def _forward_selection(pool, most, error, width, alpha=ALPHA):
    """
    Grow a tuple of items of ``pool`` (kept in pool order) while ``error`` of it falls enough.

    For an item of q parameters that explains nothing, the cross-validated error changes by
    about 2 q - chi2(q) (the fit's gain on the folds it sees, paid twice on the one it predicts,
    as in Akaike's criterion), so the best of n such items would lower it most times; an item is
    taken only if it lowers the error by more than the largest of n null items would at level
    alpha: chi2_(1 - alpha/n)(q) - 2 q.
    """
    chosen, best = (), error(())
    while len(chosen) < most:
        left = [n for n in pool if n not in chosen]
        if not left:
            break
        trials = {n: error(_in_order(pool, chosen + (n,))) for n in left}
        n = min(trials, key=trials.get)
        q = max(width(n), 1)
        if best - trials[n] <= chdtri(q, alpha / len(left)) - 2 * q:
            break
        chosen, best = _in_order(pool, chosen + (n,)), trials[n]
    return chosen


def _in_order(pool, items):
    return tuple(n for n in pool if n in items)


class _FoldedProblem:
    """
    A linear least-squares problem r ~ J x split in folds, for K-fold prediction errors.

    Each fold's normal equations (columns scaled to unit norm) are summed once, so the prediction
    error of any subset of columns costs a few small solves, not a factorisation of J per fold.
    """

    def __init__(self, r, J, fold, folds):
        scale = np.linalg.norm(J, axis=0)
        J = J / np.where(scale > 0, scale, 1.0)
        parts = [fold == f for f in range(folds)]
        self.G = np.array([J[o].T @ J[o] for o in parts])
        self.b = np.array([J[o].T @ r[o] for o in parts])
        self.rr = np.array([r[o] @ r[o] for o in parts])

    def error(self, columns):
        """Return the sum over folds of the squared prediction errors of the left-out fold."""
        S = np.ix_(columns, columns)
        G_all, b_all = self.G.sum(axis=0)[S], self.b.sum(axis=0)[columns]
        total = 0.0
        for G, b, rr in zip(self.G, self.b, self.rr):
            x = np.linalg.solve(G_all - G[S], b_all - b[columns])
            total += rr - 2 * b[columns] @ x + x @ G[S] @ x
        return float(total)


def pose_chi2(model, meas):
    """Return the per-pose chi-square contributions Gamma_k^T Sigma_k^-1 Gamma_k (K,)."""
    r_w = idf.whitened_problem(model, meas, ())[0]
    return np.sum(r_w.reshape(-1, 3) ** 2, axis=1)


def position_errors(model, meas):
    """
    Return the 3D distance (K,) between the model's effector and the camera's, m.

    The model's is the FK of its arm angles; the camera's is P0 + Pi_k.
    """
    Pi = effects.camera_increments(model.effects, meas.Pi, model.desc.camera_rotation,
                                   meas.Pi_basis)
    P_seen = model.P0 + Pi
    theta, _ = effects.model_joint_angles(model.desc, model.effects, meas.Theta, meas.direction,
                                          P_seen)
    return np.linalg.norm(delta.forward(model.desc, theta) - P_seen, axis=1)


def split(K, holdout_fraction, rng):
    """Split K poses at random into train and held-out; both sorted (visit order kept)."""
    order = rng.permutation(K)
    n_hold = int(round(holdout_fraction * K))
    return np.sort(order[n_hold:]), np.sort(order[:n_hold])


def correlations(model, meas, features):
    """Return the correlation of each leg's whitened residual with each feature, as tuples."""
    r_w = idf.whitened_problem(model, meas, ())[0].reshape(-1, 3)
    out = []
    for fname, values in features.items():
        for leg in range(3):
            f = values[:, leg] if values.ndim == 2 else values
            if np.ptp(f) == 0:
                continue
            r, p = pearson(f, r_w[:, leg])
            out.append((fname, leg + 1, r, p))
    return out


def pearson(x, y):
    """Return Pearson's r of x and y and its two-sided p-value (Student's t, n - 2 dof)."""
    r = float(np.clip(np.corrcoef(x, y)[0, 1], -1.0, 1.0))
    dof = len(x) - 2
    if abs(r) == 1.0:
        return r, 0.0
    t = abs(r) * np.sqrt(dof / (1 - r * r))
    return r, float(2 * stdtr(dof, -t))


def residual_features(model, meas, sphere, stamps):
    """Return, per pose (and per joint where it applies), what a residual may correlate with."""
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


def generic_error(model, meas, name):
    """
    Return the error (K, 3) a fitted generic effect models at each pose, and what it is along.

    joint_harmonics: the arm angle error of each joint (rad); camera_field: the measurement
    error of the sphere centre along each optical axis (m).
    """
    if name == 'joint_harmonics':
        terms = {t: v for t, v in model.effects.items() if effects.JOINT_TERM.match(t)}
        theta = effects.model_joint_angles(model.desc, terms, meas.Theta, meas.direction, None)[0]
        return theta - model.desc.theta0 - meas.Theta, 'joint'
    sphere = -meas.Pi_basis @ model.desc.camera_rotation
    return sum(np.outer(effects.camera_basis(t, sphere), v) for t, v in model.effects.items()
               if effects.is_camera_term(t)), 'axis'


def generic_correlations(model, meas, sphere, stamps, name, top=3):
    """
    Return what a fitted generic effect's error correlates with: [(feature, component, r)].

    The strongest ``top`` correlations over the poses between each component of its error
    (joint 1-3 or optical axis x, y, z) and the residual features (a joint's own feature for a
    joint's error).
    """
    error, kind = generic_error(model, meas, name)
    out = []
    for fname, values in residual_features(model, meas, sphere, stamps).items():
        for c in range(3):
            f = values[:, c] if values.ndim == 2 else values
            if values.ndim == 2 and kind == 'axis' or np.ptp(f) == 0 or np.ptp(error[:, c]) == 0:
                continue
            label = f'joint {c + 1}' if kind == 'joint' else f'optical {"xyz"[c]}'
            out.append((fname, label, float(np.corrcoef(f, error[:, c])[0, 1])))
    return sorted(out, key=lambda t: -abs(t[2]))[:top]


def holdout_test(result, floor, meas, R):
    """
    Return the held-out poses' chi-square, its dof and p-value, under the fit and its floor.

    The predictive covariance of each held-out residual adds the fitted parameters' own error,
    J C J^T, to the rests' (frames and floor).
    """
    r, J = idf.whitened_problem(result.model, floor.widen(meas, R), result.names)
    predictive = np.eye(len(r)) + J @ result.covariance @ J.T
    chi2 = float(r @ np.linalg.solve(predictive, r))
    return chi2, len(r), float(chdtrc(len(r), chi2))


def holdout_confirmation(before, after, hold):
    """
    Return the one-sided p-value that the held-out poses move as ``after`` predicts.

    With r the held-out whitened residuals under ``before``, P = I + J C J^T their predictive
    covariance (the fitted parameters' own error added, as in ``holdout_test``) and d = r - r_after
    the change ``after`` predicts, z = d^T P^-1 r / sqrt(d^T P^-1 d) is N(0, 1) when what
    ``after`` adds is absent: d then depends on the training noise only through the added
    coefficients, which are independent of ``before``'s parameters (their columns are projected
    out of them), and r on the held-out noise and those parameters. A real effect leaves its
    signal in r along d. This is the score test along the one direction the training poses
    predict, far more powerful than comparing per-pose chi-squares, whose squared noise swamps
    an effect of a few noise widths.
    """
    r, J = idf.whitened_problem(before.model, hold, before.names)
    d = r - idf.whitened_problem(after.model, hold, ())[0]
    w = np.linalg.solve(np.eye(len(r)) + J @ before.covariance @ J.T, d)
    spread = float(np.sqrt(max(d @ w, 0.0)))
    return float(ndtr(-(w @ r) / spread)) if spread > 0 else 1.0


class _Loop:
    """The state of one run: the split, the current fit and floor, the steps so far."""

    def __init__(self, declared, meas, holdout_fraction, seed, alpha, say):
        self.rng = np.random.default_rng(seed)
        self.train, self.hold = split(len(meas), holdout_fraction, self.rng)
        self.m_train, self.m_hold = meas.subset(self.train), meas.subset(self.hold)
        self.R, self.alpha, self.say = declared.camera_rotation, alpha, say
        self.start = idf.initial_model(declared, self.m_train)
        say("fitting the plain 15-parameter model and the rests' error floor")
        self.plain, self.floor = variance.identify(self.start, self.m_train)
        self.current, self.steps, self.found, self.sizes = self.plain, [], [], {}

    def widened(self, meas):
        return self.floor.widen(meas, self.R)

    def fit(self, test):
        """Return the current model with a tested candidate's identifiable parameters, fitted."""
        return idf.identify(with_candidate(self.current.model, test.name, test.size),
                            self.widened(self.m_train), self.current.names + test.parameters)

    def compare(self, before, after):
        """Return the one-sided p-value that the held-out poses confirm ``after``."""
        return holdout_confirmation(before, after, self.widened(self.m_hold))

    def tests(self, remaining):
        """Return the score tests of the candidates left (generic ones at their CV size)."""
        train = self.widened(self.m_train)
        out = []
        for name in remaining:
            if name in GENERIC:
                size = cross_validated_size(self.current, train, name, self.rng)
                if size is not None:
                    out.append(score_test(self.current, train, name, size))
            else:
                out.append(score_test(self.current, train, name))
        return out

    def step(self, remaining):
        """Run one round; return the candidates it used up (None to stop)."""
        tests = self.tests(remaining)
        if not tests:
            return None
        significant = [t for t in tests if t.p_value < self.alpha / len(tests)]
        # a name first: the most significant named effect, if any is, a generic one challenges it
        named = [t for t in significant if t.name in NAMED]
        best = max(named or tests, key=lambda t: t.z)
        step = Step(tests, best.name, chi2_before=self.current.chi2)
        self.steps.append(step)
        if not significant:
            smallest = min(t.p_value for t in tests)
            step.reason = f'no candidate significant (smallest p = {smallest:.3g})'
            return None
        self.say(f'adding {best.name} ({", ".join(best.parameters)})')
        trial = self.fit(best)
        step.chi2_after = trial.chi2
        step.lr_p_value = float(chdtrc(best.dof, self.current.chi2 - trial.chi2))
        step.holdout_p_value = self.compare(self.current, trial)
        if not (step.lr_p_value < self.alpha and step.holdout_p_value < self.alpha):
            step.reason = 'rejected: no significant improvement ' + \
                ('on the held-out poses' if step.lr_p_value < self.alpha else 'of the fit')
            return [best.name]
        name, size, used = best.name, best.size, [best.name]
        if name in NAMED:
            name, size, trial, used = self.claim_named(step, best, trial, tests, significant)
            if name is None:
                return used
        step.kept = True
        step.reason = step.reason or 'fit and held-out poses improved significantly'
        self.accept(name, size, trial)
        return used

    def claim_named(self, step, best, trial, tests, significant):
        """
        Return (effect or None, size, fit, candidates used up) for a named effect that helped.

        ``attribute`` confronts it with the generic effects and, if it stands, ``distinguish``
        with the other named ones. A named rival claimed instead meets the generic effects in its
        turn: it stands, or a generic that explains it is claimed; if neither does, ``best``
        stands (no generic explained it).
        """
        claim = self.attribute(step, best, trial, tests)
        if claim[0] != best.name:
            return claim
        rival, rival_trial = self.distinguish(step, best, trial, significant)
        if rival is best:
            return claim
        reason = step.reason
        name, size, fit, used = self.attribute(step, rival, rival_trial, tests)
        if name is not None:
            return name, size, fit, used
        step.chosen = best.name
        step.reason = f'{reason}; but {step.reason}: {best.name} stands'
        return claim

    def attribute(self, step, best, trial, tests):
        """
        Return (effect or None, size, fit, candidates used up) for a named effect that helped.

        Encompassing tests on the training poses, for each generic rival: does the generic add to
        the named effect (score test at the named fit, its size chosen again by cross-validation
        there: what is left that it would model), and does the named effect add to the generic
        (score test at the generic fit)? If no generic adds, the named effect explains what they
        would: it is claimed, a name with fewer parameters. If a generic adds and the name adds
        nothing to it, the name explains only a part of what the generic explains: the name is
        not claimed, and the generic stands if it improves the held-out poses (else neither
        does). If each adds to the other the evidence is ambiguous: the generic stands if it
        improves the held-out poses, and the name stays a candidate, to be claimed only if it
        still adds on top of it.
        """
        train = self.widened(self.m_train)
        for rival in sorted((t for t in tests if t.name in GENERIC), key=lambda t: -t.z):
            left = cross_validated_size(trial, train, rival.name, self.rng)
            adds = 1.0 if left is None else score_test(trial, train, rival.name, left).p_value
            step.generic_p_value = adds if step.generic_p_value is None else \
                min(adds, step.generic_p_value)
            if adds >= self.alpha:
                continue
            generic = self.fit(rival)
            named_adds = score_test(generic, train, best.name).p_value
            confirmed = self.compare(self.current, generic) < self.alpha
            evidence = (f'{rival.name} adds to {best.name} (p = {adds:.3g}), {best.name} adds '
                        f'{"nothing " if named_adds >= self.alpha else ""}to {rival.name} '
                        f'(p = {named_adds:.3g})')
            if named_adds >= self.alpha:
                step.chosen = rival.name if confirmed else best.name
                step.reason = (f'{best.name} helped, but {evidence}: {best.name} is not claimed'
                               + ('' if confirmed else f', and {rival.name} does not improve '
                                  'the held-out poses'))
                return ((rival.name, rival.size, generic, [best.name, rival.name]) if confirmed
                        else (None, None, None, [best.name]))
            if confirmed:
                step.chosen = rival.name
                step.reason = (f'{best.name} helped, but {evidence}: ambiguous, {rival.name} '
                               f'stands and {best.name} must add to it to be claimed')
                return rival.name, rival.size, generic, [rival.name]
        return best.name, None, trial, [best.name]

    def distinguish(self, step, best, trial, significant):
        """
        Return (test, its fit): ``best`` or another named effect's that explains more.

        Encompassing tests between the named candidates significant this round, as ``attribute``
        runs them against the generic ones: does the rival add to ``best`` (score test at best's
        fit), and does ``best`` add to the rival (at the rival's)? A rival that adds where best
        adds nothing to it is claimed instead, if it improves the held-out poses; one that
        neither adds nor gains is indistinguishable from best on these poses (step.equivalent).
        """
        train = self.widened(self.m_train)
        for rival in sorted((t for t in significant if t.name in NAMED and t.name != best.name),
                            key=lambda t: -t.z):
            adds = score_test(trial, train, rival.name).p_value
            rival_fit = self.fit(rival)
            gains = score_test(rival_fit, train, best.name).p_value
            if gains >= self.alpha and adds < self.alpha \
                    and self.compare(self.current, rival_fit) < self.alpha:
                step.chosen = rival.name
                step.reason = (f'{best.name} helped, but {rival.name} adds to it (p = '
                               f'{adds:.3g}) and {best.name} adds nothing to {rival.name} (p = '
                               f'{gains:.3g}): {rival.name} is claimed')
                step.equivalent = []
                return rival, rival_fit
            if gains >= self.alpha and adds >= self.alpha:
                step.equivalent.append((rival.name, adds, gains))
        if step.equivalent:
            step.reason = ('fit and held-out poses improved significantly; these poses cannot '
                           'tell it from ' + ', '.join(
                               f'{n} (neither adds to the other: p = {a:.2g}, {g:.2g})'
                               for n, a, g in step.equivalent))
        return best, trial

    def accept(self, name, size, trial):
        self.found.append(name)
        if size:
            self.sizes[name] = size
        self.current, self.floor = variance.identify(trial.model, self.m_train, trial.names,
                                                     self.floor)


def run(declared, meas, sphere, stamps, holdout_fraction=0.3, seed=0, alpha=ALPHA, progress=None):
    """
    Run the residual loop on one session (see the module docstring).

    Parameters
    ----------
    declared : RobotDescription
        The description the session ran with (the nominal start).
    meas : Measurements
        All rests, in visit order (Session.measurements()), with their frames' covariances.
    sphere : (K, 3) array
        Camera-frame sphere centres, for the fallback.
    stamps : (K,) array
        Rest times, for the fallback.
    holdout_fraction : float
        Share of the poses held out.
    seed : int
        Seed of the split and of the cross-validation folds.
    alpha : float
        Significance level of every decision.
    progress : callable or None
        Called with a line of text at each stage.

    """
    say = progress or (lambda text: None)
    loop = _Loop(declared, meas, holdout_fraction, seed, alpha, say)
    remaining = list(CANDIDATES)
    while remaining:
        used = loop.step(remaining)
        if used is None:
            break
        remaining = [name for name in remaining if name not in used + loop.found]
    return _diagnosis(loop, meas, sphere, stamps, alpha)


def _diagnosis(loop, meas, sphere, stamps, alpha):
    current, floor = loop.current, loop.floor
    nominal = idf.identify(loop.start, floor.widen(loop.m_train, loop.R), ('P0x', 'P0y', 'P0z'))
    chi2, dof, p = holdout_test(current, floor, loop.m_hold, loop.R)
    size = {'chi2': chi2, 'dof': dof, 'p_value': p, 'train_chi2': current.chi2,
            'train_dof': current.dof}
    fallback = []
    if p < alpha:
        m_hold = floor.widen(loop.m_hold, loop.R)
        feats = residual_features(current.model, m_hold, sphere[loop.hold],
                                  np.asarray(stamps)[loop.hold])
        tests = correlations(current.model, m_hold, feats)
        fallback = sorted((t for t in tests if t[3] < alpha / len(tests)), key=lambda t: t[3])
    models = (('nominal', nominal), ('plain', loop.plain), ('final', current))
    hold = floor.widen(loop.m_hold, loop.R)
    errors = {name: float(np.sqrt(np.mean(position_errors(r.model, hold) ** 2)) * 1e3)
              for name, r in models}
    holdout_chi2 = {name: float(np.sum(pose_chi2(r.model, hold))) for name, r in models}
    correlates = {name: generic_correlations(current.model, meas, sphere, stamps, name)
                  for name in loop.found if name in GENERIC}
    return Diagnosis(loop.plain, current, loop.found, loop.steps, loop.train, loop.hold, size,
                     errors, holdout_chi2, floor, fallback, dict(loop.sizes), correlates)
