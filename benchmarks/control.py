"""
The dynamics paper's two experiments, on the simulated robot (no ROS): figures and PNG plots.

1. Section II.A: test motion (0,0,750) -> (-200,200,750) mm, 2 m/s, 4 g. Torques of the full model
   (massive forearms, eq. 7) and of the massless-forearm simplification against a reference:
   without ADAMS, the torques the drives actually apply while the simulated full mechanism
   (RK4, 1 kHz) follows the motion under the controller. Paper: 12 % (model vs ADAMS),
   48 % (massless vs ADAMS).
2. Section III: 20 chained 4-5-6-7 segments of 250-300 mm at up to 4 m/s and 10 g. Tracking error
   as the paper measures it (desired position vs forward kinematics of the resolver readings) and
   the true error (simulator ground truth). Paper: under 10 mm. The simulated robot is the default
   truth (Table 1 calibrated geometry, its masses); the controller uses the nominal description,
   then the true geometry (a perfect calibration).

Writes report/control_torques.png and report/control_motion.png.
"""
import os

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from robotenis_control import controller as ctl  # noqa: E402
from robotenis_control import dynamics as dyn  # noqa: E402
from robotenis_control import trajectory as tr  # noqa: E402
from robotenis_kinematics import delta, description, workspace  # noqa: E402
from robotenis_sim import motors, truth as sim_truth  # noqa: E402

REPORT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'report')


def run(true_geometry, true_mass, ctl_desc, ctl_mass, waypoints, v_max, a_max, settle=0.3, seed=1):
    """
    Run the closed loop at 1 kHz: controller tick, drives and dynamics.

    Returns a dict of time series.
    """
    sim = motors.SimulatedMotors(true_geometry, true_mass, rng=np.random.default_rng(seed))
    c = ctl.MotionController(ctl_desc, ctl_mass, max_speed=v_max, max_acceleration=a_max)
    # the controller starts from where the robot is: the chain too
    waypoints = np.vstack([c.update(0.0, sim.read()[0])[1], waypoints[1:]])
    chain = tr.Chain(waypoints, v_max, a_max)
    for P in waypoints[1:]:
        c.add_goal(P, 0.0)
    n = int((chain.t1 + settle) / sim.dt)
    out = {k: np.empty((n, 3)) for k in ('P_true', 'P_est', 'tau', 'tau_d')}
    for k in range(n):
        t = k * sim.dt
        Theta, dTheta = sim.read()
        ref, P_est = c.update(t, Theta, dTheta)
        sim.set_command(ref)
        out['P_est'][k], out['P_true'][k] = P_est, sim.effector()[0]
        out['tau'][k] = sim.torque(sim.dalpha)
        P_d, dP_d, ddP_d, _ = chain.sample(t)
        out['tau_d'][k] = c.model.inverse_dynamics(P_d[0], dP_d[0], ddP_d[0])[2]
        sim.step()
    out['t'] = np.arange(n) * sim.dt
    out['P_d'], out['V_d'], out['A_d'], _ = chain.sample(out['t'])
    return out


def relative_difference(tau, ref):
    """Largest |tau - ref| over the motion as a fraction of the reference's peak, worst joint."""
    return float(np.max(np.abs(tau - ref).max(axis=0) / np.abs(ref).max(axis=0)))


def torque_study(desc):
    mass = dyn.MassParameters()
    points = np.array([[0, 0, 0.75], [-0.2, 0.2, 0.75]])
    full = run(desc, mass, desc, mass, points, 2.0, 4 * dyn.G, settle=0.1)
    ref = full['tau']
    massless = run(desc, mass, desc, mass.massless_forearms(), points, 2.0, 4 * dyn.G, settle=0.1)
    tau_massless = dyn.inverse_dynamics(desc, mass.massless_forearms(), full['P_d'], full['V_d'],
                                        full['A_d']).tau
    d_full, d_massless = (relative_difference(full['tau_d'], ref),
                          relative_difference(tau_massless, ref))
    err_massless = np.linalg.norm(massless['P_true'] - massless['P_d'], axis=1).max()
    err_full = np.linalg.norm(full['P_true'] - full['P_d'], axis=1).max()
    print('1. test motion (0,0,750) -> (-200,200,750) mm, 2 m/s, 4 g; '
          'reference: drive torques of the simulated full mechanism')
    print(f'   full model (massive forearms):    largest difference {100 * d_full:5.1f} % '
          f'of peak torque   (paper vs ADAMS: 12 %)')
    print(f'   massless-forearm simplification: largest difference {100 * d_massless:5.1f} % '
          f'of peak torque   (paper: 48 %)')
    print(f'   peak reference torque {np.abs(ref).max():.1f} N m; '
          f'tracking error with full / massless feedforward '
          f'{err_full * 1e3:.2f} / {err_massless * 1e3:.2f} mm')
    fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for j, color in enumerate('rgb'):
        axes[0].plot(full['t'], ref[:, j], color, label=f'drive (reference) {j + 1}')
        axes[0].plot(full['t'], full['tau_d'][:, j], color + '--', label=f'full model {j + 1}')
        axes[0].plot(full['t'], tau_massless[:, j], color + ':',
                     label=f'massless forearms {j + 1}')
        axes[1].plot(full['t'], full['tau_d'][:, j] - ref[:, j], color + '--')
        axes[1].plot(full['t'], tau_massless[:, j] - ref[:, j], color + ':')
    axes[0].set_ylabel('joint torque (N m)')
    axes[0].legend(fontsize=7, ncol=3)
    axes[1].set_ylabel('model - reference (N m)')
    axes[1].set_xlabel('time (s)')
    fig.suptitle('Test motion: full model (--) and massless forearms (:) '
                 'against the simulated mechanism')
    fig.savefig(os.path.join(REPORT, 'control_torques.png'), dpi=110)
    plt.close(fig)


def demanding_waypoints(desc, n=20, seed=3):
    """
    Draw n + 1 points in the workspace, each 250-300 mm from the last, 10 cm from any singularity.

    At 4 m/s a segment then lasts about 0.15 s, and 20 of them about 3 s, as in the paper.
    """
    rng = np.random.default_rng(seed)
    region = workspace.Workspace()
    points = [np.array([0.0, 0.0, 0.751])]
    while len(points) <= n:
        P = np.array([rng.uniform(-0.35, 0.35), rng.uniform(-0.35, 0.35), rng.uniform(0.65, 1.0)])
        if 0.25 <= np.linalg.norm(P - points[-1]) <= 0.30 and region.contains(desc, P) \
                and delta.singularity_distance(desc, P) > 0.1:
            points.append(P)
    return np.array(points)


def motion_study(nominal):
    truth = sim_truth.load()
    mass = motors.true_masses(truth)
    points = demanding_waypoints(nominal)
    v_max, a_max = 4.0, 10 * dyn.G
    print(f'2. demanding motion: 20 chained segments of 250-300 mm, v_max {v_max} m/s, '
          'a_max 10 g; robot: default truth')
    runs = {}
    for label, desc in (('nominal description', nominal),
                        ('true geometry (perfect calibration)', truth.geometry)):
        out = run(truth.geometry, mass, desc, dyn.MassParameters(), points, v_max, a_max)
        moving = out['t'] <= out['t'][-1] - 0.3
        e_est = np.linalg.norm(out['P_est'] - out['P_d'], axis=1)
        e_true = np.linalg.norm(out['P_true'] - out['P_d'], axis=1)
        print(f'   {label:37s}: duration {out["t"][moving][-1]:.2f} s, peak speed '
              f'{np.linalg.norm(out["V_d"], axis=1).max():.2f} m/s, '
              f'peak acc {np.linalg.norm(out["A_d"], axis=1).max() / dyn.G:.1f} g, '
              f'peak torque {np.abs(out["tau"]).max():.0f} N m')
        print(f'   {"":37s}  tracking error (paper\'s measure, FK of readings) '
              f'max {e_est.max() * 1e3:.2f} mm, '
              f'rms {np.sqrt(np.mean(e_est[moving] ** 2)) * 1e3:.2f} mm; '
              f'true error max {e_true.max() * 1e3:.2f} mm, '
              f'at rest {e_true[-1] * 1e3:.2f} mm  (paper: < 10 mm)')
        runs[label] = (out, e_est, e_true)
    out, e_est, e_true = runs['nominal description']
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
    for j, name in enumerate('xyz'):
        axes[0].plot(out['t'], out['P_d'][:, j] * 1e3, label=f'{name} desired')
        axes[0].plot(out['t'], out['P_true'][:, j] * 1e3, '--', label=f'{name} true')
    axes[0].set_ylabel('position (mm)')
    axes[0].legend(fontsize=7, ncol=3)
    speed = np.linalg.norm(np.gradient(out['P_true'], out['t'], axis=0), axis=1)
    axes[1].plot(out['t'], np.linalg.norm(out['V_d'], axis=1), label='desired')
    axes[1].plot(out['t'], speed, '--', label='true')
    axes[1].set_ylabel('speed (m/s)')
    axes[1].legend(fontsize=7)
    axes[2].plot(out['t'], e_est * 1e3, label='FK of readings (nominal) - desired')
    axes[2].plot(out['t'], e_true * 1e3, label='true - desired')
    # its chain starts where its FK puts the robot
    calibrated = runs['true geometry (perfect calibration)']
    axes[2].plot(calibrated[0]['t'], calibrated[2] * 1e3, label='true - desired, calibrated')
    axes[2].set_ylabel('error (mm)')
    axes[2].set_xlabel('time (s)')
    axes[2].legend(fontsize=7)
    fig.suptitle('20 chained trajectories, 4 m/s, 10 g (simulated RoboTenis, controller at 1 kHz)')
    fig.savefig(os.path.join(REPORT, 'control_motion.png'), dpi=110)
    plt.close(fig)


def main():
    os.makedirs(REPORT, exist_ok=True)
    nominal = description.nominal()
    torque_study(nominal)
    motion_study(nominal)
    print(f'plots: {os.path.join(REPORT, "control_torques.png")}, '
          f'{os.path.join(REPORT, "control_motion.png")}')


if __name__ == '__main__':
    main()
