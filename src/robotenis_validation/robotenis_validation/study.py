"""A static session on the simulated robot and its residual-loop diagnosis, for the studies."""
import numpy as np
from robotenis_calibration import diagnosis, poses
from robotenis_calibration.session import Session
from robotenis_kinematics import synthetic
from robotenis_sim import static_session
from robotenis_sim.scenarios import BALL_GUESS_ERROR


def static_run(truth, declared, n, seed, selection='boundary'):
    """
    Run a static session of ``n`` planned poses on ``truth`` and the residual loop on it.

    Returns (session, measurements, diagnosis). The planner knows only the declared description
    and a guess of the ball position that is off by scenarios.BALL_GUESS_ERROR.
    """
    rng = np.random.default_rng(seed)
    P = poses.select(selection, declared, truth.sphere_position + BALL_GUESS_ERROR, n, rng)
    Theta, sigma, sphere, cov, _ = static_session.run(truth, declared, P, synthetic.NoiseModel(),
                                                      rng)
    s = Session(declared, Theta, sigma, sphere, cov, 8.0 * np.arange(len(Theta)))
    meas = s.measurements()
    return s, meas, diagnosis.run(declared, meas, s.sphere, s.stamps, seed=seed)
