"""
Sub-pixel points of the ball's outline (no rclpy).

1. ``rough_circle``: where the ball is. Strong gradients of the image shrunk 4 times form blobs;
   the limb ring (joined with its pieces where it breaks) gives a box, hence a centre and a radius.
2. ``radial_edges``: coarse outline points, the outermost steep point along rays from that centre
   (the limb is the ball's outermost edge; the highlight and the terminator are inside it).
3. ``profile_edges``: the sub-pixel outline. Along the normals of a predicted outline the image is
   sampled (bilinear, every 0.5 px) and fitted with what a lit ball against a background looks like
   across its limb, blurred by a Gaussian point spread function of width sigma:

       outside (s > e):  B0 + B1 (s - e)         background level and slope (gradient, texture)
       inside  (s < e):  A0 + A1 (e - s)         the ball's shading near the limb

   The step A0 - B0 may have either sign (a darker side of the ball against a brighter background)
   and any size: the edge offset e does not depend on it, where a threshold or a steepest-gradient
   edge moves with the shading. The model is linear in the coefficients, so each profile is
   resampled at its current edge and one design (the model at e = 0) serves all: a Gauss-Newton
   step in e by variable projection is two small matrix products for all profiles at once. The blur
   is estimated per frame (``estimate_blur``: the sigma that leaves the least residual).

   Known limits (measured, benchmarks/vision.py): a Lambertian limb lit from the camera's side
   brightens as the square root of the depth inside it, which this model takes for part of the step
   (the outline comes out inside, the ball too far: a few tenths of a percent of the range, more
   for small balls and frontal light; a square-root term was tried and dropped: it depends on the
   exact point spread function and turns noise into bias). A saturated glossy highlight near the
   limb pulls the outline outward; profiles touching saturated pixels are dropped for that reason.

   A blurred curved edge looks a little inside its true place (by sigma^2 kappa / 2 for curvature
   kappa); ``profile_edges`` adds that back. Profiles touching saturated pixels are dropped.
"""
from dataclasses import dataclass
import functools

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.special import ndtr

STEP = 0.5                 # sample spacing along a profile, px
REACH = 1.5               # px: how far from the predicted outline a profile looks for the edge
RELATIVE_CONTRAST = 0.35  # a profile's step must be this fraction of the frame's median step
# grey levels (8-bit): interpolated samples beyond these touch a clipped pixel
SATURATED = (4.0, 251.0)
INTERPOLATION = cv2.INTER_LINEAR


class EdgeError(ValueError):
    """No usable outline: the message says why."""


# --- 1. where is the ball ------------------------------------------------------------------------

def rough_circle(image, r_min, r_max, factor=4):
    """
    Centre (u, v) and radius (px) of the ball, to a few pixels; EdgeError if there is none.

    r_min, r_max: the radii (px) a ball in the working range can have. Strong gradients of the
    image shrunk ``factor`` times form blobs; the best blob (strength times size: the limb ring,
    not the highlight inside it) is joined by the blobs near it (the ring breaks where the ball
    matches the background), and the box around them all is the ball's: the limb is its outermost
    edge.
    """
    h, w = image.shape
    small = cv2.resize(np.asarray(image, dtype=np.float32), (w // factor, h // factor),
                       interpolation=cv2.INTER_AREA)
    mag = cv2.magnitude(cv2.Sobel(small, cv2.CV_32F, 1, 0, ksize=3),
                        cv2.Sobel(small, cv2.CV_32F, 0, 1, ksize=3))
    threshold = max(5.0 * float(np.median(mag[::2, ::2])), 20.0)
    mask = cv2.dilate((mag > threshold).astype(np.uint8), np.ones((3, 3), np.uint8))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count < 2:
        raise EdgeError('no sphere: no strong edge in the image')
    x0, y0 = stats[1:, cv2.CC_STAT_LEFT], stats[1:, cv2.CC_STAT_TOP]
    x1, y1 = x0 + stats[1:, cv2.CC_STAT_WIDTH], y0 + stats[1:, cv2.CC_STAT_HEIGHT]
    size = np.maximum(x1 - x0, y1 - y0)            # diameter / factor + 2 (the dilation)
    too_big = 2 * r_max / factor + 4
    plausible = (size >= r_min / factor + 2) & (size <= too_big)
    if not np.any(plausible):
        raise EdgeError('no sphere: no edge blob of a plausible size '
                        f'({r_min:.0f}-{r_max:.0f} px radius)')
    strength = np.bincount(labels.ravel(), weights=mag.ravel(), minlength=count)[1:]
    best = int(np.argmax(np.where(plausible, strength * size, -1.0)))
    grow = 0.6 * size[best]
    near = ((x0 < x1[best] + grow) & (x1 > x0[best] - grow)
            & (y0 < y1[best] + grow) & (y1 > y0[best] - grow)
            & (size <= too_big))
    bx0, by0, bx1, by1 = x0[near].min(), y0[near].min(), x1[near].max(), y1[near].max()
    # small pixel i covers pixels factor i .. factor i + factor - 1; the dilation added one on each
    # side and the 3x3 Sobel about one more beyond the edge
    centre = factor * np.array([bx0 + bx1 - 1, by0 + by1 - 1], dtype=float) / 2 + (factor - 1) / 2
    radius = factor * ((bx1 - bx0 - 4) + (by1 - by0 - 4)) / 4
    if not (0.5 * r_min <= radius <= 1.5 * r_max):
        raise EdgeError(f'no sphere: the edge blob found has radius {radius:.1f} px, '
                        f'outside {r_min:.0f}-{r_max:.0f} px')
    return centre, radius


# --- sampling ----------------------------------------------------------------------------------

def sample_profiles(image_f32, points, normals, s, warp=None):
    """
    Sample the image at points + s * normals (bilinear).

    Returns the values (n, len(s)) and a mask of the rays inside the image.

    ``warp`` maps those positions (..., 2) to image pixels: the lens distortion when the points are
    ideal (undistorted) pixels; None when they are image pixels already.
    """
    xy = points[:, None, :] + s[None, :, None] * normals[:, None, :]
    if warp is not None:
        xy = warp(xy)
    h, w = image_f32.shape
    u, v = xy[..., 0].astype(np.float32), xy[..., 1].astype(np.float32)
    inside = np.all((u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1), axis=1)
    values = cv2.remap(image_f32, u, v, INTERPOLATION, borderMode=cv2.BORDER_REPLICATE)
    return values.astype(float), inside


def _peak(a, k):
    """Parabolic sub-sample position of the peak of rows of a (n, m) at indices k (n,)."""
    k = np.clip(k, 1, a.shape[1] - 2)
    rows = np.arange(len(k))
    y0, y1, y2 = a[rows, k - 1], a[rows, k], a[rows, k + 1]
    den = y0 - 2 * y1 + y2
    frac = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
    return k + np.clip(frac, -0.5, 0.5)


def _outermost_steep(profiles, s):
    """
    Find the outermost local maximum of |slope| that reaches half the largest one.

    Returns its offset (n,), to sub-sample, and that slope.
    """
    d = np.diff(profiles, axis=1)                 # slope between samples, at their midpoints
    a = np.abs(d)
    padded = np.pad(a, ((0, 0), (1, 1)), constant_values=-1.0)
    peak = (a >= padded[:, :-2]) & (a >= padded[:, 2:]) & (a >= 0.5 * a.max(axis=1, keepdims=True))
    k = a.shape[1] - 1 - np.argmax(peak[:, ::-1], axis=1)
    step = s[1] - s[0]
    return 0.5 * (s[0] + s[1]) + _peak(a, k) * step, d[np.arange(len(k)), k] / step


# --- 2. coarse outline -------------------------------------------------------------------------

def radial_edges(image_f32, centre, radius, spacing=3.0, warp=None):
    """
    Coarse outline points (n, 2): outermost steep point on rays from ``centre`` near ``radius``.

    ``centre`` and the points are in the frame ``warp`` maps to the image (see sample_profiles).
    """
    n = int(np.clip(2 * np.pi * radius / spacing, 24, 180))
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    normals = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    half = max(6.0, 0.4 * radius)       # the rough radius is good to a shrunk pixel (4 px)
    s = np.arange(-half, half + STEP / 2, STEP)
    profiles, inside = sample_profiles(image_f32, np.asarray(centre) + radius * normals, normals,
                                       s, warp)
    e, slope = _outermost_steep(profiles, s)
    points = centre + (radius + e)[:, None] * normals
    return points[inside], np.abs(slope[inside])


# --- 3. sub-pixel outline ----------------------------------------------------------------------

def limb_basis(s, sigma):
    """
    Blurred model basis (K, 4) at offsets s for an edge at 0, and its edge-offset derivative.

    Columns: H(s), s H(s), H(-s), -s H(-s) blurred by N(0, sigma^2), i.e. the coefficients
    (B0, B1, A0, A1) of the module docstring; with tau = s / sigma they are Phi(tau),
    sigma (tau Phi + phi), 1 - Phi, sigma (phi - tau (1 - Phi)).
    """
    tau = np.asarray(s, dtype=float) / sigma
    Phi = ndtr(tau)
    phi = np.exp(-0.5 * tau * tau) / np.sqrt(2 * np.pi)
    X = np.stack([Phi, sigma * (tau * Phi + phi), 1 - Phi, sigma * (phi - tau * (1 - Phi))],
                 axis=-1)
    dX_de = np.stack([-phi / sigma, -Phi, phi / sigma, 1 - Phi], axis=-1)
    return X, dX_de


@dataclass
class _Design:
    """What the profile fit needs of the model at one sigma, shared by every profile."""

    X: np.ndarray          # (K, 4) blurred basis at edge offset 0
    dX: np.ndarray         # (K, 4) its derivative in the edge offset
    pinv: np.ndarray       # (4, K) least squares: coefficients = pinv @ profile
    proj: np.ndarray       # (K, K): I - X pinv, the residual maker

    @classmethod
    def at(cls, s, sigma):
        X, dX = limb_basis(s, sigma)
        pinv = np.linalg.solve(X.T @ X, X.T)
        return cls(X, dX, pinv, np.eye(len(s)) - X @ pinv)

    def step(self, P):
        """
        Gauss-Newton step in the edge offset for profiles P (n, K) (variable projection).

        Returns (step, theta, residual, |projected derivative|^2).
        """
        theta = P @ self.pinv.T
        r = P @ self.proj.T
        g = (theta @ self.dX.T) @ self.proj.T
        gg = np.einsum('nk,nk->n', g, g)
        return np.einsum('nk,nk->n', g, r) / np.maximum(gg, 1e-12), theta, r, g, gg


@dataclass
class ProfileFit:
    e: np.ndarray          # (n,) edge offset along the normal, px (curvature-corrected)
    sigma_e: np.ndarray    # (n,) its standard error, px
    contrast: np.ndarray   # (n,) A0 - B0: ball limb minus background, grey levels
    rms: np.ndarray        # (n,) residual RMS, grey levels
    ok: np.ndarray         # (n,) inside the image and the window, enough contrast
    inside: np.ndarray     # (n,) the whole profile (and its reach) inside the image


class _Profiles:
    """
    Profiles along fixed normals, resampled at any edge offsets without warping again.

    The image positions of a grid of offsets along each normal are warped (distorted) once; the
    positions at other offsets are interpolated between grid nodes (the warp is smooth: the error
    is far below 1e-4 px over half a pixel).
    """

    def __init__(self, image_f32, points, normals, s, reach, warp=None):
        self.image, self.s, self.reach = image_f32, s, reach
        grid = np.arange(s[0] - reach, s[-1] + reach + STEP / 2, STEP)
        xy = points[:, None, :] + grid[None, :, None] * normals[:, None, :]
        if warp is not None:
            xy = warp(xy)
        u, v = (np.ascontiguousarray(xy[..., 0], np.float32),
                np.ascontiguousarray(xy[..., 1], np.float32))
        h, w = image_f32.shape
        self.inside = np.all((u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1), axis=1)
        # windows of K + 1 grid nodes starting at each node: a profile and its next node, per start
        self.u = sliding_window_view(u, len(s) + 1, axis=1)
        self.v = sliding_window_view(v, len(s) + 1, axis=1)
        self.rows = np.arange(len(points))

    def at(self, e):
        """Sample the profiles (n, K) at offsets s + e (e clipped to the reach)."""
        # grid index of offset s[0] + e
        q = (np.clip(e, -self.reach, self.reach - 1e-6) + self.reach) / STEP
        j = q.astype(np.intp)
        f = (q - j).astype(np.float32)[:, None]
        u, v = self.u[self.rows, j], self.v[self.rows, j]        # (n, K + 1)
        u = u[:, :-1] + f * np.diff(u, axis=1)
        v = v[:, :-1] + f * np.diff(v, axis=1)
        return cv2.remap(self.image, u, v, INTERPOLATION,
                         borderMode=cv2.BORDER_REPLICATE).astype(float)


def profile_edges(image_f32, points, normals, kappa, half_width, sigma, warp=None, iterations=2,
                  min_contrast=8.0, refit_blur=False, relative_contrast=None):
    """
    Sub-pixel outline along the normals of a predicted outline (points, unit normals outward).

    Each profile is resampled at its current edge estimate, so one design (the model at edge 0)
    serves every profile: a step is two small matrix products. kappa: curvature of the predicted
    outline (1/px); half_width: profile extent on each side (px); sigma: the blur (px), a first
    guess when ``refit_blur``, then estimated from the profiles once they sit on the edge
    (``estimate_blur``). ``points + e * normals`` are the outline points. Returns
    (ProfileFit, sigma).
    """
    s = np.arange(-half_width, half_width + STEP / 2, STEP)
    profiles = _Profiles(image_f32, points, normals, s, REACH, warp)
    design = _cached_design(float(s[0]), len(s), float(sigma))
    e = np.zeros(len(points))
    for it in range(iterations):
        P = profiles.at(e)
        # no profile inside the image (a ball at the border): the guess stands
        if refit_blur and it == iterations - 1 and np.any(profiles.inside):
            sigma = estimate_blur(P[profiles.inside], s)
            design = _cached_design(float(s[0]), len(s), sigma)
        e += np.clip(design.step(P)[0], -1.0, 1.0)
    P = profiles.at(e)
    de, theta, r, _, gg = design.step(P)
    e += np.clip(de, -1.0, 1.0)
    inside = profiles.inside
    rms = np.sqrt(np.sum(r * r, axis=1) / (len(s) - 1 - design.X.shape[1]))
    contrast = theta[:, 2] - theta[:, 0]
    noise = np.median(rms[inside]) if np.any(inside) else np.inf
    # a profile the model misfits counts less
    sigma_e = np.maximum(rms, noise) / np.sqrt(np.maximum(gg, 1e-12))
    # A sample at the sensor's limits (a saturated highlight) is not the model's: the profile is
    # dropped.
    clipped = np.any((P > SATURATED[1]) | (P < SATURATED[0]), axis=1)
    # Where the limb crosses the background's brightness, the shading inside outweighs the step and
    # pulls the edge: a profile needs a step of a good part of the frame's typical one.
    typical = np.median(np.abs(contrast[inside])) if np.any(inside) else 0.0
    relative_contrast = RELATIVE_CONTRAST if relative_contrast is None else relative_contrast
    ok = (inside & ~clipped & (np.abs(e) < min(half_width - 1.0, REACH - 0.1))
          & (np.abs(de) < 0.05)
          & (np.abs(contrast) > max(min_contrast, 4 * noise, relative_contrast * typical))
          & (sigma_e < 0.5))
    # The blur of a curved edge moves it inward by sigma^2 kappa / 2 (to first order): add it back.
    return ProfileFit(e + 0.5 * sigma ** 2 * kappa, sigma_e, contrast, rms, ok, inside), sigma


SIGMAS = np.geomspace(0.55, 2.2, 6)     # blur candidates, px (a factor 1.32 apart)
BLUR_GRID = np.log(1.02)


def estimate_blur(P, s, sigmas=SIGMAS):
    """
    Estimate the frame's blur sigma (px).

    The sigma whose model leaves the least residual in profiles P (n, K) sampled at offsets s
    around the current edge estimates.

    One linearised edge step is taken for each candidate sigma (all candidates in one batch of
    matrix products, on every other profile: plenty for one number); the minimum of the summed
    squared residual is refined by a parabola in log(sigma). Raise ValueError without profiles.
    """
    if len(P) == 0:
        raise ValueError('estimate_blur: no profile to estimate the blur from')
    A, Pj, D = _blur_designs(float(s[0]), len(s), tuple(sigmas))
    P = P[::2]
    theta = np.matmul(P, A)                         # (S, n, 4)
    r = np.matmul(P, Pj)                            # (S, n, K)
    g = np.matmul(theta, D)                         # (S, n, K)
    de = np.sum(g * r, axis=2) / np.maximum(np.sum(g * g, axis=2), 1e-12)
    res = r - de[..., None] * g
    per_ray = np.sum(res * res, axis=2)
    # a few wild profiles must not decide
    cap = 9 * np.median(per_ray, axis=1, keepdims=True)
    sse = np.sum(np.minimum(per_ray, cap), axis=1)
    k = int(np.clip(np.argmin(sse), 1, len(sigmas) - 2))
    y0, y1, y2 = sse[k - 1:k + 2]
    den = y0 - 2 * y1 + y2
    frac = np.clip(0.5 * (y0 - y2) / den, -1, 1) if den > 0 else 0.0
    log_sigma = np.log(sigmas[k]) + frac * np.log(sigmas[1] / sigmas[0])
    # on a 2 % grid, so the profile designs repeat (cached): far finer than the estimate itself
    return float(np.exp(np.round(log_sigma / BLUR_GRID) * BLUR_GRID))


@functools.lru_cache(maxsize=64)
def _blur_designs(s0, K, sigmas):
    """
    Build the stacked designs of the candidate sigmas.

    For each candidate sigma: pinv^T (K, 4), residual maker^T (K, K), (dX^T proj^T) (4, K).
    """
    designs = [_Design.at(s0 + STEP * np.arange(K), sig) for sig in sigmas]
    return (np.stack([d.pinv.T for d in designs]), np.stack([d.proj.T for d in designs]),
            np.stack([d.dX.T @ d.proj.T for d in designs]))


@functools.lru_cache(maxsize=256)
def _cached_design(s0, K, sigma):
    return _Design.at(s0 + STEP * np.arange(K), sigma)
