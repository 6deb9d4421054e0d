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
        """
        Return (alpha, alphad, tau) for motion (P, Pd, Pdd): ``inverse_dynamics`` (eqs. 4-5).

        The controller's every tick: written out in local floats as ``accelerations`` (13 us
        against 44 us with lists), the operations of the list form in its order.
        """
        cos, sin = math.cos, math.sin
        px, py, pz = P
        vx, vy, vz = dP
        ax, ay, az = ddP
        alpha = self.inverse_kinematics(P)
        al0, al1, al2 = alpha
        a0, a1, a2 = self.a
        cp0, cp1, cp2 = self.cp
        sp0, sp1, sp2 = self.sp
        R0, R1, R2 = self.R
        ca0, sa0 = cos(al0), sin(al0)
        ca1, sa1 = cos(al1), sin(al1)
        ca2, sa2 = cos(al2), sin(al2)
        rad = R0 + a0 * ca0
        d0x, d0y, d0z = px - rad * cp0, py - rad * sp0, pz - a0 * sa0
        rad = R1 + a1 * ca1
        d1x, d1y, d1z = px - rad * cp1, py - rad * sp1, pz - a1 * sa1
        rad = R2 + a2 * ca2
        d2x, d2y, d2z = px - rad * cp2, py - rad * sp2, pz - a2 * sa2
        r0x, r0y, r0z, t0x, t0y, t0z = _arm_axes(ca0, sa0, cp0, sp0)
        r1x, r1y, r1z, t1x, t1y, t1z = _arm_axes(ca1, sa1, cp1, sp1)
        r2x, r2y, r2z, t2x, t2y, t2z = _arm_axes(ca2, sa2, cp2, sp2)
        b0 = -2 * a0 * (d0x * t0x + d0y * t0y + d0z * t0z)
        b1 = -2 * a1 * (d1x * t1x + d1y * t1y + d1z * t1z)
        b2 = -2 * a2 * (d2x * t2x + d2y * t2y + d2z * t2z)
        w0 = -2 * (d0x * vx + d0y * vy + d0z * vz) / b0
        w1 = -2 * (d1x * vx + d1y * vy + d1z * vz) / b1
        w2 = -2 * (d2x * vx + d2y * vy + d2z * vz) / b2
        u = a0 * w0
        e0, e1, e2 = vx - u * t0x, vy - u * t0y, vz - u * t0z
        g = (2 * (e0 * e0 + e1 * e1 + e2 * e2)
             + 2 * u * w0 * (d0x * r0x + d0y * r0y + d0z * r0z))
        dd0 = -(2 * (d0x * ax + d0y * ay + d0z * az) + g) / b0
        u = a1 * w1
        e0, e1, e2 = vx - u * t1x, vy - u * t1y, vz - u * t1z
        g = (2 * (e0 * e0 + e1 * e1 + e2 * e2)
             + 2 * u * w1 * (d1x * r1x + d1y * r1y + d1z * r1z))
        dd1 = -(2 * (d1x * ax + d1y * ay + d1z * az) + g) / b1
        u = a2 * w2
        e0, e1, e2 = vx - u * t2x, vy - u * t2y, vz - u * t2z
        g = (2 * (e0 * e0 + e1 * e1 + e2 * e2)
             + 2 * u * w2 * (d2x * r2x + d2y * r2y + d2z * r2z))
        dd2 = -(2 * (d2x * ax + d2y * ay + d2z * az) + g) / b2
        # A^T lambda = M_PP Pdd + M_Pa alphadd + h_P (eq. 4)
        k0, k1, k2 = self.k
        M_PP = self.M_PP
        q0, q1, q2 = w0 ** 2, w1 ** 2, w2 ** 2
        hx = (M_PP * ax + (0 + k0 * (t0x * dd0 - q0 * r0x) + k1 * (t1x * dd1 - q1 * r1x)
                           + k2 * (t2x * dd2 - q2 * r2x)))
        hy = (M_PP * ay + (0 + k0 * (t0y * dd0 - q0 * r0y) + k1 * (t1y * dd1 - q1 * r1y)
                           + k2 * (t2y * dd2 - q2 * r2y)))
        hz = (M_PP * az + (0 + k0 * (t0z * dd0 - q0 * r0z) + k1 * (t1z * dd1 - q1 * r1z)
                           + k2 * (t2z * dd2 - q2 * r2z))) - self.g_platform
        # lambda = (A^T)^-1 rhs, A^T with columns 2 d_i
        lam0, lam1, lam2 = _solve3(2 * d0x, 2 * d1x, 2 * d2x, 2 * d0y, 2 * d1y, 2 * d2y,
                                   2 * d0z, 2 * d1z, 2 * d2z, hx, hy, hz)
        ga0, ga1, ga2 = self.g_arm
        Maa0, Maa1, Maa2 = self.M_aa
        tau = [Maa0 * dd0 + k0 * (t0x * ax + t0y * ay + t0z * az) - ga0 * cos(al0) - b0 * lam0,
               Maa1 * dd1 + k1 * (t1x * ax + t1y * ay + t1z * az) - ga1 * cos(al1) - b1 * lam1,
               Maa2 * dd2 + k2 * (t2x * ax + t2y * ay + t2z * az) - ga2 * cos(al2) - b2 * lam2]
        return alpha, [w0, w1, w2], tau

    def accelerations(self, alpha, dalpha, tau):
        """
        Return (alphadd, P, Pd) for arm angles, rates and joint torques (sequences of 3 floats).

        The reduced equations of ``forward_dynamics``, written out for speed (the simulator calls
        this four times per 1 ms step). With d_i = C_i - B_i, n_i = d_j x d_k ((i, j, k) cyclic)
        and D = d_1 . (d_2 x d_3), the inverse of A (rows 2 d_i^T) has columns n_i / (2 D), so the
        columns of J = -A^-1 diag(beta) are J_i = a_i (d_i . t_i) n_i / D and
        c = -A^-1 gamma = -sum gamma_i n_i / (2 D). Every vector is in local floats, the legs
        unrolled (9 us against 28 us with lists of tuples: the same operations in the same order,
        so the same results to the bit); the effector as in ``forward_kinematics``.
        """
        cos, sin = math.cos, math.sin
        a0, a1, a2 = self.a
        cp0, cp1, cp2 = self.cp
        sp0, sp1, sp2 = self.sp
        R0, R1, R2 = self.R
        al0, al1, al2 = alpha
        w0, w1, w2 = dalpha
        # legs: Q_i, r_i, t_i
        ca0, sa0 = cos(al0), sin(al0)
        ca1, sa1 = cos(al1), sin(al1)
        ca2, sa2 = cos(al2), sin(al2)
        rad = R0 + a0 * ca0
        q0x, q0y, q0z = rad * cp0, rad * sp0, a0 * sa0
        rad = R1 + a1 * ca1
        q1x, q1y, q1z = rad * cp1, rad * sp1, a1 * sa1
        rad = R2 + a2 * ca2
        q2x, q2y, q2z = rad * cp2, rad * sp2, a2 * sa2
        r0x, r0y, r0z, t0x, t0y, t0z = _arm_axes(ca0, sa0, cp0, sp0)
        r1x, r1y, r1z, t1x, t1y, t1z = _arm_axes(ca1, sa1, cp1, sp1)
        r2x, r2y, r2z, t2x, t2y, t2z = _arm_axes(ca2, sa2, cp2, sp2)
        # trilateration (forward_kinematics)
        ux, uy, uz = q1x - q0x, q1y - q0y, q1z - q0z
        vx, vy, vz = q2x - q0x, q2y - q0y, q2z - q0z
        d = math.sqrt(ux * ux + uy * uy + uz * uz)
        exx, exy, exz = ux / d, uy / d, uz / d
        i_ = exx * vx + exy * vy + exz * vz
        eyx, eyy, eyz = vx - i_ * exx, vy - i_ * exy, vz - i_ * exz
        j_ = math.sqrt(eyx * eyx + eyy * eyy + eyz * eyz)
        eyx, eyy, eyz = eyx / j_, eyy / j_, eyz / j_
        ezx = exy * eyz - exz * eyy
        ezy = exz * eyx - exx * eyz
        ezz = exx * eyy - exy * eyx
        b20, b21, b22 = self.b2
        x = (b20 - b21 + d * d) / (2 * d)
        y = (b20 - b22 + i_ * i_ + j_ * j_) / (2 * j_) - i_ * x / j_
        z2 = b20 - x * x - y * y
        if z2 < 0:
            raise ValueError('forward kinematics: the forearm spheres do not meet for these arm '
                             'angles')
        z = math.sqrt(z2) if ezz >= 0 else -math.sqrt(z2)
        px = q0x + x * exx + y * eyx + z * ezx
        py = q0y + x * exy + y * eyy + z * ezy
        pz = q0z + x * exz + y * eyz + z * ezz
        # d_i = P - Q_i, n_i = d_j x d_k
        d0x, d0y, d0z = px - q0x, py - q0y, pz - q0z
        d1x, d1y, d1z = px - q1x, py - q1y, pz - q1z
        d2x, d2y, d2z = px - q2x, py - q2y, pz - q2z
        n0x, n0y, n0z = d1y * d2z - d1z * d2y, d1z * d2x - d1x * d2z, d1x * d2y - d1y * d2x
        n1x, n1y, n1z = d2y * d0z - d2z * d0y, d2z * d0x - d2x * d0z, d2x * d0y - d2y * d0x
        n2x, n2y, n2z = d0y * d1z - d0z * d1y, d0z * d1x - d0x * d1z, d0x * d1y - d0y * d1x
        D = d0x * n0x + d0y * n0y + d0z * n0z
        if D == 0.0:
            raise ZeroDivisionError('parallel singularity: the forearms are coplanar')
        s = a0 * (d0x * t0x + d0y * t0y + d0z * t0z) / D
        j0x, j0y, j0z = s * n0x, s * n0y, s * n0z
        s = a1 * (d1x * t1x + d1y * t1y + d1z * t1z) / D
        j1x, j1y, j1z = s * n1x, s * n1y, s * n1z
        s = a2 * (d2x * t2x + d2y * t2y + d2z * t2z) / D
        j2x, j2y, j2z = s * n2x, s * n2y, s * n2z
        vx = 0.0 + j0x * w0 + j1x * w1 + j2x * w2
        vy = 0.0 + j0y * w0 + j1y * w1 + j2y * w2
        vz = 0.0 + j0z * w0 + j1z * w1 + j2z * w2
        k0, k1, k2 = self.k
        D2 = 2 * D
        u = a0 * w0
        e0, e1, e2 = vx - u * t0x, vy - u * t0y, vz - u * t0z
        f0 = -(2 * (e0 * e0 + e1 * e1 + e2 * e2)
               + 2 * u * w0 * (d0x * r0x + d0y * r0y + d0z * r0z)) / D2
        u = a1 * w1
        e0, e1, e2 = vx - u * t1x, vy - u * t1y, vz - u * t1z
        f1 = -(2 * (e0 * e0 + e1 * e1 + e2 * e2)
               + 2 * u * w1 * (d1x * r1x + d1y * r1y + d1z * r1z)) / D2
        u = a2 * w2
        e0, e1, e2 = vx - u * t2x, vy - u * t2y, vz - u * t2z
        f2 = -(2 * (e0 * e0 + e1 * e1 + e2 * e2)
               + 2 * u * w2 * (d2x * r2x + d2y * r2y + d2z * r2z)) / D2
        cx = 0.0 + f0 * n0x + f1 * n1x + f2 * n2x
        cy = 0.0 + f0 * n0y + f1 * n1y + f2 * n2y
        cz = 0.0 + f0 * n0z + f1 * n1z + f2 * n2z
        kw0, kw1, kw2 = k0 * w0 * w0, k1 * w1 * w1, k2 * w2 * w2
        hx = 0.0 - kw0 * r0x - kw1 * r1x - kw2 * r2x
        hy = 0.0 - kw0 * r0y - kw1 * r1y - kw2 * r2y
        hz = -self.g_platform - kw0 * r0z - kw1 * r1z - kw2 * r2z
        # reduced mass matrix: tJ[i][j] = t_i . J_j, JJ[i][j] = J_i . J_j
        tJ00 = t0x * j0x + t0y * j0y + t0z * j0z
        tJ01 = t0x * j1x + t0y * j1y + t0z * j1z
        tJ02 = t0x * j2x + t0y * j2y + t0z * j2z
        tJ10 = t1x * j0x + t1y * j0y + t1z * j0z
        tJ11 = t1x * j1x + t1y * j1y + t1z * j1z
        tJ12 = t1x * j2x + t1y * j2y + t1z * j2z
        tJ20 = t2x * j0x + t2y * j0y + t2z * j0z
        tJ21 = t2x * j1x + t2y * j1y + t2z * j1z
        tJ22 = t2x * j2x + t2y * j2y + t2z * j2z
        JJ00 = j0x * j0x + j0y * j0y + j0z * j0z
        JJ01 = j0x * j1x + j0y * j1y + j0z * j1z
        JJ02 = j0x * j2x + j0y * j2y + j0z * j2z
        JJ10 = j1x * j0x + j1y * j0y + j1z * j0z
        JJ11 = j1x * j1x + j1y * j1y + j1z * j1z
        JJ12 = j1x * j2x + j1y * j2y + j1z * j2z
        JJ20 = j2x * j0x + j2y * j0y + j2z * j0z
        JJ21 = j2x * j1x + j2y * j1y + j2z * j1z
        JJ22 = j2x * j2x + j2y * j2y + j2z * j2z
        M_PP = self.M_PP
        Maa0, Maa1, Maa2 = self.M_aa
        m00 = k0 * tJ00 + k0 * tJ00 + M_PP * JJ00 + Maa0
        m01 = k0 * tJ01 + k1 * tJ10 + M_PP * JJ01
        m02 = k0 * tJ02 + k2 * tJ20 + M_PP * JJ02
        m10 = k1 * tJ10 + k0 * tJ01 + M_PP * JJ10
        m11 = k1 * tJ11 + k1 * tJ11 + M_PP * JJ11 + Maa1
        m12 = k1 * tJ12 + k2 * tJ21 + M_PP * JJ12
        m20 = k2 * tJ20 + k0 * tJ02 + M_PP * JJ20
        m21 = k2 * tJ21 + k1 * tJ12 + M_PP * JJ21
        m22 = k2 * tJ22 + k2 * tJ22 + M_PP * JJ22 + Maa2
        ga0, ga1, ga2 = self.g_arm
        tau0, tau1, tau2 = tau
        h0 = (tau0 + ga0 * ca0 - (j0x * hx + j0y * hy + j0z * hz)
              - k0 * (t0x * cx + t0y * cy + t0z * cz) - M_PP * (j0x * cx + j0y * cy + j0z * cz))
        h1 = (tau1 + ga1 * ca1 - (j1x * hx + j1y * hy + j1z * hz)
              - k1 * (t1x * cx + t1y * cy + t1z * cz) - M_PP * (j1x * cx + j1y * cy + j1z * cz))
        h2 = (tau2 + ga2 * ca2 - (j2x * hx + j2y * hy + j2z * hz)
              - k2 * (t2x * cx + t2y * cy + t2z * cz) - M_PP * (j2x * cx + j2y * cy + j2z * cz))
        dd = _solve3(m00, m01, m02, m10, m11, m12, m20, m21, m22, h0, h1, h2)
        return list(dd), [px, py, pz], [vx, vy, vz]


def _dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _cross(u, v):
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _arm_axes(ca, sa, cp, sp):
    """
    Return r_i and t_i of one leg, as six floats.

    r_i is the unit vector along arm i at angle alpha (cos, sin: ca, sa) in the leg's plane at
    azimuth phi (cp, sp); t_i = d r_i / d alpha, its tangent.
    """
    return ca * cp, ca * sp, sa, -sa * cp, -sa * sp, ca


def _solve3(m00, m01, m02, m10, m11, m12, m20, m21, m22, h0, h1, h2):
    """
    Return x (3 floats) with M x = h, M given row by row, by cofactors.

    The cofactor rows are c0 = m1 x m2, c1 = m2 x m0, c2 = m0 x m1 and x_j = sum_i c_ij h_i / det:
    plain floats, as the 1 kHz step needs (numpy's solve costs more than the whole step).
    """
    c00, c01, c02 = m11 * m22 - m12 * m21, m12 * m20 - m10 * m22, m10 * m21 - m11 * m20
    c10, c11, c12 = m21 * m02 - m22 * m01, m22 * m00 - m20 * m02, m20 * m01 - m21 * m00
    c20, c21, c22 = m01 * m12 - m02 * m11, m02 * m10 - m00 * m12, m00 * m11 - m01 * m10
    det = m00 * c00 + m01 * c01 + m02 * c02
    if det == 0.0:
        raise ZeroDivisionError('singular 3x3 matrix (parallel singularity: the forearms are '
                                'coplanar)')
    return (c00 / det * h0 + c10 / det * h1 + c20 / det * h2,
            c01 / det * h0 + c11 / det * h1 + c21 / det * h2,
            c02 / det * h0 + c12 / det * h1 + c22 / det * h2)
