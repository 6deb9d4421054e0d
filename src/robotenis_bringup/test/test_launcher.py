"""The launcher starts processes, reports one that dies, and stops the rest in order."""
import io
import os
import signal
import stat
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
