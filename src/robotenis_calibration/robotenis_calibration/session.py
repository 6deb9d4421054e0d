"""
A calibration session reduced to what identification needs: one averaged measurement per rest.

Whatever recorded it -- this system's calibration node, another driver's bag, or the static session
simulator -- a session is the declared robot description plus, for each pose the robot rested at,
in visit order: the resolver increments and the sphere centre seen by the hand camera, each
averaged over the rest with its uncertainty.
"""
import dataclasses
from dataclasses import dataclass, field

import numpy as np

from robotenis_kinematics import effects
from robotenis_kinematics.identification import Measurements


def nearest_gap(gaps, width):
    """Return the index in ``gaps`` (G,) nearest in ratio to each of ``width`` (n,) rad."""
    return np.argmin(np.abs(np.log(gaps)[:, None] - np.log(np.atleast_1d(width))), axis=0)


@dataclass
class Session:
    """
    Averaged measurements of K rests, in the order the robot visited them.

    description : the declared RobotDescription (what the system believed during the session).
    Theta : (K, 3) resolver increments from home, rad.
    sigma_Theta : (K, 3) standard deviation of each averaged increment, rad.
    sphere : (K, 3) sphere centre in the camera optical frame, m.
    sphere_cov : (K, 3, 3) covariance of each averaged sphere centre, m^2.
    stamps : (K,) time of each rest (middle of the averaging window), s.
    samples : (K,) number of camera frames averaged at each rest.
    direction : (K, 3) sign of each joint's last motion before each rest, when the recording shows
        it (poses visited but not measured lie between rests); by default from the order of Theta.
    noise : the frames' and readings' noise models the averages were made with (plain data, for the
        result file), or None.
    approach : (K, G + V, 3) the backlash contact side by each candidate rule, when the recording
        shows the motion: for a gap of each of ``gaps`` (G,) rad, the sign of the last reversal
        of the readings across it (rests.approach_directions); then, for each of ``speeds`` (V,)
        rad/s, the sign of the last motion faster (rests.fast_motion_sides); ``direction`` is
        one of them.
    timing : the recording's pace (plain data, rests.rest_timing): the camera's rate and the robot
        time a rest costs besides its frames; or None.
    """

    description: object
    Theta: np.ndarray
    sigma_Theta: np.ndarray
    sphere: np.ndarray
    sphere_cov: np.ndarray
    stamps: np.ndarray
    samples: np.ndarray = field(default=None)
    direction: np.ndarray = field(default=None)
    noise: dict = field(default=None)
    approach: np.ndarray = field(default=None)
    gaps: np.ndarray = field(default=None)
    timing: dict = field(default=None)
    speeds: np.ndarray = field(default=None)

    def __post_init__(self):
        K = len(self.Theta)
        self.Theta = np.asarray(self.Theta, dtype=float).reshape(K, 3)
        sigma_Theta = np.asarray(self.sigma_Theta, dtype=float)
        self.sigma_Theta = np.broadcast_to(sigma_Theta, (K, 3)).copy()
        self.sphere = np.asarray(self.sphere, dtype=float).reshape(K, 3)
        sphere_cov = np.asarray(self.sphere_cov, dtype=float)
        self.sphere_cov = np.broadcast_to(sphere_cov, (K, 3, 3)).copy()
        self.stamps = np.asarray(self.stamps, dtype=float).reshape(K)
        self.samples = (np.ones(K, dtype=int) if self.samples is None
                        else np.asarray(self.samples, dtype=int))
        if self.direction is None:
            self.direction = effects.motion_direction(self.Theta)
        self.direction = np.asarray(self.direction, dtype=float).reshape(K, 3)

    def __len__(self):
        return len(self.Theta)

    def subset(self, index):
        """Return the rests selected by ``index`` (visit order is kept for a sorted index)."""
        return Session(self.description, self.Theta[index], self.sigma_Theta[index],
                       self.sphere[index], self.sphere_cov[index], self.stamps[index],
                       self.samples[index], self.direction[index], self.noise,
                       None if self.approach is None else self.approach[index], self.gaps,
                       self.timing, self.speeds)

    def with_backlash(self, width):
        """
        Return the session with each joint's backlash side taken at a gap of ``width`` (3,) rad.

        The side is that of the last reversal of the readings across the gap
        (rests.approach_directions: an overshoot at a move's end that comes back by less leaves
        the contact where it was), at the nearest of ``gaps`` (at least the first; a width fitted
        negative, on sides taken mostly wrong, by its size). The session itself when the
        recording did not give the approaches.
        """
        if self.approach is None:
            return self
        return self.at_gaps(self.gap_index(width))

    def gap_index(self, width):
        """Return the index in ``gaps`` (3,) nearest each joint's ``width`` (with_backlash's)."""
        return nearest_gap(self.gaps, np.maximum(np.abs(width), self.gaps[0]))

    def at_gaps(self, pick):
        """Return the session with each joint's sides taken by its rule ``pick`` (3,)."""
        return dataclasses.replace(self, direction=self.approach[:, pick, np.arange(3)])

    def side_rule(self, index):
        """Describe the candidate rule ``index`` of ``approach`` for a human: its gap or speed."""
        if index < len(self.gaps):
            return f'a gap of {self.gaps[index] * 1e3:.3f} mrad'
        return f'motion faster than {self.speeds[index - len(self.gaps)]:.3f} rad/s'

    def measurements(self, camera_rotation=None):
        """
        Incremental measurements for identification (eq. 3).

        The effector only translates, so with the fixed ball at S and the camera at P + t, the
        sphere seen at s_k gives P_k = (S - t) - R s_k: Pi_k = -R s_k, and P0 = S - t is the
        effector position that would put the ball at the optical centre (identified with the rest).
        R is the declared camera rotation unless another is given (the hand-eye effect refines it).
        """
        R = self.description.camera_rotation if camera_rotation is None else camera_rotation
        Pi = -self.sphere @ R.T
        cov = np.einsum('ab,kbc,dc->kad', R, self.sphere_cov, R)
        return Measurements(self.Theta, Pi, self.sigma_Theta, cov, self.direction)

    def motion_direction(self):
        """Sign (+1/-1) of each joint's last motion before each rest (K, 3)."""
        return self.direction
