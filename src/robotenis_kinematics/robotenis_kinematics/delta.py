"""
Kinematics of the RoboTenis Delta robot in the calibration paper's notation (eqs. 1-2).

Frame Sigma_0: origin at the base centre, x toward motor 1, z down into the workspace (m, rad).
Leg i has its motor axis at A_i = H_i (cos phi_i, sin phi_i, 0); the arm end is

    B_i = [(H_i + a_i cos theta_i) cos phi_i,
           (H_i + a_i cos theta_i) sin phi_i,
           a_i sin theta_i]                                                 (2)

and the forearm's ball joint on the effector is C_i = P + h_i (cos phi_i, sin phi_i, 0). The
forearm closes the loop: Gamma_i = |C_i - B_i|^2 - b_i^2 = 0 (1). Angles theta_i are absolute arm
angles (theta_i = theta_i0 + Theta_i, the resolver increment); positive theta moves the arm down.

Every function is vectorised over poses: P has shape (..., 3) and theta shape (..., 3).
"""
import numpy as np


def leg_directions(desc):
    """Return the unit vectors e_i = (cos phi_i, sin phi_i, 0), shape (3, 3), one row per leg."""
    return np.stack([np.cos(desc.phi), np.sin(desc.phi), np.zeros(3)], axis=-1)


def elbow_points(desc, theta):
    """B_i for absolute arm angles theta, shape (..., 3 legs, 3) (eq. 2)."""
    theta = np.asarray(theta, dtype=float)
    e = leg_directions(desc)
    radial = desc.H + desc.a * np.cos(theta)
    return radial[..., None] * e + (desc.a * np.sin(theta))[..., None] * np.array([0.0, 0.0, 1.0])


def effector_joints(desc, P):
    """C_i for effector positions P, shape (..., 3 legs, 3) (eq. 2)."""
    P = np.asarray(P, dtype=float)
    return P[..., None, :] + desc.h[:, None] * leg_directions(desc)


def constraint(desc, P, theta):
    """Gamma_i = |C_i - B_i|^2 - b_i^2, shape (..., 3) (eq. 1); zero on the robot."""
    d = effector_joints(desc, P) - elbow_points(desc, theta)
    return np.einsum('...ij,...ij->...i', d, d) - desc.b ** 2


def inverse(desc, P):
    """
    Return the absolute arm angles theta (..., 3) that put the effector at P (..., 3), elbow out.

    Closed form: in the plane of leg i, with u = C_i.e_i - H_i, v = C_i.(z x e_i) and w = C_iz,
    eq. (1) becomes u cos(theta) + w sin(theta) = K with K = (u^2 + v^2 + w^2 + a^2 - b^2) / (2a),
    so theta = atan2(w, u) - acos(K / sqrt(u^2 + w^2)); the minus sign keeps the elbow outward.

    Raises
    ------
    ValueError
        if a position is out of reach of some leg.

    """
    theta, reachable = _inverse(desc, P)
    if not np.all(reachable):
        bad = np.argwhere(~np.all(reachable, axis=-1))
        where = np.asarray(P).reshape(-1, 3)[bad[0][0]] if bad.size else P
        raise ValueError(f'position out of reach: {where}')
    return theta


def _inverse(desc, P):
    C = effector_joints(desc, P)
    e = leg_directions(desc)
    u = np.einsum('...ij,ij->...i', C, e) - desc.H
    v = C[..., 1] * e[:, 0] - C[..., 0] * e[:, 1]
    w = C[..., 2]
    rho = np.hypot(u, w)
    K = (u ** 2 + v ** 2 + w ** 2 + desc.a ** 2 - desc.b ** 2) / (2 * desc.a)
    ratio = K / rho
    reachable = np.abs(ratio) <= 1.0
    theta = np.arctan2(w, u) - np.arccos(np.clip(ratio, -1.0, 1.0))
    theta = (theta + np.pi) % (2 * np.pi) - np.pi
    return theta, reachable


def reachable(desc, P):
    """Return True where every leg can reach P (shape (...,))."""
    return np.all(_inverse(desc, P)[1], axis=-1)


def forward(desc, theta):
    """
    Return the effector position P (..., 3) for absolute arm angles theta (..., 3): closed form.

    P lies on the three spheres of radius b_i around Q_i = B_i - h_i e_i. Subtracting the sphere
    equations leaves a line; its two intersections with the first sphere are the two assembly
    modes, and the one below the base (larger z, as z points down) is the robot's.

    Raises
    ------
    ValueError
        if the three spheres do not meet (no assembly for these angles).

    """
    Q = elbow_points(desc, theta) - desc.h[:, None] * leg_directions(desc)
    r = desc.b
    d12 = Q[..., 1, :] - Q[..., 0, :]
    d13 = Q[..., 2, :] - Q[..., 0, :]
    d = np.linalg.norm(d12, axis=-1)
    ex = d12 / d[..., None]
    i = np.einsum('...j,...j->...', ex, d13)
    ey_raw = d13 - i[..., None] * ex
    j = np.linalg.norm(ey_raw, axis=-1)
    ey = ey_raw / j[..., None]
    ez = np.cross(ex, ey)
    x = (r[0] ** 2 - r[1] ** 2 + d ** 2) / (2 * d)
    y = (r[0] ** 2 - r[2] ** 2 + i ** 2 + j ** 2) / (2 * j) - i * x / j
    z2 = r[0] ** 2 - x ** 2 - y ** 2
    if np.any(z2 < 0):
        raise ValueError('forward kinematics: the forearm spheres do not meet'
                         ' for these arm angles')
    z = np.sqrt(z2)
    base = Q[..., 0, :] + x[..., None] * ex + y[..., None] * ey
    # Pick the branch with the larger base-frame z (below the base).
    sign = np.where(ez[..., 2] >= 0, 1.0, -1.0)
    return base + (sign * z)[..., None] * ez


def jacobian_parts(desc, P, theta):
    """
    Return the two halves of the differentiated constraint, A dP + diag(beta) dtheta = 0.

    A (..., 3, 3) has rows 2 (C_i - B_i)^T; beta (..., 3) is -2 (C_i - B_i) . dB_i/dtheta_i.
    """
    theta = np.asarray(theta, dtype=float)
    d = effector_joints(desc, P) - elbow_points(desc, theta)
    e = leg_directions(desc)
    dB = np.concatenate([(-desc.a * np.sin(theta))[..., None] * e[:, :2],
                         (desc.a * np.cos(theta))[..., None]], axis=-1)
    return 2 * d, -2 * np.einsum('...ij,...ij->...i', d, dB)


def jacobian(desc, P, theta=None):
    """J_R with dP/dt = J_R dtheta/dt (calibration paper eq. 24), shape (..., 3, 3), analytic."""
    if theta is None:
        theta = inverse(desc, P)
    A, beta = jacobian_parts(desc, P, theta)
    return -np.linalg.solve(A, np.broadcast_to(np.eye(3), A.shape) * beta[..., None, :])


def inverse_jacobian(desc, P, theta=None):
    """J_R^-1 with dtheta/dt = J_R^-1 dP/dt, shape (..., 3, 3); finite if no leg is stretched."""
    if theta is None:
        theta = inverse(desc, P)
    A, beta = jacobian_parts(desc, P, theta)
    return -A / beta[..., :, None]


def singularity_distance(desc, P):
    """Distance (m) from P to the nearest serial singularity (leg stretched or folded), (...,)."""
    return np.min(leg_singularity_margins(desc, P), axis=-1)


def leg_singularity_margins(desc, P):
    """
    Return per leg the distance (m) from C_i to the boundary of leg i's workspace, shape (..., 3).

    C_i is reachable by leg i while the circle its elbow B_i can describe (centre A_i, radius a_i,
    in the vertical plane of the leg) has points both nearer and farther than b_i. With rho the
    in-plane distance of C_i from A_i and v its distance from that plane, the nearest and farthest
    circle points are at d_min = hypot(rho - a, v) and d_max = hypot(rho + a, v); both are
    distance functions, so min(b - d_min, d_max - b) is the metric distance of C_i to the boundary
    of leg i's workspace. Negative outside it.
    """
    C = effector_joints(desc, P)
    e = leg_directions(desc)
    u = np.einsum('...ij,ij->...i', C, e) - desc.H
    v = C[..., 1] * e[:, 0] - C[..., 0] * e[:, 1]
    rho = np.hypot(u, C[..., 2])
    d_min = np.hypot(rho - desc.a, v)
    d_max = np.hypot(rho + desc.a, v)
    return np.minimum(desc.b - d_min, d_max - desc.b)


def parallel_conditioning(desc, P, theta=None):
    """
    Return the smallest singular value of the matrix of unit forearm directions.

    Dimensionless, shape (...,). Zero at the parallel (type 2) singularity where the three
    forearms become coplanar.
    """
    if theta is None:
        theta = inverse(desc, P)
    d = effector_joints(desc, P) - elbow_points(desc, theta)
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.linalg.svd(u, compute_uv=False)[..., -1]
