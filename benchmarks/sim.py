"""
Benchmark: the simulator's real-time factor at 1 kHz, and the hand camera's render time.

Real-time factor = simulated seconds per wall second of robotenis_sim.motors.SimulatedMotors: RK4
at 1 ms on the Lagrangian dynamics with massive forearms, drives (eq. 10) and resolvers, holding a
velocity command that swings the arms (no ROS). Target: at least 3 on this 2-core machine.
Baseline, same process, same step: RK4 on the vectorised numpy forward dynamics
(robotenis_control.dynamics.forward_dynamics) and scipy's solve_ivp (RK45) over each 1 ms period.
"""
import time

import numpy as np
from robotenis_control import dynamics as dyn
from robotenis_kinematics import description
from robotenis_sim import motors
from scipy.integrate import solve_ivp

TARGET_RTF = 3.0
SIM_SECONDS = 2.0


def command(t):
    """Return a swinging joint-speed command, rad/s: keeps the arms moving over the whole run."""
    return 0.8 * np.sin(2 * np.pi * 1.5 * t + np.array([0.0, 2.1, 4.2]))


def ours(desc, mass, seconds):
    sim = motors.SimulatedMotors(desc, mass, rng=np.random.default_rng(0))
    start = time.perf_counter()
    for k in range(int(round(seconds / sim.dt))):
        sim.set_command(command(k * sim.dt))
        sim.step()
        sim.read()
    return seconds / (time.perf_counter() - start), np.array(sim.alpha)


def numpy_rk4(desc, mass, seconds, dt=1e-3):
    drives = motors.DriveParameters()
    alpha, dalpha = np.array(desc.theta0, dtype=float), np.zeros(3)
    start = time.perf_counter()
    for k in range(int(round(seconds / dt))):
        ref = command(k * dt)

        def f(a, d):
            tau = np.clip(drives.K_V * (ref - d), -drives.torque_limit, drives.torque_limit)
            return dyn.forward_dynamics(desc, mass, a, d, tau)

        k1v, k1a = dalpha, f(alpha, dalpha)
        k2v = dalpha + dt / 2 * k1a
        k2a = f(alpha + dt / 2 * k1v, k2v)
        k3v = dalpha + dt / 2 * k2a
        k3a = f(alpha + dt / 2 * k2v, k3v)
        k4v = dalpha + dt * k3a
        k4a = f(alpha + dt * k3v, k4v)
        alpha = alpha + dt / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        dalpha = dalpha + dt / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
    return seconds / (time.perf_counter() - start), alpha


def scipy_ivp(desc, mass, seconds, dt=1e-3):
    drives = motors.DriveParameters()
    x = np.concatenate([desc.theta0, np.zeros(3)])
    start = time.perf_counter()
    for k in range(int(round(seconds / dt))):
        ref = command(k * dt)

        def f(t, x):
            tau = np.clip(drives.K_V * (ref - x[3:]), -drives.torque_limit, drives.torque_limit)
            return np.concatenate([x[3:], dyn.forward_dynamics(desc, mass, x[:3], x[3:], tau)])

        x = solve_ivp(f, (0.0, dt), x, rtol=1e-8, atol=1e-10).y[:, -1]
    return seconds / (time.perf_counter() - start), x[:3]


def camera_figure(frames=200, target_ms=4.0):
    """
    Render time per 640x480 frame of the hand camera (robotenis_sim.camera_model.render).

    The ball at 150-600 mm in the default scene, one core: CPU time of this process per frame (the
    machine is shared, so wall times carry the other processes), wall median and minimum. Baseline
    in the same process: full-frame noise and blur, the least a renderer that touches every pixel
    pays.
    """
    import cv2
    from robotenis_sim import camera_model
    from robotenis_vision import camera
    cv2.setNumThreads(1)
    cam, rng = camera.default(), np.random.default_rng(1)
    centres = [np.array([0.02 * np.sin(k), 0.015 * np.cos(k), 0.15 + 0.45 * (k % 10) / 9])
               for k in range(frames)]
    camera_model.render(cam, centres[0], 0.019, rng)  # builds the per-camera caches

    def run(fn, items):
        wall, cpu = [], time.process_time()
        for item in items:
            t = time.perf_counter()
            fn(item)
            wall.append(time.perf_counter() - t)
        return ((time.process_time() - cpu) / len(items) * 1e3, np.median(wall) * 1e3,
                np.min(wall) * 1e3)

    def floor(_):
        frame = np.full((cam.height, cam.width), 100.0, np.float32)
        frame += 2.0 * rng.standard_normal(frame.shape, dtype=np.float32)
        return np.clip(cv2.GaussianBlur(frame, (0, 0), 0.8), 0, 255).astype(np.uint8)

    cpu, med, low = run(lambda c: camera_model.render(cam, c, 0.019, rng), centres)
    base = run(floor, centres[:frames // 4])[0]
    # the same ball again gets only fresh noise (camera_model._Still), as an emulated rest draws
    still = run(lambda c: camera_model.render(cam, c, 0.019, rng), [centres[3]] * (frames // 4))
    print(f'hand camera render: {cpu:.2f} ms CPU per 640x480 frame '
          f'(wall median {med:.2f}, minimum {low:.2f}; '
          f'target < {target_ms:.0f} ms: {"met" if cpu < target_ms else "NOT met"}); '
          f'baseline full-frame noise + blur: {base:.2f} ms CPU; the same ball again: '
          f'{still[0]:.2f} ms CPU')


def main():
    desc, mass = description.nominal(), dyn.MassParameters()
    rtf, alpha = ours(desc, mass, SIM_SECONDS)
    rtf_np, alpha_np = numpy_rk4(desc, mass, SIM_SECONDS / 4)
    rtf_ivp, alpha_ivp = scipy_ivp(desc, mass, SIM_SECONDS / 20)
    print(f'simulated motors, RK4 at 1 kHz, {SIM_SECONDS:.0f} s simulated '
          '(drives, resolvers, no ROS)')
    print(f'  robotenis_sim.motors (scalar model):      real-time factor {rtf:7.2f}')
    print(f'  baseline: numpy vectorised model, RK4:    real-time factor {rtf_np:7.2f}')
    print(f'  baseline: scipy solve_ivp RK45 per 1 ms:  real-time factor {rtf_ivp:7.2f}')
    print(f'real-time factor: {rtf:.2f}  '
          f'(target >= {TARGET_RTF:.0f}: {"met" if rtf >= TARGET_RTF else "NOT met"}; '
          f'{rtf / rtf_np:.1f}x the numpy baseline)')
    camera_figure()


if __name__ == '__main__':
    main()
