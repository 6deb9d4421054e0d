"""
`./robotenis calibrate --call`: call the running calibration service, with a progress bar.

While it waits for the answer the client watches the service in the ROS graph: a service gone for
longer than GONE_GRACE (its node stopped, or died: a node killed outright leaves the graph when
its DDS participant's lease runs out, about 20 s with Fast DDS's default) ends the wait with exit
status 1 and what to do, instead of waiting out the time-out.
"""
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from robotenis_interfaces.msg import CalibrationProgress
from robotenis_interfaces.srv import Calibrate

SERVICE_WAIT = 10.0   # s for the service to appear
GONE_GRACE = 1.0      # s the service may be missing from the graph before the client gives up


def progress_bar(fraction, text, width=40):
    """One line of progress: a bar, the percentage and what is happening."""
    fraction = max(0.0, min(1.0, fraction))
    filled = int(round(fraction * width))
    return f"[{'#' * filled}{'.' * (width - filled)}] {100 * fraction:5.1f} % {text}"


def request_from(args):
    """Build the Calibrate request of the command line (0 or empty: the service's defaults)."""
    return Calibrate.Request(num_poses=args.poses, frames_per_pose=args.frames,
                             settle_time=float(args.settle or 0.0), seed=args.seed,
                             pose_selection=args.selection, bag_path=args.bag)


def show(msg):
    """Draw a CalibrationProgress message as the progress bar on stderr."""
    text = f'{msg.stage} pose {msg.pose_index + 1}/{msg.pose_count} {msg.message}'
    line = progress_bar(msg.fraction, text)[:120].ljust(120)
    print('\r' + line, end='', file=sys.stderr, flush=True)


def answer(r):
    """Print the service's response; the exit status."""
    if not r.success:
        print(f'robotenis calibrate: {r.message}', file=sys.stderr)
        return 1
    print(r.message)
    print(f'bag: {r.bag_path}\nresult: {r.result_path}')
    print(f'held-out RMS error: nominal {r.rms_before_mm:.3f} mm, plain {r.rms_plain_mm:.3f} mm, '
          f'final {r.rms_after_mm:.3f} mm; effects: {", ".join(r.effects) or "none"}')
    return 0


def wait_for_answer(executor, client, future, timeout_s):
    """Spin until the answer, the time-out or the service gone; 'answer', 'timeout' or 'gone'."""
    deadline = time.monotonic() + timeout_s
    missing_since = None
    while not future.done():
        now = time.monotonic()
        if now > deadline:
            return 'timeout'
        if client.service_is_ready():
            missing_since = None
        elif missing_since is None:
            missing_since = now
        elif now - missing_since > GONE_GRACE:
            return 'gone'
        executor.spin_once(timeout_sec=0.1)
    return 'answer'


def call(args, timeout_s=3600.0):
    """Call /calibrate and wait for its answer, showing /calibration/progress; the exit status."""
    rclpy.init()
    node = rclpy.create_node('calibrate_client', namespace=getattr(args, 'namespace', '') or '')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    client = node.create_client(Calibrate, 'calibrate')
    node.create_subscription(CalibrationProgress, 'calibration/progress', show, 10)
    try:
        if not client.wait_for_service(timeout_sec=SERVICE_WAIT):
            print(f'robotenis calibrate: no {client.srv_name} service (start the system: '
                  './robotenis launch)', file=sys.stderr)
            return 2
        future = client.call_async(request_from(args))
        outcome = wait_for_answer(executor, client, future, timeout_s)
        print(file=sys.stderr)
        if outcome == 'gone':
            print(f'robotenis calibrate: the {client.srv_name} service went away before answering '
                  '(its node stopped or died; see its log): no result; what the session '
                  "recorded is in the node's bags_dir", file=sys.stderr)
            return 1
        if outcome == 'timeout':
            print(f'robotenis calibrate: no answer from the service in {timeout_s:.0f} s',
                  file=sys.stderr)
            return 1
        return answer(future.result())
    except (KeyboardInterrupt, ExternalShutdownException):
        print('\nrobotenis calibrate: interrupted (the session goes on in the service)',
              file=sys.stderr)
        return 130
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
