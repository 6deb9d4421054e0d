"""
Identification of the Delta robot's geometry from incremental measurements (paper, eqs. 3-8).

Each pose k gives the resolver increments Theta_k (rad) and the incremental effector position
Pi_k = P_k - P0 (m, base frame) measured by the hand camera (eq. 3). With
theta_ik = theta_i0 + Theta_ik the loop-closure equations of the three legs are (eq. 4)

    Gamma_ik = |P0 + Pi_k + h_i e_i - (H_i + a_i cos theta_ik) e_i - a_i sin theta_ik z|^2
               - b_i^2 = 0,

stacked leg by leg into Phi(U, V) (eq. 5). The paper's unknowns are U = [u_1 u_2 u_3 P0] with
u_i = [a_i b_i h_i theta_i0] (15 parameters); H_i and phi_i can be added for the observability
study, and so can the parameters of the effects the residual loop adds (``effects.py``):
joint-side effects shift theta_ik, the hand-eye rotation turns Pi_k.

Estimator
---------
Both the resolvers and the camera are noisy, so this is an errors-in-variables problem. We use
weighted least squares with propagated noise (the *effective variance* estimator): each pose's
three residuals Gamma_k get the covariance G_k Sigma_Vk G_k^T, with G_k = dGamma_k / dV_k the
derivative with respect to that pose's measurements V_k = [Theta_k, Pi_k], and are whitened by its
Cholesky factor. To first order in the noise this is the Gauss-Helmert maximum-likelihood
estimator (it minimises the same Mahalanobis distance after eliminating the corrections to V_k) at
a fraction of the cost, and its chi-square sum_k Gamma_k^T (G Sigma G^T)^-1 Gamma_k follows
chi2(3K - p) when the model is right -- the statistic the residual loop tests. The covariance of U
is (J_w^T J_w)^-1 with J_w the whitened observation matrix; evaluated at the true parameters it is
the Cramer-Rao bound.

One second-order term is not negligible everywhere: J_w evaluated at the measurements shares
their noise with the residuals, which biases the normal equations J_w^T r_w = 0 by O(K sigma^2).
For the paper's parameters that is nothing; for a smooth field of many terms (the residual loop's
camera field) it is most of what the field's columns add to the model's, and least squares would
fit a field to pure noise. ``identify`` therefore minimises the Gauss-Helmert objective itself:
residuals and Jacobian at the observations adjusted to the model (``adjusted``), whose error is
uncorrelated with the residuals.
"""
from dataclasses import dataclass, field, replace

import numpy as np

from robotenis_kinematics import delta, effects

LEG_PARAMETERS = ('a', 'b', 'h', 'H', 'phi', 'theta0')
PAPER_PARAMETERS = (tuple(f'{p}{i}' for i in (1, 2, 3) for p in ('a', 'b', 'h', 'theta0'))
                    + ('P0x', 'P0y', 'P0z'))
ALL_PARAMETERS = (tuple(f'{p}{i}' for i in (1, 2, 3) for p in LEG_PARAMETERS)
                  + ('P0x', 'P0y', 'P0z'))


@dataclass
class Measurements:
    """
    Incremental measurements of K poses and their noise.

    Theta : (K, 3) resolver increments from home, rad.
    Pi : (K, 3) incremental effector positions in the base frame, m.
    sigma_Theta : (3,) or (K, 3) standard deviation of each resolver increment, rad.
    cov_Pi : (3, 3) or (K, 3, 3) covariance of each Pi_k, m^2.
    direction : (K, 3) sign of each joint's last motion before pose k (for backlash); by default
        from the order of Theta (``effects.motion_direction``).
    Pi_basis : (K, 3) where the camera-field terms are evaluated; by default Pi itself
        (``adjusted`` gives the increments that keep the terms uncorrelated with the residuals).
    """

    Theta: np.ndarray
    Pi: np.ndarray
    sigma_Theta: np.ndarray
    cov_Pi: np.ndarray
    direction: np.ndarray = None
    Pi_basis: np.ndarray = None

    def __post_init__(self):
        self.Theta = np.asarray(self.Theta, dtype=float)
        self.Pi = np.asarray(self.Pi, dtype=float)
        K = len(self.Theta)
        if self.Theta.shape != (K, 3) or self.Pi.shape != (K, 3):
            raise ValueError('Theta and Pi must both be (K, 3);'
                             f' got {self.Theta.shape} and {self.Pi.shape}')
        if not (np.all(np.isfinite(self.Theta)) and np.all(np.isfinite(self.Pi))):
            raise ValueError('measurements contain NaN or infinite values')
        self.sigma_Theta = np.broadcast_to(np.asarray(self.sigma_Theta, dtype=float), (K, 3))
        self.cov_Pi = np.broadcast_to(np.asarray(self.cov_Pi, dtype=float), (K, 3, 3))
        if self.direction is None:
            self.direction = effects.motion_direction(self.Theta)
        self.Pi_basis = self.Pi if self.Pi_basis is None else np.asarray(self.Pi_basis, float)

    def __len__(self):
        return len(self.Theta)

    def subset(self, index):
        """Return the measurements of the poses selected by ``index``."""
        return Measurements(self.Theta[index], self.Pi[index], self.sigma_Theta[index],
                            self.cov_Pi[index], self.direction[index], self.Pi_basis[index])


@dataclass
class Model:
    """
    A point in parameter space.

    A robot description, the camera reference position P0, and the parameters of the effects in
    use (``effects.PARAMETERS``: name -> array of 3).
    """

    desc: object
    P0: np.ndarray
    effects: dict = field(default_factory=dict)

    def get(self, names):
        """Return the parameter vector U for the given parameter names (e.g. PAPER_PARAMETERS)."""
        return np.array([_get(self, n) for n in names])

    def with_values(self, names, U):
        """Return a new Model with the named parameters set to U."""
        desc = self.desc.copy()
        P0 = np.array(self.P0, dtype=float)
        fx = {k: np.array(v, dtype=float) for k, v in self.effects.items()}
        for n, u in zip(names, U):
            if n.startswith('P0'):
                P0['xyz'.index(n[2])] = u
            elif effects.is_effect(n[:-1]):
                fx.setdefault(n[:-1], np.zeros(3))[int(n[-1]) - 1] = u
            else:
                getattr(desc, n[:-1])[int(n[-1]) - 1] = u
        return Model(desc, P0, fx)


def _get(model, name):
    if name.startswith('P0'):
        return model.P0['xyz'.index(name[2])]
    if effects.is_effect(name[:-1]):
        return model.effects.get(name[:-1], np.zeros(3))[int(name[-1]) - 1]
    return getattr(model.desc, name[:-1])[int(name[-1]) - 1]


def effect_names(effect):
    """Parameter names of one effect, e.g. ('backlash1', 'backlash2', 'backlash3')."""
    return tuple(f'{effect}{i}' for i in (1, 2, 3))


def _leg_geometry(model, meas):
    """
    Return the legs' geometry at every pose.

    d_ik = C_ik - B_ik (K, 3, 3), theta_ik (K, 3), the effector positions P_k (K, 3), the
    joint-effect derivatives dtheta_ik/d(effect parameter i) and e_i, de_i/dphi_i (3, 3).
    """
    desc = model.desc
    Pi = effects.camera_increments(model.effects, meas.Pi, desc.camera_rotation, meas.Pi_basis)
    P = model.P0 + Pi
    theta, dtheta = effects.model_joint_angles(desc, model.effects, meas.Theta, meas.direction, P)
    d = delta.effector_joints(desc, P) - delta.elbow_points(desc, theta)
    e = delta.leg_directions(desc)
    de = np.stack([-e[:, 1], e[:, 0], np.zeros(3)], axis=-1)
    return d, theta, Pi, dtheta, e, de


def constraints(model, meas):
    """Gamma_ik (K, 3) of eq. (4); zero for exact measurements of the true model."""
    d = _leg_geometry(model, meas)[0]
    return np.einsum('kij,kij->ki', d, d) - model.desc.b ** 2


def partials(model, meas):
    """
    Return the derivatives of Gamma_ik, keyed by parameter.

    Each is (K, 3): with respect to leg i's own parameters ('a', 'b', 'h', 'H', 'phi', 'theta0'),
    to the joint angle ('theta', equal to 'theta0'), to the joint effects' parameter of joint i
    ('joint_scale', 'backlash', 'gravity_compliance'), and, shape (K, 3, 3), to P0 = Pi
    ('P': dGamma_ik / dP_j), to the hand-eye rotation vector
    ('hand_eye_rotation': dGamma_ik / dr_j = 2 (Pi_k x d_ik)_j, small rotations) and to each
    camera-field term's coefficients along the optical axes (dGamma_ik / df_a =
    2 phi(s_k) d_ik . R e_a, to first order in the field).
    """
    desc = model.desc
    d, theta, Pi, dtheta_fx, e, de = _leg_geometry(model, meas)
    d_e = np.einsum('kij,ij->ki', d, e)
    d_de = np.einsum('kij,ij->ki', d, de)
    d_z = d[..., 2]
    c, s = np.cos(theta), np.sin(theta)
    dtheta = 2 * desc.a * (s * d_e - c * d_z)
    out = {
        'a': -2 * (c * d_e + s * d_z),
        'b': np.broadcast_to(-2 * desc.b, d_e.shape),
        'h': 2 * d_e,
        'H': -2 * d_e,
        'phi': 2 * (desc.h - desc.H - desc.a * c) * d_de,
        'theta0': dtheta,
        'theta': dtheta,
        'P': 2 * d,
        'hand_eye_rotation': 2 * np.cross(Pi[:, None, :], d),
    }
    out.update({name: dtheta * dt for name, dt in dtheta_fx.items()})
    R = desc.camera_rotation
    sphere = -meas.Pi_basis @ R
    for name in model.effects:
        if effects.is_camera_term(name):
            phi = effects.camera_basis(name, sphere)
            out[name] = 2 * phi[:, None, None] * np.einsum('kij,ja->kia', d, R)
    return out


def observation_matrix(model, meas, names=PAPER_PARAMETERS, parts=None):
    """Return the observation matrix J = dPhi/dU (3K, p) of eq. (7), rows leg by leg (eq. 5)."""
    parts = partials(model, meas) if parts is None else parts
    K = len(meas)
    J = np.zeros((3, K, len(names)))
    for col, n in enumerate(names):
        if n.startswith('P0'):
            J[:, :, col] = parts['P'][:, :, 'xyz'.index(n[2])].T
        elif n.startswith('hand_eye_rotation') or effects.is_camera_term(n[:-1]):
            J[:, :, col] = parts[n[:-1]][:, :, int(n[-1]) - 1].T
        else:
            i = int(n[-1]) - 1
            J[i, :, col] = parts[n[:-1]][:, i]
    return J.reshape(3 * K, len(names))


def residual_covariance(meas, parts):
    """Covariance (K, 3, 3) of Gamma_k propagated from the noise of V_k = [Theta_k, Pi_k]."""
    g_theta = parts['theta'] * meas.sigma_Theta
    D = parts['P']
    return (np.einsum('ki,ij->kij', g_theta ** 2, np.eye(3))
            + np.einsum('kia,kab,kjb->kij', D, meas.cov_Pi, D))


def whitening(meas, parts):
    """Lower-triangular L_k^-1 (K, 3, 3) with L_k L_k^T the covariance of Gamma_k."""
    return _lower_inverse(np.linalg.cholesky(residual_covariance(meas, parts)))


def _lower_inverse(L):
    """Inverse of lower-triangular 3x3 matrices (K, 3, 3) by forward substitution, vectorised."""
    M = np.zeros_like(L)
    for i in range(3):
        M[:, i, i] = 1.0 / L[:, i, i]
    M[:, 1, 0] = -L[:, 1, 0] * M[:, 0, 0] * M[:, 1, 1]
    M[:, 2, 1] = -L[:, 2, 1] * M[:, 1, 1] * M[:, 2, 2]
    M[:, 2, 0] = -(L[:, 2, 0] * M[:, 0, 0] + L[:, 2, 1] * M[:, 1, 0]) * M[:, 2, 2]
    return M


def adjusted(model, meas):
    """
    Return the observations adjusted to ``model``: each pose then meets Gamma = 0 (first order).

    The least-squares adjustment of each pose's observations V = [Theta, Pi] to its constraints
    (Gauss-Helmert, to first order): V_hat = V - Sigma_V G^T S^-1 Gamma, with G = dGamma/dV and
    S = G Sigma_V G^T the covariance of Gamma. The adjusted observations' error is uncorrelated
    with the residual Gamma, whereas the measured ones' is not: a Jacobian evaluated at the
    measurements shares the residual's noise, and in a direction nearly spanned by the model's own
    columns (a smooth field, once they are projected out) that shared noise is most of what is
    left, so a test or a fit would find a field in pure noise (``whitened_problem(...,
    adjust=True)`` evaluates everything at V_hat).
    """
    parts = partials(model, meas)
    gain = np.linalg.solve(residual_covariance(meas, parts),
                           constraints(model, meas)[..., None])[..., 0]
    Theta = meas.Theta - meas.sigma_Theta ** 2 * parts['theta'] * gain
    Pi = meas.Pi - np.einsum('kab,kib,ki->ka', meas.cov_Pi, parts['P'], gain)
    return replace(meas, Theta=Theta, Pi=Pi, Pi_basis=Pi)


def _stack_legs(x):
    """(K, 3, ...) per-pose arrays to the leg-major stacking of eq. (5)."""
    return np.swapaxes(x, 0, 1).reshape(-1, *x.shape[2:])


def whitened_problem(model, meas, names, adjust=False):
    """
    Whitened residuals r_w (3K,) and Jacobian J_w (3K, p), stacked pose by pose.

    With ``adjust``, those of the Gauss-Helmert objective: everything is evaluated at the
    observations adjusted to the model, V_hat (``adjusted``), and the residual is
    Gamma(V_hat) + G(V_hat) (V - V_hat), equal to Gamma(V) to first order; its Jacobian (by the
    envelope theorem, dGamma/dU at V_hat) shares no noise with it.
    """
    at = adjusted(model, meas) if adjust else meas
    parts = partials(model, at)
    W = whitening(at, parts)
    Gamma = constraints(model, at)
    if adjust:
        Gamma = Gamma + parts['theta'] * (meas.Theta - at.Theta) \
            + np.einsum('kij,kj->ki', parts['P'], meas.Pi - at.Pi)
    J = observation_matrix(model, at, names, parts)
    K = len(meas)
    J_pose = J.reshape(3, K, -1).transpose(1, 0, 2)
    r_w = np.einsum('kij,kj->ki', W, Gamma).reshape(-1)
    J_w = np.einsum('kij,kjp->kip', W, J_pose).reshape(3 * K, -1)
    return r_w, J_w


@dataclass
class Result:
    """An identified model with its statistics."""

    model: Model
    names: tuple
    U: np.ndarray
    covariance: np.ndarray
    chi2: float
    dof: int
    iterations: int
    converged: bool
    history: list = field(default_factory=list)

    @property
    def std(self):
        """Return the standard deviations of U (same order as names)."""
        return np.sqrt(np.diag(self.covariance))


def initial_model(desc, meas):
    """
    Return the paper's start U_0: nominal parameters and P0 from a nominal pose.

    P0 = mean_k (FK_nominal(theta0 + Theta_k) - Pi_k): every pose predicts the camera reference.
    """
    P = delta.forward(desc, effects.joint_angles(desc, meas.Theta))
    return Model(desc.copy(), np.mean(P - meas.Pi, axis=0), effects.parameters(desc))


def gauss_newton_paper(start, meas, names=PAPER_PARAMETERS, max_iterations=50, tol=1e-12):
    """
    Run the paper's iteration U_(n+1) = U_n - J(U_n)^+ Phi(U_n) (eqs. 6-8).

    Unweighted, with the pseudo-inverse. Returns the Result; its covariance assumes unit-variance
    Gamma (the paper weights nothing).
    """
    model, U = start, start.get(names)
    history = []
    for n in range(1, max_iterations + 1):
        Phi = _stack_legs(constraints(model, meas))
        J = observation_matrix(model, meas, names)
        step = np.linalg.pinv(J) @ Phi
        U = U - step
        model = model.with_values(names, U)
        history.append(float(Phi @ Phi))
        if np.max(np.abs(step)) < tol:
            break
    J = observation_matrix(model, meas, names)
    Phi = _stack_legs(constraints(model, meas))
    cov = np.linalg.pinv(J.T @ J)
    return Result(model, tuple(names), U, cov, float(Phi @ Phi), 3 * len(meas) - len(names), n,
                  np.max(np.abs(step)) < tol, history)


def identify(start, meas, names=PAPER_PARAMETERS, max_iterations=100, tol=1e-12, callback=None):
    """
    Identify by damped Gauss-Newton (Levenberg-Marquardt) on the whitened constraints.

    The default solver. Minimises chi2(U) = sum_k Gamma_k^T (G_k Sigma_k G_k^T)^-1 Gamma_k
    (effective variance; see the module docstring), in its Gauss-Helmert form: at the observations
    adjusted to the current U (``whitened_problem(..., adjust=True)``). The weights are
    re-evaluated at every accepted step. Stops when the step is below ``tol`` relative to the
    parameter scale or chi2 stops decreasing.

    Returns
    -------
    Result
        with the covariance (J_w^T J_w)^-1 at the solution and chi2 with dof = 3K - p.

    """
    names = tuple(names)
    model, U = start, start.get(names)
    r, J = whitened_problem(model, meas, names, adjust=True)
    cost = r @ r
    lam = 1e-3
    history = [float(cost)]
    converged = False
    for n in range(1, max_iterations + 1):
        JtJ, Jtr = J.T @ J, J.T @ r
        scale = np.sqrt(np.maximum(np.diag(JtJ), 1e-300))
        A = JtJ / np.outer(scale, scale)
        g = Jtr / scale
        while True:
            step = -np.linalg.solve(A + lam * np.eye(len(U)), g) / scale
            if np.all(np.abs(step) <= tol * (1 + np.abs(U))):
                break  # below tol: its cost change is rounding, not worth an evaluation
            trial = model.with_values(names, U + step)
            r_t, J_t = whitened_problem(trial, meas, names, adjust=True)
            cost_t = r_t @ r_t
            if cost_t <= cost:
                break
            lam *= 10
            if lam > 1e12:
                break
        small = np.all(np.abs(step) <= tol * (1 + np.abs(U)))
        if small or cost_t > cost:
            converged = True  # no downhill step left: at the minimum to machine precision
            break
        flat = cost - cost_t <= 1e-15 * max(cost, 1e-300)
        U, model, r, J, cost = U + step, trial, r_t, J_t, cost_t
        lam = max(lam / 10, 1e-12)
        history.append(float(cost))
        if callback is not None:
            callback(n, cost)
        if flat:
            converged = True
            break
    cov = np.linalg.inv(J.T @ J)
    return Result(model, names, U, cov, float(cost), 3 * len(meas) - len(names), n, converged,
                  history)


def cramer_rao(true_model, meas, names=PAPER_PARAMETERS):
    """Cramer-Rao bound (J_w^T J_w)^-1 of the parameters at the true model for this pose design."""
    _, J_w = whitened_problem(true_model, meas, names)
    return np.linalg.inv(J_w.T @ J_w)


def predicted_positions(model, Theta, direction):
    """Return the effector positions (K, 3) the model predicts for readings Theta (rad)."""
    return delta.forward(model.desc, effects.arm_angles(model.desc, model.effects, Theta,
                                                        direction))


def fk_covariance(result, Theta, direction=None):
    """
    Return the covariance (K, 3, 3) of the effector positions a fit predicts for readings Theta.

    At fixed readings the loop closure Gamma(P, U) = 0 (eq. 4) gives dP/dU = -(dGamma/dP)^-1
    dGamma/dU (implicit function); the parameters of the camera side (P0, the hand-eye rotation,
    the camera field) do not move the forward kinematics. ``direction``: each joint's motion into
    each pose (default from the order of Theta). What the fit cannot tell -- a near-gauge of the
    geometry, the workspace far from the poses measured -- shows here without any truth.
    """
    model = result.model
    Theta = np.atleast_2d(np.asarray(Theta, dtype=float))
    direction = effects.motion_direction(Theta) if direction is None else direction
    P = predicted_positions(model, Theta, direction)
    at = Measurements(Theta, P - model.P0, np.zeros(3), np.zeros((3, 3)), direction)
    parts = partials(model, at)
    J = observation_matrix(model, at, result.names, parts).reshape(3, len(Theta), -1)
    camera_side = [n.startswith(('P0', 'hand_eye_rotation')) or effects.is_camera_term(n[:-1])
                   for n in result.names]
    J[:, :, camera_side] = 0.0
    dP_dU = -np.linalg.solve(parts['P'], J.transpose(1, 0, 2))        # (K, 3, p)
    return np.einsum('kip,pq,kjq->kij', dP_dU, result.covariance, dP_dU)
