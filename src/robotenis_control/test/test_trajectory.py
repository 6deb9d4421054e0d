"""4-5-6-7 trajectories: boundary conditions, limits, continuity of chains."""
import numpy as np
import pytest

from robotenis_control import trajectory as tr


def test_polynomial_boundary_conditions():
    s = tr.s_derivatives(np.array([0.0, 1.0]))
    np.testing.assert_allclose([v[0] for v in s], [0, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose([v[1] for v in s], [1, 0, 0, 0], atol=1e-12)


def test_derivatives_are_derivatives():
    u = np.linspace(0.01, 0.99, 50)
    h = 1e-6
    for k in range(3):
        numeric = (tr.s_derivatives(u + h)[k] - tr.s_derivatives(u - h)[k]) / (2 * h)
        np.testing.assert_allclose(numeric, tr.s_derivatives(u)[k + 1], atol=1e-5)


def test_peaks_of_speed_and_acceleration():
    u = np.linspace(0, 1, 200001)
    _, s1, s2, _ = tr.s_derivatives(u)
    assert s1.max() == pytest.approx(tr.S1_PEAK, rel=1e-9)
    assert np.abs(s2).max() == pytest.approx(tr.S2_PEAK, rel=1e-8)


@pytest.mark.parametrize('distance, v_max, a_max',
                         [(0.2828, 2.0, 4 * 9.81), (0.4, 4.0, 98.1), (0.01, 4.0, 98.1)])
def test_segment_respects_the_limits_and_reaches_one(distance, v_max, a_max):
    seg = tr.segment([0, 0, 0.75], [distance, 0, 0.75], 0.0, v_max, a_max)
    t = np.linspace(0, seg.T, 20001)
    P, V, A, _ = seg.sample(t)
    speed, acc = np.linalg.norm(V, axis=1).max(), np.linalg.norm(A, axis=1).max()
    assert speed <= v_max * (1 + 1e-9) and acc <= a_max * (1 + 1e-6)
    assert max(speed / v_max, acc / a_max) == pytest.approx(1.0, rel=1e-6)  # the fastest that fits
    np.testing.assert_allclose(P[-1], [distance, 0, 0.75], atol=1e-12)


def test_chain_is_continuous_and_rests_at_waypoints():
    points = np.array([[0, 0, 0.75], [-0.2, 0.2, 0.75], [0.1, 0.1, 0.9], [0.0, -0.2, 0.7]])
    chain = tr.Chain(points, 4.0, 98.1, t0=1.0)
    ends = [s.t1 for s in chain.segments]
    for k, t in enumerate(ends):
        P, V, A, _ = chain.sample([t - 1e-9, t + 1e-9])
        np.testing.assert_allclose(P, [points[k + 1]] * 2, atol=1e-9)
        np.testing.assert_allclose(V, 0, atol=1e-6)
        np.testing.assert_allclose(A, 0, atol=1e-3)
    P, *_ = chain.sample([0.0, chain.t1 + 1])
    np.testing.assert_allclose(P, points[[0, -1]])


def test_bad_inputs_are_named():
    with pytest.raises(ValueError, match='waypoints'):
        tr.Chain(np.zeros((1, 3)), 1.0, 1.0)
    with pytest.raises(ValueError, match='positive'):
        tr.duration(0.1, 0.0, 1.0)


def test_one_time_in_floats_is_the_array_sample():
    """Segment.at (the controller's tick) gives sample's values exactly, before, in and after."""
    seg = tr.segment([0.0, 0.01, 0.75], [-0.2, 0.2, 0.8], 0.1, 2.0, 4 * 9.81)
    for t in np.linspace(0.0, seg.t1 + 0.1, 2001):
        for got, want in zip(seg.at(float(t)), seg.sample(float(t))[:3]):
            np.testing.assert_array_equal(got, want)
    still = tr.Segment(np.array([0.1, 0.0, 0.7]), np.array([0.1, 0.0, 0.7]), 0.0, 0.0)
    for got, want in zip(still.at(0.5), still.sample(0.5)[:3]):
        np.testing.assert_array_equal(got, want)
