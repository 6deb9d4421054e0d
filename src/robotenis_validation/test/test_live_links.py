"""Scoring a recorded session link by link against the truth it ran with."""
import numpy as np
from robotenis_calibration import rests
from robotenis_sim import scenarios, session_bag
from robotenis_sim import truth as sim_truth
from robotenis_validation import live_links
from scipy import stats


def test_a_simulated_bags_rests_meet_the_truth_within_their_noise(tmp_path):
    """The truth's prediction from the readings is what the bag measured, to its frames' noise."""
    effect = scenarios.EFFECTS['backlash']
    bag = session_bag.write(tmp_path / 'bag', session_bag.BagSpec(poses=40, seed=4,
                                                                  effects=effect))
    truth = sim_truth.with_effects(sim_truth.load(), **effect)
    session, _ = rests.load_session(bag.path)
    e = session.sphere - live_links.true_sphere(truth, session.Theta, session.direction)
    chi2 = float(np.einsum('ki,kij,kj->', e, np.linalg.inv(session.sphere_cov), e))
    dof = 3 * len(e)
    assert stats.chi2.ppf(0.005, dof) < chi2 < stats.chi2.ppf(0.995, dof)
