"""
System test: the ROS tracking chain keeps a chaotic ball centred 600 mm ahead (section 6.2.2).

sim_motors, hand_camera (the ball at up to 1.5 m/s, Table 5's fastest), sphere_detector,
motion_controller and pbvs_tracker run as processes on simulated time, the simulator in lockstep
with the controller and with the visual loop (robotenis_validation.live_tracking). 3 s of tracking
are scored against the truth, then the tracker is switched off.

Why the bound. Without the velocity feedforward v_p, eq. 23 is a first-order loop of gain K_p: on a
ball moving at v it lags by v / K_p whatever the frame delay (the ramp error of a type-1 loop), so
its mean true error is about v_mean / K_p (measured through ROS: 22.8 mm against 23.2 mm at a mean
0.39 m/s). v_p cancels that first-order lag; what is left is the ball's acceleration over the
loop's delays (about 1 mm in the offline study without camera noise), and what the detector does:

- its bias b (s - s_true, measured in the same run): the robot centres the MEASURED ball, so b goes
  into the true error one to one (about 1.6-2 mm in depth at 600 mm);
- its noise sigma (measured likewise), which the loop passes to the robot: the RMS true error it
  causes on a still ball is tlinear.noise_response's, with the filter assuming Table 2's
  noise as the node does (RMS >= mean, so this over-counts).

The test asserts mean true error < |b| + noise RMS + v_mean / (4 K_p): the feedforward must remove
at least three quarters of the first-order lag (the offline study: about 95 %). Switched off, the
robot stops and the ball gets away: the mean error then exceeds the whole lag v_mean / K_p.
"""
import os
import random

import numpy as np
import pytest
from robotenis_control import pbvs
from robotenis_kinematics import description
from robotenis_validation import live_tracking
from robotenis_validation import tracking_linear as tlinear
from robotenis_validation import tracking_setup as tsetup

TOP = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SPEED = 1.5              # m/s: the ball's top speed
TRACKING_S = 3.0         # s (simulated) scored while tracking: 360 frames
# s after the last command: the controller follows it for its 0.1 s timeout, then the robot stops
# from up to 1 m/s and settles (0.15 s measured)
STOP_S = 0.3
OFF_S = 1.0              # s scored with the tracker off
HOLD_MM = 1.0            # the joint loop holds the effector within a few resolver counts (0.2 mm)
IMAGE_HALF_HEIGHT = 0.48 * 0.6   # m at 600 mm: 240 px at f = 500 px


@pytest.fixture(scope='module')
def runs():
    for pkg, exe in (('robotenis_sim', 'sim_motors'), ('robotenis_control', 'pbvs_tracker')):
        if not os.path.exists(os.path.join(TOP, 'install', pkg, 'lib', pkg, exe)):
            pytest.skip(f'{exe} is not installed (./robotenis setup)')
    with live_tracking.LiveTracking(SPEED, top=TOP, domain_id=random.randint(1, 200)) as live:
        live.acquire()
        on = live.measure(TRACKING_S, 'tracking')
        live.set_tracker(enabled=False)
        assert live.probe.commands, (f'the tracker sent no command in {TRACKING_S} s of tracking '
                                     f'({100 * on.detected:.1f} % of the frames detected)')
        live.spin_until(lambda: live.probe.now >= live.probe.commands[-1][0] + STOP_S, 'stopping')
        off = live.measure(OFF_S, 'tracker off')
        effector = np.array([P for ns, P in sorted(live.probe.effector.items())
                             if off.t0 <= ns * 1e-9 < off.t1])
        frames = [t for t, _ in live.probe.balls]
    return on, off, effector, frames


def test_the_ball_stays_in_the_image_and_detected(runs):
    on, _, _, _ = runs
    assert on.frames >= 0.9 * TRACKING_S * 120.0, (
        f'frames missing: {on.frames} ball truths in {TRACKING_S} s, against 120 a second')
    assert on.detected > 0.95, f'only {100 * on.detected:.1f} % of the frames detected'
    assert np.max(on.true) < IMAGE_HALF_HEIGHT / 3


def test_the_feedforward_removes_most_of_the_lag(runs):
    on, _, _, _ = runs
    lag = np.mean(on.ball_speed) / pbvs.K_P
    bias = np.linalg.norm(np.mean(on.detector, axis=0))
    setup = tsetup.Setup(sigma_camera=tuple(np.std(on.detector, axis=0)),
                         filter_sigma=pbvs.SIGMA_CAMERA)
    noise_ms, _ = tlinear.noise_response(setup, description.nominal().camera_rotation,
                                         len(on.true))
    bound = bias + np.sqrt(noise_ms) + lag / 4
    assert np.mean(on.true) < bound, (
        f'mean true error {1e3 * np.mean(on.true):.2f} mm >= {1e3 * bound:.2f} mm '
        f'(bias {1e3 * bias:.2f}, noise RMS {1e3 * np.sqrt(noise_ms):.2f}, '
        f'lag / 4 {1e3 * lag / 4:.2f} mm)')


def test_without_the_tracker_the_robot_stops_and_the_ball_gets_away(runs):
    _, off, effector, frames = runs
    assert 1e3 * np.max(np.linalg.norm(effector - effector[0], axis=1)) < HOLD_MM
    assert len(off.true), (
        f'none of the {off.frames} frames in {off.t0:.3f}-{off.t1:.3f} s scored: the probe has '
        f'{len(effector)} truth samples in it, and {len(frames)} frames in all '
        f"(the last at {frames[-1] if frames else float('nan'):.3f} s)")
    assert np.mean(off.true) > np.mean(off.ball_speed) / pbvs.K_P
