"""
The error each rest carries beyond its frames' spread, learned from the data (REML).

Averaging N frames of a rest shrinks the camera's frame-to-frame noise by sqrt(N), but not what
the detector gets wrong at that pose, a vibration of the ball's holder or a resolver's systematic
error: each rest has an error of its own. Its variance (the *floor*) is a sum of components added
to the covariances of every rest's measurements:

* ``camera_x``, ``camera_y``, ``camera_z``: a constant variance along each optical axis (m^2);
* ``camera_x_range``, ... : a variance growing with the range z, (z / z_ref)^(2 m) times the
  component (z_ref = effects.CAMERA_REFERENCE_RANGE), m = ``RANGE_POWER`` of the axis: what a
  detector's error of a fixed size in pixels becomes. An error of e px in the outline's centre
  moves the ball z e / f sideways (m = 1), one in its radius z^2 e / (f R) in depth (m = 2);
* ``resolver``: a variance of each resolver increment (rad^2).

With V_k = V0_k + sum_j phi_j G_kj the covariance of pose k's three constraint residuals (V0_k
propagated from the frames' spread, G_kj that of a unit of component j, both through the same
derivatives as the identification's weights), the components phi >= 0 maximise the restricted
(REML) likelihood of the residuals r at the fit,

    l(phi) = -1/2 [sum_k log|V_k| + log|J^T V^-1 J| + r^T P r],
    P = V^-1 - V^-1 J (J^T V^-1 J)^-1 J^T V^-1,

found by Fisher scoring: score_j = -1/2 tr(P G_j) + 1/2 r^T P G_j P r, information
I_jl = 1/2 tr(P G_j P G_l), whose inverse at the estimate gives their standard errors. REML
accounts for the p parameters fitted to the same residuals, so the components are not biased low
as a plain maximum likelihood would have them. Every trace is computed pose by pose from 3x3
blocks and p-vectors: the cost grows as K p^2.
"""
from dataclasses import dataclass, field, replace

import numpy as np
from robotenis_kinematics import effects
from robotenis_kinematics import identification as idf

COMPONENTS = ('camera_x', 'camera_y', 'camera_z', 'camera_x_range', 'camera_y_range',
              'camera_z_range', 'resolver')
RANGE_POWER = {'x': 1, 'y': 1, 'z': 2}
UNITS = {name: ('rad^2' if name == 'resolver' else 'm^2') for name in COMPONENTS}


@dataclass
class Floor:
    """Variance components (``COMPONENTS``: value, SI units) and their standard errors."""

    variances: dict = field(default_factory=dict)
    std: dict = field(default_factory=dict)
    iterations: int = 0

    def widen(self, meas, R):
        """Return the measurements with each rest's covariances widened by the floor."""
        camera, resolver = self._camera_variances(meas, R), self.variances.get('resolver', 0.0)
        cov = meas.cov_Pi + np.einsum('ab,kb,cb->kac', R, camera, R)
        sigma = np.sqrt(meas.sigma_Theta ** 2 + resolver)
        return replace(meas, sigma_Theta=sigma, cov_Pi=cov)

    def _camera_variances(self, meas, R):
        grow = range_growth(meas, R)
        out = np.zeros((len(meas), 3))
        for a, axis in enumerate('xyz'):
            out[:, a] = (self.variances.get(f'camera_{axis}', 0.0)
                         + grow[:, a] ** 2 * self.variances.get(f'camera_{axis}_range', 0.0))
        return out

    def as_dict(self):
        """Return the floor as plain data for a result file (SI units, standard deviations)."""
        out = {name: {'variance': float(self.variances.get(name, 0.0)),
                      'variance_std': float(self.std.get(name, 0.0)), 'unit': UNITS[name]}
               for name in COMPONENTS}
        for axis, power in RANGE_POWER.items():
            out[f'camera_{axis}_range']['times'] = (
                f'(z / {effects.CAMERA_REFERENCE_RANGE} m)^{2 * power}')
        return out

    @classmethod
    def from_dict(cls, data):
        """Read a floor written by ``as_dict``."""
        return cls({k: float(v['variance']) for k, v in data.items() if k in COMPONENTS},
                   {k: float(v['variance_std']) for k, v in data.items() if k in COMPONENTS})


def ranges(meas, R):
    """Return the range z (K,) of the sphere in the optical frame at each rest, m."""
    return -(meas.Pi @ np.asarray(R))[:, 2]


def range_growth(meas, R):
    """Return (z / z_ref)^RANGE_POWER (K, 3): how each axis's range component's sd grows."""
    z = ranges(meas, R) / effects.CAMERA_REFERENCE_RANGE
    return z[:, None] ** np.array([RANGE_POWER[axis] for axis in 'xyz'])


def _blocks(model, meas, names, components):
    """
    Return the linearised problem at ``model``: V0 (K, 3, 3), B (K, T, 3), S (T, n), r, J.

    Each component's covariance is a sum of rank-one blocks, G_kj = sum_(t in j) b_kt b_kt^T
    (a camera axis: one vector through dGamma/dPi; the resolvers: one per joint), S the (T, n)
    indicator of which component each vector belongs to; r (K, 3) and J (K, 3, p) the residuals
    and their derivatives, pose by pose.
    """
    parts = idf.partials(model, meas)
    V0 = idf.residual_covariance(meas, parts)
    K = len(meas)
    J = idf.observation_matrix(model, meas, names, parts).reshape(3, K, -1).transpose(1, 0, 2)
    r = idf.constraints(model, meas)
    R = model.desc.camera_rotation
    A = np.einsum('kij,ja->kai', parts['P'], R)            # dGamma / d(optical axis a)
    grow = range_growth(meas, R)
    vectors, owner = [], []
    for j, name in enumerate(components):
        if name == 'resolver':
            for i in range(3):
                vectors.append(parts['theta'] * np.eye(3)[i])
                owner.append(j)
        else:
            a = 'xyz'.index(name[len('camera_')])
            vectors.append(A[:, a] * (grow[:, a, None] if name.endswith('_range') else 1.0))
            owner.append(j)
    S = np.zeros((len(owner), len(components)))
    S[np.arange(len(owner)), owner] = 1.0
    return V0, np.stack(vectors, axis=1), S, r, J


def _score_and_information(V0, B, S, r, J, phi):
    """
    Return the REML score (n,), information (n, n) and restricted log-likelihood at phi.

    In the whitened problem (each pose's residuals multiplied by L_k^-1, V_k = L_k L_k^T) P is
    I - Q Q^T, Q an orthonormal basis of the whitened J, and every trace of the module docstring
    reduces to sums over the poses of products of the whitened vectors b_kt, their projections
    Q_k^T b_kt and the projected residual e = (I - Q Q^T) L^-1 r.
    """
    K, p = len(r), J.shape[2]
    V = V0 + np.swapaxes(B * (S @ phi)[None, :, None], 1, 2) @ B
    L = np.linalg.cholesky(V)
    Jt = np.linalg.solve(L, J)
    rt = np.linalg.solve(L, r[..., None])[..., 0]
    Bt = np.linalg.solve(L, np.swapaxes(B, 1, 2))           # (K, 3, T)
    # Q from the Cholesky factor of the (column-scaled) normal matrix: a Householder QR of this
    # sparse matrix makes subnormal numbers and runs a hundred times slower
    Jf = Jt.reshape(3 * K, p)
    norm = np.linalg.norm(Jf, axis=0)
    Ls = np.linalg.cholesky((Jf / norm).T @ (Jf / norm))
    Q = np.linalg.solve(Ls, (Jf / norm).T).T
    Qk = Q.reshape(K, 3, p)
    e = rt - Qk @ (Q.T @ rt.reshape(-1))
    C = np.swapaxes(Qk, 1, 2) @ Bt                           # (K, p, T): Q_k^T b_kt
    gram = np.swapaxes(Bt, 1, 2) @ Bt                        # (K, T, T)
    D = (e[:, None, :] @ Bt)[:, 0, :]
    trace = S.T @ (np.diagonal(gram.sum(axis=0)) - np.sum(C * C, axis=(0, 1)))
    score = -0.5 * trace + 0.5 * S.T @ np.sum(D ** 2, axis=0)
    CC = np.swapaxes(C, 1, 2) @ C                            # (K, T, T): C_t . C_u
    first = S.T @ np.sum(gram ** 2, axis=0) @ S
    second = S.T @ np.sum(gram * CC, axis=0) @ S
    X = np.transpose(C, (2, 0, 1))                          # (T, K, p)
    Mt = np.swapaxes(X, 1, 2) @ X                            # Q^T (b_t b_t^T) Q summed over poses
    Mj = (S.T @ Mt.reshape(len(S), -1)).reshape(-1, p, p)   # Q^T G_j Q, per component
    third = Mj.reshape(len(Mj), -1) @ np.swapaxes(Mj, 1, 2).reshape(len(Mj), -1).T
    information = 0.5 * (first - 2 * second + third)
    logdet = 2 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2))) \
        + 2 * np.sum(np.log(np.diag(Ls) * norm))
    likelihood = -0.5 * (logdet + np.sum(e * e))
    return score, information, likelihood


def estimate(model, meas, names, start=None, components=COMPONENTS, max_iterations=100):
    """
    Return the REML Floor of the residuals of ``model`` fitted to ``meas`` on ``names``.

    ``meas`` carries the frames' spread only (V0); ``start`` is a Floor to start from. Fisher
    scoring with an active set: a component at zero whose score points below zero stays there, a
    step that would take a component below zero stops at the boundary, and each step is halved
    until the restricted likelihood does not decrease. It stops when the step would raise the
    likelihood by less than 1e-8 (half the Newton decrement s^T I^-1 s).
    """
    V0, B, S, r, J = _blocks(model, meas, names, components)
    # work with components in units of their typical effect: G_j / scale_j and phi_j scale_j
    scale = np.maximum(S.T @ np.einsum('kti,kti->t', B, B) / len(meas), 1e-300)
    B = B / np.sqrt(S @ scale)[None, :, None]
    phi = np.array([(start.variances.get(c, 0.0) if start else 0.0) for c in components]) * scale
    score, info, like = _score_and_information(V0, B, S, r, J, phi)
    n = 0
    for n in range(1, max_iterations + 1):
        step = _active_step(phi, score, info)
        if 0.5 * score @ step < 1e-8:
            break
        t = _longest_step(phi, step)
        for _ in range(40):
            trial = np.maximum(phi + t * step, 0.0)
            t_score, t_info, t_like = _score_and_information(V0, B, S, r, J, trial)
            if t_like >= like:
                break
            t /= 2
        else:
            break                     # no uphill step left: at the maximum to rounding
        phi, score, info, like = trial, t_score, t_info, t_like
    free = phi > 0
    cov = np.zeros_like(info)
    if free.any():
        cov[np.ix_(free, free)] = np.linalg.pinv(info[np.ix_(free, free)])
    std = np.sqrt(np.maximum(np.diag(cov), 0.0)) / scale
    return Floor(dict(zip(components, phi / scale)), dict(zip(components, std)), n)


def _active_step(phi, score, info):
    """Return the Fisher step over the components free to move (at zero: only upward)."""
    free = (phi > 0) | (score > 0)
    for _ in range(len(phi)):
        step = np.zeros_like(phi)
        if free.any():
            step[free] = np.linalg.lstsq(info[np.ix_(free, free)], score[free], rcond=None)[0]
        stuck = free & (phi <= 0) & (step < 0)      # at the boundary and pushed below it
        if not stuck.any():
            return step
        free &= ~stuck
    return np.zeros_like(phi)


def _longest_step(phi, step):
    """Return the step length (at most 1) that keeps every component at or above zero."""
    down = step < 0
    if not down.any():
        return 1.0
    return float(min(1.0, np.min(-phi[down] / step[down])))


def identify(start, meas, names=idf.PAPER_PARAMETERS, floor=None, components=COMPONENTS,
             rounds=10, tol=1e-3):
    """
    Identify ``names`` and the floor together: (Result on the widened measurements, Floor).

    Alternates the weighted fit (identification.identify, with the floor's weights) and the REML
    floor at that fit until the floor changes by less than ``tol`` of itself. ``meas`` carries the
    frames' spread only; the Result's chi2 and covariance are those of the widened measurements.
    """
    R = start.desc.camera_rotation
    floor = floor or Floor()
    model = start
    for _ in range(rounds):
        result = idf.identify(model, floor.widen(meas, R), names)
        new = estimate(result.model, meas, names, floor, components)
        moved = max(abs(new.variances[c] - floor.variances.get(c, 0.0))
                    / max(new.variances[c], floor.variances.get(c, 0.0), 1e-300)
                    for c in components)
        floor, model = replace(new, iterations=new.iterations), result.model
        if moved < tol:
            break
    return idf.identify(model, floor.widen(meas, R), names), floor
