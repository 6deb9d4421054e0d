"""`detect` on files: one line per good image, in order; bad ones on stderr and a non-zero exit."""
import subprocess
import sys

import cv2
import numpy as np

from robotenis_vision import camera
import simple_render

R = 0.019                       # m: the paper's ball radius R_B
CENTRES = [np.array([0.02, -0.01, 0.22]), np.array([-0.04, 0.03, 0.3])]


def run(args):
    return subprocess.run([sys.executable, '-m', 'robotenis_vision.detect_cli', *args],
                          capture_output=True, text=True, timeout=120)


def test_good_unreadable_empty_and_blank_images(tmp_path):
    cam = camera.default()
    info = tmp_path / 'camera.yaml'
    camera.save(cam, str(info))
    good = []
    for k, c in enumerate(CENTRES):
        path = tmp_path / f'good{k}.png'
        cv2.imwrite(str(path), simple_render.render(cam, c, R))
        good.append(str(path))
    unreadable = tmp_path / 'notes.png'
    unreadable.write_text('not an image')
    empty = tmp_path / 'empty.png'
    empty.write_bytes(b'')
    blank = tmp_path / 'blank.png'
    cv2.imwrite(str(blank), np.full((480, 640), 90, np.uint8))
    result = run(['--camera-info', str(info), '--radius', str(R),
                  good[0], str(unreadable), str(empty), good[1], str(blank)])
    assert result.returncode == 1
    lines = result.stdout.strip().splitlines()
    assert len(lines) == 2
    for line, c in zip(lines, CENTRES):
        xyz = np.array([float(v) for v in line.split(',')])
        # a millimetre: the lines are the right images, in order
        assert np.linalg.norm(xyz - c) < 1e-3
    for name in ('notes.png', 'empty.png', 'blank.png'):
        assert name in result.stderr
    assert 'no sphere' in result.stderr


def test_missing_camera_info_is_an_error(tmp_path):
    result = run(['--camera-info', str(tmp_path / 'none.yaml'), str(tmp_path / 'x.png')])
    assert result.returncode == 2 and 'cannot read' in result.stderr
