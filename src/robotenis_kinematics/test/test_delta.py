import numpy as np
import pytest
from robotenis_kinematics import delta, workspace
from scipy import stats


@pytest.fixture
def poses(nominal):
    return workspace.sample(nominal, 2000, np.random.default_rng(7))


def test_a_where_test_draws_from_the_workspace_part_it_selects(nominal):
    """
    Drawing with ``where`` is drawing from the workspace and keeping what ``where`` selects.

    A two-sample Kolmogorov-Smirnov test per coordinate at 0.1 % (Bonferroni over the three);
    a region that holds nothing returns an empty draw after ``max_batches`` rounds.
    """
    def off_centre(P):
        return P[:, 0] > 0.1
    inside = workspace.sample(nominal, 1500, np.random.default_rng(5), where=off_centre)
    assert np.all(off_centre(inside)) and np.all(workspace.Workspace().contains(nominal, inside))
    kept = workspace.sample(nominal, 8000, np.random.default_rng(6))
    kept = kept[off_centre(kept)]
    for j in range(3):
        assert stats.ks_2samp(inside[:, j], kept[:, j]).pvalue > 0.001 / 3
    nothing = workspace.sample(nominal, 10, np.random.default_rng(5), max_batches=3,
                               where=lambda P: P[:, 2] < 0)
    assert nothing.shape == (0, 3)


def test_fk_inverts_ik_over_the_workspace(nominal, table1, poses):
    for desc in (nominal, table1):
        P = poses[workspace.Workspace().contains(desc, poses)]
        assert len(P) > 1000
        err = np.abs(delta.forward(desc, delta.inverse(desc, P)) - P).max()
        assert err < 1e-12


def test_ik_satisfies_the_loop_closure_and_keeps_elbows_out(nominal, poses):
    theta = delta.inverse(nominal, poses)
    assert np.abs(delta.constraint(nominal, poses, theta)).max() < 1e-12
    # Elbow out: B_i farther from the z axis than the motor axis A_i.
    B = delta.elbow_points(nominal, theta)
    assert np.all(np.hypot(B[..., 0], B[..., 1]) > nominal.H)


def test_home_is_below_the_base(nominal):
    P = delta.forward(nominal, np.zeros(3))
    np.testing.assert_allclose(P[:2], 0, atol=1e-15)
    assert 0.7 < P[2] < 0.8


def test_unreachable_position_is_refused(nominal):
    with pytest.raises(ValueError, match='out of reach'):
        delta.inverse(nominal, [0.0, 0.0, 2.0])


def test_jacobian_matches_finite_differences(table1, poses):
    P = poses[:50]
    theta = delta.inverse(table1, P)
    J = delta.jacobian(table1, P, theta)
    eps = 1e-6
    Jn = np.empty_like(J)
    for j in range(3):
        dt = np.zeros(3)
        dt[j] = eps
        Jn[:, :, j] = ((delta.forward(table1, theta + dt) - delta.forward(table1, theta - dt))
                       / (2 * eps))
    # Central differences: truncation ~ eps^2 |d3P|, rounding ~ 1e-16 / eps.
    assert np.abs(J - Jn).max() < 1e-8
    np.testing.assert_allclose(delta.inverse_jacobian(table1, P, theta) @ J,
                               np.broadcast_to(np.eye(3), J.shape), atol=1e-10)


def test_singularity_distance_is_metric(nominal):
    # Put C_1 on the line of leg 1's arm, at a + b - s from A_1: the leg is s short of stretched,
    # and its margin must be exactly s.
    theta1 = 0.6
    B = np.array([nominal.H[0] + nominal.a[0] * np.cos(theta1), 0.0,
                  nominal.a[0] * np.sin(theta1)])
    direction = np.array([np.cos(theta1), 0.0, np.sin(theta1)])
    for s in (0.0, 0.02, 0.05):
        C = B + (nominal.b[0] - s) * direction  # inside: leg 1 folded back by s along the line
        P = C - nominal.h[0] * np.array([1.0, 0.0, 0.0])
        assert abs(delta.leg_singularity_margins(nominal, P)[0] - s) < 1e-12


def test_boundary_poses_lie_in_the_band(nominal):
    P = workspace.boundary_poses(nominal, 200, np.random.default_rng(3))
    s = delta.singularity_distance(nominal, P)
    assert len(P) == 200 and s.min() >= 0.05 and s.max() <= 0.10
