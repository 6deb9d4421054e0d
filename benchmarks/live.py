"""
Benchmark: the live chain names what the robot hides (issue 15, part 1).

For each named effect and the effects outside the library, one session through the ROS nodes
(``./robotenis demo``'s part 4: the simulated motors, the rendered hand camera, the detector, the
controller and the calibration service, on simulated time) on a truth carrying it. Each line
prints the effects the service claimed, the FK error of its result over 500 boundary poses
against the simulated truth (as ``./robotenis fk`` applies it), and beside it the same robot
calibrated from a static session of 300 poses measured through the noise model instead of
images (the demo's part 3: the static floor). Targets: the effect named and nothing else (the
generic model of its kind for an effect outside the library), error at most 0.1 mm and at most
3x the static floor. Each session takes about 5 minutes of wall time on 2 cores.
"""
import argparse
import glob
import os
import tempfile
import time
from types import SimpleNamespace

from robotenis_calibration import result
from robotenis_kinematics import description
from robotenis_sim import scenarios
from robotenis_sim import truth as sim_truth
from robotenis_validation import demo, study
from robotenis_validation.live_links import workspace_error_mm

EXPECTED = {**{name: name for name in scenarios.EFFECTS if scenarios.EFFECTS[name]},
            **{name: generic for name, (_, generic) in scenarios.OUTSIDE_LIBRARY.items()}}
STATIC_POSES = 300
TARGET_MM, TARGET_RATIO = 0.1, 3.0


def verdict(expected, claimed, live, static):
    """MET or NOT MET with the reason."""
    if claimed != [expected]:
        return f'NOT MET (claimed {", ".join(claimed) or "nothing"})'
    if live > TARGET_MM or live > TARGET_RATIO * static:
        return f'NOT MET ({live:.3f} mm; {live / static:.1f}x the static floor)'
    return 'MET'


def live_session(effect, folder, args):
    """Run one session through the nodes; return (claimed effects, result description, wall s)."""
    out = os.path.join(folder, effect)
    t = time.perf_counter()
    status = demo.ros_session(description.nominal(), sim_truth.load(), SimpleNamespace(
        ros_poses=args.poses, frames=args.frames, settle=args.settle, seed=args.seed, out=out,
        effect=effect))
    wall = time.perf_counter() - t
    results = sorted(glob.glob(os.path.join(out, 'calibration-*.yaml')))
    if status != 0 or not results:
        return None, None, wall
    desc = description.load(results[-1])
    return [e['name'] for e in desc.effects], desc, wall


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--effects', nargs='+', default=list(EXPECTED), choices=list(EXPECTED))
    parser.add_argument('--poses', type=int, default=90)
    parser.add_argument('--frames', type=int, default=30)
    parser.add_argument('--settle', type=float, default=0.3)
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args()
    nominal, rows = description.nominal(), []
    with tempfile.TemporaryDirectory() as folder:
        for effect in args.effects:
            robot = sim_truth.with_effects(sim_truth.load(), **demo.LIVE_EFFECTS[effect])
            _, _, d = study.static_run(robot, nominal, STATIC_POSES, args.seed + 1)
            static = workspace_error_mm(result.calibrated_description(d, nominal), robot)
            claimed, desc, wall = live_session(effect, folder, args)
            if desc is None:
                rows.append((effect, 'session failed', float('nan'), static, wall, 'NOT MET'))
                continue
            live = workspace_error_mm(desc, robot)
            rows.append((effect, ', '.join(claimed) or 'none', live, static, wall,
                         verdict(EXPECTED[effect], claimed, live, static)))
    print(f'\nlive sessions: {args.poses} poses, {args.frames} frames, settle {args.settle} s; FK '
          'error over 500 boundary poses against the truth')
    print(f'  {"hidden effect":20s} {"claimed":28s} {"live":>9s} {"static":>9s} {"wall":>6s}')
    for effect, claimed, live, static, wall, v in rows:
        print(f'  {effect:20s} {claimed:28s} {live:6.3f} mm {static:6.3f} mm {wall:5.0f} s  {v}')
    failed = sum(r[-1] != 'MET' for r in rows)
    print(f'\n{failed} of {len(rows)} NOT MET' if failed else '\nall MET')


if __name__ == '__main__':
    main()
