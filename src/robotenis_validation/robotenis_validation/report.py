"""
`./robotenis report [--session BAG_DIR] [--quick]`: the validation report, report/index.html.

Every number in it is computed by this run, from the simulator: the identification beside the
paper's Table 1, the observability analysis, the residual loop on robots with each undeclared
effect (errors before and after on held-out poses), pose selection, the Jacobian study of
section 6.2.1, the ISO 9283 static tests of section 6.1 (nominal, plain-calibrated and final
models) and the tracking tests of section 6.2.2. The residual loop and the models of the static
tests are calibrated twice: from rests measured through the noise model, and through rendered
images and the product's detector as the live session measures them (the paper's own chain,
which the figures set beside the paper's come from). ``--session`` adds the calibration of a
recorded bag.
``--quick`` uses fewer poses and seeds (for CI: 374 s in a clean-clone CI run on 2 cores; its
sessions through rendered images take most of it, a process per core, while the other sections
run).
"""
import argparse
from concurrent.futures import ProcessPoolExecutor
import html
import os
import sys
import time

import numpy as np

from robotenis_calibration import poses, result
from robotenis_kinematics import description, observability
from robotenis_kinematics import identification as idf
from robotenis_sim import motors, truth as sim_truth
from robotenis_sim.scenarios import EFFECTS as STUDY
from robotenis_validation import iso_study, jacobian_study, live_links, paper
from robotenis_validation import study
from robotenis_validation import tracking_study as ts
from robotenis_validation.demo import human
from robotenis_vision import camera as vision_camera


def table(header, rows):
    """Build an HTML table from a header and rows of cells (strings or numbers)."""
    head = ''.join(f'<th>{html.escape(str(h))}</th>' for h in header)
    body = ''.join('<tr>' + ''.join(f'<td>{html.escape(str(c))}</td>' for c in row) + '</tr>'
                   for row in rows)
    return f'<table><tr>{head}</tr>{body}</table>'


def section_identification(nominal, truth, n, seed):
    s, meas, _ = study.static_run(truth, nominal, n, seed)
    fit = idf.identify(idf.initial_model(nominal, meas), meas)
    rows = []
    for j, name in enumerate(idf.PAPER_PARAMETERS):
        if name.startswith('P0'):
            continue  # P0 here is the camera reference, not Table 1's home position
        unit = 'deg' if name.startswith('theta') else 'mm'
        rows.append([name, f'{paper.TABLE1_NOMINAL[j]:.3f}', f'{human(name, fit.U[j]):.4f}',
                     f'{human(name, fit.std[j]):.4f}', f'{paper.TABLE1_CALIBRATED[j]:.3f}', unit])
    obs = observability.analyse(fit.model, meas)
    text = (f'<p>{len(s)} rests of a static session '
            '(poses 5-10 cm from a singularity that the camera sees); '
            f'chi2/dof of the fit {fit.chi2 / fit.dof:.3f}. '
            "The simulator's truth is Table 1's calibrated column, "
            'so the identified values should agree with it within a few standard deviations.</p>')
    text += table(['parameter', 'nominal (Table 1)', 'identified', 'std', 'calibrated (Table 1)',
                   'unit'], rows)
    text += '<h3>Observability (QR with column pivoting, units 1 mm / 1 mrad)</h3><pre>' + \
        html.escape(observability.format_report(obs)) + '</pre>'
    return text, fit


ISO_EFFECT = 'joint_scale'   # the undeclared effect of the robot the static tests run on
ISO_SEED = 7                 # their session's, through the noise model and through images alike


def image_run(robot, nominal, n, seed):
    """
    Return (session, diagnosis) of a session through rendered images, planned as the node plans.

    Each rest is measured through rendered images as the sphere_detector node measures it,
    emulated without the robot's dynamics (study.static_run's ``images``: its frames' noise and
    the detector's error at rest; the live chain's rests differ from it by noise: live_links),
    the poses planned as a session's request that names none is (poses.SESSION_SELECTION), the
    ball within poses.IMAGE_MAX_RANGE around where the first rests see it.
    """
    s, _, d = study.static_run(robot, nominal, n, seed, poses.SESSION_SELECTION,
                               -robot.camera_translation, images=True,
                               max_range=poses.IMAGE_MAX_RANGE)
    return s, d


def image_sessions(pool, truth, nominal, n, image_poses, image_seeds):
    """
    Submit to ``pool`` every session through rendered images the report uses; their futures.

    {(effect, seed): image_run} for each studied effect (``image_poses`` each), and under
    'static' the static tests' (``n`` poses on the robot with ISO_EFFECT), submitted first: the
    longest. They are rendered and measured while the report computes its other sections.
    """
    jobs = {'static': (sim_truth.with_effects(truth, **STUDY[ISO_EFFECT]), nominal, n, ISO_SEED)}
    jobs.update({(name, seed): (sim_truth.with_effects(truth, **effect), nominal, image_poses,
                                100 + seed)
                 for name, effect in STUDY.items() for seed in range(image_seeds)})
    return {key: pool.submit(image_run, *args) for key, args in jobs.items()}


def section_residual_loop(nominal, truth, n, seeds, out_dir, images, image_poses, image_seeds):
    rows, plot = [], None
    for name, effect in STUDY.items():
        robot = sim_truth.with_effects(truth, **effect)
        found, errors = [], []
        for seed in range(seeds):
            s, meas, d = study.static_run(robot, nominal, n, 100 + seed)
            found.append(d.effects)
            errors.append([d.errors_mm['nominal'], d.errors_mm['plain'], d.errors_mm['final']])
            if name == 'backlash' and plot is None:
                plot = 'residuals-backlash.png'
                result.plot_residuals(d, meas, s.sphere, s.stamps, os.path.join(out_dir, plot))
                loop_text = '\n'.join(result.summary(d))
        named = sum(f == ([name] if effect else []) for f in found)
        e = np.mean(errors, axis=0)
        seen, held_out, at_rests = [], [], []
        for seed in range(image_seeds):
            s, d = images[name, seed].result()
            seen.append(d.effects == ([name] if effect else []))
            held_out.append(d.errors_mm['final'])
            # a static session's sides are the truth's and the calibration's alike
            at_rests.append(live_links.rest_error_mm(
                result.calibrated_description(d, nominal), robot, s.Theta, s.direction,
                s.direction)[1])
        rows.append([name, f'{named}/{seeds}', f'{e[0]:.3f}', f'{e[1]:.3f}', f'{e[2]:.3f}',
                     f'{sum(seen)}/{image_seeds}', f'{np.mean(held_out):.3f}',
                     f'{np.mean(at_rests):.3f}'])
    text = ('<p>Each row: a robot whose truth carries one effect that the declared description '
            f'does not; {seeds} sessions of {n} planned poses each, 30 % of the rests held out. '
            '"named" counts the sessions where the loop found exactly that effect (for "none": '
            'claimed nothing). Errors are the held-out RMS 3D distances between where each model '
            'puts the effector and where the camera saw it. The first columns measure each rest '
            "through the noise model (Table 3's averaged frames); the last three through "
            "rendered images and the product's detector, as the live session does "
            f'({image_seeds} sessions of {image_poses} poses planned as the calibration node '
            'plans them, the ball within 0.40 m): each rest measured as the sphere_detector node '
            "measures it, emulated without the robot's dynamics (its frames' noise and the "
            "detector's error at rest, what limits the live chain: live_links), and the last "
            "column is the calibrated FK's error against the truth at the rests, less their "
            'common offset.</p>')
    text += table(['undeclared effect', 'named', 'nominal (mm)', 'plain 15-parameter (mm)',
                   'final (mm)', 'named, images', 'final, images (mm)',
                   'FK at the rests, images (mm)'], rows)
    text += f'<h3>One session with backlash, step by step</h3><pre>{html.escape(loop_text)}</pre>'
    text += f'<p><img src="{plot}" width="100%"></p>'
    return text


def section_pose_selection(nominal, truth, n, seeds):
    rows = []
    for selection in ('boundary', 'optimal'):
        rests, lengths, angles, errors = [], [], [], []
        for seed in range(seeds):
            s, _, d = study.static_run(truth, nominal, n, 50 + seed, selection=selection)
            std = dict(zip(d.plain.names, d.plain.std))
            rests.append(len(s))
            lengths.append(np.mean([std[f'{p}{i}'] for p in 'abh' for i in (1, 2, 3)]))
            angles.append(np.mean([std[f'theta0{i}'] for i in (1, 2, 3)]))
            errors.append(d.errors_mm['plain'])
        rows.append([selection, f'{np.mean(rests):.0f}', f'{np.mean(lengths) * 1e3:.4f}',
                     f'{np.degrees(np.mean(angles)):.5f}', f'{np.mean(errors):.4f}'])
    return ('<p>The paper draws its poses at random 5-10 cm from a singularity ("boundary"); '
            'the optimal design picks, among poses where the camera should see the ball, those '
            'that most increase the log-determinant '
            "of the 15 parameters' information matrix (D-optimality). "
            f'{n} planned poses, {seeds} sessions each; the plain 15-parameter model.</p>' +
            table(['selection', 'rests measured', 'mean std of a, b, h (mm)',
                   'mean std of theta0 (deg)', 'held-out RMS error (mm)'], rows))


def section_jacobian(nominal, fit, out_dir):
    calibrated = fit.model.desc
    peak, median = jacobian_study.volume_max(calibrated, nominal)
    jacobian_study.plot(calibrated, nominal, os.path.join(out_dir, 'jacobian.png'),
                        'largest singular value of J_RC (J_RN^-1 - J_RC^-1)')
    return ('<p>Over the cylinder of radius 300 mm and height 400 mm '
            f'(z from {jacobian_study.Z_RANGE[0] * 1e3:.0f} '
            f'to {jacobian_study.Z_RANGE[1] * 1e3:.0f} mm): '
            f'largest singular value {peak:.4f} at most, median {median:.4f}; '
            f'the paper found about {paper.JACOBIAN_MAX}. At 2000 mm/s of command this is at most '
            f'{peak * 2000:.1f} mm/s of difference between the nominal and the calibrated control '
            'law.</p>'
            '<p><img src="jacobian.png" width="100%"></p>')


def section_session(bag_dir, out_dir):
    from robotenis_calibration import pipeline  # reads bags: only needed with --session
    outcome = pipeline.calibrate_bag(bag_dir, os.path.join(out_dir, 'session-result.yaml'))
    return (f'<p>Bag <code>{html.escape(bag_dir)}</code>.</p><pre>' +
            html.escape('\n'.join(result.summary(outcome.diagnosis))) +
            f'</pre><p><img src="{os.path.basename(outcome.plot_path)}" width="100%"></p>')


def section_static(nominal, truth, n, quick, out_dir, static_images, say):
    """
    Report section 6.1 on a robot whose truth carries an undeclared gear error.

    Table 4 and Figures 9-10. ``static_images``: the same session through rendered images
    (image_sessions' 'static' future).
    """
    robot = sim_truth.with_effects(truth, **STUDY[ISO_EFFECT])
    _, _, d = study.static_run(robot, nominal, n, ISO_SEED)
    if not static_images.done():
        say(f'waiting for the same session through rendered images ({n} poses)')
    images, d_images = static_images.result()
    models = {'nominal': nominal, 'plain 15-parameter': d.plain.model.desc,
              'final (residual loop)': result.calibrated_description(d, nominal),
              'plain, through images': d_images.plain.model.desc,
              'final, through images': result.calibrated_description(d_images, nominal)}
    plate = iso_study.Plate.in_front_of(iso_study.CUBE_CENTRE, robot.camera_translation
                                        + iso_study.STANDOFF * robot.camera_rotation[:, 2])
    # the user sets the plates by eye and knows the camera offset from the drawings to 5 mm
    offset_guess = (robot.camera_translation + iso_study.STANDOFF * robot.camera_rotation[:, 2]
                    + 0.005)
    repetitions, loops, rendered_repetitions = (3, 3, 1) if quick else (25, 25, 25)
    maps = {}
    for name, desc in models.items():
        say(f'distance accuracy with the {name} model')
        maps[name] = iso_study.distance_accuracy(robot, desc, plate, offset_guess, repetitions,
                                                 np.random.default_rng(11))
    iso_study.plot_maps(maps, plate, os.path.join(out_dir, 'distance_accuracy.png'))
    rendered = {}
    for name, desc in models.items():
        say(f'distance accuracy with the {name} model, circles rendered and measured')
        rendered[name] = iso_study.distance_accuracy(robot, desc, plate, offset_guess,
                                                     rendered_repetitions,
                                                     np.random.default_rng(13), say,
                                                     camera=vision_camera.default())
    iso_study.plot_maps(rendered, plate, os.path.join(out_dir, 'distance_accuracy_rendered.png'))
    paper_mean = paper.DISTANCE_ACCURACY_MEAN
    ad_rows = [[name, f'{AD.mean() * 1e3:.4f}', f'{AD.max() * 1e3:.4f}',
                f'{rendered[name].mean() * 1e3:.4f}',
                f'{paper_mean["nominal"] if name == "nominal" else paper_mean["calibrated"]:.3f}']
               for name, AD in maps.items()]
    rp_rows = []
    for speed in (1.0, 2.0):
        say(f'repeatability: five-point loop at {speed} m/s')
        samples = iso_study.repeatability(robot, motors.true_masses(robot),
                                          models['final, through images'],
                                          speed, loops, np.random.default_rng(12))
        ranges, RP = iso_study.repeatability_figures(samples)
        paper_ranges, paper_RP = paper.TABLE4[speed]
        rp_rows.append([f'{speed:.1f}', ', '.join(f'{v * 1e3:.3f}' for v in ranges),
                        f'{RP * 1e3:.4f}',
                        ', '.join(f'{v:.3f}' for v in paper_ranges), f'{paper_RP:.4f}'])
    return (f"<p>The robot's truth carries an undeclared gear error ({ISO_EFFECT}: "
            f'{STUDY[ISO_EFFECT][ISO_EFFECT]}); the plain and final models are calibrated from '
            f'one static session of {n} planned poses, measured through the noise model (the '
            "first plain and final rows) or through rendered images and the product's detector "
            f'as the live session measures ({len(images)} rests; effects claimed: '
            f'{", ".join(d_images.effects) or "none"}): the paper calibrated from its images, so '
            'the rows "through images" with the rendered circles are the ones to set beside its '
            'figures. The camera servoes to 200 mm in front of '
            'each circle of the plate (25 circles, 40 mm, 100 mm apart) in five vertical planes '
            '100 mm apart, until the circle is centred to under a pixel (0.4 mm); its position is '
            'the forward kinematics of the readings corrected by the averaged visual measurement '
            f'(Table 3 noise). {repetitions} repetitions of the whole plate per model. '
            'In the fourth column (and the second set of maps) the camera renders the plate '
            f'through the true mounting, one frame per visit, {rendered_repetitions} '
            'repetition(s), and robotenis_vision.circle measures the circle from its ink '
            'coverage. AD of each pair of neighbouring circles against their 100 mm '
            '(ISO 9283 appendix); each circle shows the mean of its pairs. '
            "The paper's figures are for its real robot, calibrated by the paper's method.</p>" +
            table(['model', 'mean AD (mm)', 'largest (mm)', 'mean AD, rendered circles (mm)',
                   'paper, mean (mm)'], ad_rows) +
            '<p><img src="distance_accuracy.png" width="100%"></p>'
            '<p>The same with the circles rendered and measured:</p>'
            '<p><img src="distance_accuracy_rendered.png" width="100%"></p>'
            '<h3>Repeatability (Table 4)</h3><p>The ISO 9283 loop through the centre and four '
            f'corners of a rectangle in a diagonal plane of the cube, {loops} times, '
            'on the dynamic simulation (motion controller at 1 kHz with the final model '
            'calibrated through images); '
            'the visual data of the circle at the focus point after each loop.</p>' +
            table(['speed (m/s)', 'range Xc, Yc, Zc (mm)', 'RP (mm)', 'paper: range (mm)',
                   'paper: RP (mm)'], rp_rows))


def section_tracking(quick, out_dir):
    """Section 6.2.2: Table 5 on the simulated robot, nominal against calibrated kinematics."""
    table = ts.run(quick=quick)
    ts.plot(table, os.path.join(out_dir, 'tracking.png'))
    return ('<p>Position-based visual servoing (eq. 23, K_p = 16.8/s; eq. 25 through the motion '
            'controller at 1 kHz) keeps a ball 600 mm in front of the camera while it flies a '
            'chaotic path at up to the given speed; the camera gives one detection per 8.3 ms '
            "frame, a frame late, with the single-frame noise of Table 2; the ball's velocity "
            'comes from a Kalman filter. "calibrated" is the truth\'s geometry '
            "(Table 1's calibrated column): what a perfect calibration finds. The paper's "
            'figures are for its real robot and ball.</p><pre>' +
            html.escape('\n'.join(ts.table_lines(table))) +
            '</pre><p><img src="tracking.png" width="100%"></p>')


def build(out_dir, quick=False, session=None, say=print):
    os.makedirs(out_dir, exist_ok=True)
    nominal, truth = description.nominal(), sim_truth.load()
    n, seeds = (300, 1) if quick else (300, 10)
    image_poses, image_seeds = 90, (1 if quick else 3)
    started = time.perf_counter()
    parts = []
    with ProcessPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        images = image_sessions(pool, truth, nominal, n, image_poses, image_seeds)
        say(f'{len(images)} sessions through rendered images: measured in the background')
        say('identification beside Table 1')
        text, fit = section_identification(nominal, truth, n, 1)
        parts.append(("Identification beside the paper's Table 1", text))
        say(f'residual loop on each undeclared effect ({seeds} sessions each)')
        parts.append(('The residual loop: finding what the model lacks',
                      section_residual_loop(nominal, truth, n, seeds, out_dir, images,
                                            image_poses, image_seeds)))
        say('pose selection: boundary against optimal')
        parts.append(('Choosing the poses',
                      section_pose_selection(nominal, truth, n, max(1, seeds // 2))))
        say('Jacobian study')
        parts.append(('The Jacobian study (section 6.2.1)',
                      section_jacobian(nominal, fit, out_dir)))
        if session:
            say(f'calibrating the session {session}')
            parts.append(('A recorded session', section_session(session, out_dir)))
        say('static tests (ISO 9283)')
        parts.append(('Static tests, ISO 9283 (section 6.1)',
                      section_static(nominal, truth, n, quick, out_dir, images['static'], say)))
    say('tracking tests (Table 5)')
    parts.append(('Tracking (section 6.2.2)', section_tracking(quick, out_dir)))
    body = ''.join(f'<h2>{html.escape(title)}</h2>{text}' for title, text in parts)
    page = ('<!doctype html><html><head><meta charset="utf-8">'
            '<title>RoboTenis calibration report</title>'
            '<style>body{font-family:sans-serif;max-width:1100px;margin:auto}'
            'table{border-collapse:collapse}'
            'td,th{border:1px solid #999;padding:3px 8px;text-align:right}</style></head><body>'
            '<h1>RoboTenis calibration report</h1>'
            f'<p>Generated by <code>./robotenis report{" --quick" if quick else ""}</code> in '
            f'{time.perf_counter() - started:.0f} s on the simulated robot. '
            'Lengths in mm, angles in degrees.</p>'
            f'{body}</body></html>')
    path = os.path.join(out_dir, 'index.html')
    with open(path + '.tmp', 'w') as f:
        f.write(page)
    os.replace(path + '.tmp', path)
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis report', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--session',
                        help='a recorded session (bag directory) to calibrate and show')
    parser.add_argument('--quick', action='store_true', help='fewer poses and seeds (CI)')
    parser.add_argument('--out', default='report')
    args = parser.parse_args(argv)
    path = build(args.out, args.quick, args.session,
                 say=lambda text: print(f'[report] {text}', file=sys.stderr))
    print(f'wrote {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
