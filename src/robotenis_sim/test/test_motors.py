"""The simulated motors: energy, replay of inverse dynamics, resolvers, and a closed loop."""
import numpy as np
import pytest

from robotenis_control import controller as ctl
from robotenis_control import dynamics as dyn
from robotenis_control import trajectory as tr
from robotenis_kinematics import delta, description
from robotenis_sim import motors, truth as sim_truth


@pytest.fixture(scope='module')
def desc():
    return description.nominal()


def free_motion(desc, mass, dt, duration):
    """Swing the arms from home, unforced (tau = 0) and undamped: energy at start and end."""
    model = dyn.SingleRobotDynamics(desc, mass)
    alpha, dalpha = list(desc.theta0), [1.0, -0.5, 0.2]
    E0 = dyn.energy(desc, mass, alpha, dalpha)
    for k in range(int(round(duration / dt))):
        alpha, dalpha = motors.rk4_step(lambda t, a, d: model.accelerations(a, d, [0, 0, 0])[0],
                                        k * dt, alpha, dalpha, dt)
    return E0, dyn.energy(desc, mass, alpha, dalpha)


def test_energy_is_conserved_to_the_order_of_rk4(desc):
    """
    Check that energy is conserved to the order of RK4.

    RK4's global error is O(dt^4): the drift halves the step and shrinks ~16 times, and at the
    simulator's 1 ms it is under 1e-6 of the kinetic energy scale (here ~1 J) over 0.3 s of fall.
    """
    mass = dyn.MassParameters()
    E0, E1 = free_motion(desc, mass, 1e-3, 0.3)
    _, E2 = free_motion(desc, mass, 0.5e-3, 0.3)
    drift_1, drift_2 = abs(E1 - E0), abs(E2 - E0)
    assert drift_1 < 1e-6
    assert drift_1 / drift_2 > 8, (drift_1, drift_2)   # order >= 3 (theory 4, ratio 16)


def test_inverse_dynamics_torques_replay_the_trajectory(desc):
    """
    The paper's test motion, open loop: torques of eqs. 4-5 fed to the forward simulation.

    With RK4 at 1 ms the joint error stays far below one resolver count (3.8e-5 rad) and shrinks
    with the step faster than O(dt^2): not the full O(dt^4), as the motion's fourth derivative
    jumps where the segment ends inside a step (s = -840 / T^4 at u = 1).
    """
    mass = dyn.MassParameters()
    seg = tr.segment([0, 0, 0.75], [-0.2, 0.2, 0.75], 0.0, 2.0, 4 * dyn.G)
    model = dyn.SingleRobotDynamics(desc, mass)

    def torque(t):
        P, V, A, _ = seg.sample(t)
        return dyn.inverse_dynamics(desc, mass, P, V, A).tau

    def replay(dt):
        start = dyn.inverse_dynamics(desc, mass, *seg.sample(0.0)[:3])
        alpha, dalpha = list(start.alpha), list(start.dalpha)
        n = int(np.ceil(seg.T / dt))
        for k in range(n):
            alpha, dalpha = motors.rk4_step(
                lambda t, a, d: model.accelerations(a, d, torque(t))[0], k * dt, alpha, dalpha, dt)
        return np.array(alpha) - delta.inverse(desc, seg.sample(n * dt)[0])

    err_1, err_2 = np.abs(replay(1e-3)).max(), np.abs(replay(0.5e-3)).max()
    assert err_1 < motors.ResolverParameters().resolution / 10
    assert err_1 / err_2 > 4, (err_1, err_2)


def test_resolver_readings_are_quantised_with_the_stated_noise(desc):
    res = motors.ResolverParameters(noise=3e-4)
    sim = motors.SimulatedMotors(desc.copy(theta0=np.array([0.01, -0.02, 0.03])),
                                 dyn.MassParameters(), resolver=res, rng=np.random.default_rng(0))
    Theta = np.array([sim.read()[0] for _ in range(4000)])
    counts = Theta / res.resolution
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    # quantisation adds q^2/12 to the noise variance; 4000 samples: std known to ~1.1 %, allow
    # 4 sigma
    expected = np.sqrt(res.noise ** 2 + res.resolution ** 2 / 12)
    np.testing.assert_allclose(Theta.std(axis=0), expected, rtol=0.045)
    np.testing.assert_allclose(Theta.mean(axis=0), 0, atol=4 * expected / np.sqrt(4000))


def test_brakes_hold_until_the_first_command(desc):
    sim = motors.SimulatedMotors(desc, dyn.MassParameters(),
                                 resolver=motors.ResolverParameters(noise=0))
    for _ in range(100):
        sim.step()
    np.testing.assert_array_equal(sim.read()[0], 0)
    sim.set_command([0, 0, 0])
    for _ in range(100):
        sim.step()
    # a damper alone does not hold gravity: the arms sink (theta down)
    assert np.all(sim.read()[0] > 0)


def test_joint_effects_hook_sits_between_joint_and_reading(desc):
    offset = np.array([1e-3, 0, -2e-3])
    sim = motors.SimulatedMotors(desc, dyn.MassParameters(),
                                 resolver=motors.ResolverParameters(noise=0),
                                 joint_effects=lambda alpha, dalpha: alpha - desc.theta0 + offset)
    q = sim.resolver.resolution
    np.testing.assert_allclose(sim.read()[0], np.round(offset / q) * q)


def move_to(sim, controller, goal, steps):
    """Run the 1 kHz closed loop for ``steps`` periods, ``goal`` given after the first reading."""
    for k in range(steps):
        Theta, dTheta = sim.read()
        ref, _ = controller.update(k * sim.dt, Theta, dTheta)
        if k == 0:
            controller.add_goal(goal, 0.0)
        sim.set_command(ref)
        sim.step()


def test_closed_loop_reaches_a_goal_within_the_resolver_resolution(desc):
    """
    Check that the closed loop reaches a goal within the resolver resolution.

    Controller and robot share geometry and masses: at rest after the move, the joint error is the
    static loop's: the readings' quantisation and noise (a few counts), so the effector is within
    |J| * 4 counts of the goal (|J| < 1.2 m/rad here).
    """
    mass = dyn.MassParameters()
    sim = motors.SimulatedMotors(desc, mass, rng=np.random.default_rng(7))
    c = ctl.MotionController(desc, mass, max_speed=2.0, max_acceleration=4 * dyn.G)
    goal = np.array([-0.2, 0.2, 0.75])
    move_to(sim, c, goal, 700)
    P, dP = sim.effector()
    J = delta.jacobian(desc, P)
    bound = np.linalg.norm(J, 2) * 4 * sim.resolver.resolution
    assert np.linalg.norm(P - goal) < bound, (np.linalg.norm(P - goal), bound)
    assert np.linalg.norm(dP) < 0.01


def test_a_calibrated_models_joint_effects_bring_the_robot_to_the_goal(desc):
    """
    Check that a calibrated model's joint effects bring the robot to the goal.

    The truth has a gear error and backlash; a controller whose description carries them reaches
    the goal within the loop's resolution, one without them misses it by more.
    """
    truth = sim_truth.with_effects(sim_truth.load(), joint_scale=[5e-3, -4e-3, 4e-3],
                                   backlash=[1e-3, 6e-4, 8e-4])
    # the truth scales the reading, (1 + s)(motor - theta0); the model scales the angle:
    # k = 1/(1 + s) - 1
    scale = (1 / (1 + np.array([5e-3, -4e-3, 4e-3])) - 1).tolist()
    calibrated = truth.geometry.copy(effects=[{'name': 'joint_scale', 'scale': scale},
                                              {'name': 'backlash', 'width': [1e-3, 6e-4, 8e-4]}])
    goal = np.array([-0.2, 0.2, 0.75])
    errors = []
    for model in (calibrated, truth.geometry):
        mass = motors.true_masses(truth)
        sim = motors.SimulatedMotors(truth.geometry, mass, rng=np.random.default_rng(8),
                                     joint_effects=sim_truth.JointReadings(truth))
        c = ctl.MotionController(model, mass, max_speed=2.0, max_acceleration=4 * dyn.G)
        move_to(sim, c, goal, 800)
        errors.append(np.linalg.norm(sim.effector()[0] - goal))
    bound = (np.linalg.norm(delta.jacobian(truth.geometry, goal), 2) * 4
             * motors.ResolverParameters().resolution)
    assert errors[0] < bound < errors[1], (errors, bound)


def test_batch_motors_step_as_the_scalar_motors_do(desc):
    """
    Check that the batch motors step as the scalar motors do.

    BatchMotors is SimulatedMotors vectorised: the same commands give the same arms, readings
    and effector, to rounding (the two evaluate the dynamics with different code).
    """
    truth = sim_truth.load()
    mass = motors.true_masses(truth)
    start = np.array([[0.0, 0.0, 0.0], [0.1, -0.05, 0.2], [-0.1, 0.15, 0.05]])
    resolver = motors.ResolverParameters(noise=0.0)
    batch = motors.BatchMotors(truth.geometry, mass, start, resolver=resolver)
    scalar = [motors.SimulatedMotors(truth.geometry, mass, resolver=resolver, Theta_start=s)
              for s in start]
    rng = np.random.default_rng(2)
    for k in range(200):
        readings = batch.read()
        np.testing.assert_allclose(readings[0], [m.read()[0] for m in scalar], atol=1e-12)
        if k >= 20:                                      # brakes on for the first 20 ms
            command = rng.normal(scale=0.5, size=(3, 3))
            batch.set_command(command)
            for m, c in zip(scalar, command):
                m.set_command(c)
        batch.step()
        for m in scalar:
            m.step()
    np.testing.assert_allclose(batch.alpha, [m.alpha for m in scalar], atol=1e-10)
    np.testing.assert_allclose(batch.effector(), [m.effector()[0] for m in scalar], atol=1e-10)
    assert np.ptp(batch.alpha, axis=0).min() > 0.01     # the robots did move, differently


def test_a_step_is_the_vectorised_reference_step_to_rounding():
    """
    SimulatedMotors.step (the dynamics written out in floats) against RK4 on forward_dynamics.

    The reference evaluates the same equations with numpy's matrices: one step from 300 random
    states and commands agrees to a few units of the last place (double precision: 2.2e-16
    relative), and far below a resolver count (3.8e-5 rad).
    """
    truth = sim_truth.load()
    geometry, mass = truth.geometry, motors.true_masses(truth)
    rng = np.random.default_rng(4)
    for _ in range(300):
        sim = motors.SimulatedMotors(geometry, mass)
        sim.alpha = list(geometry.theta0 + rng.uniform(-0.3, 0.6, 3))
        sim.dalpha = list(rng.normal(scale=2.0, size=3))
        command = rng.normal(scale=2.0, size=3)
        sim.set_command(command)
        alpha, dalpha = np.array(sim.alpha), np.array(sim.dalpha)
        sim.step()
        K, limit = sim.drives.K_V, sim.drives.torque_limit

        def reference(t, a, d):
            tau = np.clip(K * (command - np.asarray(d)), -limit, limit)
            return dyn.forward_dynamics(geometry, mass, a, d, tau)
        want_alpha, want_dalpha = motors.rk4_step(reference, 0.0, alpha, dalpha, sim.dt)
        np.testing.assert_allclose(sim.alpha, want_alpha, rtol=0, atol=1e-15)
        np.testing.assert_allclose(sim.dalpha, want_dalpha, rtol=1e-14, atol=1e-14)


def test_readings_are_the_truth_s_increments_quantised(desc):
    """The float readings against numpy's: Truth.increments, noise, rounding half to even."""
    truth = sim_truth.with_effects(sim_truth.load(), backlash=[1e-3, 6e-4, 8e-4],
                                   joint_scale=[5e-3, -4e-3, 4e-3])
    mass = motors.true_masses(truth)
    sim = motors.SimulatedMotors(truth.geometry, mass, rng=np.random.default_rng(1),
                                 joint_effects=sim_truth.JointReadings(truth))
    noise, direction = np.random.default_rng(1), np.ones(3)
    q = sim.resolver.resolution
    commands = np.random.default_rng(2).normal(scale=1.0, size=(40, 3))
    last = np.round(truth.increments(np.asarray(sim.alpha), direction, None) / q) * q
    for k in range(400):
        direction = np.where(np.abs(sim.dalpha) > 0.02, np.sign(sim.dalpha), direction)
        want = np.round((truth.increments(np.asarray(sim.alpha), direction, None)
                         + noise.normal(scale=sim.resolver.noise, size=3)) / q) * q
        Theta, dTheta = sim.read()
        np.testing.assert_array_equal(Theta, want)
        np.testing.assert_array_equal(dTheta, (want - last) / sim.dt)
        last = want
        sim.set_command(commands[k // 10])
        sim.step()
