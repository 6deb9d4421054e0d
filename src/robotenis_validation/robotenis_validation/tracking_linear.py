"""
The tracking loop on a still ball as a linear system: the error the camera noise and delays cause.

``noise_response`` predicts the mean square true error from the camera noise and the loop's delays
alone (the robot ideal, or the simulated robot linearised at a pose), to check the simulated
tracking against.
"""
from dataclasses import replace

import numpy as np
from robotenis_control import controller as ctl
from robotenis_control import pbvs
from robotenis_kinematics import delta
from robotenis_validation.tracking_engines import BatchPlant


def kalman_gain(setup, W):
    """
    Compute the steady-state gain K (6, 3) and transition (I - K H) F of BallKalman.

    At the frame period, for measurement covariance W (3, 3): the filter's own covariance iterated
    until it settles.
    """
    T = setup.frame_period
    kf = pbvs.BallKalman(setup.kalman_q)
    kf.update(np.zeros(3), W)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    for _ in range(5000):
        kf.predict(T)
        P_minus = kf.P.copy()
        kf.update(np.zeros(3), W)
    K = P_minus @ H.T @ np.linalg.inv(H @ P_minus @ H.T + W)
    F = np.eye(6)
    F[:3, 3:] = T * np.eye(3)
    return K, (np.eye(6) - K @ H) @ F


def ideal_plant(setup):
    """
    Return (A, B, C) of a robot that moves exactly at the commanded velocity.

    p_(k+1) = p_k + T v_k.
    """
    I3 = np.eye(3)
    return I3, setup.frame_period * I3, I3


def linearized_plant(truth, desc, setup, P, eps=1e-6, settle=0.3):
    """
    Return (A, B, C): one true robot with its motion controller (BatchPlant) over one frame.

    Linearised at rest at P (m) by central differences: x_(k+1) = A x_k + B v_k and p_k = C x_k,
    with x the deviations of (alpha, alphad, held position), v the velocity command held over the
    frame and p the true effector position. Resolver counts and noise are left out (they are far
    below the camera noise); the frame must last a whole number of ticks, and the controller must
    not use kd.
    """
    ticks = int(round(setup.frame_period / setup.dt))
    if abs(ticks * setup.dt - setup.frame_period) > 1e-12 or ctl.Gains().kd != 0:
        raise ValueError('linearized_plant: needs a frame of whole ticks '
                         'and a controller without kd')
    n = 12                                               # alpha, alphad, hold, v
    Theta = delta.inverse(truth.geometry, np.asarray(P, dtype=float)) - truth.geometry.theta0
    plant = BatchPlant(truth, [desc] * (2 * n + 1), np.tile(Theta, (2 * n + 1, 1)),
                       replace(setup, resolver_noise=0.0), np.random.default_rng(0),
                       quantise=False)
    t = 0.0
    for _ in range(int(round(settle / setup.dt))):       # settle under gravity, no command
        plant.control(t, *plant.read())
        plant.step()
        t += setup.dt
    robots, controller = plant.motors, plant.controller
    state = np.hstack([robots.alpha, robots.dalpha, controller.hold, np.zeros((2 * n + 1, 3))])
    state[1:] += np.vstack([eps * np.eye(n), -eps * np.eye(n)])
    robots.alpha, robots.dalpha = state[:, 0:3].copy(), state[:, 3:6].copy()
    controller.hold = state[:, 6:9].copy()
    plant.set_velocity(state[:, 9:12], t)
    for _ in range(ticks):
        plant.control(t, *plant.read())
        plant.step()
        t += setup.dt
    after = np.hstack([robots.alpha, robots.dalpha, controller.hold])
    D = (after[1:n + 1] - after[n + 1:]).T / (2 * eps)   # (9, 12)
    alpha = state[0, 0:3]
    J = delta.jacobian(truth.geometry, delta.forward(truth.geometry, alpha), alpha)
    return D[:, :9], D[:, 9:], np.hstack([J, np.zeros((3, 6))])


def closed_loop(setup, R, plant=None):
    """
    Model the visual loop on a still ball as a linear system, frame by frame.

    S_(k+1) = M S_k + G w_k. Frame period T, L = latency_frames. The robot is a linear plant
    x_(k+1) = A x_k + B v_k, e_k = C x_k (``plant``; default ``ideal_plant``, or the
    ``linearized_plant`` of the simulated robot). The camera measures y_k = e_k + w_k, w_k its
    noise in the base frame, covariance W = R diag(sigma^2) R^T. The ball is still, so only the
    noise moves its measured position, and the filter at its steady gain K (for the noise it
    assumes, ``Setup.assumed_sigma``) is f_k = A_f f_(k-1) - K w_k; a camera bias only shifts e's
    mean and is left out. The command u_k = -K_p y_k + v_k (eq. 23, v_k the filter's velocity)
    drives the plant during frame k + L. State S_k = (x_k, f_(k-1), u_(k-1) .. u_(k-L)). Returns
    (M, G, W, Ce) with e_k = Ce S_k.
    """
    A, B, C = plant if plant is not None else ideal_plant(setup)
    L, nx = setup.latency_frames, A.shape[0]
    R = np.asarray(R, dtype=float)
    W = R @ np.diag(np.square(setup.sigma_camera)) @ R.T
    K, A_f = kalman_gain(setup, R @ np.diag(np.square(setup.assumed_sigma)) @ R.T)
    V = np.hstack([np.zeros((3, 3)), np.eye(3)]) if setup.feedforward else np.zeros((3, 6))
    ns = nx + 6 + 3 * L
    f, pend = slice(nx, nx + 6), [slice(nx + 6 + 3 * j, nx + 9 + 3 * j) for j in range(L)]
    Ux, Uw = np.zeros((3, ns)), -setup.K_p * np.eye(3) - V @ K      # u_k = Ux S_k + Uw w_k
    Ux[:, :nx] = -setup.K_p * C
    Ux[:, f] = V @ A_f
    M, G = np.zeros((ns, ns)), np.zeros((ns, 3))
    M[:nx, :nx] = A
    if L == 0:
        M[:nx] += B @ Ux
        G[:nx] = B @ Uw
    else:
        M[:nx, pend[-1]] = B
        M[pend[0]], G[pend[0]] = Ux, Uw
        for j in range(1, L):
            M[pend[j], pend[j - 1]] = np.eye(3)
    M[f, f], G[f] = A_f, -K
    Ce = np.zeros((3, ns))
    Ce[:, :nx] = C
    return M, G, W, Ce


def noise_response(setup, R, n_samples, runs=1, plant=None, max_lag=3000):
    """
    Predict the mean square true error (m^2) on a still ball from camera noise and delays alone.

    Also returns the standard error of its estimate from ``runs`` runs of ``n_samples`` frames.

    The stationary covariance of ``closed_loop`` solves a discrete Lyapunov equation; the
    autocovariances C(tau) of e give the variance of a sample mean of |e|^2 for a Gaussian process,
    (2/n) sum_tau tr(C(tau) C(tau)^T).
    """
    from scipy.linalg import solve_discrete_lyapunov

    M, G, W, Ce = closed_loop(setup, R, plant)
    if max(abs(np.linalg.eigvals(M))) >= 1:
        raise ValueError('noise_response: the linear loop is unstable for this setup')
    S = solve_discrete_lyapunov(M, G @ W @ G.T)
    C0 = Ce @ S @ Ce.T
    total, MS = np.sum(C0 * C0), S @ Ce.T
    for _ in range(max_lag):
        MS = M @ MS
        Ct = Ce @ MS
        total += 2 * np.sum(Ct * Ct)
    return float(np.trace(C0)), float(np.sqrt(2 * total / (n_samples * runs)))
