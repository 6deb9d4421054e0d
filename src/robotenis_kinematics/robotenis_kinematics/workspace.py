"""
Sampling the Delta robot's workspace, and the paper's calibration poses near its boundary.

The usable workspace is where every leg reaches (eq. 1 has a solution), the arm angles stay inside
the drives' range, the forearms are away from the parallel singularity, and the effector is inside
a vertical cylinder below the base. Calibration poses (paper, section 5.1) are drawn at random from
the shell 5-10 cm from a serial singularity.
"""
from dataclasses import dataclass

import numpy as np

from robotenis_kinematics import delta


@dataclass(frozen=True)
class Workspace:
    """Bounds of the region sampled (m, rad)."""

    radius: float = 0.5              # cylinder radius about the z axis
    z_min: float = 0.45
    z_max: float = 1.4
    theta_min: float = -np.pi / 3    # arm angle range of the drives (absolute, positive down)
    theta_max: float = np.pi / 2
    min_parallel_conditioning: float = 0.2

    def contains(self, desc, P):
        """Boolean mask (...,) of positions inside the usable workspace of ``desc``."""
        P = np.asarray(P, dtype=float)
        inside = (np.hypot(P[..., 0], P[..., 1]) <= self.radius) & (P[..., 2] >= self.z_min) \
            & (P[..., 2] <= self.z_max)
        theta, reach = delta._inverse(desc, P)
        in_range = (theta >= self.theta_min) & (theta <= self.theta_max)
        ok = inside & np.all(reach, axis=-1) & np.all(in_range, axis=-1)
        cond = np.zeros(ok.shape)
        if np.any(ok):
            cond[ok] = delta.parallel_conditioning(desc, P[ok], theta[ok])
        return ok & (cond >= self.min_parallel_conditioning)


def sample(desc, n, rng, workspace=Workspace(), band=None, batch=4096, where=None,
           max_batches=None):
    """
    Draw ``n`` positions (n, 3) uniformly from the usable workspace.

    Parameters
    ----------
    desc : RobotDescription
        The robot whose workspace is sampled.
    n : int
        Number of positions returned.
    rng : numpy.random.Generator
        Source of the random draws.
    workspace : Workspace
        Bounds of the region sampled.
    band : (float, float) or None
        If given, keep only positions whose distance to the nearest serial singularity
        (``delta.singularity_distance``) lies in [band[0], band[1]] m: the paper's 5-10 cm shell.
    batch : int
        Candidate positions drawn per round.
    where : callable or None
        If given, keep only positions P (k, 3) with ``where(P)`` true: uniform draws from the
        part of the workspace it selects. It is tested before the workspace itself, so a cheap
        test that rejects most draws spares their inverse kinematics.
    max_batches : int or None
        If given, stop after this many rounds and return the positions found, fewer than ``n``
        if the region is too small.

    """
    out = []
    count = 0
    rounds = 0
    while count < n and (max_batches is None or rounds < max_batches):
        rounds += 1
        r = workspace.radius * np.sqrt(rng.uniform(size=batch))
        a = rng.uniform(0, 2 * np.pi, size=batch)
        z = rng.uniform(workspace.z_min, workspace.z_max, size=batch)
        P = np.stack([r * np.cos(a), r * np.sin(a), z], axis=-1)
        if where is not None:
            P = P[where(P)]
        P = P[workspace.contains(desc, P)]
        if band is not None and len(P):
            s = delta.singularity_distance(desc, P)
            P = P[(s >= band[0]) & (s <= band[1])]
        out.append(P)
        count += len(P)
    return np.concatenate(out)[:n]


def boundary_poses(desc, n, rng, workspace=Workspace(), band=(0.05, 0.10)):
    """Draw the paper's calibration poses: random, 5-10 cm from a singularity (section 5.1)."""
    return sample(desc, n, rng, workspace, band=band)
