import numpy as np
import pytest

from robotenis_sim.ball import ChaoticBall, FixedBall


def test_fixed_ball_stays():
    ball = FixedBall((0.7, 0.0, 1.35))
    np.testing.assert_array_equal(ball.at(np.array([0.0, 5.0])), [[0.7, 0.0, 1.35]] * 2)


@pytest.mark.parametrize('max_speed', [0.5, 1.5])
def test_chaotic_ball_keeps_its_box_and_top_speed(max_speed):
    ball = ChaoticBall(centre=(1.2, 0.0, 0.95), half_size=(0.15, 0.3, 0.2), max_speed=max_speed,
                       seed=3, duration=20.0)
    t = np.arange(0.0, ball.duration, 1e-3)
    p = ball.at(t)
    assert np.all(np.abs(p - [1.2, 0.0, 0.95]) <= np.array([0.15, 0.3, 0.2]) + 1e-12)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / 1e-3
    # Finite differences of the piecewise-linear path over its whole length: top speed within 1 %.
    assert speed.max() == pytest.approx(max_speed, rel=0.01)
    assert np.mean(speed) > 0.2 * max_speed          # it really moves, all the time


def test_chaotic_ball_is_deterministic_for_a_seed_and_differs_across_seeds():
    a = ChaoticBall((0, 0, 1), (0.1, 0.1, 0.1), 1.0, seed=1, duration=5.0)
    b = ChaoticBall((0, 0, 1), (0.1, 0.1, 0.1), 1.0, seed=1, duration=5.0)
    c = ChaoticBall((0, 0, 1), (0.1, 0.1, 0.1), 1.0, seed=2, duration=5.0)
    t = np.linspace(0, 4, 50)
    np.testing.assert_array_equal(a.at(t), b.at(t))
    assert np.abs(a.at(t) - c.at(t)).max() > 0.01
