"""
Study: where the model fit's depth bias comes from (issue 13), one effect taken out at a time.

The benchmark's scene list (benchmarks/vision.py: ``SCENES`` scenes of seed ``SEED``) rendered
without sensor noise by the project's renderer, so that a scene's error is its bias, and again
with one effect taken out:

- *light on axis*: the light's direction moved onto the ray from the ball to the camera, so that no
  terminator crosses the limb (a light from the front but off that ray leaves one side of the limb
  in shadow: the shading is cut, max(0, n . l), where the model fit assumes it smooth);
- *disc -> Gaussian*: the thin lens's defocus disc replaced by a Gaussian of the same variance
  (sigma = radius / 2), the blur the model fit assumes;
- *no highlight*: a glossy ball's specular lobe taken out.

Printed per variant: the model fit's depth error RMS (% of range) over groups of scenes by the
light's angle to the line of sight and by the defocus radius, over the scenes it read within
MISREAD_PERCENT (beyond, a fit in another minimum: a misread, not a bias), with the misread and
the failed scenes counted. Then the same for Mitsuba (``--mitsuba N``: the first N point-lit
scenes lit from the front, rendered at MITSUBA_SPP samples per pixel without sensor noise, about 4
s each): as drawn, and with the lamp moved onto the ray from the ball to the camera, at least
twice as far as the camera (a lamp nearer than the camera lights less than the limb: its
terminator then runs all around inside the outline).

Usage: ./robotenis bench vision_bias [--mitsuba N] [--seed N --scenes K] (another list, as
``bench vision --seed``)
"""
import argparse
import copy
import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import sys  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import mitsuba_scenes as ms  # noqa: E402
import numpy as np  # noqa: E402
from robotenis_sim import camera_model as cm  # noqa: E402
import vision  # noqa: E402

ANGLES = ((0, 10), (10, 40), (40, 80), (80, 180))    # deg: the light to the line of sight
DEFOCUS = ((0.0, 0.01), (0.01, 1.0), (1.0, 3.0))      # px: the defocus disc's radius
MITSUBA_SPP = 256
MISREAD_PERCENT = 2.0
SEED_RENDER = 5


def light_angle(c, kw):
    """
    Return the angle (deg) between a scene's light and the ray from its ball c to the camera.

    ``c, kw``: the scene as vision.project_scene gives it.
    """
    return float(np.degrees(np.arccos(np.clip(np.dot(kw['lighting'].direction,
                                                     -c / np.linalg.norm(c)), -1, 1))))


def variants(c, kw):
    """Return cm.render's arguments for each variant of a scene (project renderer, no noise)."""
    L, plain = kw['lighting'], dict(kw, noise_sigma=0.0)
    on_axis = cm.Lighting(direction=tuple(-c / np.linalg.norm(c)), ambient=L.ambient,
                          diffuse=L.diffuse, specular=L.specular, shininess=L.shininess)
    matte = cm.Lighting(direction=L.direction, ambient=L.ambient, diffuse=L.diffuse,
                        specular=0.0, shininess=L.shininess)
    return {'as rendered': plain,
            'light on axis': dict(plain, lighting=on_axis),
            'disc -> Gaussian': dict(plain, defocus_px=0.0, blur_sigma=kw['defocus_px'] / 2),
            'no highlight': dict(plain, lighting=matte)}


def depth_error(image, cam, c, gamma):
    """Return the model fit's depth error (% of range), or NaN where it fails."""
    det = vision.attempt(image, cam, 'model', gamma)
    if isinstance(det, str):
        return np.nan
    return float(100 * (det.position - c) @ c / (c @ c))


def rms_cell(e):
    """Return 'RMS (misread/failed)' of depth errors (%, NaN for a failure)."""
    read = np.isfinite(e) & (np.abs(e) <= MISREAD_PERCENT)
    rms = np.sqrt(np.mean(e[read] ** 2)) if read.any() else np.nan
    misread = int(np.sum(np.isfinite(e) & ~read))
    return f'{rms:.3f} ({misread}/{int(np.sum(~np.isfinite(e)))})'


def table(rows, groups, names):
    """Print the depth error RMS of each variant over each group of scenes (rms_cell)."""
    for label, member in groups:
        print(f'{label:20s} {int(member.sum()):3d} '
              + ' '.join(f'{rms_cell(rows[member, k]):>15s}' for k in range(len(names))))


def project_study(scenes):
    """Render each scene's variants on the project's renderer and print the table."""
    rng = np.random.default_rng(SEED_RENDER)
    names, rows, angles, defocus = None, [], [], []
    for scene in scenes:
        c, kw = vision.project_scene(scene)
        cases = variants(c, kw)
        names = list(cases)
        rows.append([depth_error(cm.render(vision.CAM, c, vision.R, rng, **args), vision.CAM, c,
                                 args['gamma']) for args in cases.values()])
        angles.append(light_angle(c, kw))
        defocus.append(kw['defocus_px'])
    rows, angles, defocus = np.array(rows), np.array(angles), np.array(defocus)
    print(f'Project renderer, {len(scenes)} scenes without noise: depth error RMS %, over the '
          f'scenes read within {MISREAD_PERCENT:g} % (misread/failed)')
    print(f'{"scenes":20s}   n ' + ' '.join(f'{n:>15s}' for n in names))
    groups = [(f'light {a}-{b} deg', (angles >= a) & (angles < b)) for a, b in ANGLES]
    groups += [(f'defocus {a:g}-{b:g} px', (defocus >= a) & (defocus < b)) for a, b in DEFOCUS]
    table(rows, groups + [('all', np.ones(len(rows), bool))], names)


def lamp_on_axis(scene):
    """Return the scene with its lamp on the ray from the ball to the camera, behind the camera."""
    moved = copy.deepcopy(scene)
    c = np.asarray(scene['ball']['center_m'])
    distance = max(scene['light']['distance_m'], 2 * np.linalg.norm(c))
    moved['light']['position_m'] = list(c - c / np.linalg.norm(c) * distance)
    return moved


def mitsuba_study(scenes, count):
    """Render ``count`` point-lit frontal scenes by Mitsuba, as drawn and lamp on the axis."""
    angle = {s['id']: light_angle(*vision.project_scene(s)) for s in scenes}
    lit = [s for s in scenes if s['light']['type'] == 'point'
           and s['light'].get('direction') == 'frontal' and 10 <= angle[s['id']] < 40][:count]
    print(f'\nMitsuba, {len(lit)} point-lit scenes lit from the front (10-40 deg), '
          f'{MITSUBA_SPP} spp, no sensor noise: depth error %')
    print(f'{"scene":8s} {"angle":>6s} {"material":>9s} {"defocus":>8s} {"as drawn":>9s} '
          f'{"lamp on axis":>13s}')
    errors = []
    for scene in lit:
        row = []
        for case in (scene, lamp_on_axis(scene)):
            case = copy.deepcopy(case)
            case['noise']['sigma_grey'], case['spp'] = 0.0, MITSUBA_SPP
            image, truth = ms.render(case)
            row.append(depth_error(image, vision.PINHOLE, np.asarray(truth['ball']['center_m']),
                                   case['exposure']['gamma']))
        errors.append(row)
        print(f'{scene["id"]:8s} {angle[scene["id"]]:6.1f} {scene["material"]["type"]:>9s} '
              f'{scene["blur"]["radius_px"]:8.2f} {row[0]:+9.3f} {row[1]:+13.3f}', flush=True)
    e = np.array(errors)
    print(f'{"RMS (misread/failed)":33s} {rms_cell(e[:, 0]):>15s} {rms_cell(e[:, 1]):>15s}')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--mitsuba', type=int, default=8, metavar='N',
                        help='Mitsuba scenes to render twice (0: none)')
    parser.add_argument('--seed', type=int, default=vision.SEED, help='the scene list drawn')
    parser.add_argument('--scenes', type=int, default=vision.SCENES, help='scenes in it')
    args = parser.parse_args(argv)
    scenes = ms.cached_scene_list(args.scenes, args.seed, vision.CACHE)
    project_study(scenes)
    if args.mitsuba > 0:
        mitsuba_study(scenes, args.mitsuba)


if __name__ == '__main__':
    main()
