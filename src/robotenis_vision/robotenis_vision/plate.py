"""
The scene behind the ball, pixel by pixel, from the views in which the ball was elsewhere.

A Delta robot's effector only translates, so a hand camera sees a background far behind the
ball at the same pixels from every pose; only the ball moves in the image. Whatever the ball
hides at one rest, it left in view at others. The model fit (``model_fit.fit(...,
background=...)``) then knows the background behind each pixel of its annulus instead of taking
it as a level and slopes per bin, which cannot follow a texture finer than a bin (on the hand
camera's default scene its texture was most of a rest's depth error: docs/investigations.md,
"What the rests' detector error is made of").

Each view (a mean image of a rest) is added with the disc it shows the ball in, widened by a
margin for the blurred edge, and with its pixel noise; a pixel's plate is the weighted mean of
the views that showed it. A background that is not still in the image (near enough for the
camera's translation to shift it, lit differently from pose to pose) shows as views that disagree
by more than their noise: ``trusted`` accepts a group of pixels (a bin of the fit's annulus) each
seen in at least MIN_VIEWS views, whose views' scatter about their means is at most MAX_SCATTER
times what their noise gives (chi-square per degree of freedom). At 2, the background's own
change between views may be as large as a view's noise, not more: a texture of 2 grey levels per
pixel shifted by a third of a pixel between views, against a rest's mean of 12 frames of noise 2.
"""
import numpy as np

MIN_VIEWS = 2
MAX_SCATTER = 2.0               # the views' scatter a trusted group may show, per dof
MARGIN_PX = 4.0                 # beyond the ball's outline, px: its blurred edge and a halo
NOISE_FLOOR = 0.3               # grey levels: an 8-bit frame's rounding, 1 / sqrt(12)


class BackgroundPlate:
    """
    The background of a hand camera that only translates, from views of the ball elsewhere.

    ``add`` a view; ``at`` returns the plate's grey levels at pixels and their views' scatter.
    """

    def __init__(self, shape):
        self.shape = tuple(shape)
        self.w = np.zeros(self.shape)          # sum of the views' weights (1 / noise^2)
        self.wx = np.zeros(self.shape)         # ... times the grey level
        self.wxx = np.zeros(self.shape)        # ... times its square
        self.views = np.zeros(self.shape, dtype=np.int32)
        self.added = 0                         # views added

    def add_ball(self, image, camera, position, radius, noise):
        """Add a view with the ball at ``position`` (m, optical), ``radius`` (m), in ``camera``."""
        self.add(image, camera.project(position), camera.apparent_radius(position, radius), noise)

    def add(self, image, centre_px, radius_px, noise):
        """
        Add a view: a mono image, the ball's centre and apparent radius in it (px), its noise.

        ``noise``: the image's pixel noise, grey levels (a mean of n frames: the frames' over
        sqrt(n)), floored at NOISE_FLOOR. The ball's disc, widened by MARGIN_PX, is left out.
        """
        image = np.asarray(image, dtype=float)
        if image.shape != self.shape:
            raise ValueError(f'background plate: a view of {image.shape}, the plate is '
                             f'{self.shape}')
        if not (np.isfinite(radius_px) and radius_px > 0 and np.all(np.isfinite(centre_px))):
            raise ValueError(f'background plate: the ball at {centre_px}, radius {radius_px} px')
        v, u = np.ogrid[:self.shape[0], :self.shape[1]]
        seen = ((u - centre_px[0]) ** 2 + (v - centre_px[1]) ** 2
                > (radius_px + MARGIN_PX) ** 2)
        w = seen / max(float(noise), NOISE_FLOOR) ** 2
        self.w += w
        self.wx += w * image
        self.wxx += w * image * image
        self.views += seen
        self.added += 1

    def at(self, pixels):
        """
        Return the plate at integer pixels (n, 2: u, v): grey levels, chi-square and its dof (n,).

        The chi-square is the pixel's views' scatter about their weighted mean, with views - 1
        degrees of freedom; a pixel seen in fewer than MIN_VIEWS views has a NaN level.
        """
        u, v = np.asarray(pixels, dtype=int).T
        w, wx, n = self.w[v, u], self.wx[v, u], self.views[v, u]
        mean = wx / np.maximum(w, 1e-300)
        scatter = np.maximum(self.wxx[v, u] - wx * mean, 0.0)
        return np.where(n >= MIN_VIEWS, mean, np.nan), scatter, np.maximum(n - 1, 0)


def trusted(levels, scatter, dof):
    """Return whether a group of the plate's pixels (``at``'s three arrays) may be used."""
    return bool(np.all(np.isfinite(levels)) and np.sum(scatter) <= MAX_SCATTER * np.sum(dof))
