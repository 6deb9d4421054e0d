"""
How long to measure each rest: the frames that buy the most information per second of robot time.

A rest of N frames measures the ball with variance sigma^2 / N + f^2 per optical axis: the frames'
noise averaged down, and the rest's own error floor f, which no number of frames removes. It costs
T0 + N / rate seconds of robot time (T0: the move and the settling). The information per second,
1 / ((sigma^2 / N + f^2) (T0 + N / rate)), is largest at N* = (sigma / f) sqrt(T0 rate): beyond it
the floor dominates the average and more frames buy less than a new pose would.
"""
import numpy as np


def frames_per_rest(frame_sigma, floor, overhead, rate, least=2, most=2000):
    """
    Return N*, the frames per rest with the most information per second of robot time.

    The axis that needs the most frames decides (every axis then has at least its N*).

    Parameters
    ----------
    frame_sigma : array of 3
        One frame's noise along the optical axes (m).
    floor : array of 3
        The rests' own error floor along the same axes (m); an axis with no floor is ignored.
    overhead : float
        Robot time per rest besides the frames (s): the move and the settling.
    rate : float
        Camera frame rate (Hz).
    least, most : int
        Bounds of the answer.

    """
    sigma, f = np.asarray(frame_sigma, dtype=float), np.asarray(floor, dtype=float)
    if overhead <= 0 or rate <= 0:
        raise ValueError(f'overhead and rate must be positive; got {overhead} s, {rate} Hz')
    floored = f > 0
    if not floored.any():
        return most
    best = np.max(sigma[floored] / f[floored]) * np.sqrt(overhead * rate)
    return int(np.clip(np.ceil(best), least, most))


def rest_variance(frame_sigma, floor, frames):
    """Return the variance (3,) of a rest's average of ``frames`` frames, floor included (m^2)."""
    return np.square(frame_sigma) / frames + np.square(floor)
