"""
Benchmark: the paper's session protocol against one of a tenth of its robot time (issue 15).

The paper's protocol: 300 random boundary poses, a 4 s settle, 500 frames each (about 40 minutes of
robot time). Ours, as a user recalibrating the same robot would run it, from what the previous
calibration (the paper protocol's) recorded in its result: D-optimal poses within the camera's
view (poses.optimal, planned around the ball where that session saw it), the settle margin that
session's data showed, and the frames per rest that buy the most information per second
(protocol.frames_per_rest, from that session's frame noise and learned floor), as many poses as
fit in 4 minutes. Both sessions are simulated as bags (the simulator's timing: moves, vibration of
the ball holder, frames at the camera rate, each rest's own floor), calibrated with
``./robotenis calibrate``'s pipeline, and scored on the same 500 boundary poses against the
simulated truth, which carries an undeclared backlash. Target: the paper protocol's accuracy or
better in at most 4 minutes of robot time. Wall time here is the offline simulation and
calibration; the live chain's is measured by ``./robotenis demo``. The simulated moves are exact
quintics (no controller settling), so the settle found here is the ball holder's alone.
"""
import argparse
from pathlib import Path
import tempfile
import time

from calibrate import REST_FLOOR
import numpy as np
from robotenis_calibration import bag_io, pipeline, poses, protocol, rests
from robotenis_kinematics import description
from robotenis_sim import scenarios, session_bag
from robotenis_sim import truth as sim_truth
from robotenis_validation.live_links import workspace_error_mm

ROBOT_TIME_TARGET = 240.0   # s
TEST_POSES = 500
PAPER = {'poses': 300, 'settle': 4.0, 'frames_per_pose': 500}
SEED = 900


def robot_time(bag, spec):
    """Return the robot time of a simulated session: from the start to the last departure (s)."""
    return float(session_bag.schedule(bag.Theta, spec)[-1, 4])


def settle_found(bag_path):
    """Return the settle margin the session's data show (s after the joints stop)."""
    with bag_io.BagReader(bag_path) as reader:
        rec = rests.read(reader, [])
    return rests.settle_time(rec, rests.still_periods(rec.t_joint, rec.Theta))


def run(folder, name, spec):
    """Write the session's bag and calibrate it; return (outcome, robot time, wall time)."""
    t = time.perf_counter()
    bag = session_bag.write(folder / name, spec)
    outcome = pipeline.calibrate_bag(bag.path, folder / f'{name}.yaml',
                                     pipeline.Settings(force=True))
    return bag, outcome, robot_time(bag, spec), time.perf_counter() - t


def our_plan(previous, paper_bag_path, spec, guess):
    """Return (settle, frames, overhead) from what the previous session recorded."""
    frame_sigma, floor_sigma = protocol.rest_sigmas(previous.description.report['frame_noise'],
                                                    previous.diagnosis.floor)
    settle = settle_found(paper_bag_path) + 1.0 / spec.camera_rate
    move = spec.move_time[0] + spec.move_time[1] * 0.5   # a typical move of 0.5 rad
    frames = protocol.frames_per_rest(frame_sigma, floor_sigma, move + settle, spec.camera_rate)
    return settle, frames, move + settle


def fill(folder, base, nominal, guess, settle, frames, n, seed, tries=5):
    """
    Return (outcome, robot time, wall time) of our session with the most poses in the budget.

    The number of D-optimal poses is scaled by budget / robot time until it stops growing: the
    moves' lengths (the planner spreads the poses) are only known once planned.
    """
    best = None
    for _ in range(tries):
        targets = poses.optimal(nominal, guess, n, np.random.default_rng(seed + 1))
        spec = session_bag.BagSpec(**{**base.__dict__, 'poses': len(targets),
                                      'targets': tuple(map(tuple, targets)),
                                      'settle': settle, 'frames_per_pose': frames})
        _, outcome, t_robot, t_wall = run(folder, f'ours-{n}', spec)
        print(f'  {n} poses planned, {len(outcome.session)} measured: {t_robot:.0f} s of robot '
              'time', flush=True)
        if t_robot <= ROBOT_TIME_TARGET and (best is None or t_robot > best[1]):
            best = (outcome, t_robot, t_wall, n)
        n_next = max(20, int(0.98 * n * ROBOT_TIME_TARGET / t_robot))
        if best is not None and n_next <= best[3]:
            break
        n = n_next
    if best is None:
        raise RuntimeError(f'no session of at least 20 poses fits {ROBOT_TIME_TARGET:.0f} s')
    return best[:3]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seed', type=int, default=SEED)
    args = parser.parse_args()
    truth = sim_truth.with_effects(sim_truth.load(), **scenarios.EFFECTS['backlash'])
    nominal = description.nominal()
    guess = truth.sphere_position + scenarios.BALL_GUESS_ERROR
    base = session_bag.BagSpec(seed=args.seed, effects=scenarios.EFFECTS['backlash'],
                               rest_floor=REST_FLOOR)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print('paper protocol: writing and calibrating the bag (300 poses x 500 frames) ...',
              flush=True)
        paper_spec = session_bag.BagSpec(**{**base.__dict__, **PAPER})
        bag, paper, t_robot, t_wall = run(folder, 'paper', paper_spec)
        rows.append(('paper: 300 boundary, 4 s settle, 500 frames', paper, t_robot, t_wall))
        settle, frames, overhead = our_plan(paper, bag.path, base, guess)
        # the previous session saw the ball: plan around where it saw it, not the rough guess
        guess = poses.refined_guess(nominal, paper.session.Theta, paper.session.sphere)
        per_rest = overhead + frames / base.camera_rate
        n = int(ROBOT_TIME_TARGET / (per_rest + session_bag.TAIL))
        print(f'ours: settle {settle:.3f} s (found in the paper session), {frames} frames '
              f'per rest (protocol.frames_per_rest), {n} D-optimal poses to fit '
              f'{ROBOT_TIME_TARGET:.0f} s ...', flush=True)
        ours, t_robot, t_wall = fill(folder, base, nominal, guess, settle, frames, n, args.seed)
        rows.append((f'ours: {len(ours.session)} D-optimal, {settle:.2f} s settle, '
                     f'{frames} frames', ours, t_robot, t_wall))
    print(f'\n{"protocol":48s} {"robot time":>10s} {"wall":>7s} {"rests":>5s} '
          f'{"frames":>7s} {"held-out":>9s} {"workspace vs truth":>19s}  effects')
    errors = []
    for label, outcome, t_robot, t_wall in rows:
        d = outcome.diagnosis
        error = workspace_error_mm(outcome.description, truth, TEST_POSES, args.seed)
        errors.append(error)
        print(f'{label:48s} {t_robot / 60:8.1f} min {t_wall:6.0f} s {len(outcome.session):5d} '
              f'{int(np.sum(outcome.session.samples)):7d} '
              f'{d.errors_mm["final"]:6.3f} mm {error:15.3f} mm  {", ".join(d.effects) or "none"}')
    met = errors[1] <= errors[0] and rows[1][2] <= ROBOT_TIME_TARGET
    print(f"\ntarget: the paper's accuracy or better in at most {ROBOT_TIME_TARGET / 60:.0f} "
          f'minutes of robot time: {"MET" if met else "NOT MET"} ({errors[1]:.3f} against '
          f'{errors[0]:.3f} mm over {TEST_POSES} boundary poses, {rows[1][2] / 60:.1f} min '
          f'against {rows[0][2] / 60:.1f} min)')


if __name__ == '__main__':
    main()
