"""
The exact method: the sphere's outline is a conic, and the centre follows from it in closed form.

(Equations C1, C2 are this module's: the paper works with tangent lines,
robotenis_vision.paper_method.)

Rays from the optical centre that touch a sphere of radius R centred at c form a cone. A ray
p = (x, y, 1) (undistorted normalized image point) lies on it when

    (p^T c)^2 - (c^T c - R^2) p^T p = 0,   i.e.   p^T Q p = 0,   Q = c c^T - (c^T c - R^2) I.  (C1)

Q has the eigenvalue R^2 with eigenvector c / |c| and the double eigenvalue -(|c|^2 - R^2), so a
fitted conic lambda Q gives the centre without iteration (``sphere_from_conic``):

    |c|^2 = R^2 (1 - mu / lambda_1),   c = |c| e_1                                             (C2)

(lambda_1, e_1 the single eigenpair, mu the mean of the two others; the sign makes c_z > 0).

The conic is fitted to the undistorted edge points with Taubin's method (``taubin``), whose bias is
far below that of a plain algebraic fit, and the centre is then refined by Gauss-Newton on the
geometric (Sampson) distances of the points to the cone (C1) in pixels (``refine_sphere``), which
also gives the covariance of c from the scatter of the points (``correlation_inflation`` widens it
when neighbouring points' errors are correlated).

Three rays touching the sphere fix it too (``sphere_from_three_rays``: the cone's axis is equally
inclined to them): the minimal problem of ``ransac_sphere``, the robust start from coarse points.
"""
from dataclasses import dataclass

import numpy as np


class ConicError(ValueError):
    """The points do not determine a sphere's outline: the message says why."""


def _design(x, y):
    return np.stack([x * x, x * y, y * y, x, y], axis=1)


def taubin(xy, weights=None):
    """
    Conic matrix (3x3, symmetric, unit Frobenius norm) through points xy (n, 2), Taubin's fit.

    Minimises sum w (xi^T theta)^2 / sum w |grad xi^T theta|^2 with the constant term eliminated by
    centring (Taubin 1991). The points are first shifted to their mean and scaled to unit RMS
    radius, and the conic is mapped back.
    """
    xy = np.asarray(xy, dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 5:
        raise ConicError(f'conic fit: need at least 5 points (n, 2), got shape {xy.shape}')
    w = np.ones(len(xy)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    m = w @ xy
    scale = np.sqrt(w @ np.sum((xy - m) ** 2, axis=1))
    if not scale > 0:
        raise ConicError('conic fit: the points coincide')
    x, y = ((xy - m) / scale).T
    Z = _design(x, y)
    zbar = w @ Z
    Zc = Z - zbar
    M = (Zc * w[:, None]).T @ Zc
    # sum of grad(xi) grad(xi)^T: d/dx = (2x, y, 0, 1, 0), d/dy = (0, x, 2y, 0, 1)
    N = np.zeros((5, 5))
    N[0, 0] = 4 * (w @ (x * x))
    N[0, 1] = N[1, 0] = 2 * (w @ (x * y))
    N[0, 3] = N[3, 0] = 2 * (w @ x)
    N[1, 1] = w @ (x * x + y * y)
    N[1, 2] = N[2, 1] = 2 * (w @ (x * y))
    N[1, 3] = N[3, 1] = w @ y
    N[1, 4] = N[4, 1] = w @ x
    N[2, 2] = 4 * (w @ (y * y))
    N[2, 4] = N[4, 2] = 2 * (w @ y)
    N[3, 3] = N[4, 4] = 1.0
    try:                                   # M v = lambda N v through the Cholesky factor of N
        L = np.linalg.cholesky(N)
        Li = np.linalg.inv(L)
        values, vectors = np.linalg.eigh(Li @ M @ Li.T)
    except np.linalg.LinAlgError as e:
        raise ConicError(f'conic fit: degenerate points ({e})') from None
    v = Li.T @ vectors[:, 0]
    A, B, C, D, E = v
    F = -zbar @ v
    Qn = np.array([[A, B / 2, D / 2], [B / 2, C, E / 2], [D / 2, E / 2, F]])
    T = np.array([[1 / scale, 0, -m[0] / scale], [0, 1 / scale, -m[1] / scale], [0, 0, 1]])
    Q = T.T @ Qn @ T
    return Q / np.linalg.norm(Q)


def sphere_conic(c, R):
    """Return the cone (C1) of a sphere of radius R at c: Q = c c^T - (c^T c - R^2) I."""
    c = np.asarray(c, dtype=float)
    return np.outer(c, c) - (c @ c - R * R) * np.eye(3)


def sphere_from_conic(Q, R):
    """
    Centre c (3,) of the sphere of radius R whose outline is the conic Q (C2).

    Q may carry any scale and sign. Raises ConicError when Q is not a sphere's outline (it must
    have one eigenvalue of one sign and two of the other).
    """
    Q = np.asarray(Q, dtype=float)
    Q = 0.5 * (Q + Q.T)
    values, vectors = np.linalg.eigh(Q)
    signs = np.sign(values)
    if np.sum(signs > 0) == 1:
        k = int(np.argmax(values))
    elif np.sum(signs < 0) == 1:
        k = int(np.argmin(values))
    else:
        raise ConicError(f'conic {values} is not the outline of a sphere in front of the camera')
    others = np.delete(values, k)
    mu = others.mean()
    d2 = R * R * (1 - mu / values[k])
    c = np.sqrt(d2) * vectors[:, k]
    return c if c[2] > 0 else -c


def sampson(xy, c, R):
    """
    Signed Sampson distances (n,) of normalized points xy to the outline of the sphere (c, R).

    Normalized units (multiply by the focal length for pixels); positive outside the outline.
    Several spheres at once: c (k, 3) gives (k, n).
    """
    c = np.asarray(c, dtype=float)
    cx, cy, cz = (c[..., i, None] for i in range(3))
    x, y = xy[:, 0], xy[:, 1]
    pc = x * cx + y * cy + cz
    k = np.sum(c * c, axis=-1)[..., None] - R * R
    f = pc * pc - k * (x * x + y * y + 1)
    gx, gy = 2 * pc * cx - 2 * k * x, 2 * pc * cy - 2 * k * y
    d = -f / np.hypot(gx, gy)
    return d if c.ndim > 1 else d.reshape(-1)


@dataclass
class SphereFit:
    c: np.ndarray            # centre (3,), optical frame, m
    cov: np.ndarray          # (3, 3) covariance of c from the scatter of the points, m^2
    residuals_px: np.ndarray  # (n,) distance of each point to the fitted outline, px
    rms_px: float
    inliers: np.ndarray      # (n,) bool


def refine_sphere(xy, c0, R, f, weights=None, iterations=2, reject=4.0):
    """
    Refine c by Gauss-Newton, minimising sum w (f * Sampson distance)^2.

    Outliers beyond ``reject`` sigma are dropped.
    xy: undistorted normalized points (n, 2); f: focal length (px) to express distances in pixels;
    weights: relative weights (inverse variances up to a common factor). The covariance is
    s^2 (J^T W J)^-1 with s^2 the weighted residual variance (n - 3 degrees of freedom).
    """
    xy = np.asarray(xy, dtype=float)
    w = np.ones(len(xy)) if weights is None else np.asarray(weights, dtype=float)
    w = w / np.mean(w)
    c = np.asarray(c0, dtype=float).copy()
    inl = np.ones(len(xy), dtype=bool)
    P = np.column_stack([xy, np.ones(len(xy))])
    p2 = np.sum(P * P, axis=1)
    for it in range(iterations):
        r, J = _residual_and_jacobian(P, p2, c, R, f)
        if it == 1:    # the start is close: one rejection of outliers is enough
            inl = np.abs(r) * np.sqrt(w) < reject * _robust_scale(r, w)
        if inl.sum() < 6:
            raise ConicError(f'sphere fit: only {int(inl.sum())} outline points agree')
        Jw = J[inl] * w[inl, None]
        step = np.linalg.solve(Jw.T @ J[inl], -Jw.T @ r[inl])
        c = c + step
        if c[2] < 0:       # the cone of -c is the same cone: stay in front of the camera
            c = -c
        if np.max(np.abs(step)) < 1e-10 * np.linalg.norm(c) and it >= 1:
            break
    # The last step is small: residuals and Jacobian from before it, the residuals moved along it.
    r = r + J @ step
    W = w[inl]
    A = (J[inl] * W[:, None]).T @ J[inl]
    s2 = np.sum(W * r[inl] ** 2) / max(inl.sum() - 3, 1)
    return SphereFit(c, s2 * np.linalg.inv(A), r, float(np.sqrt(np.mean(r[inl] ** 2))), inl)


def correlation_inflation(residuals, lags=4):
    """
    Variance factor for residuals correlated along the outline (points in outline order).

    Neighbouring outline points see overlapping pixels and the same background texture, so their
    errors are not independent; with lag-k autocorrelations rho_k of the residual sequence the
    variance of a mean grows by 1 + 2 sum_k rho_k (the effective number of independent points
    shrinks by it). Negative correlations are not credited.
    """
    r = np.asarray(residuals, dtype=float)
    r = r - r.mean()
    var = r @ r
    if len(r) < 4 * lags or var <= 0:
        return 1.0
    # circular autocorrelations: the sequence wraps around the closed outline
    rho = np.array([(r[:-k] @ r[k:] + r[-k:] @ r[:k]) / var for k in range(1, lags + 1)])
    return float(1 + 2 * np.sum(np.maximum(rho, 0) * (1 - np.arange(1, lags + 1) / len(r))))


def _robust_scale(r, w):
    """1.4826 x the median absolute weighted residual: sigma of the inliers, blind to outliers."""
    return 1.4826 * np.median(np.abs(r) * np.sqrt(w)) + 1e-12


def _residual_and_jacobian(P, p2, c, R, f):
    """
    Compute f * Sampson distance (n,) and its derivative in c (n, 3), analytically.

    P (n, 3): the rays p = (x, y, 1); p2 = |p|^2. With F = (p.c)^2 - k |p|^2 (k = c.c - R^2) and
    its image gradient g = 2 (p.c) c_xy - 2 k p_xy, the distance is r = -F / |g|, and
    dr/dc = -(dF/dc + r d|g|/dc) / |g|.
    """
    pc = P @ c
    k = c @ c - R * R
    F = pc * pc - k * p2
    g = 2 * pc[:, None] * c[:2] - 2 * k * P[:, :2]
    gn = np.sqrt(np.sum(g * g, axis=1))
    r = -F / gn
    dF = 2 * pc[:, None] * P - 2 * p2[:, None] * c
    # d g_j / dc = 2 c_j p + 2 (p.c) e_j - 4 p_j c, for j = x, y
    dg = (g[:, 0:1] * (2 * c[0] * P - 4 * P[:, 0:1] * c)
          + g[:, 1:2] * (2 * c[1] * P - 4 * P[:, 1:2] * c))
    dg[:, :2] += 2 * pc[:, None] * g
    J = -(dF + r[:, None] * dg / gn[:, None]) / gn[:, None]
    return f * r, f * J


def sphere_from_three_rays(xy1, xy2, xy3, R):
    """
    Centres (..., 3) of the spheres of radius R touched by three rays (x, y, 1) each (normalized).

    The cone's axis a makes the same angle beta with the three unit rays d_i, so it is normal to
    d1 - d2 and d2 - d3; cos(beta) = a.d1 and |c| = R / sin(beta). The minimal problem for RANSAC.
    A degenerate triple (two rays alike, or three in a plane through the camera) gives NaN.
    """
    def unit(xy):
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)
    d1, d2, d3 = unit(xy1), unit(xy2), unit(xy3)
    a = np.cross(d1 - d2, d2 - d3)
    size = np.linalg.norm(a, axis=-1, keepdims=True)
    a = a / np.where(size > 0, size, np.nan)
    a *= np.sign(a[..., 2:3])
    cos_b = np.clip(np.sum(a * d1, axis=-1), -1.0, 1.0)
    sin_b = np.sqrt(1 - cos_b ** 2)
    return a * (R / np.maximum(sin_b, 1e-12))[..., None]


def ransac_sphere(xy, R, f, threshold_px=1.0, trials=32, rng=None):
    """
    Find the sphere that most outline points (normalized) lie within ``threshold_px`` of.

    The sphere is the best of those through ``trials`` random triples, refitted on the points
    within the threshold of it (Taubin + closed form). Returns (c, inlier mask).

    With a quarter of the points wrong, a triple is clean with probability 0.42: 32 trials all miss
    with probability 3e-8. The draws are seeded: the same points give the same sphere.
    """
    xy = np.asarray(xy, dtype=float)
    n = len(xy)
    if n < 5:
        raise ConicError(f'sphere fit: need at least 5 points, got {n}')
    rng = np.random.default_rng(0) if rng is None else rng
    # three distinct points per trial
    idx = np.argpartition(rng.random((trials, n)), 3, axis=1)[:, :3]
    C = sphere_from_three_rays(xy[idx[:, 0]], xy[idx[:, 1]], xy[idx[:, 2]], R)
    C = C[np.all(np.isfinite(C), axis=1) & (C[:, 2] > R)]
    if len(C) == 0:
        raise ConicError('sphere fit: no three outline points describe a sphere '
                         'in front of the camera')
    inliers = np.abs(f * sampson(xy, C, R)) < threshold_px
    best = inliers[np.argmax(inliers.sum(axis=1))]
    if best.sum() < 5:
        raise ConicError(f'sphere fit: only {int(best.sum())} outline points agree')
    c = sphere_from_conic(taubin(xy[best]), R)
    return c, np.abs(f * sampson(xy, c, R)) < threshold_px


def fit_sphere(xy, R, f, weights=None, c0=None):
    """
    Taubin conic -> closed-form centre (C2) -> geometric refinement: a SphereFit.

    ``c0``: a sphere whose outline lies within a pixel or so of the points (the one the outline was
    searched along); the refinement then starts from it and the conic is not needed.
    """
    if c0 is None:
        c0 = sphere_from_conic(taubin(xy, weights), R)
    return refine_sphere(xy, c0, R, f, weights)
