"""Parameters declared from one table; spinning until a clean stop, on either executor."""
import signal
import subprocess
import sys

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter

from robotenis_ros.node import declare_parameters, DeferredService, spin
from std_srvs.srv import Trigger

TABLE = {'rate': (1000.0, 'Hz'), 'name': ('x', 'a name'), 'gains': ([1.0, 2.0], 'two gains')}


def test_the_table_is_declared_with_its_defaults_overrides_and_descriptions():
    rclpy.init()
    try:
        overrides = [Parameter('rate', value=250.0)]
        node = rclpy.create_node('table_test', parameter_overrides=overrides)
        values = declare_parameters(node, TABLE, name='y')
        assert values == {'rate': 250.0, 'name': 'y', 'gains': [1.0, 2.0]}
        assert node.describe_parameter('gains').description == 'two gains'
        node.destroy_node()
    finally:
        rclpy.try_shutdown()


def failing_node(shut_down_first):
    """Return a node factory whose timer raises as rclpy does when a signal shut it down."""
    def make():
        node = rclpy.create_node('spin_test')

        def tick():
            if shut_down_first:
                rclpy.try_shutdown()   # what the signal handler does under a running callback
            raise RuntimeError('Unable to convert call argument')
        node.create_timer(0.01, tick)
        return node
    return make


@pytest.mark.parametrize('events', [False, True])
def test_an_error_after_the_context_was_shut_down_is_a_clean_stop(events):
    assert spin(failing_node(True), 'spin_test', events=events) == 0


@pytest.mark.parametrize('events', [False, True])
def test_an_error_while_the_context_is_alive_is_not_hidden(events):
    with pytest.raises(RuntimeError, match='Unable to convert'):
        spin(failing_node(False), 'spin_test', events=events)


SPINNER = """
import sys, rclpy
from robotenis_ros.node import spin
def make():
    node = rclpy.create_node('signal_test')
    node.create_timer(0.01, lambda: print('tick', flush=True))
    return node
sys.exit(spin(make, 'signal_test', events=True))
"""


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_a_node_on_the_events_executor_cleanly(sig):
    """Its spin() alone would not return on a signal: the slices let the signal through."""
    proc = subprocess.Popen([sys.executable, '-c', SPINNER], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == 'tick\n', 'the node did not spin'
        proc.send_signal(sig)
        assert proc.wait(timeout=5.0) == 0     # a slice (EVENTS_SLICE) and a node's shutdown
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize('make_executor', [SingleThreadedExecutor, EventsExecutor])
def test_a_deferred_service_answers_later_and_meanwhile_serves_other_requests(make_executor):
    """The first request is answered three timer ticks later; the second at once, meanwhile."""
    rclpy.init()
    try:
        server, client_node = rclpy.create_node('deferred'), rclpy.create_node('asker')
        pending, ticks = [], []

        def on_request(request, answer):
            if pending:
                answer(Trigger.Response(success=False, message='busy'))
            else:
                pending.append(answer)

        def tick():
            ticks.append(len(ticks))
            if pending and len(ticks) >= 3:
                pending.pop()(Trigger.Response(success=True, message=f'after {len(ticks)} ticks'))
        DeferredService(server, Trigger, 'deferred', on_request)
        server.create_timer(0.02, tick)
        executor = make_executor()
        executor.add_node(server)
        executor.add_node(client_node)
        client = client_node.create_client(Trigger, 'deferred')
        assert client.wait_for_service(timeout_sec=10.0)
        first = client.call_async(Trigger.Request())
        while not pending:
            executor.spin_once(timeout_sec=0.1)
        second = client.call_async(Trigger.Request())
        executor.spin_until_future_complete(second, timeout_sec=10.0)
        assert second.result().message == 'busy' and not first.done()
        executor.spin_until_future_complete(first, timeout_sec=10.0)
        assert first.result().success and first.result().message == f'after {len(ticks)} ticks'
        assert len(ticks) >= 3
        executor.shutdown()
    finally:
        rclpy.try_shutdown()
