"""
The model method: the ball's image near its outline, modelled pixel by pixel and fitted.

Every pixel of an annulus around the outline is predicted from the sphere (centre c, the known
radius R) and the lens blur, and c is found by Gauss-Newton on those pixels with robust weights.
Across the outline at a pixel whose signed distance to it is t (px, positive inside), blurred by a
Gaussian of width s (lens and pixel), the image is

    outside:  b0 + b1 (-t)                                  the local background and its slope
    inside:   a0 + a1 (sin(i) - 1) + beta(phi) cos(i)       the ball's shading near its limb

with i the angle between the ball's surface normal and the line of sight at the pixel. The four
levels are fitted per bin of the outline (BIN_ARC_PX of it), each with a slope along the bin (a
gradient, a texture, a lit and a dark side of the ball): 8 per bin. A Lambertian ball under a
light from direction l is amb + D max(0, n.l); near the limb n = sin(i) m + cos(i) v (m the
outline's normal, v toward the camera), so the shading is a0 + a1 sin(i) + beta cos(i) with beta =
D (v.l). Since cos(i) grows as the square root of the depth inside (cos^2(i) = w2' t near the
limb), that term is what a model linear in t takes for part of the step, and reads the ball too
far (a few tenths of a percent of the range with a frontal light). Its coefficient is one function
around the outline, beta0 + beta1 cos(phi) + beta2 sin(phi) (phi the direction of the outline's
normal): three coefficients for the ball, so that the bins' levels cannot trade it against the
edge. Blurred:

    H(-t), -t H(-t), H(t)  ->  1 - Phi, s (phi - tau (1 - Phi)), Phi          (tau = t / s)
    (sin(i) - 1) H(t)      ->  -(w2' / 2) s (tau Phi + phi) + the rest, unblurred (O(t^2))
    cos(i) H(t)            ->  sqrt(w2') (s^0.5 g_0.5(tau) - (kappa / 4) s^1.5 g_1.5(tau))
                               + the rest, unblurred (O(t^2.5))

where g_nu(tau) = E[((tau + N(0, 1))^+)^nu] (parabolic cylinder functions, tabulated), and tau is
taken at t - s^2 kappa / 2: a blurred curved step appears that much inside the outline (kappa its
curvature). The t^1.5 term is cos(i)'s next one: on a circle of radius 1 / kappa, cos^2(i) =
2 kappa t - kappa^2 t^2, so cos(i) = sqrt(2 kappa t) (1 - kappa t / 4 - ...). Left unblurred it
moved the outline of a frontally lit 19 px ball over a darker background by a tenth of a pixel
at a blur of 1 px (0.46 % of the range, 0.12 % with it; noise-free renders). Known limits:
where the terminator crosses the limb the shading is clamped (max(0, n.l)) and this model
misreads it; a lens's defocus is a disc, not the Gaussian assumed (benchmarks/vision.py measures
both). A specular highlight is no part of this model: one found on the ball's disc is measured
there and its predicted tail taken out of the annulus's pixels before the fit (``highlight``).
A texture finer than a bin is no part of it either, unless a plate of the background from other
views of the scene gives it (``background``, robotenis_vision.plate): then it is (``behind``).

Geometry. The outline is the cone of rays touching the sphere, q(u) = (r.c)^2 - (c.c - R^2) r.r = 0
for the ray r = K^-1 (u, 1) of an ideal (undistorted) pixel u (C1 of robotenis_vision.conic). A
pixel's distance to it is measured from its foot point (two Sampson steps onto the conic), scaled
to image pixels by the lens distortion's stretch along the normal; its derivative in c is
(dq/dc) / |grad q| at the foot point.

Solution. The levels and beta are linear: the bins' levels are eliminated bin by bin (a Schur
complement), leaving a small system in (c, s, beta) for each Gauss-Newton step. Pixels get Tukey's
biweight of their residual (a highlight, a background edge) and a bin whose residuals exceed the
noise is down-weighted as a whole (what the model cannot follow); saturated pixels get none. The
image is first linearised by the camera's response (``gamma``), each pixel weighted by its noise
there, and the ball, the background and the edge zone by their own noise levels. The covariance
of c is sigma^2 times the (c, c) block of the inverse weighted normal matrix, sigma the pixel
noise from differences of neighbouring pixels' residuals (blind to the smooth part of what the
model misses, which repeats from frame to frame and is no noise).
"""
from dataclasses import dataclass, field
import functools

import numpy as np
from robotenis_vision import plate
from robotenis_vision.detection import DetectionError
from scipy.special import gamma as gamma_function, ndtr, pbdv

TUKEY = 4.685                  # biweight constant, in robust sigmas (95 % efficiency)
BIN_ARC_PX = 6.0               # outline length per bin of levels
MIN_BINS, MAX_BINS = 12, 96
BIN_EXCESS = 2.0               # a bin's weight: (1 + k) / (excess + k), excess = its MSE / noise^2
SATURATED = (0.5, 254.5)       # grey levels: a pixel at the sensor's limit is not the model's
BLUR_RANGE = (0.25, 4.0)       # px: the edge spread the fit may settle on
INNER = 0.2                    # of the ball's apparent radius: how deep inside the annulus goes
MIN_PIXELS = 60
MAX_STEP_PX = 1.0              # outline displacement a Gauss-Newton step may make
SCALE_FLOOR = 1.0              # grey levels: the least residual scale the weights assume
N_LEVELS = 8                   # per bin: b0, b1, a0, a1 and their slopes along the bin


TAU_LOW, TAU_STEP, TAU_TOP = -8.0, 0.002, 10.0     # the tables' range and step, blur sigmas


@functools.lru_cache(maxsize=None)
def _power_edge_table(nu):
    """Tabulate g_nu(tau) = E[((tau + Z)^+)^nu] and its derivative, Z ~ N(0, 1), on the range."""
    tau = np.arange(TAU_LOW, TAU_TOP + TAU_STEP / 2, TAU_STEP)
    # int_0^inf x^nu phi(tau - x) dx = Gamma(nu + 1) exp(-tau^2 / 4) D_{-nu-1}(-tau) / sqrt(2 pi)
    D, Dp = pbdv(-nu - 1, -tau)
    scale = gamma_function(nu + 1) / np.sqrt(2 * np.pi) * np.exp(-tau * tau / 4)
    return scale * D, scale * (-0.5 * tau * D - Dp)


def power_edge(tau, nu):
    """
    Return g_nu(tau) and its derivative: x^nu H(x) blurred by N(0, 1), at tau (any shape).

    Beyond the table, the asymptotic series tau^nu (1 + c2 / tau^2 + c4 / tau^4), c2 = nu (nu - 1)
    / 2, c4 = nu (nu - 1) (nu - 2) (nu - 3) / 8 (the moments of Z in the binomial series).
    """
    G, DG = _power_edge_table(nu)
    tau = np.asarray(tau, dtype=float)
    q = np.clip((tau - TAU_LOW) / TAU_STEP, 0.0, len(G) - 1.000001)
    i = q.astype(np.intp)
    f = q - i
    g = G[i] + f * (G[i + 1] - G[i])
    dg = DG[i] + f * (DG[i + 1] - DG[i])
    far = tau > TAU_LOW + TAU_STEP * (len(G) - 1)
    if np.any(far):
        x = tau[far]
        c2, c4 = nu * (nu - 1) / 2, nu * (nu - 1) * (nu - 2) * (nu - 3) / 8
        g[far] = x ** nu * (1 + c2 / x ** 2 + c4 / x ** 4)
        dg[far] = x ** (nu - 1) * (nu + c2 * (nu - 2) / x ** 2 + c4 * (nu - 4) / x ** 4)
    return g, dg


def camera_key(camera):
    return (camera.K.tobytes(), camera.D.tobytes(), camera.width, camera.height)


@functools.lru_cache(maxsize=4)
def ideal_maps(key):
    """
    Return each image pixel's ideal (undistorted) position and the undistortion's stretch.

    (height, width, 2) ideal pixels and (height, width, 2, 2) d(ideal) / d(image) for the camera
    of ``key`` (camera_key); None for the stretch when the camera has no distortion.
    """
    from robotenis_vision.camera import Camera
    K, D = np.frombuffer(key[0]).reshape(3, 3), np.frombuffer(key[1])
    camera = Camera(K, D, key[2], key[3])
    v, u = np.mgrid[0:camera.height, 0:camera.width].astype(float)
    uv = np.stack([u, v], axis=-1)
    if not np.any(D):
        return uv, None
    ideal = camera.undistort_pixels(uv)
    if not np.all(np.isfinite(ideal)):
        raise DetectionError('camera: its distortion cannot be inverted over the whole image')
    d_dv, d_du = np.gradient(ideal, axis=(0, 1))
    return ideal, np.stack([d_du, d_dv], axis=-1)


@dataclass
class Annulus:
    """The pixels a fit uses, fixed while it iterates, sorted by bin."""

    values: np.ndarray       # (n,) grey levels
    ideal: np.ndarray        # (n, 2) ideal pixel positions
    stretch: np.ndarray      # (n, 2, 2) d(ideal) / d(image), or None (no distortion)
    bins: np.ndarray         # (n,) bin of each pixel
    gather: np.ndarray       # (n_bins, m) the bins' pixels, padded with -1
    angle: np.ndarray        # (n,) direction of the outline's normal at the pixel, rad
    bin_angle: np.ndarray    # (n_bins,) direction at each bin's centre, rad
    along: np.ndarray        # (n,) position along its bin's arc, -1 to 1
    right: np.ndarray        # (n,) the pixel to the right, -1 if not in the annulus
    usable: np.ndarray       # (n,) not saturated
    pixels: np.ndarray       # (n, 2) image pixels (u, v), integers


def outline_offset(camera, R, a, b):
    """Return how far sphere b's outline lies from sphere a's: its centre and its radius, px."""
    return (float(np.linalg.norm(camera.project(b) - camera.project(a))),
            abs(camera.apparent_radius(b, R) - camera.apparent_radius(a, R)))


def outline_conic(camera, c, R):
    """Return the sphere's outline as a conic in ideal pixels (3x3, positive inside)."""
    c = np.asarray(c, dtype=float)
    Kinv = np.linalg.inv(camera.K)
    return Kinv.T @ (np.outer(c, c) - (c @ c - R * R) * np.eye(3)) @ Kinv


def _ellipse(Qpx):
    """Return the centre and shape M ((u - u0)^T M (u - u0) = 1 on the outline) of the conic."""
    A, b, F = Qpx[:2, :2], Qpx[:2, 2], Qpx[2, 2]
    centre = -np.linalg.solve(A, b)
    M = A / -(F + b @ centre)
    if np.any(np.linalg.eigvalsh(M) <= 0):
        raise DetectionError('the sphere is too far off the optical axis to be measured '
                             '(outline not an ellipse)')
    return centre, M


def annulus(img, camera, c, R, outer, inner):
    """
    Cut the pixels from ``outer`` px outside sphere c's outline to ``inner`` px inside it.

    DetectionError when the annulus leaves the image (the sphere touches its border) or holds too
    few pixels.
    """
    centre, M = _ellipse(outline_conic(camera, c, R))
    values, V = np.linalg.eigh(M)
    axes = 1 / np.sqrt(values)
    ideal_map, stretch_map = ideal_maps(camera_key(camera))
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    outline = centre + (np.stack([np.cos(t), np.sin(t)], 1) * axes) @ V.T
    image_outline = camera.distort_pixels(outline)
    lo = np.floor(image_outline.min(axis=0) - outer - 2).astype(int)
    hi = np.ceil(image_outline.max(axis=0) + outer + 2).astype(int)
    if lo[0] < 0 or lo[1] < 0 or hi[0] >= camera.width or hi[1] >= camera.height:
        raise DetectionError('the sphere touches the image border')
    ideal = ideal_map[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1].reshape(-1, 2)
    d = ideal - centre
    rho = np.sqrt(np.einsum('ni,ij,nj->n', d, M, d))
    # distance from the outline along the ray from the centre, with slack for the normal's slant
    slack = 1 + 0.1 * (axes.max() / axes.min() - 1)
    # (a pixel on the ellipse's very centre, rho = 0, is as deep inside as any)
    dist = np.where(rho > 0, (1 - rho) * np.linalg.norm(d, axis=1) / np.maximum(rho, 1e-300),
                    np.inf)
    keep = (dist < inner * slack + 0.5) & (dist > -outer * slack - 0.5)
    width = hi[0] - lo[0] + 1
    index = np.flatnonzero(keep)
    if len(index) < MIN_PIXELS:
        raise DetectionError(f'only {len(index)} pixels around the outline')
    vv, uu = np.divmod(index, width)
    vals = np.asarray(img, dtype=float)[vv + lo[1], uu + lo[0]]
    normal = d[index] @ M
    angle = np.arctan2(normal[:, 1], normal[:, 0])
    perimeter = np.pi * (3 * axes.sum() - np.sqrt((3 * axes[0] + axes[1])
                                                  * (axes[0] + 3 * axes[1])))
    n_bins = int(np.clip(np.round(perimeter / BIN_ARC_PX), MIN_BINS, MAX_BINS))
    position = (angle + np.pi) / (2 * np.pi) * n_bins
    bins = np.minimum(position.astype(int), n_bins - 1)
    along = 2 * (position - bins) - 1
    order = np.argsort(bins, kind='stable')
    index, bins, angle, vals, along = (index[order], bins[order], angle[order], vals[order],
                                       along[order])
    present, starts, counts = np.unique(bins, return_index=True, return_counts=True)
    bins = np.searchsorted(present, bins)
    slot = np.arange(len(index)) - starts[bins]
    gather = np.full((len(present), counts.max()), -1)
    gather[bins, slot] = np.arange(len(index))
    position = np.full(keep.size, -1)
    position[index] = np.arange(len(index))
    nxt = index + 1
    right = np.where(nxt % width != 0, position[np.minimum(nxt, keep.size - 1)], -1)
    stretch = (None if stretch_map is None
               else stretch_map[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1].reshape(-1, 2, 2)[index])
    usable = (vals > SATURATED[0]) & (vals < SATURATED[1])
    bin_angle = (present + 0.5) / n_bins * 2 * np.pi - np.pi
    pixels = np.column_stack([uu + lo[0], vv + lo[1]])[order]
    return Annulus(vals, ideal[index], stretch, bins, gather, angle, bin_angle, along, right,
                   usable, pixels)


@dataclass
class Geometry:
    """Where each annulus pixel is with respect to the outline of sphere c."""

    d: np.ndarray            # (n,) signed distance to the outline, image px, positive inside
    dd_dc: np.ndarray        # (n, 3) its derivative in c, px / m
    kappa: np.ndarray        # (n,) the outline's curvature at the foot point, 1 / image px
    w2_slope: np.ndarray     # (n,) d cos^2(i) / dt at the outline, 1 / image px
    cos_deep: np.ndarray     # (n,) cos(i) - sqrt(w2' t) (1 - kappa t / 4) inside, 0 outside
    sin_deep: np.ndarray     # (n,) sin(i) - 1 + w2' t / 2 inside, 0 outside


def geometry(ann, camera, c, R):
    """Compute each pixel's distance to sphere c's outline, its derivative, curvature, shading."""
    c = np.asarray(c, dtype=float)
    Kinv = np.linalg.inv(camera.K)
    Qpx = outline_conic(camera, c, R)
    A, b, F = Qpx[:2, :2], Qpx[:2, 2], Qpx[2, 2]
    u = ann.ideal.copy()
    for _ in range(2):                                  # Sampson steps onto the conic
        g = 2 * (u @ A + b)
        q = np.einsum('ni,ij,nj->n', u, A, u) + 2 * u @ b + F
        u -= (q / np.einsum('ni,ni->n', g, g))[:, None] * g
    g = 2 * (u @ A + b)
    gn = np.sqrt(np.einsum('ni,ni->n', g, g))
    n = g / gn[:, None]                                 # inward unit normal at the foot point
    d = np.einsum('ni,ni->n', ann.ideal - u, n)
    tangent = np.stack([-n[:, 1], n[:, 0]], axis=1)     # curvature of q = 0 (Hessian 2A)
    kappa = np.abs(2 * np.einsum('ni,ij,nj->n', tangent, A, tangent) / gn)
    r = np.column_stack([u, np.ones(len(u))]) @ Kinv.T  # rays of the foot points
    rr = np.einsum('ni,ni->n', r, r)
    dd_dc = (2 * (r @ c)[:, None] * r - 2 * rr[:, None] * c) / gn[:, None]
    w2_slope = gn / (R * R * rr)
    rp = np.column_stack([ann.ideal, np.ones(len(u))]) @ Kinv.T   # the pixels' own rays
    rpc = rp @ c
    w2 = (rpc * rpc / np.einsum('ni,ni->n', rp, rp) - (c @ c - R * R)) / (R * R)
    if ann.stretch is not None:
        # ideal-pixel distances to image pixels: d_image = d_ideal / |(d ideal / d image)^T n|
        scale = 1 / np.linalg.norm(np.einsum('nji,nj->ni', ann.stretch, n), axis=1)
        d, dd_dc = d * scale, dd_dc * scale[:, None]
        kappa, w2_slope = kappa / scale, w2_slope / scale
    inside = d > 0
    depth = np.maximum(d, 0.0)
    cos_deep = np.where(inside, np.sqrt(np.clip(w2, 0, 1))
                        - np.sqrt(w2_slope * depth) * (1 - 0.25 * kappa * depth), 0.0)
    sin_deep = np.where(inside, np.sqrt(np.clip(1 - w2, 0, 1)) - 1 + 0.5 * w2_slope * depth,
                        0.0)
    return Geometry(d, dd_dc, kappa, w2_slope, cos_deep, sin_deep)


def columns(geo, ann, s):
    """
    Return the model's columns at blur s and their derivatives in t and s.

    X (n, 8): the bins' levels' (b0, b1, a0, a1, then each times the position along the bin);
    H (n, 3): the limb's square-root term's (beta0, beta1 cos(phi), beta2 sin(phi)); dX_dt,
    dX_ds, dH_dt, dH_ds the same shapes.
    """
    t = geo.d - 0.5 * s * s * geo.kappa
    tau = t / s
    Phi = ndtr(tau)
    phi = np.exp(-0.5 * tau * tau) / np.sqrt(2 * np.pi)
    k = -0.5 * geo.w2_slope
    ramp = s * (tau * Phi + phi)
    X = np.stack([1 - Phi, s * (phi - tau * (1 - Phi)), Phi, k * ramp + geo.sin_deep], axis=1)
    dX_dt = np.stack([-phi / s, -(1 - Phi), phi / s, k * Phi], axis=1)
    dX_ds = np.stack([phi * tau / s, phi, -phi * tau / s, k * phi], axis=1)
    # cos(i) near the limb: sqrt(w2' t) (1 + k3 t), k3 = -kappa / 4; both powers blurred
    g, dg = power_edge(tau, 0.5)
    g3, dg3 = power_edge(tau, 1.5)
    root, k3 = np.sqrt(geo.w2_slope), -0.25 * geo.kappa
    h = root * (np.sqrt(s) * g + k3 * s ** 1.5 * g3) + geo.cos_deep
    dh_dt = root * (dg / np.sqrt(s) + k3 * np.sqrt(s) * dg3)
    dh_ds = root * ((0.5 * g - tau * dg) / np.sqrt(s) + k3 * np.sqrt(s) * (1.5 * g3 - tau * dg3))
    a = ann.along[:, None]
    X, dX_dt, dX_ds = (np.hstack([m, m * a]) for m in (X, dX_dt, dX_ds))
    fourier = np.stack([np.ones(len(t)), np.cos(ann.angle), np.sin(ann.angle)], axis=1)
    shift = -s * geo.kappa[:, None]          # the curvature shift moves with s: dt/ds = -s kappa
    return (X, fourier * h[:, None], dX_dt, dX_ds + dX_dt * shift, fourier * dh_dt[:, None],
            fourier * (dh_ds[:, None] + dh_dt[:, None] * shift))


def _solve(X, G, y, w, ann):
    """
    Solve the weighted least squares in the bins' levels and the global parameters.

    min sum w (y - X l_bin - G p)^2, X (n, 8) each pixel's own bin's columns, G (n, k) the global
    ones. Every bin's normal equations come from one batched product of its (padded) pixels; its
    levels are eliminated (Schur complement). Returns p, the levels (n_bins, 8), the inverse of
    the Schur complement (k, k) and the bins' own normal matrices' inverses (n_bins, 8, 8: the
    levels' covariance over the noise's square, p held). A global column that vanishes gets no
    step.
    """
    m = X.shape[1]
    Z = np.hstack([X, G, y[:, None]]) * np.sqrt(w)[:, None]
    Zp = np.concatenate([Z, np.zeros((1, Z.shape[1]))])[ann.gather]     # (B, P, m + k + 1)
    M = np.matmul(Zp.transpose(0, 2, 1), Zp)
    Nbb, Nbg, vb = M[:, :m, :m], M[:, :m, m:-1], M[:, :m, -1]
    Nbb = Nbb + (1e-6 * np.trace(Nbb, axis1=1, axis2=2) / m + 1e-12)[:, None, None] * np.eye(m)
    inv = np.linalg.inv(Nbb)
    T = np.matmul(inv, Nbg)
    raw = M[:, m:-1, m:-1].sum(axis=0)
    S = raw - np.einsum('bik,bil->kl', Nbg, T)
    rhs = M[:, m:-1, -1].sum(axis=0) - np.einsum('bik,bi->k', T, vb)
    diag = np.diag(S)
    # a column is dead when the bins' levels explain it all, or it is zero (each on its own scale)
    live = (diag > 1e-9 * np.diag(raw)) & (np.diag(raw) > 0)
    d = np.sqrt(diag[live])
    S_inv = np.zeros_like(S)
    S_inv[np.ix_(live, live)] = np.linalg.pinv(
        S[np.ix_(live, live)] / np.outer(d, d), rcond=1e-12, hermitian=True) / np.outer(d, d)
    p = S_inv @ rhs
    levels = np.einsum('bij,bj->bi', inv, vb) - np.einsum('bik,k->bi', T, p)
    return p, levels, S_inv, inv


@dataclass
class ModelFit:
    c: np.ndarray                  # (3,) sphere centre, optical frame, m
    cov: np.ndarray                # (3, 3) its covariance, m^2
    blur: float                    # px: the edge spread fitted (lens and pixel)
    noise: float                   # grey levels (linearised): the pixel noise estimated
    beta: np.ndarray               # (3,) the limb's square-root shading coefficients
    levels: np.ndarray             # (n_bins, 8) per bin
    step_sd: np.ndarray            # (n_bins,) standard error of each bin's step a0 - b0
    weights: np.ndarray            # (n,) weight of each annulus pixel
    residuals: np.ndarray          # (n,) grey levels (linearised)
    iterations: int
    annulus: Annulus = field(repr=False)
    prior_weights: np.ndarray = field(default=None, repr=False)   # (n,) before robust weights
    # the robust scale, the noise the weights assumed and the edge's, ball's, background's noise
    noise_levels: tuple = field(default=None, repr=False)
    plate_share: float = None      # of the bins the background plate gave (None: no plate)

    def edge_bins(self, min_step=8.0):
        """
        Return which bins show the ball's edge: a step from background to limb out of the noise.

        The step is a0 - b0; a bin's needs min_step grey levels and four times its standard error
        (``step_sd``, from the fit: about noise sqrt(12 / n) for n pixels with weight across a
        sharp edge, and more where the blur makes the bin's levels hard to tell apart).
        """
        step = self.levels[:, 2] - self.levels[:, 0]
        n = self._weighted_pixels()
        return (np.abs(step) > np.maximum(min_step, 4 * self.step_sd)) & (n >= 8)

    def _weighted_pixels(self):
        """Return each bin's number of pixels the robust weights kept."""
        return np.bincount(self.annulus.bins, self.weights > 0, minlength=len(self.levels))

    def coverage(self, min_step=8.0):
        """Return how much of the outline (rad) its edge bins cover: 2 pi less the widest gap."""
        a = np.sort(self.annulus.bin_angle[self.edge_bins(min_step)])
        if len(a) < 2:
            return 0.0
        gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
        return float(2 * np.pi - gaps.max() + 2 * np.pi / len(self.annulus.bin_angle))

    def polarity_flips(self, min_step=8.0):
        """Return how often the step's sign changes around the outline, over its edge bins."""
        edge = self.edge_bins(min_step)
        step = (self.levels[:, 2] - self.levels[:, 0])[edge]
        if len(step) < 2:
            return 0
        sign = np.sign(step)
        return int(np.sum(sign != np.roll(sign, 1)))

    def limb_variation(self):
        """
        Return how rough the ball's side of the outline is, against its edge's step.

        The RMS of the bins' limb levels a0 about their least-squares Fourier series of order 2
        in the outline's direction (bins with 8 pixels of weight or more), over the median step
        |a0 - b0| of the edge bins. A Lambertian ball's limb, amb + D max(0, cos(phi - phi_l)),
        leaves 3 % of D past order 2; a false outline on a pattern (a checkerboard, a texture)
        crosses inside it what it crosses outside, and its inner levels jump like the outer ones.
        """
        used, edge = self._weighted_pixels() >= 8, self.edge_bins()
        phi = self.annulus.bin_angle[used]
        A = np.column_stack([np.ones_like(phi), np.cos(phi), np.sin(phi), np.cos(2 * phi),
                             np.sin(2 * phi)])
        if len(phi) <= 2 * A.shape[1] or not edge.any():
            return np.inf
        a0 = self.levels[used, 2]
        rough = np.sqrt(np.mean((a0 - A @ np.linalg.lstsq(A, a0, rcond=None)[0]) ** 2))
        return float(rough / np.median(np.abs(self.levels[edge, 2] - self.levels[edge, 0])))

    @property
    def kept(self):
        """Return the fraction of the pixels' weight the robust weights leave: 1 for all of it."""
        return float(self.weights.sum() / max(self.prior_weights.sum(), 1e-300))

    @property
    def rms(self):
        """Return the weighted RMS residual over the noise (1 for a model that fits; floored)."""
        w = self.weights > 0
        return float(np.sqrt(np.average(self.residuals[w] ** 2, weights=self.weights[w]))
                     / max(self.noise, SCALE_FLOOR))


def _noise(r, ann, ok):
    """Return the white pixel noise: robust spread of differences of neighbouring residuals."""
    j = ann.right
    pair = (j >= 0)
    pair[pair] &= ok[pair] & ok[j[pair]]
    if pair.sum() < 20:
        return float(1.4826 * np.median(np.abs(r[ok]))) if ok.any() else 1.0
    return float(1.4826 * np.median(np.abs(r[pair] - r[j[pair]])) / np.sqrt(2))


def _weights(r, w0, ann, scale, noise):
    """Return Tukey's biweight of the residuals times the bins' weight (what the model follows)."""
    u = r / (TUKEY * scale)
    tukey = np.where((w0 > 0) & (np.abs(u) < 1), (1 - u * u) ** 2, 0.0)
    ok = (w0 > 0).astype(float)
    n = np.bincount(ann.bins, ok, minlength=len(ann.gather))
    ms = np.bincount(ann.bins, ok * np.minimum(r * r, (TUKEY * scale) ** 2),
                     minlength=len(ann.gather)) / np.maximum(n, 1)
    excess = ms / (noise * noise)
    per_bin = np.minimum(1.0, (1 + BIN_EXCESS) / np.maximum(excess + BIN_EXCESS, 1e-9))
    return w0 * tukey * per_bin[ann.bins]


def scores(img, camera, R, fits, gamma=1.0, irls=4):
    """
    Return how badly each of ``fits`` (ModelFits of one image) explains the image: (n,) costs.

    Fits from different starts each weigh their own annulus and noise; to compare them, every
    sphere (its centre and blur held) is scored on one annulus that holds all their outlines,
    with one robust scale (their median noise, floored at SCALE_FLOOR): the levels and beta
    fitted by weighted least squares, then ``irls`` rounds with Tukey's weights; the score is
    the sum of Tukey's rho. DetectionError when that annulus leaves the image.
    """
    c_mid = np.mean([f.c for f in fits], axis=0)
    spread = max(sum(outline_offset(camera, R, c_mid, f.c)) for f in fits)
    r_mid = camera.apparent_radius(c_mid, R)
    outer = _outer_px(max(f.blur for f in fits), r_mid) + spread
    ann = annulus(img, camera, c_mid, R, outer, max(2.5, INNER * r_mid) + spread)
    y, w0 = linearise(ann.values, gamma)
    w0 = w0 * ann.usable
    scale = max(float(np.median([f.noise for f in fits])), SCALE_FLOOR)
    return np.array([_tukey_cost(ann, camera, R, f, y, w0, scale, irls) for f in fits])


def _tukey_cost(ann, camera, R, fit, y, w0, scale, irls):
    """Return the sum of Tukey's rho of the annulus's residuals to fit's sphere and blur."""
    X, H = columns(geometry(ann, camera, fit.c, R), ann, fit.blur)[:2]

    def scaled_residuals(w):
        beta, levels = _solve(X, H, y, w, ann)[:2]
        r = y - np.einsum('ni,ni->n', X, levels[ann.bins]) - H @ beta
        return r * np.sqrt(w0) / (TUKEY * scale)

    u = scaled_residuals(w0)
    for _ in range(irls):
        u = scaled_residuals(np.where((w0 > 0) & (np.abs(u) < 1), w0 * (1 - u * u) ** 2, 0.0))
    u = u[w0 > 0]
    return float(np.sum(np.where(np.abs(u) < 1, 1 - (1 - u * u) ** 3, 1.0)))


def _outer_px(s, r_px):
    """Return how far outside the outline (px) a fit's annulus reaches, at blur s, radius r_px."""
    return min(float(np.clip(3 * s + 2.0, 3.5, 6.0)), max(2.5, 0.3 * r_px))


def linearise(values, gamma):
    """
    Return linear intensities and each one's noise weight for a response grey = 255 (I/255)^(1/g).

    The sensor's noise is added after the response: a grey level's noise becomes
    gamma (grey / 255)^(gamma - 1) times it in linear units (weight: its inverse square).
    """
    if gamma == 1.0:
        return values.astype(float), np.ones(len(values))
    g = np.maximum(values, 1.0) / 255.0
    return 255.0 * g ** gamma, g ** (2 - 2 * gamma)


def behind(background, ann, geo, s, gamma):
    """
    Return the background's texture behind each annulus pixel, its slope, the share it covers.

    ``background``: what lies behind the ball (``plate.BackgroundPlate``), linear units. T: per
    bin, the plate less its mean over the bin (the bin's level b0 keeps the rest), over the pixels
    the ball may leave to the background (within 4 blurs inside the outline at the start); T_t:
    the plate's slope along the outline's inward normal there (central differences, per px).
    Both zero in a bin whose plate there is not trusted (``plate.trusted``): such a bin keeps its
    levels alone. T, T_t (n,); the share of those bins whose plate was trusted.
    """
    grey, scatter, dof = background.at(ann.pixels)
    levels = linearise(np.nan_to_num(grey), gamma)[0]
    step = [background.at(ann.pixels + o)[0] for o in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    du, dv = ((linearise(np.nan_to_num(a), gamma)[0] - linearise(np.nan_to_num(b), gamma)[0])
              / 2 for a, b in (step[:2], step[2:]))
    slope = -(du * np.cos(ann.angle) + dv * np.sin(ann.angle))
    slope = np.where(np.all(np.isfinite(step), axis=0), slope, 0.0)
    needed = geo.d < 4 * s
    T, T_t = np.zeros(len(levels)), np.zeros(len(levels))
    bins = np.flatnonzero(np.bincount(ann.bins[needed], minlength=len(ann.gather)))
    used = 0
    for b in bins:
        k = ann.gather[b][ann.gather[b] >= 0]
        k = k[needed[k]]
        if plate.trusted(grey[k], scatter[k], dof[k]):
            T[k], T_t[k] = levels[k] - levels[k].mean(), slope[k]
            used += 1
    return T, T_t, used / max(len(bins), 1)


def texture_columns(T, T_t, geo, s):
    """
    Return a known background texture's share of the pixels, and its derivatives in t and s.

    A background B(t) behind the edge, blurred by a Gaussian of width s with the ball's step:
    B(t) (1 - Phi) - s B'(t) phi(tau), B' = T_t its slope inward (the first order of B's
    expansion about the pixel; with B linear, the b1 column of ``columns``).
    """
    t = geo.d - 0.5 * s * s * geo.kappa
    tau = t / s
    Phi = ndtr(tau)
    phi = np.exp(-0.5 * tau * tau) / np.sqrt(2 * np.pi)
    value = T * (1 - Phi) - s * T_t * phi
    d_dt = -T * phi / s + T_t * tau * phi
    d_ds = T * phi * tau / s - T_t * phi * (1 + tau * tau)
    return value, d_dt, d_ds - s * geo.kappa * d_dt


def _known(texture, geo, s):
    """Return texture_columns of ``behind``'s (T, T_t), or zeros without a plate."""
    return (0.0, 0.0, 0.0) if texture is None else texture_columns(*texture[:2], geo, s)


def fit(img, camera, R, c0, blur0=1.0, gamma=1.0, iterations=10, tol=0.01, limb=True,
        noise_levels=None, highlight=None, background=None):
    """
    Fit the sphere of radius R to the image from a start c0 (m) whose outline is a pixel or so off.

    ``blur0``: the first guess of the edge spread (px); ``gamma``: the camera's response
    (grey = 255 (I / 255)^(1 / gamma), 1 for a linear camera). Stops when the step in c is below
    ``tol`` of its standard deviation. ``limb``: fit the limb's square-root shading (without it,
    a coarse first fit that only pulls the outline into place). A step moves the outline by at
    most MAX_STEP_PX and the blur by a third. DetectionError when the fit cannot be made.
    ``noise_levels``: a previous fit's of the same scene (ModelFit.noise_levels, a frame before at
    rest): the robust scale and the zones' noise start there instead of being found in the first
    iterations, so that the weights are settled from the first step (half the iterations).
    ``highlight``: the ball's specular lobe measured on its disc (``highlight.fit``), taken out
    of the annulus's pixels before the fit. ``background``: a plate of what lies behind the ball
    (``plate.BackgroundPlate``); the background's texture (``behind``) is then part of the model,
    blurred with the edge as the levels are (``texture_columns``).
    """
    c = np.asarray(c0, dtype=float).copy()
    s = float(np.clip(blur0, *BLUR_RANGE))
    r_px = camera.apparent_radius(c, R)
    outer = _outer_px(s, r_px)
    ann = annulus(img, camera, c, R, outer, max(2.5, INNER * r_px))
    y, w0 = linearise(ann.values, gamma)
    w0 = w0 * ann.usable
    geo = geometry(ann, camera, c, R)
    if highlight is not None:
        y = y - highlight.values(camera, ann.pixels, c, R, s)
    texture = None if background is None else behind(background, ann, geo, s, gamma)
    X, H = columns(geo, ann, s)[:2]
    H = H if limb else H[:, :0]
    beta, levels = _solve(X, H, y - _known(texture, geo, s)[0], w0, ann)[:2]
    known = noise_levels is not None
    scale, noise, zone_noise = ((noise_levels[0], noise_levels[1], noise_levels[2:]) if known
                                else (None, None, None))
    for it in range(1, iterations + 1):
        X, H, dX_dt, dX_ds, dH_dt, dH_ds = columns(geo, ann, s)
        if not limb:
            H, dH_dt, dH_ds = H[:, :0], dH_dt[:, :0], dH_ds[:, :0]
        lv = levels[ann.bins]
        seen, seen_dt, seen_ds = _known(texture, geo, s)
        y_bt = y - seen                 # less the background's texture, where it shows
        r = (y_bt - np.einsum('ni,ni->n', X, lv) - H @ beta) * np.sqrt(w0)
        if it <= 3 and not known:
            # floored: on an image without noise the model's own small misfit must not count as
            # outliers (a grey level: 8-bit rounding and a few tenths of a percent of a step)
            scale = max(1.4826 * np.median(np.abs(r[w0 > 0])), SCALE_FLOOR)
            noise = max(_noise(r, ann, w0 > 0), SCALE_FLOOR)
        if it == (1 if known else 2):
            # the ball, the background and the edge need not be equally noisy (a sensor's noise
            # grows with the signal; a renderer's sampling of the lens and the pixel with the
            # edge): each zone weighted by its own, the edge's (within 1.5 blurs) from its
            # residuals' spread, the others' from neighbouring differences
            edge = np.abs(geo.d) < 1.5 * s
            inside = (geo.d > 0) & ~edge
            zone = np.where(edge, 0, np.where(inside, 1, 2))
            if not known:
                zone_noise = (max(1.4826 * np.median(np.abs(r[(w0 > 0) & edge])), SCALE_FLOOR)
                              if np.sum((w0 > 0) & edge) > 20 else noise,
                              max(_noise(r, ann, (w0 > 0) & inside), SCALE_FLOOR),
                              max(_noise(r, ann, (w0 > 0) & (geo.d <= 0) & ~edge), SCALE_FLOOR))
            factor = np.maximum(np.array(zone_noise)[zone] / noise, 1e-3)
            w0, r = w0 / factor ** 2, r / factor
        w = _weights(r, w0, ann, scale, noise)
        dy_dt = np.einsum('ni,ni->n', dX_dt, lv) + dH_dt @ beta + seen_dt
        dy_ds = np.einsum('ni,ni->n', dX_ds, lv) + dH_ds @ beta + seen_ds
        # linearised in c and s about the current values; levels and beta solved afresh
        G = np.column_stack([dy_dt[:, None] * geo.dd_dc, dy_ds, H])
        p, levels, S_inv, level_inv = _solve(X, G, y_bt, w, ann)
        dc, ds, beta = p[:3], p[3], p[4:]
        # at most MAX_STEP_PX of outline a step (the outline moves by about the image of dc)
        dc *= min(1.0, MAX_STEP_PX / max(np.max(np.abs(geo.dd_dc @ dc)), 1e-12))
        c = c + dc
        s = float(np.clip(s + np.clip(ds, -s / 3, s / 3), *BLUR_RANGE))
        geo = geometry(ann, camera, c, R)
        sd = np.sqrt(np.maximum(np.diag(S_inv)[:3], 1e-30)) * noise
        if np.all(np.abs(dc) < tol * sd) and abs(ds) < 1e-3 and it >= 2:
            break
    if not np.all(np.isfinite(c)) or c[2] <= R:
        raise DetectionError('the model fit did not converge')
    # the outline must have stayed within the annulus it was fitted on
    moved, grown = outline_offset(camera, R, c0, c)
    if moved > outer or grown > outer:
        raise DetectionError(f'the outline is not where the fit started ({moved:.1f} px off, '
                             f'radius {grown:.1f} px off)')
    X, H = columns(geo, ann, s)[:2]
    H = H if limb else H[:, :0]
    r = (y - _known(texture, geo, s)[0] - np.einsum('ni,ni->n', X, levels[ann.bins])
         - H @ beta) * np.sqrt(w0)
    weight_noise, noise = noise, _noise(r, ann, w > 0)
    # the step's standard error from the bin's own normal equations and the larger of the noise
    # and the bin's residuals: a blurred edge's columns and the ramps beside them can sum to a flat
    # image, and a fit that wandered there shows a step a0 - b0 that its residuals belie
    kept = w > 0
    n_kept = np.bincount(ann.bins, kept, minlength=len(levels))
    bin_ms = np.bincount(ann.bins, np.where(kept, r * r, 0.0), minlength=len(levels))
    spread = np.maximum(noise, np.sqrt(bin_ms / np.maximum(n_kept, 1)))
    step_sd = spread * np.sqrt(np.maximum(
        level_inv[:, 0, 0] + level_inv[:, 2, 2] - 2 * level_inv[:, 0, 2], 0.0))
    return ModelFit(c, noise * noise * S_inv[:3, :3], s, noise, beta, levels, step_sd, w, r, it,
                    ann, w0, (scale, weight_noise, *zone_noise),
                    None if texture is None else texture[2])
