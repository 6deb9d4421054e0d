import io

import numpy as np
import pytest

from robotenis_kinematics import delta, description, fk_cli


def run(monkeypatch, capsys, args, stdin):
    monkeypatch.setattr('sys.stdin', io.StringIO(stdin))
    code = fk_cli.main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_fk_writes_one_row_per_reading(monkeypatch, capsys, table1, tmp_path):
    path = tmp_path / 'robot.yaml'
    description.save(table1, path)
    Theta = np.array([[0.0, 0.0, 0.0], [0.1, -0.2, 0.3], [0.4, 0.1, -0.1]])
    rows = '\n'.join(','.join(str(float(v)) for v in row) for row in Theta)
    text = '# Theta1,Theta2,Theta3\n' + rows + '\n\n'
    code, out, _ = run(monkeypatch, capsys, ['--model', str(path)], text)
    assert code == 0
    P = np.array([[float(v) for v in line.split(',')] for line in out.splitlines()])
    # 9 decimals printed
    np.testing.assert_allclose(P, delta.forward(table1, table1.theta0 + Theta), atol=1e-9)


@pytest.mark.parametrize('stdin, message', [('0.1,0.2\n', 'line 1: expected three finite numbers'),
                                            ('0,0,0\n0.1,x,0\n', 'line 2: not three numbers'),
                                            ('nan,0,0\n', 'line 1')])
def test_bad_rows_are_named(monkeypatch, capsys, stdin, message):
    model = description.config_path('nominal.yaml')
    code, out, err = run(monkeypatch, capsys, ['--model', model], stdin)
    assert code == 2 and message in err and out == ''


def test_bad_model_is_named(monkeypatch, capsys, tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('legs: []\n')
    code, _, err = run(monkeypatch, capsys, ['--model', str(bad)], '0,0,0\n')
    assert code == 2 and 'bad.yaml: legs' in err
