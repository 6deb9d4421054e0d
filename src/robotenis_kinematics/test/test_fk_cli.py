import io
import re

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


def test_a_row_without_forward_kinematics_is_named_and_the_others_printed(monkeypatch, capsys):
    model = description.config_path('nominal.yaml')
    stdin = '0,0,0\n\n0.8,-1.4,-2.8\n0.1,0.1,0.1\n'    # the third: the forearms cannot close
    code, out, err = run(monkeypatch, capsys, ['--model', model], stdin)
    rows = out.splitlines()
    assert code == 1 and 'line(s) 3' in err and len(rows) == 3 and rows[1] == 'nan,nan,nan'
    nominal = description.nominal()
    np.testing.assert_allclose([float(v) for v in rows[2].split(',')],
                               delta.forward(nominal, np.full(3, 0.1)), atol=1e-9)


@pytest.mark.parametrize('effects, key', [
    ([{'name': 'gravity_compliance', 'compliance': [1e-4, 1e-4, 1e-4],
       'gravity_load': {'arm': float('nan'), 'platform': 3.0}}], 'gravity_load.arm'),
    ([{'name': 'backlash', 'width': [1e-3, 1e-3, 1e-3]},
      {'name': 'backlash', 'width': [2e-3, 2e-3, 2e-3]}], 'effects.1..name: backlash is listed'),
])
def test_a_model_with_a_bad_effect_is_refused(monkeypatch, capsys, tmp_path, effects, key):
    path = tmp_path / 'model.yaml'
    description.save(description.nominal().copy(effects=effects), path)
    code, out, err = run(monkeypatch, capsys, ['--model', str(path)], '0,0,0\n')
    assert code == 2 and out == '' and re.search(key, err), err
