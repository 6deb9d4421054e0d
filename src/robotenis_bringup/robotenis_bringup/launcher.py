"""
Start, watch and stop node processes, as ``ros2 launch`` does.

Each node runs as its own process (its console script with ``--ros-args``) in its own process
group and logs to ``<log_dir>/<node>.log``; when one dies the launcher says so with its exit code
and the tail of its log, and Ctrl-C or SIGTERM stops all of them (SIGINT first, then SIGTERM, then
SIGKILL). ``failures`` names every node that did not end cleanly: one that died while the others
ran, and one that did not stop cleanly on SIGINT (it exited non-zero: it crashed on shutdown, or
needed SIGTERM or SIGKILL). Dying of the SIGINT itself (a node still starting up, before its
handler is set) is a clean stop.
"""
import os
import signal
import subprocess
import sys
import time

CLEAN_STOP = (0, -signal.SIGINT)    # exit codes of a node that stopped on SIGINT


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class Launcher:
    """Start, watch and stop the processes of a list of launch_file.NodeSpec."""

    def __init__(self, nodes, prefix, log_dir, out=sys.stderr, env=None):
        """Run nodes from ``prefix`` (the install folder) in ``env`` (default: ours)."""
        self.nodes, self.prefix, self.log_dir = nodes, prefix, log_dir
        self.out, self.env = out, env
        self.procs = {}
        self.dead = []              # (name, exit code) of the nodes that died, in order
        self.unclean = []           # (name, exit code) of the nodes that exited non-zero on stop

    def say(self, text):
        """Print one line of the launcher's own output."""
        print(f'[launch] {text}', file=self.out, flush=True)

    def start(self):
        """Start every node; FileNotFoundError (and nothing left running) if one is not built."""
        os.makedirs(self.log_dir, exist_ok=True)
        for node in self.nodes:
            cmd = node.command(self.prefix)
            if not os.path.exists(cmd[0]):
                self.stop()
                raise FileNotFoundError(f"node '{node.name}': {cmd[0]} is not installed "
                                        '(build the workspace)')
            log = open(os.path.join(self.log_dir, f'{node.name}.log'), 'w')
            # Own process group: a Ctrl-C in the terminal reaches the launcher only, which
            # then stops the nodes in order. SIGINT back to its default: a launcher started in
            # the background of a shell inherits it ignored, and Python then never installs its
            # handler, so the node would only stop on SIGTERM.
            proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                    start_new_session=True, preexec_fn=_default_sigint)
            self.procs[node.name] = (proc, log)
            self.say(f'started {node.name} (pid {proc.pid}), log {log.name}')

    def pid(self, name):
        """Return the process id of a running node."""
        return self.procs[name][0].pid

    def check(self):
        """Report and return the nodes that have exited since the last check."""
        dead = []
        for name, (proc, log) in list(self.procs.items()):
            if proc.poll() is not None:
                log.close()
                self.say(f'node {name} died with exit code {proc.returncode}; '
                         'last lines of its log:')
                with open(log.name) as f:
                    for line in f.readlines()[-10:]:
                        self.say('  ' + line.rstrip())
                del self.procs[name]
                self.dead.append((name, proc.returncode))
                dead.append(name)
        return dead

    def stop(self, timeout=5.0):
        """SIGINT, then SIGTERM, then SIGKILL whatever is still running."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            alive = [p for p, _ in self.procs.values() if p.poll() is None]
            if not alive:
                break
            for proc in alive:
                proc.send_signal(sig)
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline and any(p.poll() is None for p in alive):
                time.sleep(0.05)
        for name, (proc, log) in self.procs.items():
            log.close()
            self.say(f'stopped {name} (exit code {proc.poll()})')
            if proc.poll() not in CLEAN_STOP:
                self.unclean.append((name, proc.poll()))
        self.procs = {}

    @property
    def failures(self):
        """Return the sentences naming each node that did not end cleanly (empty: all did)."""
        return ([f'{name} died (exit code {code})' for name, code in self.dead]
                + [f'{name} exited with code {code} when stopped' for name, code in self.unclean])

    def wait(self, stop_when_one_dies=False):
        """Watch the nodes until a signal (or, optionally, the first death), then stop them all."""
        stopping = []

        def handler(signum, frame):
            stopping.append(signum)     # set a flag; the loop below acts on it
        old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            while not stopping and self.procs:
                if self.check() and stop_when_one_dies:
                    break
                time.sleep(0.1)
        finally:
            for s, h in old.items():
                signal.signal(s, h)
            self.check()                # a node that died since the last look is a death too
            self.stop()
