"""Position-based visual servoing of the RoboTenis (calibration paper, section 6.2, eqs. 23-25).

The camera sees the ball at s (optical frame); the robot wants it at s_d (centred, 600 mm ahead).
With R the camera rotation (optical axes in the effector frame, which is parallel to the base), the
error of the robot's position relative to the ball is e_r = -R (s - s_d), and the law

    u_r = -K_p e_r + v_p          (23)      u_q = J_R^-1 u_r          (25)

drives it to zero while v_p, the ball's velocity from a Kalman filter on its measured positions,
feeds the motion forward. J_R^-1 comes from the robot description in use (nominal or calibrated);
the tracking error reported is |e_r|.
"""
import numpy as np

K_P = 16.8                                  # 1/s, the paper's gain
S_DESIRED = np.array([0.0, 0.0, 0.600])     # m: ball centred in the image, 600 mm ahead


def relative_error(s, R, s_desired=S_DESIRED):
    """e_r = -R (s - s_d) (m, base frame): where the robot is relative to where it should be."""
    return -np.asarray(R) @ (np.asarray(s, dtype=float) - s_desired)


def cartesian_command(e_r, v_p, K_p=K_P):
    """u_r = -K_p e_r + v_p (eq. 23), m/s in the base frame."""
    return -K_p * np.asarray(e_r) + np.asarray(v_p)


def joint_command(J_inv, u_r):
    """u_q = J_R^-1 u_r (eq. 25), rad/s."""
    return np.asarray(J_inv) @ np.asarray(u_r)


class BallKalman:
    """Constant-velocity Kalman filter on the ball's position (base frame).

    State x = [p, v] (6). The ball's acceleration is modelled as white noise of spectral density q
    (m^2/s^3): a chaotic ball that turns at 1.5 m/s needs q of order (a_max)^2 * tau.
    """

    def __init__(self, q=20.0):
        self.q = q
        self.x = None
        self.P = None

    def predict(self, dt):
        F = np.eye(6)
        F[:3, 3:] = dt * np.eye(3)
        G = np.block([[dt ** 3 / 3 * np.eye(3), dt ** 2 / 2 * np.eye(3)],
                      [dt ** 2 / 2 * np.eye(3), dt * np.eye(3)]])
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + self.q * G

    def update(self, z, R):
        """Fuse a measured position z (3,) with covariance R (3, 3); starts the filter if needed."""
        z = np.asarray(z, dtype=float)
        if self.x is None:
            self.x = np.concatenate([z, np.zeros(3)])
            self.P = np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), np.eye(3) * 4.0]])  # v unknown: (2 m/s)^2
            return
        H = np.hstack([np.eye(3), np.zeros((3, 3))])
        S = H @ self.P @ H.T + R
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ (z - H @ self.x)
        self.P = (np.eye(6) - K @ H) @ self.P

    @property
    def velocity(self):
        return np.zeros(3) if self.x is None else self.x[3:].copy()
