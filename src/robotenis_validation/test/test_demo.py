import re

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
