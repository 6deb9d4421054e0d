import numpy as np

from robotenis_kinematics import delta
from robotenis_validation import jacobian_study


def test_same_parameters_give_zero(nominal):
    assert jacobian_study.volume_max(nominal, nominal, n=5)[0] < 1e-12


def test_matches_the_definition_at_one_point(nominal, table1):
    P = np.array([0.1, -0.05, 0.9])
    J = delta.jacobian(table1, P)
    D = J @ (np.linalg.inv(delta.jacobian(nominal, P)) - np.linalg.inv(J))
    sigma_max = jacobian_study.largest_singular_value(table1, nominal, P)
    assert np.isclose(sigma_max, np.linalg.norm(D, 2), rtol=1e-9)


def test_first_order_in_the_parameter_error(nominal, table1):
    """Halving every parameter difference halves sigma_max (to first order)."""
    half = nominal.copy(**{k: (getattr(nominal, k) + getattr(table1, k)) / 2
                           for k in ('a', 'b', 'h', 'theta0')})
    full = jacobian_study.volume_max(table1, nominal, n=7)[0]
    assert abs(jacobian_study.volume_max(half, nominal, n=7)[0] / full - 0.5) < 0.05
