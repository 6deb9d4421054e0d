"""
From a recorded session (a rosbag2 bag) to RESULT.yaml.

This is the one path shared by the live calibration service and
`./robotenis calibrate BAG_DIR --out RESULT.yaml`, with the same defaults (``Settings``): the same
bag gives the same result, and the result records the settings and the noise model it was made
with, so that it can be reproduced from its bag alone.

Nothing partial is ever written. The destination is checked before any work (a folder, a file
that cannot be written: refused at once). The result and its residual plot are written to
temporary files beside them and renamed only after the whole calibration succeeded, the plot
first and RESULT.yaml last; if the second rename fails the first is undone, so either both
appear or neither. A calibration whose held-out error is worse than the declared description's
is refused (``force`` keeps it), and a failed or refused one leaves a previous result untouched.
"""
from dataclasses import asdict, dataclass, field
import itertools
import os
import shlex
import shutil
import tempfile

import numpy as np

from robotenis_calibration import diagnosis, protocol, rests, result
from robotenis_calibration.rests import RestParameters
from robotenis_kinematics import description
from robotenis_kinematics import identification as idf
from robotenis_ros.names import JOINTS

MIN_POSES = 20   # below this the 15 parameters plus a held-out set are not worth fitting
SIDE_ROUNDS = 5  # at most: loops on new backlash sides, sweeps of their choice
# Gauss-Newton steps of the refits that choose the backlash gaps: from the final model they reach
# machine precision in 9-13, and after 5 their chi2 was within 1e-4 of it (a live backlash bag,
# 30 candidate gaps, chi2 72-410 over them): the choice is the same, at half the steps.
PROFILE_ITERATIONS = 5
# a gap rule's gap within this ratio of the fitted width, where tied rules are chosen among: the
# width fitted on a gap's sides comes out short of the play when those sides are wrong
GAP_RATIO = 2.0


class CalibrationError(RuntimeError):
    """A calibration that could not be done; the message says why."""


@dataclass(frozen=True)
class Settings:
    """Everything a calibration from a bag depends on besides the bag (the same everywhere)."""

    holdout_fraction: float = 0.3
    seed: int = 0
    alpha: float = diagnosis.ALPHA
    rests: RestParameters = field(default_factory=RestParameters)
    joints: tuple = JOINTS
    force: bool = False

    def command(self, bag_dir, out_path):
        """Return the command line that reproduces a calibration with these settings."""
        args = ['./robotenis', 'calibrate', str(bag_dir), '--out', str(out_path),
                '--holdout', str(self.holdout_fraction), '--seed', str(self.seed)]
        if self.rests.settle is not None:
            args += ['--settle', str(self.rests.settle)]
        if tuple(self.joints) != JOINTS:
            args += ['--joints', ','.join(self.joints)]
        return shlex.join(args)


@dataclass
class Outcome:
    """What a calibration from a bag made: the loop's diagnosis, the result, its files."""

    diagnosis: object
    description: object
    result_path: str
    plot_path: str
    notes: list
    session: object = None     # the rests the bag gave


def plot_path_for(out_path):
    """Return the residual plot's path beside RESULT.yaml."""
    return os.path.splitext(out_path)[0] + '-residuals.png'


def check_destination(out_path):
    """
    Raise CalibrationError unless RESULT.yaml and its plot can be written where asked.

    Checked before any work: a folder given as the file, a folder that cannot be made, a
    read-only folder or file are refused with the path named.
    """
    for path in (out_path, plot_path_for(out_path)):
        if os.path.isdir(path):
            raise CalibrationError(f'{path} is a folder: give the file to write')
        folder = os.path.dirname(os.path.abspath(path))
        try:
            os.makedirs(folder, exist_ok=True)
            probe = _temporary(path)
        except OSError as e:
            raise CalibrationError(f'cannot write {path}: {e.strerror or e}') from None
        os.unlink(probe)
        if os.path.exists(path) and not os.access(path, os.W_OK):
            raise CalibrationError(f'cannot write {path}: it is read-only')


def calibrate_session(session, settings=Settings(), progress=None):
    """Return (Diagnosis, Measurements) of the residual loop on a Session; CalibrationError."""
    if len(session) < MIN_POSES:
        raise CalibrationError(f'only {len(session)} usable rests in the session; at least '
                               f'{MIN_POSES} are needed')
    d, meas = _loop(session, settings, progress)
    # the sides were first taken at a coarse gear's gap; with a backlash found, each joint's rule
    # (a gap or a speed) is chosen by the fit, and the loop runs again on its sides until they stay
    tried = [session.direction]
    for _ in range(SIDE_ROUNDS):
        if 'backlash' not in d.final.model.effects or session.approach is None:
            break
        pick = backlash_gaps(session, d)
        sided = session.at_gaps(pick)
        if any(np.array_equal(sided.direction, seen) for seen in tried):
            break
        tried.append(sided.direction)
        if progress:
            changed = int(np.sum(sided.direction != session.direction))
            rules = '; '.join(session.side_rule(i) for i in pick)
            progress(f'backlash {np.round(d.final.model.effects["backlash"] * 1e3, 3)} mrad: '
                     f'sides taken by {rules}, {changed} of {session.direction.size} changed; '
                     'the loop runs again')
        session = sided
        d, meas = _loop(session, settings, progress)
    return d, meas


def backlash_gaps(session, d):
    """
    Return the index among ``session.approach``'s rules (3,) of each joint's best-fitting rule.

    Sides taken at too small a gap count short returns as reversals; the width fitted on them
    comes out smaller still, so a width and the sides at that width, found in turn, drift apart
    (measured on live bags: 0.6 mrad found as 0.1). Instead each joint's rule (a gap, or a speed
    of the other family) is chosen, one joint at a time until none changes, as the one whose
    sides give the smallest chi2 of the diagnosis's final model refitted on its training rests,
    from the gap nearest the fitted width: a profile of the likelihood over the rules, the
    held-out rests left out of it. Rules that give a joint the same training sides tie; the
    middle of the widest run of them (``widest_run``) is taken.
    """
    R = session.description.camera_rotation
    final, floor = d.final, d.floor
    known = {}                      # training rests' sides -> chi2: rules often give the same

    def chi2(pick):
        sided = session.at_gaps(pick)
        key = sided.direction[d.train].tobytes()
        if key not in known:
            train = sided.measurements().subset(d.train)
            try:
                known[key] = idf.identify(final.model, floor.widen(train, R), final.names,
                                          max_iterations=PROFILE_ITERATIONS).chi2
            except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                known[key] = np.inf
        return known[key]

    pick = session.gap_index(final.model.effects['backlash'])
    best = chi2(pick)
    for _ in range(SIDE_ROUNDS):
        start = pick.copy()
        for j, g in itertools.product(range(3), range(session.approach.shape[1])):
            if g == pick[j]:
                continue
            trial = pick.copy()
            trial[j] = g
            value = chi2(trial)
            if value < best:
                best, pick = value, trial
        if np.array_equal(pick, start):
            break
    train = session.approach[d.train]
    grids = [grid for grid in (session.gaps, session.speeds) if grid is not None]
    width = np.abs(final.model.effects['backlash'])
    for j in range(3):
        same = np.all(train[:, :, j] == train[:, pick[j], j][:, None], axis=0)
        near = same & near_width(session.gaps, len(same), width[j])
        pick[j] = widest_run(near if near.any() else same, grids)
    return pick


def near_width(gaps, n_rules, width, ratio=GAP_RATIO):
    """
    Return which of ``n_rules`` rules (gaps (G,) rad, then the other family's) a play allows.

    A play of the fitted ``width`` turns the arm over on a return of that width: a gap rule more
    than ``ratio`` times off it contradicts the width the same fit finds (a return of 3.4 mrad
    to turn over a 0.8 mrad play), however it ties on the training rests. Rules of the other
    family are all allowed. Where only such gaps tie, they are used (``backlash_gaps``): a
    gap's training sides may have pulled the width short.
    """
    allowed = np.ones(n_rules, dtype=bool)
    allowed[:len(gaps)] = np.abs(np.log(np.asarray(gaps) / width)) <= np.log(ratio)
    return allowed


def widest_run(same, grids):
    """
    Return the index of the middle of the widest run of True in ``same`` (sum of the grids' sizes).

    ``same`` spans the candidate rules of ``grids`` (each a geometric grid of a rule's parameter,
    in order: gaps, speeds); a run is one grid's neighbours giving the same sides, its width the
    log of the parameter's interval it covers: its range plus one grid step (half a step each
    side; a lone candidate is as wide as its step). Where the training rests cannot tell rules
    apart, the one whose sides change least as its parameter moves is the one held-out rests are
    likeliest to agree with. Between the families (a gap in rad, a speed in rad/s) the widths are
    ratios, with no common scale: a lone speed (25 % steps) outweighs four tied gaps (5 %).
    """
    best, index, offset = -np.inf, None, 0
    for grid in grids:
        log = np.log(grid)
        step = log[1] - log[0] if len(grid) > 1 else 1.0
        k = 0
        while k < len(grid):
            if same[offset + k]:
                end = k
                while end + 1 < len(grid) and same[offset + end + 1]:
                    end += 1
                width = log[end] - log[k] + step
                if width > best + 1e-12:
                    best, index = width, offset + (k + end) // 2
                k = end + 1
            else:
                k += 1
        offset += len(grid)
    return index


def _loop(session, settings, progress):
    meas = session.measurements()
    try:
        d = diagnosis.run(session.description, meas, session.sphere, session.stamps,
                          settings.holdout_fraction, settings.seed, settings.alpha,
                          progress=progress)
    except (ValueError, ArithmeticError) as e:
        raise CalibrationError(f'identification failed ({e}): the rests do not determine the '
                               'parameters') from e
    return d, meas


def refuse_if_worse(d, force):
    """Raise CalibrationError if the calibration predicts held-out poses worse than declared."""
    before, after = d.errors_mm['nominal'], d.errors_mm['final']
    if after > before and not force:
        raise CalibrationError(f'the calibration is worse than the declared description on the '
                               f'held-out poses ({after:.3f} mm against {before:.3f} mm): not '
                               'written (--force keeps it)')


def _temporary(path):
    """Return a new empty file beside ``path`` (same folder: the rename is atomic), readable."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix='.tmp-', suffix=os.path.splitext(path)[1], dir=folder)
    os.close(fd)
    os.chmod(tmp, 0o644)
    return tmp


def _keep(path):
    """Return a second name of ``path``'s current contents (a hard link, else a copy)."""
    backup = _temporary(path)
    os.unlink(backup)
    try:
        os.link(path, backup)
    except OSError:
        shutil.copy2(path, backup)
    return backup


def _write_text(text, path):
    with open(path, 'w') as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())


def write_together(writers):
    """
    Write each {path: write(tmp_path)} to a temporary file, then rename them all, in order.

    On any failure no target is left changed: the files already renamed get their previous
    contents back (a hard link kept them, so a target is never missing, not even for an instant)
    or are removed if they are new, and the temporary files are removed.
    """
    temporary, kept, done = {}, {}, []
    try:
        for path, write in writers.items():
            temporary[path] = _temporary(path)
            write(temporary[path])
        for path, tmp in temporary.items():
            if os.path.exists(path):
                kept[path] = _keep(path)
            os.replace(tmp, path)
            done.append(path)
    except BaseException:
        for path in done:
            if path in kept:
                os.replace(kept.pop(path), path)
            else:
                os.unlink(path)
        raise
    finally:
        for tmp in list(temporary.values()) + list(kept.values()):
            if os.path.exists(tmp):
                os.unlink(tmp)


def calibrate_bag(bag_dir, out_path, settings=Settings(), progress=None):
    """Read the bag, run the residual loop, write RESULT.yaml and the residual plot beside it."""
    say = progress or (lambda text: None)
    check_destination(out_path)
    say(f'reading {bag_dir}')
    try:
        session, notes = rests.load_session(bag_dir, settings.rests, progress=say,
                                            joints=settings.joints)
    except (OSError, ValueError) as e:
        raise CalibrationError(str(e)) from e
    for note in notes:
        say(f'note: {note}')
    say(f'{len(session)} rests averaged')
    d, meas = calibrate_session(session, settings, progress=say)
    refuse_if_worse(d, settings.force)
    desc = result.calibrated_description(d, session.description)
    desc.report['source'] = {'bag': os.path.abspath(bag_dir), 'notes': [str(n) for n in notes],
                             'rests_used': len(session)}
    desc.report['settings'] = _plain(asdict(settings))
    desc.report['reproduce'] = settings.command(bag_dir, out_path)
    desc.report['frame_noise'] = session.noise
    plan = protocol.next_session(session.noise, d.floor, session.timing)
    if plan is not None:
        desc.report['next_session'] = plan
    plot_path = plot_path_for(out_path)
    text = description.dumps(desc)
    write_together({plot_path: lambda tmp: result.plot_residuals(d, meas, session.sphere,
                                                                 session.stamps, tmp),
                    out_path: lambda tmp: _write_text(text, tmp)})
    return Outcome(d, desc, out_path, plot_path, list(notes), session)


def _plain(value):
    """Return settings as plain YAML data (tuples as lists)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
