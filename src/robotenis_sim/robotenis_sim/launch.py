"""`./robotenis launch`: start the RoboTenis nodes as separate processes, as `ros2 launch` would.

Each node runs as its own process (its console script, with ``--ros-args`` parameters), logs to
``log/launch/<node>.log``; when one dies the launcher says so with its exit code and the tail of its
log, and Ctrl-C or SIGTERM stops all of them (SIGINT first, then SIGTERM, then SIGKILL).
"""
import argparse
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field

CAMERA_RATE = 120.0   # Hz: the hand camera (the paper's 8.34 ms frames)


@dataclass
class NodeSpec:
    """One node to start: the package and console script, and its ROS parameters."""

    name: str
    package: str
    executable: str
    parameters: dict = field(default_factory=dict)

    def command(self, prefix):
        exe = os.path.join(prefix, self.package, 'lib', self.package, self.executable)
        args = [exe, '--ros-args', '-r', f'__node:={self.name}']
        for key, value in self.parameters.items():
            args += ['-p', f'{key}:={value}']
        return args


def default_nodes(truth_path, description_path, sim_time=False, calibration=True, extra=None, tracker=False):
    """The simulated system: motors and hand camera (truth), detector, controller, calibration service,
    and with ``tracker`` the visual servo (pbvs_tracker: keeps the ball centred through the controller's
    velocity mode).

    Wall clock by default. With ``sim_time`` the simulator owns /clock and steps in lockstep with the
    controller (it waits for the command answering each reading), and every other node runs on
    /clock: a session takes as long as the CPU needs, and the 1 kHz loop keeps its 1 ms delay
    whatever the load. (Free-running at half speed was measured unstable here: the executor's timer
    jitter made the simulator catch up in bursts of up to 10 ms with a stale command.) With the
    tracker on simulated time the visual loop is in lockstep too: the camera exposes on the
    simulator's samples and the simulator waits for each frame's command for up to one frame period
    (sim_motors' visual lockstep), else the loop's delay in simulated time would grow with the load.
    ``extra`` adds or overrides parameters per node name.
    """
    clock = {'use_sim_time': 'true'} if sim_time else {}
    truth = {'truth_path': truth_path} if truth_path else {}
    desc = {'description_path': description_path}
    motors = {'publish_clock': 'true', 'lockstep': 'true', 'speed': '0.0', 'clock_decimation': '4'} if sim_time else {}
    ticks = {'tick_on_joint_states': 'true'} if sim_time else {}
    camera = {}
    if sim_time and tracker:
        motors.update(camera_rate=str(CAMERA_RATE), visual_delay=str(1.0 / CAMERA_RATE))
        camera.update(rate=str(CAMERA_RATE), tick_on_effector='true')
    nodes = [
        NodeSpec('sim_motors', 'robotenis_sim', 'sim_motors', {**truth, **motors}),
        NodeSpec('hand_camera', 'robotenis_sim', 'hand_camera', {**truth, **clock, **camera}),
        NodeSpec('sphere_detector', 'robotenis_vision', 'sphere_detector', {**desc, **clock}),
        NodeSpec('motion_controller', 'robotenis_control', 'motion_controller', {**desc, **clock, **ticks}),
    ]
    if calibration:
        nodes.append(NodeSpec('calibration', 'robotenis_calibration', 'calibration', {**desc, **clock}))
    if tracker:
        nodes.append(NodeSpec('pbvs_tracker', 'robotenis_control', 'pbvs_tracker', {**desc, **clock}))
    for node in nodes:
        node.parameters.update((extra or {}).get(node.name, {}))
    return nodes


class Launcher:
    """Start, watch and stop a set of node processes."""

    def __init__(self, nodes, prefix, log_dir, out=sys.stderr, env=None):
        """env: the nodes' environment (default this process's), e.g. with a ROS_DOMAIN_ID of their own."""
        self.nodes, self.prefix, self.log_dir, self.out, self.env = nodes, prefix, log_dir, out, env
        self.procs = {}

    def say(self, text):
        print(f'[launch] {text}', file=self.out, flush=True)

    def start(self):
        os.makedirs(self.log_dir, exist_ok=True)
        for node in self.nodes:
            cmd = node.command(self.prefix)
            if not os.path.exists(cmd[0]):
                self.stop()
                raise FileNotFoundError(f"node '{node.name}': {cmd[0]} is not installed (build the workspace)")
            log = open(os.path.join(self.log_dir, f'{node.name}.log'), 'w')
            # Own process group: a Ctrl-C in the terminal reaches the launcher, which stops nodes in order.
            self.procs[node.name] = (subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                                      start_new_session=True), log)
            self.say(f'started {node.name} (pid {self.procs[node.name][0].pid}), log {log.name}')

    def check(self):
        """Names of nodes that have exited since the last check (each reported once)."""
        dead = []
        for name, (proc, log) in list(self.procs.items()):
            if proc.poll() is not None:
                log.close()
                self.say(f'node {name} died with exit code {proc.returncode}; last lines of its log:')
                with open(log.name) as f:
                    for line in f.readlines()[-10:]:
                        self.say('  ' + line.rstrip())
                del self.procs[name]
                dead.append(name)
        return dead

    def stop(self, timeout=5.0):
        """SIGINT, then SIGTERM, then SIGKILL whatever is still running."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            alive = [(n, p) for n, (p, _) in self.procs.items() if p.poll() is None]
            if not alive:
                break
            for _, proc in alive:
                proc.send_signal(sig)
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline and any(p.poll() is None for _, p in alive):
                time.sleep(0.05)
        for name, (proc, log) in self.procs.items():
            log.close()
            self.say(f'stopped {name} (exit code {proc.poll()})')
        self.procs = {}

    def wait(self, stop_when_one_dies=False):
        """Watch the nodes until a signal (or, optionally, the first death)."""
        stopping = []
        handler = lambda signum, frame: stopping.append(signum)  # noqa: E731 - set a flag, act in the loop
        old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            while not stopping and self.procs:
                if self.check() and stop_when_one_dies:
                    break
                time.sleep(0.1)
        finally:
            for s, h in old.items():
                signal.signal(s, h)
            self.stop()


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis launch', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--truth', default='', help="the simulator's truth file (default: Table 1, no effects)")
    parser.add_argument('--description', default='', help='robot description the system uses (default: nominal)')
    parser.add_argument('--sim-time', action='store_true',
                        help='run on the simulator clock (/clock), simulator and controller in lockstep')
    args = parser.parse_args(argv)
    from robotenis_kinematics import description
    desc_path = os.path.abspath(args.description) if args.description else description.config_path('nominal.yaml')
    truth_path = os.path.abspath(args.truth) if args.truth else ''
    top = os.environ.get('ROBOTENIS_TOP', os.getcwd())
    launcher = Launcher(default_nodes(truth_path, desc_path, args.sim_time), os.path.join(top, 'install'),
                        os.path.join(top, 'log', 'launch'))
    try:
        launcher.start()
    except FileNotFoundError as e:
        print(f'robotenis launch: {e}', file=sys.stderr)
        return 2
    launcher.wait()
    return 0


if __name__ == '__main__':
    sys.exit(main())
