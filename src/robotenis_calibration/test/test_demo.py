import re

from robotenis_calibration import demo


def test_demo_identifies_within_the_covariance_and_reports_observability(capsys):
    assert demo.main(['--poses', '120', '--seed', '3']) == 0
    out = capsys.readouterr().out
    # The Mahalanobis distance of the error is chi2(15): below 30.6 with probability 0.99.
    distance = float(re.search(r'Mahalanobis distance of the error: ([0-9.]+)', out).group(1))
    assert distance < 30.6
    assert all(f'enter only as H{i} - h{i}' in out for i in (1, 2, 3))
    assert 'weak (sensitivity < 0.33 of the median): phi1, phi2, phi3' in out
    assert 'a1' in out and 'Table 1' in out
