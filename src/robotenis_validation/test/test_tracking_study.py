"""
The tracking tests of section 6.2.2 (Table 5) in simulation.

Engines, noise floor, latency, segments, table.
"""
import os

import numpy as np
import pytest

from robotenis_kinematics import delta, description
from robotenis_kinematics.description import DescriptionError
from robotenis_sim import ball as sim_ball
from robotenis_sim import truth as sim_truth
from robotenis_validation import paper
from robotenis_validation import tracking_engines as tengines
from robotenis_validation import tracking_linear as tlinear
from robotenis_validation import tracking_setup as tsetup
from robotenis_validation import tracking_study as ts
from scipy import stats


@pytest.fixture(scope='module')
def truth():
    return sim_truth.load()


def still_balls(truth, setup, n):
    """Return n balls resting where the robot's box centre puts them at the reference."""
    centre = np.asarray(setup.robot_centre) + tsetup.robot_offset(truth, setup)
    return [sim_ball.FixedBall(tuple(centre))] * n


class IdealPlant:
    """Test double: a robot moving exactly at the commanded velocity (no drives, no dynamics)."""

    def __init__(self, geometry, P, dt):
        self.geometry, self.P, self.dt = geometry, np.array(P, dtype=float), dt
        self.v = np.zeros_like(self.P)

    def read(self):
        Theta = delta.inverse(self.geometry, self.P) - self.geometry.theta0
        return Theta, np.zeros_like(Theta)

    def effector(self):
        return self.P.copy()

    def set_velocity(self, U, t):
        self.v = np.array(U)

    def control(self, t, Theta, dTheta):
        pass

    def step(self):
        self.P = self.P + self.v * self.dt


def test_batch_engine_reproduces_the_project_simulator_and_controller(truth):
    """
    Check BatchPlant and BatchServo (vectorised) against the scalar engine on a fast ball.

    The scalar engine is SimulatedMotors + MotionController + pbvs.Tracker; both descriptions.
    Without resolver noise both are deterministic and integrate the same equations; what may differ
    is a resolver count rounded the other way after a 1e-15 difference, which the joint PD answers
    with a move of about one count: |J| q < 1.3 m/rad * 3.8e-5 rad = 0.05 mm at the effector.
    """
    setup = tsetup.Setup(resolver_noise=0.0, warmup_frames=30)
    descs = [description.nominal(), truth.geometry]
    path = tsetup.make_ball(truth, setup, 1.5, 0)
    balls = [tsetup.ShiftedBall(path, 3.0)] * 2  # 3 s into the path: the ball is moving
    out = {}
    for engine, (Plant, Servo) in tengines.ENGINES.items():
        plant = Plant(truth, descs, tsetup.start_position(truth, setup, balls), setup,
                      np.random.default_rng(0))
        out[engine] = tengines.simulate(plant, Servo(descs, setup), balls, truth, setup, 30,
                                        np.random.default_rng(1))
    for batch, scalar in zip(out['batch'], out['scalar']):
        np.testing.assert_allclose(batch, scalar, rtol=0, atol=0.05e-3)
    assert np.all(out['batch'][1] > 1e-5)  # a real tracking error, not a trivial zero


@pytest.mark.parametrize('feedforward, noisier', [(True, 1.0), (False, 1.0), (True, 3.0)])
def test_still_ball_error_is_the_noise_and_latency_prediction(truth, feedforward, noisier):
    """
    Mean square true error on a still ball = linear loop model (noise, delays, linearised robot).

    ``noisier``: the detections are that many times noisier than the filter assumes (as with the
    live detector at 600 mm), so the filter's gain is not the optimal one for the noise it gets.

    Frames of 8 ms (whole ticks) so that the model's frame is the simulation's; the tolerance is 4
    standard errors of the sample mean, computed by the model from its own autocovariances. The
    measured error adds the camera noise n, independent of the true error at its frame (it acts on
    the robot only later): |y|^2 - |e|^2 = 2 e.n + |n|^2 has mean sum(sigma^2) and variance at most
    4 sigma_max^2 E|e|^2 + 2 sum(sigma^4), uncorrelated from frame to frame.
    """
    setup = tsetup.Setup(frame_period=0.008, feedforward=feedforward,
                         filter_sigma=tsetup.SIGMA_FRAME,
                         sigma_camera=tuple(noisier * np.asarray(tsetup.SIGMA_FRAME)))
    runs, n = 12, 200
    balls = still_balls(truth, setup, runs)
    descs = [truth.geometry] * runs
    plant = tengines.BatchPlant(truth, descs, tsetup.start_position(truth, setup, balls), setup,
                                np.random.default_rng(2))
    e_visual, e_true = tengines.simulate(plant, tengines.BatchServo(descs, setup), balls, truth,
                                         setup, n, np.random.default_rng(3))
    lin = tlinear.linearized_plant(truth, truth.geometry, setup, setup.robot_centre)
    mse, se = tlinear.noise_response(setup, truth.geometry.camera_rotation, n, runs, plant=lin)
    assert abs(np.mean(e_true ** 2) - mse) < 4 * se
    sigma2 = np.square(setup.sigma_camera)
    added = np.mean(e_visual ** 2 - e_true ** 2)
    assert abs(added - sigma2.sum()) < 4 * np.sqrt((4 * sigma2.max() * mse
                                                    + 2 * np.sum(sigma2 ** 2)) / (n * runs))
    # and the robot's own dynamics matter: a robot moving exactly as commanded would do visibly
    # better
    ideal, _ = tlinear.noise_response(setup, truth.geometry.camera_rotation, n, runs)
    assert mse - ideal > 4 * se


@pytest.mark.parametrize('latency', [0, 1, 2])
def test_the_command_acts_latency_frames_after_its_image(truth, latency):
    """
    Noise-free, no feedforward, a robot that moves as commanded, 5 mm off the reference.

    The error follows e_(k+L+1) = e_(k+L) - T K_p e_k exactly (eq. 23 with the loop's delay of L
    frames).
    """
    setup = tsetup.Setup(frame_period=0.008, feedforward=False, sigma_camera=(0.0, 0.0, 0.0),
                         latency_frames=latency, warmup_frames=0)
    balls = still_balls(truth, setup, 1)
    offset = np.array([0.005, 0.0, 0.0])
    P0 = np.array([b.at(0.0) for b in balls]) - tsetup.robot_offset(truth, setup) + offset
    _, e_true = tengines.simulate(IdealPlant(truth.geometry, P0, setup.dt),
                                  tengines.BatchServo([truth.geometry], setup), balls,
                                  truth, setup, 40, np.random.default_rng(0))
    e = [np.linalg.norm(offset)] * (latency + 1)
    while len(e) < 40:
        e.append(e[-1] - setup.frame_period * setup.K_p * e[-latency - 1])
    np.testing.assert_allclose(e_true[0], np.abs(e), rtol=0, atol=1e-12)


def test_a_camera_bias_moves_the_true_error_not_the_visual_one(truth):
    """
    Noise-free detections biased by b, a still ball, a robot that moves as commanded.

    The loop drives the measured s to s_d, so the true error settles at |b| and the visual one at 0
    (the error decays as (1 - T K_p)^k: below 1e-9 m after 150 frames).
    """
    bias = np.array([0.0, 0.0, 1.7e-3])
    setup = tsetup.Setup(frame_period=0.008, sigma_camera=(0.0, 0.0, 0.0),
                         camera_bias=tuple(bias), warmup_frames=150)
    balls = still_balls(truth, setup, 1)
    P0 = np.array([b.at(0.0) for b in balls]) - tsetup.robot_offset(truth, setup)
    e_visual, e_true = tengines.simulate(IdealPlant(truth.geometry, P0, setup.dt),
                                         tengines.TrackerServo([truth.geometry], setup),
                                         balls, truth, setup, 20, np.random.default_rng(0))
    np.testing.assert_allclose(e_true, np.linalg.norm(bias), rtol=0, atol=1e-9)
    np.testing.assert_allclose(e_visual, 0.0, atol=1e-9)


def test_segments_reproduce_one_continuous_test(truth):
    """
    A test cut in two segments, each after its own warm-up, gives one continuous run's samples.

    Noise-free, resolvers without counts (the joint loop hunts within a count, 0.05 mm, otherwise),
    and segments of 30 frames = 250 ms (whole ticks) so that both see the same instants. What is
    left of the start after the warm-up decays at least like rho^W, rho the spectral radius of the
    linear loop (robot linearised): from an initial error under 20 mm (the ball at 1 m/s, the robot
    at rest).
    """
    setup = tsetup.Setup(sigma_camera=(0.0, 0.0, 0.0), resolver_noise=0.0)
    path = tsetup.make_ball(truth, setup, 1.0, 0)
    one = [tsetup.ShiftedBall(path, 0.0)]
    two = [tsetup.ShiftedBall(path, 0.0), tsetup.ShiftedBall(path, 30 * setup.frame_period)]
    results = []
    for balls, n in ((one, 60), (two, 30)):
        descs = [truth.geometry] * len(balls)
        plant = tengines.BatchPlant(truth, descs, tsetup.start_position(truth, setup, balls),
                                    setup, np.random.default_rng(0), quantise=False)
        results.append(tengines.simulate(plant, tengines.BatchServo(descs, setup), balls, truth,
                                         setup, n, np.random.default_rng(0))[1])
    M = tlinear.closed_loop(tsetup.Setup(frame_period=0.008), truth.geometry.camera_rotation,
                            tlinear.linearized_plant(truth, truth.geometry,
                                                     tsetup.Setup(frame_period=0.008),
                                                     setup.robot_centre))[0]
    rho = max(abs(np.linalg.eigvals(M)))
    np.testing.assert_allclose(results[1].reshape(-1), results[0][0], rtol=0,
                               atol=0.02 * rho ** setup.warmup_frames)
    assert results[0].max() > 1e-4  # the ball moves: there is an error to match


def test_calibrated_tracks_better_than_nominal(truth):
    """
    Check that the true error is smaller with the calibrated description than the nominal one.

    Paired over 8 tests (same ball, same noise); the calibrated description is the truth's
    geometry; one-sided t-test at 1 %.

    Why it must: with the nominal description the robot moves J_true J_nom^-1 u_r (eq. 26), off the
    command by up to 1.5 % (section 6.2.1), and the still-ball linear model already predicts a 2 %
    larger mean square error from that alone.
    """
    table = ts.run(tests=8, samples=120, speeds=(0.5,), setup=tsetup.Setup(segment_samples=120),
                   workers=1, progress=False, truth=truth)
    d = (table.true['nominal'] - table.true['calibrated'])[0]
    t = d.mean() / (d.std(ddof=1) / np.sqrt(len(d)))
    assert t > stats.t.ppf(0.99, len(d) - 1)


def test_run_gives_the_table_its_lines_and_its_plot(truth, tmp_path):
    table = ts.run(tests=2, samples=40, speeds=(0.5, 1.5), workers=1, progress=False, truth=truth)
    assert table.labels == ('nominal', 'calibrated') and table.speeds == (0.5, 1.5)
    for label in table.labels:
        for kind in ('visual', 'true'):
            values = getattr(table, kind)[label]
            assert values.shape == (2, 2) and np.all(values > 0) and np.all(values < 0.03)
    text = '\n'.join(ts.table_lines(table))
    for value in (paper.TABLE5_NOMINAL[0], paper.TABLE5_CALIBRATED[-1]):
        assert f'{value:.2f}' in text
    assert f'{table.mean_mm("calibrated")[1]:.2f}' in text
    path = tmp_path / 'tracking.png'
    ts.plot(table, str(path))
    assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert [p.name for p in tmp_path.iterdir()] == ['tracking.png']


def test_quick_is_two_tests_of_1000_samples_and_the_full_study_the_papers(monkeypatch, truth):
    calls = []
    monkeypatch.setattr(ts, 'run_description',
                        lambda label, desc, tr, speeds, tests, samples, *a, **k:
                        calls.append((tests, samples))
                        or (np.ones((len(speeds), tests)), np.ones((len(speeds), tests))))
    quick = ts.run(quick=True, workers=1, truth=truth)
    full = ts.run(workers=1, truth=truth)
    assert calls == [(2, 1000)] * 2 + [(10, 5000)] * 2
    assert quick.speeds == full.speeds == tuple(v / 1e3 for v in paper.TABLE5_SPEEDS)


def test_descriptions_may_be_yaml_paths(monkeypatch, truth, tmp_path):
    path = tmp_path / 'calibrated.yaml'
    description.save(truth.geometry, str(path))
    seen = []
    monkeypatch.setattr(ts, 'run_description',
                        lambda label, desc, *a, **k: seen.append(desc)
                        or (np.ones((1, 1)), np.ones((1, 1))))
    ts.run(tests=1, samples=1, speeds=(0.5,), descriptions={'calibrated': str(path)}, workers=1,
           truth=truth)
    np.testing.assert_allclose(seen[0].theta0, truth.geometry.theta0)


def test_bad_input_is_refused_with_a_reason(truth, tmp_path):
    with pytest.raises(ValueError, match='K_p'):
        tsetup.Setup(K_p=-1.0)
    with pytest.raises(ValueError, match='sigma_camera'):
        tsetup.Setup(sigma_camera=(1e-4, 1e-4))
    with pytest.raises(ValueError, match='camera_bias'):
        tsetup.Setup(camera_bias=(0.0, np.nan, 0.0))
    with pytest.raises(ValueError, match='filter_sigma'):
        tsetup.Setup(filter_sigma=(-1e-4, 1e-4, 1e-4))
    with pytest.raises(ValueError, match='tests'):
        ts.run(tests=0, truth=truth)
    with pytest.raises(ValueError, match='backlash'):
        ts.run(quick=True, truth=sim_truth.with_effects(truth, backlash=[1e-3] * 3))
    with pytest.raises(ValueError, match='workspace'):
        ts.run(quick=True, truth=truth, setup=tsetup.Setup(half_size=(0.4, 0.4, 0.4)))
    with pytest.raises((DescriptionError, OSError)):
        ts.run(quick=True, truth=truth,
               descriptions={'x': os.path.join(str(tmp_path), 'missing.yaml')})
    with pytest.raises(ValueError, match='unstable'):
        tlinear.noise_response(tsetup.Setup(K_p=400.0), np.eye(3), 100)
