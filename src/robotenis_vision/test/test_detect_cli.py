"""`detect` on files: one line per good image, in order; bad ones on stderr and a non-zero exit."""
import subprocess
import sys

import cv2
import numpy as np

from robotenis_kinematics import description
from robotenis_vision import camera
import simple_render

R = 0.019                       # m: the paper's ball radius R_B
CENTRES = [np.array([0.02, -0.01, 0.22]), np.array([-0.04, 0.03, 0.3])]
# a millimetre: the lines are the right images, in order, at the right scale (a radius wrong by
# a factor k moves the centre by (k - 1) times its range, 0.2 m and more here)
SAME_MM = 1e-3


def run(args):
    return subprocess.run([sys.executable, '-m', 'robotenis_vision.detect_cli', *args],
                          capture_output=True, text=True, timeout=120)


def positions(stdout):
    return [np.array([float(v) for v in line.split(',')]) for line in stdout.strip().splitlines()]


def write_good(tmp_path):
    """Write the camera file and the CENTRES' images; return the camera, its file, the images."""
    cam = camera.default()
    info = tmp_path / 'camera.yaml'
    camera.save(cam, str(info))
    good = []
    for k, c in enumerate(CENTRES):
        path = tmp_path / f'good{k}.png'
        cv2.imwrite(str(path), simple_render.render(cam, c, R))
        good.append(str(path))
    return cam, str(info), good


def test_good_unreadable_empty_and_blank_images(tmp_path):
    _, info, good = write_good(tmp_path)
    unreadable = tmp_path / 'notes.png'
    unreadable.write_text('not an image')
    empty = tmp_path / 'empty.png'
    empty.write_bytes(b'')
    blank = tmp_path / 'blank.png'
    cv2.imwrite(str(blank), np.full((480, 640), 90, np.uint8))
    result = run(['--camera-info', info, '--radius', str(R),
                  good[0], str(unreadable), str(empty), good[1], str(blank)])
    assert result.returncode == 1
    found = positions(result.stdout)
    assert len(found) == 2
    for xyz, c in zip(found, CENTRES):
        assert np.linalg.norm(xyz - c) < SAME_MM
    for name in ('notes.png', 'empty.png', 'blank.png'):
        assert name in result.stderr
    assert 'no sphere' in result.stderr


def test_colour_16_bit_cut_and_two_balls_are_refused_each_with_its_reason(tmp_path):
    """
    Refuse what cannot be measured, one message per image, and measure the others.

    A grey image saved with three equal channels is mono and measured.
    """
    cam, info, good = write_good(tmp_path)
    mono = simple_render.render(cam, CENTRES[0], R)
    files = {}

    def write(name, image):
        files[name] = str(tmp_path / name)
        cv2.imwrite(files[name], image)

    colour = cv2.merge([mono, mono, mono])
    write('grey3.png', colour)
    colour[..., 2] = np.minimum(colour[..., 2].astype(int) + 30, 255).astype(np.uint8)
    write('colour.png', colour)
    write('deep.png', mono.astype(np.uint16) * 256)
    write('cut.png', simple_render.render(cam, np.array([0.13, 0.0, 0.2]), R))
    write('two.png', np.maximum(simple_render.render(cam, np.array([-0.06, 0.0, 0.25]), R),
                                simple_render.render(cam, np.array([0.06, 0.02, 0.3]), R)))
    order = ['grey3.png', 'colour.png', 'deep.png', 'cut.png', 'two.png']
    result = run(['--camera-info', info, '--radius', str(R), good[1]]
                 + [files[n] for n in order])
    assert result.returncode == 1
    found = positions(result.stdout)
    assert len(found) == 2
    assert np.linalg.norm(found[0] - CENTRES[1]) < SAME_MM
    assert np.linalg.norm(found[1] - CENTRES[0]) < SAME_MM
    messages = dict(line.split(': ', 1) for line in result.stderr.strip().splitlines())
    assert 'colour' in messages[files['colour.png']]
    assert '16-bit' in messages[files['deep.png']]
    assert 'border' in messages[files['cut.png']]
    assert 'two balls' in messages[files['two.png']]
    assert files['grey3.png'] not in messages


def test_radius_from_option_description_or_nominal(tmp_path):
    """
    Read the ball's size from --radius, --description or the nominal description.

    An image fixes the ball's direction and its angular size, so a radius k times R reads every
    centre k times as far.
    """
    _, info, good = write_good(tmp_path)
    doubled = tmp_path / 'robot.yaml'
    nominal = description.nominal()
    assert nominal.sphere_radius == R
    text = description.dumps(nominal).replace(f'sphere_radius: {R}', f'sphere_radius: {2 * R}')
    doubled.write_text(text)
    assert description.load(str(doubled)).sphere_radius == 2 * R
    for extra, scale in (([], 1.0), (['--radius', str(R / 2)], 0.5),
                         (['--description', str(doubled)], 2.0)):
        result = run(['--camera-info', info, *extra, *good])
        assert result.returncode == 0, result.stderr
        for xyz, c in zip(positions(result.stdout), CENTRES):
            assert np.linalg.norm(xyz - scale * c) < scale * SAME_MM
    result = run(['--camera-info', info, '--description', str(tmp_path / 'none.yaml'), good[0]])
    assert result.returncode == 2 and 'cannot read' in result.stderr
    result = run(['--camera-info', info, '--radius', '-1', good[0]])
    assert result.returncode == 2 and 'positive' in result.stderr


def test_missing_camera_info_is_an_error(tmp_path):
    result = run(['--camera-info', str(tmp_path / 'none.yaml'), str(tmp_path / 'x.png')])
    assert result.returncode == 2 and 'cannot read' in result.stderr
