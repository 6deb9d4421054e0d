"""The launcher starts processes, reports one that dies, and stops the rest in order."""
import io
import os
import re
import signal
import stat
import subprocess
import sys
import time

import pytest
from robotenis_bringup.launch_file import NodeSpec
from robotenis_bringup.launcher import Launcher

SLEEPER = """#!/usr/bin/env python3
import signal, sys, time
signal.signal(signal.SIGINT, lambda *a: (print("clean exit", flush=True), sys.exit(0)))
print("running", sys.argv[1:], flush=True)
while True:
    time.sleep(0.05)
"""
CRASHER = """#!/usr/bin/env python3
import sys
print("something went wrong", flush=True)
sys.exit(3)
"""


def install(prefix, package, name, text):
    folder = prefix / package / 'lib' / package
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IEXEC)


@pytest.fixture
def prefix(tmp_path):
    install(tmp_path / 'install', 'pkg', 'sleeper', SLEEPER)
    install(tmp_path / 'install', 'pkg', 'crasher', CRASHER)
    return tmp_path


def test_parameters_reach_the_node_and_sigint_stops_it_cleanly(prefix):
    out = io.StringIO()
    node = NodeSpec('a', 'pkg', 'sleeper', namespace='robot1', param_files=['/p.yaml'],
                    parameters={'truth_path': '/x.yaml', 'guess': [0.5, 1.0], 'on': True},
                    remaps=[('joint_states', 'js')])
    launcher = Launcher([node], str(prefix / 'install'), str(prefix / 'log'), out)
    launcher.start()
    time.sleep(0.5)
    launcher.stop()
    log = (prefix / 'log' / 'a.log').read_text()
    assert ("'-r', '__node:=a', '-r', '__ns:=/robot1', '--params-file', '/p.yaml', "
            "'-p', 'truth_path:=/x.yaml', '-p', 'guess:=[0.5, 1.0]', '-p', 'on:=true', "
            "'-r', 'joint_states:=js'") in log and 'clean exit' in log
    assert 'stopped a (exit code 0)' in out.getvalue()


def test_a_dying_node_is_reported_with_its_log(prefix):
    out = io.StringIO()
    launcher = Launcher([NodeSpec('ok', 'pkg', 'sleeper'), NodeSpec('bad', 'pkg', 'crasher')],
                        str(prefix / 'install'), str(prefix / 'log'), out)
    launcher.start()
    launcher.wait(stop_when_one_dies=True)
    text = out.getvalue()
    assert 'node bad died with exit code 3' in text and 'something went wrong' in text
    assert 'stopped ok' in text and launcher.dead == [('bad', 3)]


def test_sigterm_stops_everything(prefix):
    out = io.StringIO()
    launcher = Launcher([NodeSpec('a', 'pkg', 'sleeper'), NodeSpec('b', 'pkg', 'sleeper')],
                        str(prefix / 'install'), str(prefix / 'log'), out)
    launcher.start()
    signal.setitimer(signal.ITIMER_REAL, 0.5)
    old = signal.signal(signal.SIGALRM, lambda *a: os.kill(os.getpid(), signal.SIGTERM))
    try:
        launcher.wait()
    finally:
        signal.signal(signal.SIGALRM, old)
    assert launcher.procs == {}
    assert out.getvalue().count('(exit code 0)') == 2


def test_missing_node_is_named(prefix):
    launcher = Launcher([NodeSpec('x', 'pkg', 'nothere')], str(prefix / 'install'),
                        str(prefix / 'log'), io.StringIO())
    with pytest.raises(FileNotFoundError, match="node 'x'.*not installed"):
        launcher.start()


SHUTDOWN_CRASHER = """#!/usr/bin/env python3
import signal, sys, time
signal.signal(signal.SIGINT, lambda *a: (print("crash on shutdown", flush=True), sys.exit(1)))
print("running", flush=True)
while True:
    time.sleep(0.05)
"""
PLAIN_SLEEPER = """#!/usr/bin/env python3
import time
print("running", flush=True)
while True:
    time.sleep(0.05)
"""
# s: the fakes start at once and answer SIGINT at once; the launcher looks every 0.1 s and waits
# at most 5 s per signal when stopping, so 10 s is only reached if it hangs.
BOUND_S = 10.0


def wait_for(path, text, deadline):
    """Return the file's text once it holds ``text`` (AssertionError past the deadline)."""
    while time.monotonic() < deadline:
        content = path.read_text()
        if text in content:
            return content
        time.sleep(0.05)
    raise AssertionError(f'{text!r} not in {path}:\n{path.read_text()}')


def run_launch(prefix, nodes, kill=None):
    """
    Run ``robotenis launch`` on a launch file of ``nodes`` ((name, exec) pairs), then Ctrl-C it.

    ``kill``: the node killed by PID (SIGKILL) first. Returns (exit status, stderr); every process
    started is gone when it returns, even on failure.
    """
    install(prefix / 'install', 'pkg', 'shutdown_crasher', SHUTDOWN_CRASHER)
    install(prefix / 'install', 'pkg', 'plain_sleeper', PLAIN_SLEEPER)
    launch = prefix / 'fake.launch.yaml'
    launch.write_text('launch:\n' + ''.join(f'- node: {{pkg: pkg, exec: {e}, name: {n}}}\n'
                                            for n, e in nodes))
    err = prefix / 'stderr.txt'
    env = dict(os.environ, ROBOTENIS_TOP=str(prefix))
    with open(err, 'w') as f:
        proc = subprocess.Popen([sys.executable, '-m', 'robotenis_bringup.launch_cli',
                                 str(launch)], stderr=f, env=env)
    try:
        deadline = time.monotonic() + BOUND_S
        for name, _ in nodes:       # each node's handler is set once it says 'running'
            text = wait_for(err, f'started {name} (pid ', deadline)
            wait_for(prefix / 'log' / 'launch' / f'{name}.log', 'running', deadline)
        if kill is not None:
            os.kill(int(re.search(rf'started {kill} \(pid (\d+)\)', text).group(1)),
                    signal.SIGKILL)
            wait_for(err, f'node {kill} died', deadline)
        proc.send_signal(signal.SIGINT)
        return proc.wait(timeout=BOUND_S), err.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid in re.findall(r'\(pid (\d+)\)', err.read_text()):
            try:
                os.kill(int(pid), signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_launch_exits_0_when_every_node_ran_and_stopped_cleanly(prefix):
    """A node without a SIGINT handler dies of the signal (exit code -2): a clean stop too."""
    status, err = run_launch(prefix, [('a', 'sleeper'), ('d', 'plain_sleeper')])
    assert status == 0 and 'stopped d (exit code -2)' in err, err


def test_launch_exits_non_zero_naming_a_node_killed_by_pid(prefix):
    status, err = run_launch(prefix, [('a', 'sleeper'), ('b', 'sleeper')], kill='b')
    assert status == 1 and 'robotenis launch: b died (exit code -9)' in err, err


def test_launch_exits_non_zero_naming_a_node_that_crashed_on_shutdown(prefix):
    status, err = run_launch(prefix, [('a', 'sleeper'), ('c', 'shutdown_crasher')])
    assert status == 1 and 'robotenis launch: c exited with code 1 when stopped' in err, err
