"""
How much a wrong Jacobian changes the visual servoing command (calibration paper, section 6.2.1).

With the robot's Jacobian J_RC taken as the calibrated one and the controller using J_RN
(eq. 27-28), the command error is Delta u_r = J_RC (J_RN^-1 - J_RC^-1) v; its largest singular
value bounds the relative error for any velocity v. The paper mapped it over a cylinder of radius
300 mm and height 400 mm and found about 0.015.
"""
import numpy as np

from robotenis_kinematics import delta

RADIUS = 0.30
Z_RANGE = (0.75, 1.15)   # m: the 400 mm height, from the home height down


def largest_singular_value(real, used, P):
    """sigma_max of J_real (J_used^-1 - J_real^-1) at positions P (..., 3) (eq. 28)."""
    J = delta.jacobian(real, P)
    D = J @ (delta.inverse_jacobian(used, P) - delta.inverse_jacobian(real, P))
    return np.linalg.svd(D, compute_uv=False)[..., 0]


def planes(real, used, n=61):
    """Map sigma_max on the cylinder's vertical planes y = 0, x = 0: (s, z, map_xz, map_yz)."""
    s = np.linspace(-RADIUS, RADIUS, n)
    z = np.linspace(*Z_RANGE, n)
    S, Z = np.meshgrid(s, z, indexing='ij')
    zeros = np.zeros_like(S)
    xz = largest_singular_value(real, used, np.stack([S, zeros, Z], axis=-1))
    yz = largest_singular_value(real, used, np.stack([zeros, S, Z], axis=-1))
    return s, z, xz, yz


def cylinder(real, used, n_angle=73, n_z=41):
    """sigma_max on the cylinder's outer surface: (angle, z, map)."""
    angle = np.linspace(0, 2 * np.pi, n_angle)
    z = np.linspace(*Z_RANGE, n_z)
    A, Z = np.meshgrid(angle, z, indexing='ij')
    P = np.stack([RADIUS * np.cos(A), RADIUS * np.sin(A), Z], axis=-1)
    return angle, z, largest_singular_value(real, used, P)


def volume_max(real, used, n=21):
    """Largest and median sigma_max over a grid filling the cylinder."""
    r, a, z = np.meshgrid(np.linspace(0, RADIUS, n), np.linspace(0, 2 * np.pi, 3 * n),
                          np.linspace(*Z_RANGE, n), indexing='ij')
    P = np.stack([r * np.cos(a), r * np.sin(a), z], axis=-1).reshape(-1, 3)
    sigma = largest_singular_value(real, used, P)
    return float(sigma.max()), float(np.median(sigma))


def plot(real, used, path, title):
    """PNG: the two vertical planes and the unrolled cylinder surface, in one colour scale."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    s, z, xz, yz = planes(real, used)
    angle, zc, surf = cylinder(real, used)
    vmax = max(xz.max(), yz.max(), surf.max())
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    maps = [(s * 1e3, z * 1e3, xz, 'plane y = 0: x (mm)'),
            (s * 1e3, z * 1e3, yz, 'plane x = 0: y (mm)'),
            (np.degrees(angle), zc * 1e3, surf, 'cylinder r = 300 mm: angle (deg)')]
    for ax, (x, y, m, label) in zip(axes, maps):
        im = ax.pcolormesh(x, y, m.T, shading='auto', vmin=0, vmax=vmax, cmap='viridis')
        ax.set_xlabel(label)
        ax.set_ylabel('z (mm, down)')
        ax.invert_yaxis()
    fig.colorbar(im, ax=axes, label='largest singular value')
    fig.suptitle(title)
    fig.savefig(path, dpi=80)
    plt.close(fig)
