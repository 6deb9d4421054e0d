"""
Running a node: parameters declared from one table, spinning with an ordered shutdown, services.

Each node module keeps its parameters in one table,
``PARAMETERS = {name: (default, description)}``, declared by ``declare_parameters``; launch files
are checked against these tables (robotenis_bringup's tests). A service whose answer takes long
(a calibration session) is a ``DeferredService``: answered later, without blocking the executor.
"""
import functools
import signal
import sys

from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.task import Future

# A latched topic (the robot description): the last message reaches late subscribers too.
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# s: the EventsExecutor is spun in slices this long, so that a signal stops it (see spin)
EVENTS_SLICE = 0.1


def declare_parameters(node, table, **defaults):
    """
    Declare the parameters of ``table`` not declared yet on ``node``; return all their values.

    ``defaults`` replace table defaults that the node works out at start (e.g. from a file that
    an earlier declared parameter names).
    """
    for name, (default, text) in table.items():
        if not node.has_parameter(name):
            node.declare_parameter(name, defaults.get(name, default),
                                   ParameterDescriptor(description=text))
    return {name: node.get_parameter(name).value for name in table}


def spin(make_node, name, fatal=(ValueError,), args=None, finish=None, events=False):
    """
    Run one node until Ctrl-C or shutdown; return the exit code.

    ``fatal`` errors raised while building the node (a bad parameter, an unreadable file) are
    printed as ``name: message`` and give exit code 2; a stop by signal gives 0, even when it
    interrupts a callback. Shutdown goes in the order rclpy needs:
    executor, ``finish(node)`` (e.g. close a file the node writes), node, context.

    The executor is a SingleThreadedExecutor, or with ``events`` rclpy's EventsExecutor, which
    takes and dispatches each message in C++: 2-3x less CPU per message (a JointState ping-pong
    between two processes here: 3600 round trips/s and 170 us of CPU per trip on each side,
    against 1100-1400/s and 350-490 us). For the nodes a message at 1 kHz wakes (the simulator,
    the controller in lockstep). It serves no coroutine (async) service callback and no guard
    condition, and its spin() does not return on SIGINT or SIGTERM: it is spun in slices of
    EVENTS_SLICE (until a future that never completes, so that a slice runs every callback due
    in it) while the context is up and no SIGINT came (its handler only notes it: raised in a
    callback, KeyboardInterrupt would be logged by the executor as a fatal callback error).
    """
    rclpy.init(args=args)
    node = None
    executor = EventsExecutor() if events else SingleThreadedExecutor()
    try:
        node = make_node()
        executor.add_node(node)
        if events:
            stop = []
            previous = signal.signal(signal.SIGINT, lambda *_: stop.append(True))
            try:
                never = Future()
                while rclpy.ok() and not stop:
                    executor.spin_until_future_complete(never, timeout_sec=EVENTS_SLICE)
            finally:
                signal.signal(signal.SIGINT, previous)
        else:
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (_rclpy.RCLError, RuntimeError):
        # a callback or a take caught mid-way by Ctrl-C or SIGTERM (the signal handler shut the
        # context down under it: RCLError from a publish, RuntimeError from rclpy's take of a
        # message) is a normal stop; a failure while the context is alive is not
        if rclpy.ok():
            raise
    except fatal as e:
        print(f'{name}: {e}', file=sys.stderr)
        return 2
    finally:
        executor.shutdown()
        if node is not None:
            if finish is not None:
                finish(node)
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


class _Deferred:
    """What a DeferredService's rclpy callback returns: the request, until its header is known."""

    def __init__(self, request):
        self.request = request


class DeferredService:
    """
    A service answered when the work is done, not when its callback returns.

    ``callback(request, answer)`` is called for each request; ``answer(response)`` sends that
    request's response, then or later (from any callback of the node's executor). rclpy answers
    with what a service callback returns, so a request that takes minutes would hold the executor,
    unless the callback is a coroutine, which the EventsExecutor does not run. Both executors
    hand the callback's result and the request's header to the service's ``send_response``;
    here that receives the request instead, and the header is kept for ``answer``, which
    calls rclpy's own ``Service.send_response(response, header)``.
    """

    def __init__(self, node, srv_type, name, callback, **kwargs):
        self.callback = callback
        self.service = node.create_service(srv_type, name, self._take, **kwargs)
        self._send = self.service.send_response
        self.service.send_response = self._dispatch

    def _take(self, request, response):
        return _Deferred(request)

    def _dispatch(self, deferred, header):
        self.callback(deferred.request, functools.partial(self._send, header=header))
