"""
Synthetic incremental measurements for identification studies (design, tests, benchmarks).

Given a geometry taken as true and the effector positions visited, it produces what the resolvers
and the hand camera would report, with the paper's noise. It knows nothing of unmodelled effects:
those belong to the simulator (robotenis_sim), whose truth no other package reads.
"""
from dataclasses import dataclass

import numpy as np

from robotenis_kinematics import delta
from robotenis_kinematics.identification import Measurements, Model


@dataclass(frozen=True)
class NoiseModel:
    """
    Noise of one averaged measurement.

    sigma_camera : standard deviation along the optical axes x, y, z (m) of the sphere position
        averaged over 500 frames; default the paper's Table 3 (0.0025, 0.0049, 0.0212 mm).
    sigma_resolver : standard deviation of a resolver increment at rest (rad). The paper says only
        that the encoders cannot guarantee better than 0.02 mm at the effector; 2e-5 rad on a 0.5 m
        arm is 0.01 mm, the same order.
    """

    sigma_camera: tuple = (0.0025e-3, 0.0049e-3, 0.0212e-3)
    sigma_resolver: float = 2e-5

    def cov_Pi(self, camera_rotation):
        """Covariance of Pi in the base frame: R diag(sigma_camera^2) R^T."""
        R = np.asarray(camera_rotation, dtype=float)
        return R @ np.diag(np.square(self.sigma_camera)) @ R.T


def true_model(desc):
    """Return the Model whose camera reference P0 is the home position FK(theta0)."""
    return Model(desc.copy(), delta.forward(desc, desc.theta0))


def measure(true_desc, P, noise=NoiseModel(), rng=None):
    """
    Measurements (Theta_k, Pi_k) of the positions P (K, 3) on a robot of geometry ``true_desc``.

    Theta_k = IK(P_k) - theta0 and Pi_k = P_k - P0 with P0 = FK(theta0), the home position, plus
    independent Gaussian noise when ``rng`` is given (noise-free otherwise). The covariances in the
    returned Measurements are those of ``noise``.
    """
    P = np.asarray(P, dtype=float)
    Theta = delta.inverse(true_desc, P) - true_desc.theta0
    Pi = P - delta.forward(true_desc, true_desc.theta0)
    cov = noise.cov_Pi(true_desc.camera_rotation)
    if rng is not None:
        Theta = Theta + rng.normal(scale=noise.sigma_resolver, size=Theta.shape)
        Pi = Pi + rng.multivariate_normal(np.zeros(3), cov, size=len(P))
    return Measurements(Theta, Pi, np.full(3, noise.sigma_resolver), cov)
