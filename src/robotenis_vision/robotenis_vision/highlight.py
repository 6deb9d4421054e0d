"""
The ball's specular highlight, measured on its disc and taken out of the pixels near its outline.

The model fit (``model_fit``) follows a Lambertian limb: around the outline the ball's shading is
a0 + a1 (sin(i) - 1) + beta(phi) cos(i), beta three Fourier terms around the outline. A
highlight's lobe reaches into the annulus over a few bins only, rising inward; blurred, its rise
looks like the limb's square root of an edge further out, and the ball reads too near. On the
simulator's renders (noise-free, its default light, 15 balls at 0.2-0.4 m) the depth error was
-0.116 mm on average with a spread of 0.132 mm, against -0.047 and 0.087 mm for the same balls
rendered without their highlight; with the highlight taken out, -0.038 and 0.080 mm.

So the lobe is measured where it is bright, on the disc, and its tail predicted where it is faint.
On the disc pixels (deeper than 3 blurs and a pixel inside the outline, not saturated) the
shading is

    y = sum_k s_k Y_k(n) + d max(0, n.l) + A_1 g_1(n, v) + A_2 g_2(n, v)

with Y_k the nine real spherical harmonics of order <= 2 of the surface normal n (a Lambertian
ball under any distant light, to about 1 %), the same light's clamped diffuse term (what the
harmonics miss at a terminator, and would otherwise take from the lobe), and two lobes of one
width w around the half vector h = (l + v) / |l + v| between the light's direction l and the
direction v back to the camera: Blinn-Phong's and a microfacet one (``lobes``). The amplitudes are
linear, the lobes' not negative (``solve``); l and w are found by least squares with the linear
part projected out, from the mirror direction of the brightest pixel above the harmonics' fit.

No highlight is taken out unless its peak stands PEAK_SIGMAS of the noise above the diffuse fit,
it halves the disc's residuals (MIN_GAIN: a Lambertian ball's misfit gains 1.0-1.2, a highlight
12-2000) and its mirror normal lies on the measured disc, a lobe's width inside its rim (a
back-lit ball's highlight on the limb is left to the fit's robust weights). On Mitsuba 3's rough
plastic (GGX with Fresnel) the light's direction comes out within 0.3-3.5 degrees of the
truth's for point lights, and the depth errors of single frames are unchanged: 20 of 53 glossy
dev scenes with a lobe, RMS 0.512 -> 0.523 % of the range, median 0.271 -> 0.269 %; their
errors there are others'.

Cost (one core, the hand camera's default scene at 0.25-0.35 m): 23-25 ms for ``fit`` (33-35 ms
in the same run with each set of lobes solved by its own lstsq on the pixels; ``solve``), about a
fifth of a seeded model fit's time with the lobe looked for. It is looked for in every image fitted
(detector.measure): a rest's mean images carry less noise than its first frame, whose lobe moved
every later fit of the rest by up to 0.27 mm at 0.415 m when it was carried along.
"""
from dataclasses import dataclass
import itertools

import numpy as np
from robotenis_vision.model_fit import (camera_key, ideal_maps, linearise, SATURATED,
                                        SCALE_FLOOR)
from scipy.ndimage import binary_dilation, gaussian_filter
from scipy.optimize import least_squares

PEAK_SIGMAS = 8.0              # a highlight's peak above the diffuse fit, in noise sigmas
MIN_GAIN = 2.0                 # the lobe must halve the disc's sum of squared residuals
WIDTH_RANGE = (0.02, 0.35)     # rad: the lobes' width w (Blinn-Phong exponents 2500 to 8)
MAX_PIXELS = 3000              # disc pixels the lobe is fitted on (a regular subsample)
SUBSAMPLES = 2                 # per pixel side: the rays the lobe's image is averaged over


@dataclass
class Highlight:
    """A specular lobe on the ball: light direction l (optical frame), width w, amplitudes A."""

    light: np.ndarray          # (3,) unit, toward the light
    width: float               # rad
    amplitude: np.ndarray      # (2,) grey levels (linearised): Blinn-Phong's and GGX's lobes

    def values(self, camera, pixels, c, R, s):
        """
        Return the lobe's grey levels at image pixels (u, v), blurred as the edge is (s px).

        Each pixel is the mean of SUBSAMPLES x SUBSAMPLES rays over its area (rays that miss the
        ball see no lobe), blurred by the rest of the edge's spread, sqrt(s^2 - 1/12) px: near the
        limb the normal turns fast and the lobe with it (taken at the pixels' centres, unblurred,
        a side-lit ball's lobe was predicted 0.2-0.5 grey levels low within 2 px of the outline,
        and that moved its fit 0.15 mm).
        """
        lo, shape, vv, uu = ring(camera, pixels, s)
        k = SUBSAMPLES
        n, view, cos_i = _normals(camera, subpixels(camera, lo, vv, uu, k).reshape(-1, 2), c, R)
        g = np.where(cos_i > 0, lobes(n, view, self.light, self.width) @ self.amplitude, 0.0)
        image = np.zeros(shape)
        image[vv, uu] = g.reshape(-1, k * k).mean(axis=1)
        return blurred_at(image, s, pixels, lo)


def ring(camera, pixels, s):
    """
    Return the pixels within 3 blurs (s px) and one pixel of image pixels (u, v), in their box.

    Returns the box's corner lo (u, v), its shape (rows, columns) and the ring's rows vv and
    columns uu within it.
    """
    margin = int(np.ceil(3 * s)) + 1
    lo = np.maximum(pixels.min(axis=0) - margin, 0)
    hi = np.minimum(pixels.max(axis=0) + margin + 1, [camera.width, camera.height])
    inside = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), dtype=bool)
    inside[pixels[:, 1] - lo[1], pixels[:, 0] - lo[0]] = True
    inside = binary_dilation(inside, iterations=margin)
    vv, uu = np.nonzero(inside)
    return lo, inside.shape, vv, uu


def subpixels(camera, lo, vv, uu, k):
    """Return the ideal positions (n, k^2, 2) of k x k rays over each pixel (lo + (uu, vv))."""
    ideal_map, stretch_map = ideal_maps(camera_key(camera))
    offsets = np.stack(np.meshgrid((np.arange(k) + 0.5) / k - 0.5,
                                   (np.arange(k) + 0.5) / k - 0.5), -1).reshape(-1, 2)
    return ideal_map[vv + lo[1], uu + lo[0]][:, None, :] + (
        offsets if stretch_map is None
        else np.einsum('nij,kj->nki', stretch_map[vv + lo[1], uu + lo[0]], offsets))


def blurred_at(image, s, pixels, lo):
    """Return ``image`` (its corner at lo) blurred by sqrt(s^2 - 1/12) px, at image pixels."""
    image = gaussian_filter(image, np.sqrt(max(s * s - 1 / 12, 0.0)), mode='nearest')
    return image[pixels[:, 1] - lo[1], pixels[:, 0] - lo[0]]


def harmonics(n):
    """Return the nine real spherical harmonics of order <= 2 (unnormalised) of unit normals n."""
    x, y, z = n.T
    return np.column_stack([np.ones_like(x), x, y, z, x * y, y * z, x * z, x * x - y * y,
                            3 * z * z - 1])


def lobes(n, v, light, w):
    """
    Return the two lobes' values (m, 2) at unit normals n seen from unit directions v.

    Blinn-Phong's (n.h)^(1 / w^2), and a microfacet specular: the Trowbridge-Reitz (GGX)
    distribution D(n.h) of roughness a = 2 w, times Smith's masking and shadowing G1(n.v) G1(n.l),
    over n.v (radiance: D F G / (4 n.l n.v) times the irradiance n.l; F constant for a distant
    light). That factor makes the microfacet lobe's tail up to 2 / a times brighter at the limb.
    Both are normalised to 1 at the lobe's peak seen face on, and 0 where n.l <= 0.
    """
    h = light[None, :] + v
    h /= np.linalg.norm(h, axis=1)[:, None]
    cos = np.clip(np.einsum('ni,ni->n', n, h), 0.0, 1.0)
    nv = np.clip(np.einsum('ni,ni->n', n, v), 0.0, 1.0)
    nl = n @ light
    a2 = 4 * w * w
    ggx = (a2 / (a2 * cos * cos + 1 - cos * cos)) ** 2
    masking = 2 / (nv + np.sqrt(a2 + (1 - a2) * nv * nv))            # G1(n.v) / n.v
    shadowing = 2 * nl / (nl + np.sqrt(a2 + (1 - a2) * nl * nl))       # G1(n.l)
    microfacet = ggx * masking * np.where(nl > 0, shadowing, 0.0) / 2
    return np.column_stack([np.where(nl > 0, cos ** (1 / (w * w)), 0.0), microfacet])


def _normals(camera, ideal, c, R):
    """Return the normals, the directions back to the camera and cos(i) at ideal pixels."""
    rays = np.column_stack([ideal, np.ones(len(ideal))]) @ np.linalg.inv(camera.K).T
    rays /= np.linalg.norm(rays, axis=1)[:, None]
    b = rays @ c
    disc = b * b - (c @ c - R * R)
    t = b - np.sqrt(np.maximum(disc, 0.0))           # the nearer root; closest approach if missed
    n = t[:, None] * rays - c
    n /= np.linalg.norm(n, axis=1)[:, None]
    return n, -rays, np.sqrt(np.maximum(disc, 0.0)) / R


def disc_pixels(img, camera, c, R, blur, gamma=1.0, most=MAX_PIXELS):
    """
    Return the normals, view directions, linear values and weights of the ball's disc pixels.

    Pixels deeper than 3 blurs and a pixel inside the outline (near the limb cos^2(i) = 2 t / r
    at a depth of t px on a ball of r px), not saturated, subsampled to at most ``most`` (None:
    all); then their image pixels (u, v) and the pixels' noise (the image's grey levels).
    """
    r_px = camera.apparent_radius(c, R)
    centre = camera.project(c)
    lo = np.maximum(np.floor(centre - 1.2 * r_px).astype(int), 0)
    hi = np.minimum(np.ceil(centre + 1.2 * r_px).astype(int) + 1, [camera.width, camera.height])
    ideal = ideal_maps(camera_key(camera))[0][lo[1]:hi[1], lo[0]:hi[0]]
    values = np.asarray(img, dtype=float)[lo[1]:hi[1], lo[0]:hi[0]]
    n, v, cos_i = _normals(camera, ideal.reshape(-1, 2), c, R)
    keep = ((cos_i.reshape(values.shape) > np.cos(_rim_angle(camera, c, R, blur)))
            & (values > SATURATED[0]) & (values < SATURATED[1]))
    y, w = linearise(values.ravel(), gamma)
    # second differences along rows: blind to the shading's gradient, sqrt(6) sigma for noise
    triple = keep[:, 2:] & keep[:, 1:-1] & keep[:, :-2]
    weighted = (y * np.sqrt(w)).reshape(values.shape)       # the sensor's noise, uniform
    noise = (1.4826 * np.median(np.abs(np.diff(weighted, 2, axis=1)[triple])) / np.sqrt(6)
             if triple.any() else np.inf)
    index = np.flatnonzero(keep)
    if most is not None:
        index = index[::max(1, int(np.ceil(len(index) / most)))]
    vv, uu = np.divmod(index, values.shape[1])
    return (n[index], v[index], y[index], w[index], np.column_stack([uu + lo[0], vv + lo[1]]),
            float(noise))


def fit(img, camera, c, R, blur, gamma=1.0):
    """
    Measure the highlight on the disc of sphere c (m, radius R); None when there is none.

    ``blur``: the edge's spread (px), from a fit of the same sphere or a previous frame's;
    ``gamma``: the camera's response (model_fit.linearise).
    """
    n, v, y, weight, _, noise = disc_pixels(img, camera, c, R, blur, gamma)
    B = harmonics(n)
    if len(y) < 4 * B.shape[1]:
        return None
    sw = np.sqrt(weight)
    m = B.shape[1] + 1                               # the diffuse columns
    excess = y - B @ np.linalg.lstsq(B * sw[:, None], y * sw, rcond=None)[0]
    peak = int(np.argmax(excess * sw))
    noise = max(noise, SCALE_FLOOR)
    if excess[peak] * sw[peak] < PEAK_SIGMAS * noise:
        return None
    h = n[peak]
    l0 = 2 * (h @ v[peak]) * h - v[peak]             # the mirror direction at the peak
    e1 = np.cross(l0, [1.0, 0.0, 0.0] if abs(l0[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(l0, e1)

    def light(p):
        d = l0 + p[0] * e1 + p[1] * e2
        return d / np.linalg.norm(d)

    def design(p):
        d = light(p)
        return np.hstack([B, np.maximum(n @ d, 0.0)[:, None], lobes(n, v, d, np.exp(p[2]))])

    def residuals(p):
        A = design(p) * sw[:, None]
        return y * sw - A @ solve(A, y * sw, m)

    bounds = ([-1.0, -1.0, np.log(WIDTH_RANGE[0])], [1.0, 1.0, np.log(WIDTH_RANGE[1])])
    starts = [np.array([0.0, 0.0, np.log(w)]) for w in (0.05, 0.12, 0.25)]
    p = min(starts, key=lambda q: np.sum(residuals(q) ** 2))
    p = least_squares(residuals, p, bounds=bounds, x_scale=[0.05, 0.05, 0.3], xtol=1e-4,
                      ftol=1e-4, max_nfev=60).x
    A = design(p) * sw[:, None]
    coef = solve(A, y * sw, m)
    without = y * sw - A[:, :m] @ np.linalg.lstsq(A[:, :m], y * sw, rcond=None)[0]
    gain = np.sum(without ** 2) / max(np.sum((y * sw - A @ coef) ** 2), 1e-300)
    if gain < MIN_GAIN or np.max(A[:, m:] @ coef[m:]) < PEAK_SIGMAS * noise:
        return None
    if _mirror_angle(c, light(p)) > _rim_angle(camera, c, R, blur) - np.exp(p[2]):
        return None
    return Highlight(light(p), float(np.exp(p[2])), coef[m:])


def solve(A, b, m):
    """
    Return the least-squares coefficients of A x = b with the lobes' (columns m on) not negative.

    A lobe's light is reflected, never taken away; unconstrained, two lobes of one width can
    cancel into a third shape (a narrow Blinn-Phong lobe less a GGX one) that extrapolates wrongly.
    The lobes' sets are tried from the largest; the best fit within the bounds is returned. Each
    set is solved on the normal equations, formed once (a dozen columns of harmonics and lobes
    over the disc are far from singular; lstsq takes a column that is all zero).
    """
    M, v = A.T @ A, A.T @ b
    best, best_gain = None, -np.inf
    for k in range(A.shape[1] - m, -1, -1):
        for kept in itertools.combinations(range(m, A.shape[1]), k):
            cols = list(range(m)) + list(kept)
            x = np.zeros(A.shape[1])
            x[cols] = np.linalg.lstsq(M[np.ix_(cols, cols)], v[cols], rcond=None)[0]
            gain = x @ v                                 # the fall of the squared residuals
            if x[m:].min(initial=0.0) >= 0 and gain > best_gain:
                best, best_gain = x, gain
        if best is not None:
            return best
    return best


def _rim_angle(camera, c, R, blur):
    """Return the angle i (rad) between normal and line of sight where the disc pixels end."""
    return float(np.arccos(np.sqrt(min(1.0, 2 * (3 * blur + 1) / camera.apparent_radius(c, R)))))


def _mirror_angle(c, light):
    """Return the angle i (rad) of the normal mirroring the light toward the centre ray."""
    v = -c / np.linalg.norm(c)
    h = (light + v) / np.linalg.norm(light + v)
    return float(np.arccos(np.clip(h @ v, -1.0, 1.0)))
