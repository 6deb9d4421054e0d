"""
How long to measure each rest: the frames that buy the most information per second of robot time.

A rest of N frames measures the ball with variance sigma^2 / N + f^2 per optical axis: the frames'
noise averaged down, and the rest's own error floor f, which no number of frames removes. It costs
T0 + N / rate seconds of robot time (T0: the move and the settling). The information per second,
1 / ((sigma^2 / N + f^2) (T0 + N / rate)), is largest at N* = (sigma / f) sqrt(T0 rate): beyond it
the floor dominates the average and more frames buy less than a new pose would.

A calibrated session measures all three: the frames' noise (rests.FrameNoise), the floor (the
identification's variance components) and its pace (rests.rest_timing); ``next_session`` turns them
into the frames per rest for the next session on that robot.
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


def rest_sigmas(frame_noise, floor):
    """
    Return one frame's noise and the rests' floor (each (3,), m) at the noise model's range.

    ``frame_noise``: a Session's ``noise`` ('camera': rests.FrameNoise.as_dict()); ``floor``: a
    variance.Floor, whose camera components are written at the same reference range (the constant
    and the range-grown one add there).
    """
    sigma = np.sqrt(frame_noise['camera']['variance_at_reference'])
    v = floor.variances
    f = np.sqrt([v.get(f'camera_{a}', 0.0) + v.get(f'camera_{a}_range', 0.0) for a in 'xyz'])
    return sigma, f


def next_session(frame_noise, floor, timing):
    """
    Return the frames per rest a session like a measured one should take, as plain data, or None.

    ``frame_noise``, ``floor``: as for rest_sigmas; ``timing``: rests.rest_timing's pace of the
    measured session. None when one of them is missing or the rests show no floor (more frames
    then always help).
    """
    if frame_noise is None or floor is None or timing is None:
        return None
    sigma, f = rest_sigmas(frame_noise, floor)
    if not np.any(f > 0):
        return None
    frames = frames_per_rest(sigma, f, timing['rest_overhead_s'], timing['camera_rate_hz'])
    return {'frames_per_rest': frames, 'frame_sigma_m': sigma.tolist(), 'floor_m': f.tolist(),
            **timing}


def next_session_text(plan):
    """Return one line for a human about ``next_session``'s plan (mm, s, Hz)."""
    mm = ', '.join(f'{a} {s * 1e3:.3f}/{f * 1e3:.3f}'
                   for a, s, f in zip('xyz', plan['frame_sigma_m'], plan['floor_m']))
    return (f"next session: {plan['frames_per_rest']} frames per rest (protocol.frames_per_rest: "
            f"one frame's noise / the rests' floor {mm} mm, {plan['rest_overhead_s']:.2f} s a "
            f"rest besides its frames, {plan['camera_rate_hz']:.0f} frames per second)")
