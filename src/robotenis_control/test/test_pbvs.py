import numpy as np
import pytest
from robotenis_control import pbvs
from robotenis_kinematics import delta, description
from robotenis_kinematics import effects as fx
from scipy import stats

R_CAM = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # looking along base +x


def test_error_is_zero_when_the_ball_is_where_it_should_be():
    np.testing.assert_allclose(pbvs.relative_error(pbvs.S_DESIRED, R_CAM), 0.0)
    # Ball 10 cm too far along the optical axis (base +x): the robot is 10 cm behind, e_r = -0.1 x.
    np.testing.assert_allclose(pbvs.relative_error(pbvs.S_DESIRED + [0, 0, 0.1], R_CAM),
                               [-0.1, 0, 0])


def test_closed_loop_converges_at_the_gain_and_tracks_a_steady_ball():
    """Ideal kinematics, e' = -K_p e + (v_p - v_ball): for v_p = v_ball e decays as exp(-K_p t)."""
    dt, v_ball = 1e-3, np.array([0.5, -0.2, 0.1])
    ball, robot = np.array([1.2, 0.0, 1.0]), np.array([0.5, 0.1, 0.9])
    e0 = None
    for k in range(300):
        s = R_CAM.T @ (ball - robot)            # the camera at the effector centre, for the test
        e = pbvs.relative_error(s, R_CAM)
        e0 = e if e0 is None else e0
        robot = robot + dt * pbvs.cartesian_command(e, v_ball)
        ball = ball + dt * v_ball
    s = R_CAM.T @ (ball - robot)
    # After 0.3 s the error is e0 (1 - K_p dt)^300 (explicit Euler of the exponential decay).
    np.testing.assert_allclose(pbvs.relative_error(s, R_CAM), e0 * (1 - pbvs.K_P * dt) ** 300,
                               atol=1e-12)


def test_kalman_velocity_is_consistent_with_its_covariance():
    """NEES of the velocity estimate over 200 runs follows chi2(3) on average (two-sided 1 %)."""
    rng = np.random.default_rng(0)
    sigma, dt, q, runs = 0.5e-3, 1 / 120, 20.0, 200
    # The process noise of continuous white acceleration over one step (the filter's own model).
    Q = q * np.block([[dt ** 3 / 3 * np.eye(3), dt ** 2 / 2 * np.eye(3)],
                      [dt ** 2 / 2 * np.eye(3), dt * np.eye(3)]])
    nees = 0.0
    for _ in range(runs):
        f = pbvs.BallKalman(q)
        p, v = np.zeros(3), rng.normal(scale=1.0, size=3)
        for k in range(60):
            if k:
                f.predict(dt)
                w = rng.multivariate_normal(np.zeros(6), Q)
                p, v = p + v * dt + w[:3], v + w[3:]
            f.update(p + rng.normal(scale=sigma, size=3), sigma ** 2 * np.eye(3))
        e = f.velocity - v
        nees += e @ np.linalg.solve(f.P[3:, 3:], e)
    n = 3 * runs
    assert stats.chi2.ppf(0.005, n) < nees < stats.chi2.ppf(0.995, n)


def test_joint_command_uses_the_inverse_jacobian():
    J_inv = np.diag([2.0, 3.0, 4.0])
    np.testing.assert_allclose(pbvs.joint_command(J_inv, [1.0, 1.0, 1.0]), [2.0, 3.0, 4.0])


# ----------------------------------------------------------------------------------------------
# Tracker: the filter, eq. 23 and the clipping for one robot, fed detections.

FRAME = 1.0 / 120.0
# m: the robot at rest in the middle of the tracking region
P_ROBOT = np.array([0.0, 0.0, 0.95])


def seen(desc, ball, P):
    """Return s = R^T (ball - P): what the description's camera at the effector sees, no offset."""
    return desc.camera_rotation.T @ (np.asarray(ball) - P)


def readings(desc, P):
    return delta.inverse(desc, P) - desc.theta0


def ball_path(desc, v, P=P_ROBOT):
    """Return p(t) of a ball flying at v (m/s, base frame) from the reference of a robot at P."""
    return lambda t: P + desc.camera_rotation @ pbvs.S_DESIRED + v * t


def fly(tracker, ball, times, P=P_ROBOT):
    """Detect ``ball`` at ``times`` from a still robot at P; return the tracker's last output."""
    for t in times:
        out = tracker.update(t, seen(tracker.desc, ball(t), P), readings(tracker.desc, P))
    return out


def test_tracker_on_a_still_ball_commands_minus_kp_times_the_error():
    desc = description.nominal()
    s = pbvs.S_DESIRED + [0.01, -0.02, 0.03]
    u_r, e_r = pbvs.Tracker(desc).update(1.0, s, readings(desc, P_ROBOT))
    np.testing.assert_allclose(e_r, pbvs.relative_error(s, desc.camera_rotation), atol=1e-15)
    np.testing.assert_allclose(u_r, -pbvs.K_P * e_r, atol=1e-15)


def test_tracker_feeds_the_balls_velocity_forward_or_not():
    """
    Check that the tracker feeds the ball's velocity forward, or not.

    Noise-free positions of a constant-velocity ball: within 60 frames the filter's v_p is v to
    1e-9 (its error decays geometrically); without feedforward the command is the proportional
    term only. (max_speed high: the ball drifts 0.19 m, K_p e_r is 3 m/s.)
    """
    desc, v = description.nominal(), np.array([0.3, -0.2, 0.1])
    u_r, e_r = fly(pbvs.Tracker(desc, max_speed=10.0), ball_path(desc, v), FRAME * np.arange(60))
    np.testing.assert_allclose(u_r, -pbvs.K_P * e_r + v, atol=1e-9)
    u_r, e_r = fly(pbvs.Tracker(desc, max_speed=10.0, feedforward=False), ball_path(desc, v),
                   FRAME * np.arange(60))
    np.testing.assert_allclose(u_r, -pbvs.K_P * e_r, atol=1e-15)


def test_tracker_filters_the_ball_in_the_base_frame():
    """
    Check that the tracker filters the ball in the base frame.

    The robot moves, the ball stays: s changes but P_est + R s does not, so v_p stays 0 (a filter
    on s alone would see the ball move at minus the robot's speed).
    """
    desc = description.nominal()
    ball = P_ROBOT + desc.camera_rotation @ pbvs.S_DESIRED
    tracker = pbvs.Tracker(desc, max_speed=10.0)
    for k in range(30):
        P = P_ROBOT + np.array([0.0, 0.5, -0.3]) * k * FRAME
        u_r, e_r = tracker.update(k * FRAME, seen(desc, ball, P), readings(desc, P))
    np.testing.assert_allclose(u_r, -pbvs.K_P * e_r, atol=1e-9)
    assert np.linalg.norm(e_r) > 0.05           # the robot did move away from the reference


def test_tracker_places_the_ball_with_the_calibrated_joint_effects():
    """
    Check that the tracker places the ball with the calibrated joint effects.

    A calibrated description with a gear scale and a backlash: the robot moves, the ball stays.
    Through the effects (readings from effects.increments_for, their inverse) P_est + R s stays
    put, v_p = 0; the same readings taken as plain theta0 + Theta make the still ball seem to move
    at about k times the robot's speed.
    """
    effects = [{'name': 'joint_scale', 'scale': [5e-3, -4e-3, 4e-3]},
               {'name': 'backlash', 'width': [1e-3, 6e-4, 8e-4]}]
    desc = description.nominal().copy(effects=effects)
    ball = P_ROBOT + desc.camera_rotation @ pbvs.S_DESIRED
    with_effects, plain = (pbvs.Tracker(desc, max_speed=10.0),
                           pbvs.Tracker(description.nominal(), max_speed=10.0))
    velocity = np.array([0.0, 0.5, -0.3])
    for k in range(30):
        P = P_ROBOT + velocity * k * FRAME
        theta = delta.inverse(desc, P)
        Theta = fx.increments_for(desc, theta,
                                  np.sign(theta - delta.inverse(desc, P - velocity * FRAME)), P)
        outputs = [t.update(k * FRAME, seen(desc, ball, P), Theta) for t in (with_effects, plain)]
    (u_r, e_r), (u_plain, e_plain) = outputs
    np.testing.assert_allclose(u_r, -pbvs.K_P * e_r, atol=1e-9)
    assert np.linalg.norm(u_plain + pbvs.K_P * e_plain) > 1e-3   # 4e-3 of 0.58 m/s, at least


def test_tracker_restarts_its_filter_after_losing_the_ball():
    """
    Check that the tracker restarts its filter after losing the ball.

    The ball flies on out of sight: after a gap longer than lost_after the velocity is forgotten
    (v_p = 0 on the next detection); after a shorter one the filter predicts across the gap, and
    on a constant-velocity ball it lands exactly on the detection (v_p = v).
    """
    desc, v = description.nominal(), np.array([0.3, -0.2, 0.1])
    for gap, v_expected in ((pbvs.LOST_S + 0.01, np.zeros(3)), (pbvs.LOST_S - 0.01, v)):
        times = FRAME * np.arange(60)
        u_r, e_r = fly(pbvs.Tracker(desc, max_speed=10.0), ball_path(desc, v),
                       [*times, times[-1] + gap])
        np.testing.assert_allclose(u_r + pbvs.K_P * e_r, v_expected, atol=1e-9)


def test_tracker_clips_the_command_and_ignores_repeats():
    desc = description.nominal()
    tracker = pbvs.Tracker(desc, max_speed=1.0)
    # a metre too far: 16.8 m/s asked
    u_r, e_r = tracker.update(1.0, [0.0, 0.0, 1.6], readings(desc, P_ROBOT))
    assert np.linalg.norm(u_r) == pytest.approx(1.0)
    np.testing.assert_allclose(u_r / np.linalg.norm(u_r), -e_r / np.linalg.norm(e_r), atol=1e-15)
    x = tracker.kalman.x.copy()
    assert tracker.update(1.0, pbvs.S_DESIRED, readings(desc, P_ROBOT)) is None  # a repeat
    # out of order
    assert tracker.update(1.0 - FRAME, pbvs.S_DESIRED, readings(desc, P_ROBOT)) is None
    np.testing.assert_array_equal(tracker.kalman.x, x)


def test_the_matcher_pairs_a_detection_with_the_reading_of_its_exposure():
    matcher = pbvs.ReadingMatcher(match_s=0.02)
    for k in range(5):
        assert matcher.reading(1.0 + 1e-3 * k, np.full(3, k)) == []
    (t, s, key, Theta), = matcher.detection(1.002, 'ball', 'stamp')
    assert (t, s, key) == (1.002, 'ball', 'stamp') and Theta[0] == 2
    assert matcher.detection(1.006, 'later', None) == []         # its reading is on the way
    assert matcher.reading(1.005, np.full(3, 5)) == []
    (_, s, _, Theta), = matcher.reading(1.006, np.full(3, 6))
    assert s == 'later' and Theta[0] == 6
    (_, _, _, Theta), = matcher.detection(0.9, 'old', None)      # nothing within 20 ms of it
    assert Theta is None
    matcher.detection(2.0, 'waiting', None)
    matcher.clear()
    assert matcher.reading(2.0, np.zeros(3)) == []
