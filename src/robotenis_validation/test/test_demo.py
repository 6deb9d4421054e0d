import re
from types import SimpleNamespace

from robotenis_sim import scenarios, session_bag
from robotenis_sim import truth as sim_truth
from robotenis_validation import demo


def test_demo_identifies_within_the_covariance_and_reports_observability(capsys, tmp_path):
    assert demo.main(['--poses', '200', '--seed', '3', '--out', str(tmp_path), '--offline']) == 0
    out = capsys.readouterr().out
    # The Mahalanobis distance of the error of 12 leg parameters is chi2(12): below 26.2 with
    # p = 0.99.
    distance = float(re.search(r'Mahalanobis distance of the error ([0-9.]+)', out).group(1))
    assert distance < 26.2
    assert all(f'enter only as H{i} - h{i}' in out for i in (1, 2, 3))
    assert 'weak (sensitivity < 0.33 of the median): phi1, phi2, phi3' in out
    assert 'effects found: backlash' in out
    assert (tmp_path / 'result.yaml').exists() and (tmp_path / 'residuals.png').exists()


def test_part_3s_answer_is_scored_against_the_truth_it_ran_with(tmp_path):
    """The found backlash brings the held-out rests closer to the truth than the plain model."""
    effect = scenarios.EFFECTS['backlash']
    session_bag.write(tmp_path / 'session-1', session_bag.BagSpec(poses=40, seed=4,
                                                                  effects=effect))
    sim_truth.save(sim_truth.with_effects(sim_truth.load(), **effect), tmp_path / 'truth.yaml')
    lines = demo.against_the_truth(SimpleNamespace(out=str(tmp_path), seed=1))
    found = re.search(r'service did: ([a-z_, ]+)\): held-out RMS error plain ([0-9.]+) mm, '
                      r'final ([0-9.]+) mm', lines[0])
    assert found.group(1) == 'backlash'
    assert float(found.group(3)) < float(found.group(2))
