"""
Rigid-body dynamics of the RoboTenis with massive forearms (dynamics paper, eqs. 1-9).

Names. The dynamics paper (Fig. 2) and the calibration paper (Fig. 2, our code) name the same
things differently: L_a = ``a`` (arm), L_b = ``b`` (forearm), theta_i (paper) = ``phi`` (leg
direction), alpha_i (paper) = ``theta`` (absolute arm angle, positive down; written alpha here as
in the paper), Delta r = ``H - h``. The paper puts the forearm's ball joint at the platform centre
and shortens the base radius by h; we keep C_i = P + h_i e_i, which is the same because the
platform only translates.

Model. Generalised coordinates q = (x, y, z, alpha_1, alpha_2, alpha_3) (eq. 2), one constraint per
leg f_i = |C_i - B_i|^2 - b_i^2 = 0 (eq. 3, the calibration paper's Gamma_i), Lagrange's equations
with multipliers (eq. 1):

    M(alpha) qdd + h(alpha, alphad) = Q + Phi_q^T lambda,    Phi_q = [A | diag(beta)]

with A, beta from ``delta.jacobian_parts`` (rows 2 (C_i - B_i)^T and
-2 (C_i - B_i) . dB_i/dalpha_i). Kinetic energy (eqs. 6-7), with the unit vectors of arm i
r_i = (B_i - A_i)/a_i (radial) and t_i = dB_i/dalpha_i / a_i (tangential, so that
dB_i/dt = a_i alphad_i t_i):

    T_c  = 1/2 m_p |Pd|^2                            platform with camera
    T_ai = 1/2 I_t alphad_i^2                        arm and geared rotor about the motor axis
    T_bi = m_b/6 (|Bd_i|^2 + Bd_i . Pd + |Pd|^2)     forearm: a uniform slender rod from B_i to C_i

Eq. 7 as printed, 1/2 m_b [1/3 |Pd - Bd_i|^2 + Bd_i . Pd], is the same rod energy rearranged. A
parallelogram forearm of two such rods has the same energy (its rods only translate sideways).
Potential energy with gravity along +z (eqs. 8-9): the arm's centre of mass at a/2, the rod's at
the middle of B_i C_i:

    V = -g [ m_p z + sum_i ( m_a a_i/2 sin alpha_i + m_b/2 (z + a_i sin alpha_i) ) ]

Because M depends on alpha only through t_i(alpha_i), the velocity terms in the alpha equations
cancel, and those of the P equations are -m_b a_i/6 alphad_i^2 r_i.

Everything is vectorised over leading axes: P, alpha, ... of shape (..., 3).
"""
from dataclasses import dataclass, replace
import math

import numpy as np

from robotenis_kinematics import delta

G = 9.81                        # m/s^2, along +z of the base frame
Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class MassParameters:
    """
    Inertial parameters of the RoboTenis (SI), the same for the three legs.

    m_a : arm mass (kg), centre of mass at half the arm (eq. 9): an aluminium tube of 0.5 m.
    m_b : forearm mass (kg), both rods of the parallelogram with their ball joints: 1.315 kg
    (paper). m_c : platform mass without the camera (kg). m_camera : hand camera (kg), 0.05 kg
    (calibration paper, section 2). I_t : inertia of arm + geared rotor about the motor axis, at
    the joint (kg m^2): the arm as a
        uniform rod m_a a^2/3 = 0.0833 plus a servomotor rotor of 1.2e-4 kg m^2 seen through a 10:1
        planetary gearbox (N^2 J_m = 0.012), rounded up for the gearbox and hub: 0.097.

    The nominal static load these imply (arm m_a/2 + m_b/2, platform m_c + m_camera + 3 m_b/2) is
    the one calibration assumes (robotenis_kinematics.effects.NOMINAL_GRAVITY_LOAD).
    """

    m_a: float = 1.0
    m_b: float = 1.315
    m_c: float = 1.0
    m_camera: float = 0.05
    I_t: float = 0.097

    def __post_init__(self):
        for name in ('m_a', 'm_b', 'm_c', 'm_camera', 'I_t'):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f'MassParameters.{name}: must be finite and >= 0, got {value!r}')

    @property
    def m_p(self):
        """Everything that moves with the platform: m_c + m_camera (kg)."""
        return self.m_c + self.m_camera

    def massless_forearms(self):
        """Return the usual Delta simplification the paper compares against: massless forearms."""
        return replace(self, m_b=0.0)


def arm_vectors(desc, alpha):
    """
    Return the unit vectors of each arm, radial r_i and tangential t_i, each (..., 3, 3).

    r_i = (B_i - A_i)/a_i, t_i = dr_i/dalpha_i and dt_i/dalpha_i = -r_i; rows are legs.
    """
    alpha = np.asarray(alpha, dtype=float)
    e = delta.leg_directions(desc)
    c, s = np.cos(alpha)[..., None], np.sin(alpha)[..., None]
    return c * e + s * Z, -s * e + c * Z


def mass_blocks(desc, mass, alpha):
    """
    Return the blocks of M(alpha) (eqs. 6-7): M_PP, M_aa and M_Pa.

    M_PP is a scalar (times I3), M_aa (..., 3) the diagonal, M_Pa (..., 3, 3):
    M_PP = m_p + 3 m_b/3; M_aa,i = I_t + m_b a_i^2/3; column i of M_Pa is m_b a_i/6 t_i.
    """
    _, t = arm_vectors(desc, alpha)
    M_PP = mass.m_p + mass.m_b
    M_aa = mass.I_t + mass.m_b * desc.a ** 2 / 3.0
    M_Pa = np.swapaxes(t, -1, -2) * (mass.m_b * desc.a / 6.0)
    return M_PP, np.broadcast_to(M_aa, np.shape(alpha)), M_Pa


def bias_forces(desc, mass, alpha, dalpha, g=G):
    """
    Return the velocity and gravity terms h as (h_P (..., 3), h_a (..., 3)).

    h = d/dt dT/dqd - dT/dq - M qdd + dV/dq:

    h_P = -sum_i m_b a_i/6 alphad_i^2 r_i - g (m_p + 3 m_b/2) z      (eqs. 4, 7, 9)
    h_a,i = -g (m_a + m_b)/2 a_i cos alpha_i                          (eqs. 5, 9)
    """
    alpha = np.asarray(alpha, dtype=float)
    r, _ = arm_vectors(desc, alpha)
    h_P = -np.einsum('...i,...ij->...j', mass.m_b * desc.a / 6.0 * np.asarray(dalpha) ** 2, r)
    h_P = h_P - g * (mass.m_p + 1.5 * mass.m_b) * Z
    h_a = -g * 0.5 * (mass.m_a + mass.m_b) * desc.a * np.cos(alpha)
    return h_P, h_a


def constraint_bias(desc, P, dP, alpha, dalpha):
    """
    Return gamma (..., 3) in A Pdd + beta alphadd + gamma = 0 (eq. 3 differentiated twice).

    With d_i = C_i - B_i: gamma_i = 2 |dd_i/dt|^2 + 2 a_i alphad_i^2 d_i . r_i.
    """
    d = delta.effector_joints(desc, P) - delta.elbow_points(desc, alpha)
    r, t = arm_vectors(desc, alpha)
    dalpha = np.asarray(dalpha, dtype=float)
    dd = np.asarray(dP, dtype=float)[..., None, :] - (desc.a * dalpha)[..., None] * t
    return (2 * np.einsum('...ij,...ij->...i', dd, dd)
            + 2 * desc.a * dalpha ** 2 * np.einsum('...ij,...ij->...i', d, r))


@dataclass
class JointMotion:
    """The joint-space image of a Cartesian motion and what drives it (arrays (..., 3), SI)."""

    alpha: np.ndarray
    dalpha: np.ndarray
    ddalpha: np.ndarray
    tau: np.ndarray        # actuator torques at the joints (N m, positive drives the arm down)
    # Lagrange multipliers (N/m: force along C_i - B_i is 2 lambda_i |C_i - B_i|)
    lam: np.ndarray


def joint_motion(desc, P, dP, ddP, alpha=None):
    """
    Return alpha, alphad, alphadd for an effector motion (P, Pd, Pdd), each (..., 3).

    alphad = -(A Pd)/beta and alphadd = -(A Pdd + gamma)/beta: the constraint differentiated once
    and twice; ``alpha`` defaults to the closed-form inverse kinematics.
    """
    P, dP, ddP = (np.asarray(v, dtype=float) for v in (P, dP, ddP))
    if alpha is None:
        alpha = delta.inverse(desc, P)
    A, beta = delta.jacobian_parts(desc, P, alpha)
    dalpha = -np.einsum('...ij,...j->...i', A, dP) / beta
    gamma = constraint_bias(desc, P, dP, alpha, dalpha)
    ddalpha = -(np.einsum('...ij,...j->...i', A, ddP) + gamma) / beta
    return alpha, dalpha, ddalpha


def inverse_dynamics(desc, mass, P, dP, ddP, g=G, alpha=None):
    """
    Return as a JointMotion the joint torques producing effector motion (P, Pd, Pdd) (eqs. 4-5).

    The three P equations (4) give the multipliers, A^T lambda = M_PP Pdd + M_Pa alphadd + h_P; the
    three alpha equations (5) then give
    tau_i = M_aa,i alphadd_i + (M_Pa^T Pdd)_i + h_a,i - beta_i lambda_i (the paper's A_{i,3+i} is
    our beta_i). Vectorised over leading axes.
    """
    P, dP, ddP = (np.asarray(v, dtype=float) for v in (P, dP, ddP))
    alpha, dalpha, ddalpha = joint_motion(desc, P, dP, ddP, alpha)
    A, beta = delta.jacobian_parts(desc, P, alpha)
    M_PP, M_aa, M_Pa = mass_blocks(desc, mass, alpha)
    h_P, h_a = bias_forces(desc, mass, alpha, dalpha, g)
    rhs_P = M_PP * ddP + np.einsum('...ij,...j->...i', M_Pa, ddalpha) + h_P
    lam = np.linalg.solve(np.swapaxes(A, -1, -2), rhs_P[..., None])[..., 0]
    tau = M_aa * ddalpha + np.einsum('...ji,...j->...i', M_Pa, ddP) + h_a - beta * lam
    return JointMotion(alpha, dalpha, ddalpha, tau, lam)


def forward_dynamics(desc, mass, alpha, dalpha, tau, g=G):
    """
    Return arm accelerations alphadd (..., 3) under torques tau (independent coordinates alpha).

    The effector follows from the closed-form forward kinematics, so the constraint holds exactly
    at every step and no drift stabilisation (Baumgarte, projection) is needed. With
    J = -A^-1 diag(beta) (Pd = J alphad) and Pdd = J alphadd + c, c = -A^-1 gamma, eliminating
    lambda from eqs. 4-5 (beta o lambda = -J^T A^T lambda) leaves the reduced equations

        (M_aa + M_Pa^T J + J^T M_Pa + M_PP J^T J) alphadd
            = tau - h_a - J^T h_P - (M_Pa^T + M_PP J^T) c.
    """
    alpha, dalpha, tau = (np.asarray(v, dtype=float) for v in (alpha, dalpha, tau))
    P = delta.forward(desc, alpha)
    A, beta = delta.jacobian_parts(desc, P, alpha)
    Ainv = np.linalg.inv(A)
    J = -Ainv * beta[..., None, :]
    dP = np.einsum('...ij,...j->...i', J, dalpha)
    c = -np.einsum('...ij,...j->...i', Ainv, constraint_bias(desc, P, dP, alpha, dalpha))
    M_PP, M_aa, M_Pa = mass_blocks(desc, mass, alpha)
    JT = np.swapaxes(J, -1, -2)
    M_PaT = np.swapaxes(M_Pa, -1, -2)
    M_red = M_PaT @ J + JT @ M_Pa + M_PP * (JT @ J)
    M_red = M_red + M_aa[..., None] * np.eye(3)
    h_P, h_a = bias_forces(desc, mass, alpha, dalpha, g)
    rhs = (tau - h_a - np.einsum('...ij,...j->...i', JT, h_P)
           - np.einsum('...ij,...j->...i', M_PaT + M_PP * JT, c))
    return np.linalg.solve(M_red, rhs[..., None])[..., 0]


def energy(desc, mass, alpha, dalpha, g=G):
    """Return the total mechanical energy T + V (J) at (alpha, alphad), shape (...,) (eqs. 6-9)."""
    alpha, dalpha = np.asarray(alpha, dtype=float), np.asarray(dalpha, dtype=float)
    P = delta.forward(desc, alpha)
    dP = np.einsum('...ij,...j->...i', delta.jacobian(desc, P, alpha), dalpha)
    _, t = arm_vectors(desc, alpha)
    dB = (desc.a * dalpha)[..., None] * t
    v2 = np.einsum('...j,...j->...', dP, dP)
    T = (0.5 * mass.m_p * v2 + 0.5 * mass.I_t * np.sum(dalpha ** 2, axis=-1)
         + mass.m_b / 6.0 * np.sum(np.einsum('...ij,...ij->...i', dB, dB)
                                   + np.einsum('...ij,...j->...i', dB, dP) + v2[..., None],
                                   axis=-1))
    s = np.sin(alpha)
    V = -g * (mass.m_p * P[..., 2]
              + np.sum(0.5 * mass.m_a * desc.a * s
                       + 0.5 * mass.m_b * (P[..., 2][..., None] + desc.a * s), axis=-1))
    return T + V


class SingleRobotDynamics:
    """
    ``forward_dynamics`` and ``inverse_dynamics`` for ONE robot, with Python floats.

    The simulator evaluates the forward dynamics four times per 1 ms RK4 step and the controller
    the inverse dynamics every 1 ms tick; on 3x3 matrices numpy's per-call overhead dominates
    (0.3-0.4 ms per evaluation with the vectorised functions above, about 0.05 ms here), so this
    class writes the same equations out in scalars. test_dynamics checks that both give the same
    results.
    """

    def __init__(self, desc, mass, g=G):
        self.cp = [float(np.cos(p)) for p in desc.phi]
        self.sp = [float(np.sin(p)) for p in desc.phi]
        self.a = [float(v) for v in desc.a]
        self.b2 = [float(v) ** 2 for v in desc.b]
        self.R = [float(H - h) for H, h in zip(desc.H, desc.h)]   # the paper's Delta r
        self.M_PP = mass.m_p + mass.m_b
        self.M_aa = [mass.I_t + mass.m_b * a * a / 3.0 for a in self.a]
        self.k = [mass.m_b * a / 6.0 for a in self.a]              # M_Pa column i = k_i t_i
        self.g_arm = [g * 0.5 * (mass.m_a + mass.m_b) * a for a in self.a]
        self.g_platform = g * (mass.m_p + 1.5 * mass.m_b)

    def forward_kinematics(self, alpha):
        """
        Return (P, Q, r, t): the effector position and, per leg, Q_i and the arm's unit vectors.

        Q_i = B_i - h_i e_i. P lies at distance b_i from the three Q_i; of the two solutions the
        one below the base.
        """
        Q, r, t = [], [], []
        for i in range(3):
            ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
            cp, sp, a = self.cp[i], self.sp[i], self.a[i]
            rad = self.R[i] + a * ca
            Q.append((rad * cp, rad * sp, a * sa))
            r.append((ca * cp, ca * sp, sa))
            t.append((-sa * cp, -sa * sp, ca))
        q1, q2, q3 = Q
        d12 = [q2[j] - q1[j] for j in range(3)]
        d13 = [q3[j] - q1[j] for j in range(3)]
        d = math.sqrt(_dot(d12, d12))
        ex = [v / d for v in d12]
        i_ = _dot(ex, d13)
        ey = [d13[j] - i_ * ex[j] for j in range(3)]
        j_ = math.sqrt(_dot(ey, ey))
        ey = [v / j_ for v in ey]
        ez = _cross(ex, ey)
        x = (self.b2[0] - self.b2[1] + d * d) / (2 * d)
        y = (self.b2[0] - self.b2[2] + i_ * i_ + j_ * j_) / (2 * j_) - i_ * x / j_
        z2 = self.b2[0] - x * x - y * y
        if z2 < 0:
            raise ValueError('forward kinematics: the forearm spheres do not meet for these arm '
                             'angles')
        z = math.sqrt(z2) if ez[2] >= 0 else -math.sqrt(z2)
        P = [q1[j] + x * ex[j] + y * ey[j] + z * ez[j] for j in range(3)]
        return P, Q, r, t

    def inverse_kinematics(self, P):
        """Return arm angles (elbow out) at P as ``delta.inverse``; ValueError if out of reach."""
        alpha = []
        for i in range(3):
            cp, sp, a = self.cp[i], self.sp[i], self.a[i]
            u = P[0] * cp + P[1] * sp - self.R[i]  # in the leg's plane, from the motor axis
            v = P[1] * cp - P[0] * sp
            w = P[2]
            ratio = (u * u + v * v + w * w + a * a - self.b2[i]) / (2 * a * math.hypot(u, w))
            if abs(ratio) > 1.0:
                raise ValueError(f'position out of reach of leg {i + 1}: {list(P)}')
            alpha.append(math.atan2(w, u) - math.acos(ratio))
        return alpha

    def inverse_dynamics(self, P, dP, ddP):
        """Return (alpha, alphad, tau) for motion (P, Pd, Pdd): ``inverse_dynamics`` (eqs. 4-5)."""
        alpha = self.inverse_kinematics(P)
        _, Q, r, t = self.forward_kinematics(alpha)
        dv = [[P[j] - Q[i][j] for j in range(3)] for i in range(3)]
        beta = [-2 * self.a[i] * _dot(dv[i], t[i]) for i in range(3)]
        dalpha = [-2 * _dot(dv[i], dP) / beta[i] for i in range(3)]
        ddalpha = []
        for i in range(3):
            w = self.a[i] * dalpha[i]
            dd = [dP[j] - w * t[i][j] for j in range(3)]
            gamma = 2 * _dot(dd, dd) + 2 * w * dalpha[i] * _dot(dv[i], r[i])
            ddalpha.append(-(2 * _dot(dv[i], ddP) + gamma) / beta[i])
        # A^T lambda = M_PP Pdd + M_Pa alphadd + h_P (eq. 4)
        rhs = [self.M_PP * ddP[j]
               + sum(self.k[i] * (t[i][j] * ddalpha[i] - dalpha[i] ** 2 * r[i][j])
                     for i in range(3))
               for j in range(3)]
        rhs[2] -= self.g_platform
        AT_inv = _inverse3([[2 * dv[0][j], 2 * dv[1][j], 2 * dv[2][j]] for j in range(3)])
        lam = [_dot(AT_inv[i], rhs) for i in range(3)]
        tau = [self.M_aa[i] * ddalpha[i] + self.k[i] * _dot(t[i], ddP)
               - self.g_arm[i] * math.cos(alpha[i]) - beta[i] * lam[i] for i in range(3)]
        return alpha, dalpha, tau

    def accelerations(self, alpha, dalpha, tau):
        """
        Return (alphadd, P, Pd) for arm angles, rates and joint torques (sequences of 3 floats).

        The reduced equations of ``forward_dynamics``, written out for speed (the simulator calls
        this four times per 1 ms step). With d_i = C_i - B_i, n_i = d_j x d_k ((i, j, k) cyclic)
        and D = d_1 . (d_2 x d_3), the inverse of A (rows 2 d_i^T) has columns n_i / (2 D), so the
        columns of J = -A^-1 diag(beta) are J_i = a_i (d_i . t_i) n_i / D and
        c = -A^-1 gamma = -sum gamma_i n_i / (2 D).
        """
        P, Q, r, t = self.forward_kinematics(alpha)
        px, py, pz = P
        d = [(px - q[0], py - q[1], pz - q[2]) for q in Q]
        n = [_cross(d[(i + 1) % 3], d[(i + 2) % 3]) for i in range(3)]
        D = d[0][0] * n[0][0] + d[0][1] * n[0][1] + d[0][2] * n[0][2]
        if D == 0.0:
            raise ZeroDivisionError('parallel singularity: the forearms are coplanar')
        Jc, dP = [], [0.0, 0.0, 0.0]
        for i in range(3):
            di, ti, ni = d[i], t[i], n[i]
            s = self.a[i] * (di[0] * ti[0] + di[1] * ti[1] + di[2] * ti[2]) / D
            col = (s * ni[0], s * ni[1], s * ni[2])
            Jc.append(col)
            w = dalpha[i]
            dP[0] += col[0] * w
            dP[1] += col[1] * w
            dP[2] += col[2] * w
        c = [0.0, 0.0, 0.0]
        hP = [0.0, 0.0, -self.g_platform]
        for i in range(3):
            di, ri, ti, ni = d[i], r[i], t[i], n[i]
            w = self.a[i] * dalpha[i]
            e0, e1, e2 = dP[0] - w * ti[0], dP[1] - w * ti[1], dP[2] - w * ti[2]
            gamma = (2 * (e0 * e0 + e1 * e1 + e2 * e2)
                     + 2 * w * dalpha[i] * (di[0] * ri[0] + di[1] * ri[1] + di[2] * ri[2]))
            f = -gamma / (2 * D)
            kw = self.k[i] * dalpha[i] * dalpha[i]
            for j in range(3):
                c[j] += f * ni[j]
                hP[j] -= kw * ri[j]
        # reduced mass matrix (symmetric) and right-hand side, dot products written out
        tJ = [[ti[0] * col[0] + ti[1] * col[1] + ti[2] * col[2] for col in Jc] for ti in t]
        JJ = [[ci[0] * ck[0] + ci[1] * ck[1] + ci[2] * ck[2] for ck in Jc] for ci in Jc]
        k, M_PP = self.k, self.M_PP
        M = [[k[i] * tJ[i][j] + k[j] * tJ[j][i] + M_PP * JJ[i][j] for j in range(3)]
             for i in range(3)]
        rhs = []
        for i in range(3):
            M[i][i] += self.M_aa[i]
            ci, ti = Jc[i], t[i]
            rhs.append(tau[i] + self.g_arm[i] * math.cos(alpha[i])
                       - (ci[0] * hP[0] + ci[1] * hP[1] + ci[2] * hP[2])
                       - k[i] * (ti[0] * c[0] + ti[1] * c[1] + ti[2] * c[2])
                       - M_PP * (ci[0] * c[0] + ci[1] * c[1] + ci[2] * c[2]))
        return _solve3(M, rhs), P, dP


def _dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _cross(u, v):
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _inverse3(m):
    """Return the inverse of a 3x3 matrix (list of rows) by cofactors."""
    c0, c1, c2 = _cross(m[1], m[2]), _cross(m[2], m[0]), _cross(m[0], m[1])
    det = _dot(m[0], c0)
    if det == 0.0:
        raise ZeroDivisionError('singular 3x3 matrix (parallel singularity: the forearms are '
                                'coplanar)')
    return [[c0[j] / det, c1[j] / det, c2[j] / det] for j in range(3)]


def _solve3(m, rhs):
    inv = _inverse3(m)
    return [_dot(inv[j], rhs) for j in range(3)]
