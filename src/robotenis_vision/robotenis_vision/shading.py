"""
The ball's limb shading known from the light measured on its disc: a model fit without free limb.

The model fit (``model_fit``) takes the shading near the limb as a0 + a1 (sin(i) - 1) +
beta(phi) cos(i), beta three free coefficients around the outline. Collinear with the edge's
position, they double the depth noise of a fit and turn a small misfit of the edge into a large
depth error (docs/investigations.md, "What the 3x target asks of the detector"). A Lambertian
ball under one distant light shades as

    y = ambient + max(0, n . L)                                   (L: diffuse times the light)

at its surface normal n. ``measure_light`` fits ambient and L on the disc's deep pixels (a
specular lobe measured by ``highlight`` taken out first, Tukey's weights for what is left);
``KnownLimb`` renders that diffuse term near the outline, less its value at the limb (so it is
continuous across the edge: the step stays the fit's own), over subsampled pixels and blurred as
the edge is, and the fit takes it out of the annulus's pixels as it takes out a lobe, its limb
term off (``fit``). Where one light does not explain the disc (an environment, an area light, a
texture on the ball) ``measure_light`` returns None and the free limb is kept. One light may
explain the disc and not the limb (a glossy ball's Fresnel rim, a near or broad light): the known
limb is used only where its depth lies within the free limb's 99 % interval (``agrees``). On the
benchmark's Mitsuba scenes at rest that gate keeps it on one in six, where it is no worse than
the free limb; without it, it was worse on most (docs/investigations.md, "The known
limb on a renderer this project did not write").
"""
from dataclasses import dataclass

import numpy as np
from robotenis_vision import highlight, model_fit
from robotenis_vision.detection import DetectionError
from robotenis_vision.model_fit import camera_key, ideal_maps, SCALE_FLOOR
from scipy.special import chdtri

# rays per pixel side near the outline, where the limb's shading rises as a square root (8 moved
# six noise-free balls' depth by 2 um at most, for twice the CPU), and deeper, where it is smooth
SUBSAMPLES, DEEP_SUBSAMPLES = 4, 3
BAND_PX = 2.0                  # how near the outline a pixel takes SUBSAMPLES
TUKEY = 4.685                  # biweight constant, in robust sigmas
ITERATIONS = 25
MIN_PIXELS = 200               # disc pixels the light needs
MAX_MISFIT = 1.5               # the disc's residual RMS over its noise: one light fails beyond
PASSES = 2                     # the known limb follows the sphere: refitted from where it ended,
REFIT_PX = 0.1                 # if its outline moved this much
AGREE = float(chdtri(1, 0.01))  # chi2(1) quantile 0.99: the known depth within the free's interval


@dataclass(frozen=True)
class KnownLimb:
    """The ball's diffuse shading near its outline from a measured light, and a specular lobe."""

    ambient: float
    L: np.ndarray              # (3,) optical frame: the diffuse level times the light's direction
    lobe: object = None        # highlight.Highlight or None

    def values(self, camera, pixels, c, R, s):
        """
        Return the shading less its limb value at image pixels (u, v), blurred as the edge (s px).

        Each pixel is the mean over its area of rays that meet the ball (the others see none):
        SUBSAMPLES x SUBSAMPLES of them within BAND_PX of the outline, where the shading rises as
        a square root, DEEP_SUBSAMPLES x DEEP_SUBSAMPLES elsewhere; then blurred by the rest of
        the edge's spread, sqrt(s^2 - 1/12) px. The lobe's values (``highlight.Highlight.values``)
        are added.
        """
        lo, shape, vv, uu = highlight.ring(camera, pixels, s)
        centre = ideal_maps(camera_key(camera))[0][vv + lo[1], uu + lo[0]]
        rays = np.column_stack([centre, np.ones(len(centre))]) @ np.linalg.inv(camera.K).T
        rays /= np.linalg.norm(rays, axis=1)[:, None]
        # the limb's value along each pixel's plane through the centre (it varies slowly)
        limb = np.maximum(limb_normals(rays, c, R) @ self.L, 0.0)
        # how far from the outline, px: the angle to the centre's ray less the outline's
        angle = np.arccos(np.clip(rays @ (c / np.linalg.norm(c)), -1.0, 1.0))
        near = np.abs(angle - np.arcsin(R / np.linalg.norm(c))) * camera.fx < BAND_PX
        image = np.zeros(shape)
        for k, where in ((SUBSAMPLES, near), (DEEP_SUBSAMPLES, ~near)):
            ideal = highlight.subpixels(camera, lo, vv[where], uu[where], k)
            n, _, cos_i = highlight._normals(camera, ideal.reshape(-1, 2), c, R)
            g = np.where(cos_i > 0, np.maximum(n @ self.L, 0.0)
                         - np.repeat(limb[where], k * k), 0.0)
            image[vv[where], uu[where]] = g.reshape(-1, k * k).mean(axis=1)
        out = highlight.blurred_at(image, s, pixels, lo)
        if self.lobe is not None:
            out = out + self.lobe.values(camera, pixels, c, R, s)
        return out


def limb_normals(rays, c, R):
    """
    Return the normals (n, 3) where each unit ray's plane through centre c touches the outline.

    The outline's ray at angle b0 from the centre's (sin b0 = R / |c|) touches the sphere where
    its normal is cos(b0) e - sin(b0) c / |c|, e the unit direction from the centre's ray toward
    the ray within their plane.
    """
    ch = np.asarray(c, dtype=float) / np.linalg.norm(c)
    e = rays - (rays @ ch)[:, None] * ch
    e /= np.maximum(np.linalg.norm(e, axis=1), 1e-12)[:, None]
    b0 = np.arcsin(R / np.linalg.norm(c))
    return np.cos(b0) * e - np.sin(b0) * ch


def measure_light(img, camera, c, R, blur, gamma=1.0, lobe=None):
    """
    Fit ambient + max(0, n . L) on the disc of sphere c; a KnownLimb, or None if one light fails.

    Started from the unclamped fit (ambient + n . L, linear) with the ambient at the disc's
    darkest values, then Gauss-Newton on the clamped model with Tukey's weights from the fourth
    iteration. None with fewer than MIN_PIXELS disc pixels or a residual RMS (over the weights'
    kept pixels) above MAX_MISFIT times the disc's noise (floored at SCALE_FLOOR).
    """
    n, _, y, _, pixels, noise = highlight.disc_pixels(img, camera, c, R, blur, gamma, None)
    if len(y) < MIN_PIXELS:
        return None
    if lobe is not None:
        y = y - lobe.values(camera, pixels, c, R, blur)
    p = np.linalg.lstsq(np.column_stack([np.ones(len(y)), n]), y, rcond=None)[0]
    p[0] = np.percentile(y, 2)
    w = np.ones(len(y))
    for it in range(ITERATIONS):
        s = n @ p[1:]
        lit = s > 0
        r = y - (p[0] + np.where(lit, s, 0.0))
        if it >= 3:
            scale = max(1.4826 * np.median(np.abs(r)), SCALE_FLOOR)
            u = r / (TUKEY * scale)
            w = np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        J = np.column_stack([np.ones(len(y)), n * lit[:, None]])
        p = p + np.linalg.solve(J.T @ (J * w[:, None]) + 1e-9 * np.eye(4), J.T @ (w * r))
    kept = w > 0
    misfit = np.sqrt(np.mean(r[kept] ** 2)) if kept.any() else np.inf
    if not misfit <= MAX_MISFIT * max(noise, SCALE_FLOOR):
        return None
    return KnownLimb(float(p[0]), p[1:].copy(), lobe)


def fit(img, camera, R, c0, blur, gamma=1.0, noise_levels=None, lobe=None, background=None):
    """
    Return the model fit of sphere c0's ball with its limb known (model_fit.ModelFit), or None.

    The light is measured on the disc where the sphere lies (``measure_light``), its limb shading
    taken out of the annulus's pixels, and the model fitted without its limb term; again from
    where it ended if its outline moved REFIT_PX or more (the known shading was drawn from c0).
    None when one light does not explain the disc or the fit without a free limb fails.
    """
    c = np.asarray(c0, dtype=float)
    for _ in range(PASSES):
        known = measure_light(img, camera, c, R, blur, gamma, lobe)
        if known is None:
            return None
        try:
            result = model_fit.fit(img, camera, R, c, blur, gamma, limb=False,
                                   noise_levels=noise_levels, highlight=known,
                                   background=background)
        except DetectionError:          # the free limb's fit stands
            return None
        if max(model_fit.outline_offset(camera, R, c, result.c)) < REFIT_PX:
            break
        c, blur = result.c, result.blur
    return result


def agrees(known, free):
    """
    Return whether the known limb's fit lies within the free limb's 99 % interval in depth.

    Both are model_fit.ModelFit of one ball; where the light on the disc explains the limb, both
    are consistent and the known is the tighter, so their difference along the line of sight,
    squared over the free fit's variance there, is below chi2(1)'s 0.99 quantile (AGREE) but for
    one ball in a hundred.
    """
    u = free.c / np.linalg.norm(free.c)
    return float(((free.c - known.c) @ u) ** 2) <= AGREE * float(u @ free.cov @ u)
