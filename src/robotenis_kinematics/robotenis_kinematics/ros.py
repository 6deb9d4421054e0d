"""What every RoboTenis node shares: the joint names, reading them from a JointState, stamps in
seconds, and spinning.

The only module of this package that touches ROS; the mathematics never imports it.
"""
import sys

import numpy as np

JOINTS = ('motor_1', 'motor_2', 'motor_3')


def joint_vector(msg, field):
    """motor_1..3 of a JointState field (position, velocity), whatever the order of the names; None
    when the field does not hold one value per name or a motor is missing."""
    values = getattr(msg, field)
    if len(values) != len(msg.name):
        return None
    index = {name: i for i, name in enumerate(msg.name)}
    if any(j not in index for j in JOINTS):
        return None
    return np.array([values[index[j]] for j in JOINTS], dtype=float)


def stamp_seconds(stamp):
    """A builtin_interfaces/Time (a header stamp) in seconds, as rclpy.time.Time(...).nanoseconds * 1e-9."""
    return (stamp.sec * 1_000_000_000 + stamp.nanosec) * 1e-9


def spin(make_node, name, fatal=(ValueError,), args=None, finish=None):
    """Run one node on a SingleThreadedExecutor until Ctrl-C or shutdown; returns the exit code.

    ``fatal`` errors raised while building the node (a bad parameter, an unreadable file) are printed
    as ``name: message`` and give exit code 2. Shutdown goes in the order rclpy needs: executor,
    ``finish(node)`` (e.g. close a file the node writes), node, context.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    rclpy.init(args=args)
    node = None
    executor = SingleThreadedExecutor()
    try:
        node = make_node()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
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
