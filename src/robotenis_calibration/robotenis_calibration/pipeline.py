"""
From a recorded session (a rosbag2 bag) to RESULT.yaml.

This is the one path shared by the live calibration service and
`./robotenis calibrate BAG_DIR --out RESULT.yaml`.

Nothing partial is ever written: the result and its residual plot are first written to temporary
files beside them, and renamed only after the whole calibration succeeded (the plot first,
RESULT.yaml last); a failed calibration leaves a previous result untouched.
"""
from dataclasses import dataclass
import os
import tempfile

import numpy as np

from robotenis_calibration import diagnosis, rests, result
from robotenis_kinematics import description

MIN_POSES = 20   # below this the 15 parameters plus a held-out set are not worth fitting


class CalibrationError(RuntimeError):
    """A calibration that could not be done; the message says why."""


@dataclass
class Outcome:
    diagnosis: object
    description: object
    result_path: str
    plot_path: str
    notes: list


def with_detector_floor(session, floor):
    """
    Return the session with each averaged sphere position's covariance widened.

    The widening is the detector's systematic error, which averaging frames does not shrink:
    standard deviations ``floor`` = (lateral, depth) as fractions of the range z, along the optical
    axes.

    This project's conic detector is biased by about 0.3 % of the range in depth off the image
    centre (``./robotenis bench vision``, lighting from the camera's side); its lateral share,
    0.05 %, is what makes the chi-square per degree of freedom of a live session's fit about 1
    (measured on the demo's session: 1.15). A driver whose detector is better known gives its own;
    (0, 0) adds nothing.
    """
    lateral, depth = floor
    if lateral < 0 or depth < 0:
        raise ValueError(f'detector floor: fractions of the range must be >= 0, got {floor}')
    z = np.abs(session.sphere[:, 2])
    extra = np.zeros((len(z), 3, 3))
    extra[:, 0, 0] = extra[:, 1, 1] = (lateral * z) ** 2
    extra[:, 2, 2] = (depth * z) ** 2
    widened = session.subset(np.arange(len(session)))
    widened.sphere_cov = session.sphere_cov + extra
    return widened


def calibrate_session(session, holdout_fraction=0.3, seed=0, progress=None):
    """Run the residual loop on a Session: (Diagnosis, Measurements), or raise CalibrationError."""
    if len(session) < MIN_POSES:
        raise CalibrationError(f'only {len(session)} usable rests in the session;'
                               f' at least {MIN_POSES} are needed')
    meas = session.measurements()
    try:
        d = diagnosis.run(session.description, meas, session.sphere, session.stamps,
                          holdout_fraction, seed, progress=progress)
    except np.linalg.LinAlgError as e:
        raise CalibrationError(f'identification failed ({e}):'
                               ' the rests do not determine the parameters') from e
    return d, meas


def _temporary(path):
    """Make an empty file beside ``path`` (same folder, for an atomic rename), readable by all."""
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix='.tmp-', suffix=os.path.splitext(path)[1], dir=folder)
    os.close(fd)
    os.chmod(tmp, 0o644)
    return tmp


def _write_text(text, path):
    with open(path, 'w') as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())


def write_together(writers):
    """
    Write each {path: write(tmp_path)} to a temporary file, then rename them all in order.

    On any failure no target is touched and the temporary files are removed.
    """
    temporary = {}
    try:
        for path, write in writers.items():
            temporary[path] = _temporary(path)
            write(temporary[path])
        for path, tmp in temporary.items():
            os.replace(tmp, path)
    finally:
        for tmp in temporary.values():
            if os.path.exists(tmp):
                os.unlink(tmp)


def calibrate_bag(bag_dir, out_path, holdout_fraction=0.3, seed=0, params=rests.RestParameters(),
                  progress=None, detector_floor=(0.0, 0.0)):
    """Read the bag, run the residual loop, write RESULT.yaml and the residual plot beside it."""
    say = progress or (lambda text: None)
    say(f'reading {bag_dir}')
    try:
        session, notes = rests.load_session(bag_dir, params, progress=say)
    except (OSError, ValueError) as e:
        raise CalibrationError(str(e)) from e
    for note in notes:
        say(f'note: {note}')
    say(f'{len(session)} rests averaged')
    session = with_detector_floor(session, detector_floor)
    d, meas = calibrate_session(session, holdout_fraction, seed, progress=say)
    desc = result.calibrated_description(d, session.description)
    desc.report['source'] = {'bag': os.path.abspath(bag_dir), 'notes': [str(n) for n in notes]}
    plot_path = os.path.splitext(out_path)[0] + '-residuals.png'
    text = description.dumps(desc)
    write_together({plot_path: lambda tmp: result.plot_residuals(d, meas, session.sphere,
                                                                 session.stamps, tmp),
                    out_path: lambda tmp: _write_text(text, tmp)})
    return Outcome(d, desc, out_path, plot_path, list(notes))
