"""
The tracking tests of the calibration paper (section 6.2.2, Table 5), simulated without ROS.

A ball flies a chaotic path (robotenis_sim.ball.ChaoticBall, a Lorenz attractor re-timed to a top
speed) in front of the robot; the robot keeps it centred in the image 600 mm ahead with the
position-based visual servoing law of eqs. 23-25 (robotenis_control.pbvs). Per run:

- the TRUE robot: the truth's geometry and masses, velocity-command drives (eq. 10), resolvers and
  RK4 rigid-body dynamics at 1 kHz (robotenis_sim.motors.SimulatedMotors);
- the motion controller at 1 kHz in velocity mode (robotenis_control.controller.MotionController):
  it integrates the Cartesian command u_r and follows it through the inverse kinematics and inverse
  dynamics of the description under test, i.e. the joints move at J_R^-1 u_r (eq. 25) with J_R that
  of the description, and the robot at J_R,true J_R^-1 u_r (eq. 26);
- the hand camera at 120 Hz (one frame every 8.33 ms): the ball's position s in the optical frame
  from the TRUE effector and ball positions through the TRUE camera mounting, plus Gaussian noise
  of one detection (``SIGMA_FRAME``), delivered one frame period late (the paper's visual loop
  delay);
- on each delivered detection, what pbvs.Tracker does: e_r = -R (s - s_d) with
  s_d = (0, 0, 600 mm) (the ball centred at 600 mm, as in the paper), v_p from the ball's Kalman
  filter (pbvs.BallKalman) on the ball's base-frame position P_est + R s (P_est: forward kinematics
  of the description on the resolvers read at the exposure), u_r = -K_p e_r + v_p (eq. 23,
  K_p = 16.8), sent to the motion controller.

The tracking error is what the paper reports (Table 5: "the mean of the tracking errors in
millimetres when 10 tests are done"): per test, the mean over its samples of |e_r| from the visual
measurement; per speed, the mean (and spread) over the tests. The true error |s_true - s_d|,
without the camera's noise, is recorded beside it. Nominal and calibrated runs of one test see the
same ball, the same camera noise and the same resolver noise (a paired comparison).

The loop itself is simulated by robotenis_validation.tracking_engines (a scalar reference engine
and a batch engine vectorised over runs), its setup and ball by tracking_setup, its linear model by
tracking_linear. Each test is cut into segments of ``Setup.segment_samples`` frames simulated side
by side, each after its own warm-up.

Without the velocity feedforward (``Setup(feedforward=False)``) the law is the pure proportional
-K_p e_r: the baseline of benchmarks/tracking.py.
"""
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
import os
import sys
import time

import numpy as np
from robotenis_kinematics import description
from robotenis_sim import truth as sim_truth
from robotenis_validation import paper
from robotenis_validation.tracking_engines import ENGINES, simulate
from robotenis_validation.tracking_setup import (check_region, check_truth, make_ball,
                                                 QUICK_SAMPLES, QUICK_TESTS, SAMPLES, segments,
                                                 Setup, ShiftedBall, SPEEDS, start_position,
                                                 TESTS)


@dataclass
class TrackingTable:
    """
    Table 5 measured: per description label, per speed and test, the mean error (m).

    ``visual[label]`` has shape (len(speeds), tests): each test's mean |e_r| of the visual
    measurement (the paper's figure); ``true[label]`` the same for the true error. Means and
    spreads over the tests in mm come from ``mean_mm`` and ``std_mm``.
    """

    speeds: tuple
    labels: tuple
    visual: dict
    true: dict
    tests: int
    samples: int
    setup: Setup = field(default_factory=Setup)
    wall_time: float = 0.0

    def mean_mm(self, label, kind='visual'):
        return 1e3 * getattr(self, kind)[label].mean(axis=1)

    def std_mm(self, label, kind='visual'):
        """
        Return the spread of the per-test means over the tests (mm).

        The sample standard deviation; 0 for one test.
        """
        values = getattr(self, kind)[label]
        return 1e3 * (values.std(axis=1, ddof=1) if values.shape[1] > 1 else np.zeros(len(values)))


def run_description(label, desc, truth, speeds, tests, samples, setup, seed, engine='batch',
                    progress=True):
    """
    Run all speeds x tests of one description: (visual, true) per-test means.

    Each is (len(speeds), tests), m. A test is ``samples`` consecutive frames of one ball path. Its
    segments are simulated side by side, each from ``warmup_frames`` before its first frame with
    the robot at the reference and the filter at rest: after the warm-up (8 time constants 1/K_p)
    the start no longer shows, so the counted samples are those of one continuous test, and the
    batch is wider (numpy's cost per call dominates, so a wide batch is almost free).
    """
    count, length = segments(samples, setup)
    balls = []
    for v in speeds:
        for j in range(tests):
            path = make_ball(truth, setup, v, j)
            needed = ((setup.warmup_frames + count * length + setup.latency_frames + 1)
                      * setup.frame_period)
            if path.duration < needed:
                raise ValueError(f"tracking: the ball's path lasts {path.duration:.1f} s, "
                                 f'a test needs {needed:.1f} s')
            balls += [ShiftedBall(path, m * length * setup.frame_period) for m in range(count)]
    descs = [desc] * len(balls)
    rng = np.random.default_rng(seed)
    plant_rng, camera_rng = (np.random.default_rng(s) for s in rng.integers(2 ** 32, size=2))
    Plant, Servo = ENGINES[engine]
    plant = Plant(truth, descs, start_position(truth, setup, balls), setup, plant_rng)
    start = time.perf_counter()

    def report(fraction):
        if progress:
            print(f'tracking [{label}]: {100 * fraction:3.0f} % '
                  f'({time.perf_counter() - start:.0f} s)',
                  file=sys.stderr, flush=True)

    e_visual, e_true = simulate(plant, Servo(descs, setup), balls, truth, setup, length,
                                camera_rng, report)
    shape = (len(speeds), tests, count * length)
    return (e_visual.reshape(shape)[..., :samples].mean(axis=2),
            e_true.reshape(shape)[..., :samples].mean(axis=2))


def _load(desc):
    return description.load(desc) if isinstance(desc, (str, os.PathLike)) else desc


def run(quick=False, tests=None, samples=None, speeds=SPEEDS, descriptions=None, truth=None,
        setup=Setup(), seed=0, workers=None, progress=True):
    """
    Run Table 5 in simulation; return a TrackingTable.

    quick: 2 tests of 1,000 samples per speed instead of 10 of 5,000 (``tests``/``samples``
    override); descriptions: {label: RobotDescription or YAML path}, default the nominal
    description and the truth's geometry (what a perfect calibration finds; on the default truth,
    Table 1's calibrated column); truth: a robotenis_sim Truth, default the simulator's default;
    workers: processes, one description each (default: as many as descriptions and CPUs allow).
    Progress goes to stderr.
    """
    truth = truth or sim_truth.load()
    check_truth(truth)
    tests = (QUICK_TESTS if quick else TESTS) if tests is None else tests
    samples = (QUICK_SAMPLES if quick else SAMPLES) if samples is None else samples
    if tests < 1 or samples < 1 or not speeds or min(speeds) <= 0:
        raise ValueError('tracking: need tests >= 1, samples >= 1 and positive speeds '
                         f'(got {tests}, {samples}, {speeds})')
    descriptions = descriptions or {'nominal': description.nominal(), 'calibrated': truth.geometry}
    descriptions = {label: _load(d) for label, d in descriptions.items()}
    check_region(list(descriptions.values()), truth, setup)
    workers = workers or min(len(descriptions), os.cpu_count() or 1)
    args = [(label, d, truth, tuple(speeds), tests, samples, setup, seed)
            for label, d in descriptions.items()]
    start = time.perf_counter()
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            futures = [pool.submit(run_description, *a, progress=progress) for a in args]
            results = [f.result() for f in futures]
    else:
        results = [run_description(*a, progress=progress) for a in args]
    labels = tuple(descriptions)
    return TrackingTable(tuple(speeds), labels, {k: r[0] for k, r in zip(labels, results)},
                         {k: r[1] for k, r in zip(labels, results)}, tests, samples, setup,
                         time.perf_counter() - start)


# ----------------------------------------------------------------------------------------------
# Presentation.

def paper_row(speed):
    """(nominal, calibrated) of the paper's Table 5 at a speed (m/s), in mm; None off the table."""
    mm = round(speed * 1e3)
    if mm not in paper.TABLE5_SPEEDS:
        return None
    i = paper.TABLE5_SPEEDS.index(mm)
    return paper.TABLE5_NOMINAL[i], paper.TABLE5_CALIBRATED[i]


def _paired(table, a, b, kind):
    """Mean over tests of (a - b) per speed, and its standard error (mm)."""
    d = 1e3 * (getattr(table, kind)[a] - getattr(table, kind)[b])
    se = d.std(axis=1, ddof=1) / np.sqrt(d.shape[1]) if d.shape[1] > 1 else np.full(len(d), np.nan)
    return d.mean(axis=1), se


def table_lines(table):
    """Text lines: Table 5's layout, the paper's numbers beside ours (mm)."""
    labels, width = table.labels, max(16, *(len(lab) for lab in table.labels))
    lines = [f'Table 5, tracking error mean (mm): {table.tests} tests of {table.samples} samples '
             f'per speed (paper: 10 x 5,000), K_p = {table.setup.K_p:g}/s, '
             f'{"with" if table.setup.feedforward else "WITHOUT"} the Kalman velocity feedforward']
    for kind, title in (('visual', 'visual error |e_r|, as the paper measures it'),
                        ('true', 'true error |s_true - s_d| (without the camera noise)')):
        lines += [f'{title}: mean over the tests +- spread of the test means',
                  f'  {"speed (mm/s)":>12s}  {"paper nominal":>13s}  {"paper calibr.":>13s}'
                  + ''.join(f'  {lab:>{width}s}' for lab in labels)]
        for j, v in enumerate(table.speeds):
            ref = paper_row(v)
            ref_txt = f'{ref[0]:13.2f}  {ref[1]:13.2f}' if ref else f'{"-":>13s}  {"-":>13s}'
            cells = [f'{table.mean_mm(lab, kind)[j]:.2f} +- {table.std_mm(lab, kind)[j]:.2f}'
                     for lab in labels]
            ours = ''.join(f'  {cell:>{width}s}' for cell in cells)
            lines.append(f'  {1e3 * v:12.0f}  {ref_txt}{ours}')
    if len(labels) >= 2:
        a, b = labels[0], labels[1]
        lines.append(f'{a} minus {b}, paired over the tests (+- standard error), relative to {a}:')
        dv, sv = _paired(table, a, b, 'visual')
        dt, st = _paired(table, a, b, 'true')
        for j, v in enumerate(table.speeds):
            ref = paper_row(v)
            ref_txt = f'paper {100 * (ref[0] - ref[1]) / ref[0]:4.1f} %' if ref else 'paper -'
            lines.append(f'  {1e3 * v:12.0f}  visual {dv[j]:+.4f} +- {sv[j]:.4f} mm '
                         f'({100 * dv[j] / table.mean_mm(a)[j]:+.1f} %), '
                         f'true {dt[j]:+.4f} +- {st[j]:.4f} mm '
                         f'({100 * dt[j] / table.mean_mm(a, "true")[j]:+.1f} %); {ref_txt}')
    return lines


def plot(table, path):
    """PNG of the tracking error against the ball's top speed: the paper's Table 5 beside ours."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    speeds = 1e3 * np.asarray(table.speeds)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.plot(paper.TABLE5_SPEEDS, paper.TABLE5_NOMINAL, 'ks-', mfc='none', label='paper, nominal')
    ax.plot(paper.TABLE5_SPEEDS, paper.TABLE5_CALIBRATED, 'k^--', mfc='none',
            label='paper, calibrated')
    for k, label in enumerate(table.labels):
        color = f'C{k}'
        ax.errorbar(speeds + 8 * k, table.mean_mm(label), yerr=table.std_mm(label), fmt='o-',
                    color=color, capsize=3,
                    label=f'simulated, {label} (visual, +- spread over tests)')
        ax.plot(speeds + 8 * k, table.mean_mm(label, 'true'), ':', color=color,
                label=f'simulated, {label} (true)')
    ax.set_xlabel('maximum speed of the ball (mm/s)')
    ax.set_ylabel('tracking error mean (mm)')
    ax.set_title(f'Tracking (Table 5): {table.tests} tests x {table.samples} samples per speed')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    tmp = os.path.join(folder, f'.{os.path.basename(path)}.{os.getpid()}.tmp.png')
    try:
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.unlink(tmp)
