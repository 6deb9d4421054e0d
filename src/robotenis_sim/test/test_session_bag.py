"""The simulated session's plan: random boundary poses, or a planner's targets."""
import numpy as np
from robotenis_kinematics import delta, description, workspace
from robotenis_sim import session_bag


def test_a_planners_targets_are_visited_in_order_and_unseen_ones_skipped():
    nominal = description.nominal()
    targets = workspace.boundary_poses(nominal, 200, np.random.default_rng(1))
    spec = session_bag.BagSpec(poses=len(targets), targets=tuple(map(tuple, targets)))
    declared, Theta, sphere, P_true = session_bag.plan(spec)
    every = delta.inverse(declared, targets) - declared.theta0
    index = [int(np.argmin(np.linalg.norm(every - th, axis=1))) for th in Theta]
    np.testing.assert_allclose(Theta, every[index], atol=1e-12)
    # in the planner's order, each once; random boundary poses are often out of the camera's view
    assert np.all(np.diff(index) > 0) and 0 < len(Theta) < len(targets)
