"""
What a detector returns: a measured sphere centre with its covariance, or the reason it could not.

Shared by every method (robotenis_vision.detector, baseline, paper_method).
"""
from dataclasses import dataclass, field

import numpy as np

RANGE = (0.08, 1.2)            # m: distances at which a ball is looked for


class DetectionError(ValueError):
    """No trustworthy measurement in this image: the message gives the reason."""


@dataclass
class Detection:
    position: np.ndarray        # (3,) sphere centre, optical frame, m
    covariance: np.ndarray      # (3, 3), m^2
    # (n, 2) outline points used, in ideal pixels (camera.distort_pixels gives the image's)
    edge_points: np.ndarray
    fit_rms_px: float           # RMS distance of the points to the fitted outline, px
    method: str
    extra: dict = field(default_factory=dict)
