"""The live tracking probe's scoring: the effector at a frame's stamp, truth samples missed."""
from types import SimpleNamespace

import numpy as np
from robotenis_validation import live_tracking

PERIOD_NS = 4_000_000     # the simulator's truth period
A = np.array([20.0, -10.0, 5.0])     # m/s^2: the effector's constant acceleration


def P(t):
    return 0.5 * A * t ** 2


def probe(missing):
    """Return a probe on a stand-in node, truth samples every 4 ms but ``missing`` (indices)."""
    node = SimpleNamespace(create_subscription=lambda *args: None)
    truth = SimpleNamespace(camera_rotation=np.eye(3), camera_translation=np.zeros(3))
    p = live_tracking.Probe(node, truth, s_d=np.zeros(3))
    p.effector = {k * PERIOD_NS: P(k * PERIOD_NS * 1e-9) for k in range(100) if k not in missing}
    return p


def test_a_received_sample_is_used_as_it_is():
    p = probe(missing=())
    t = np.arange(100) * PERIOD_NS * 1e-9
    assert np.array_equal(p.effector_at(t), P(t[:, None]))


def test_a_missed_sample_is_interpolated_within_the_bound():
    p = probe(missing={10, 20, 21})
    t = np.array([10, 20, 21]) * PERIOD_NS * 1e-9
    err = np.linalg.norm(p.effector_at(t) - P(t[:, None]), axis=1)
    gap = np.array([2, 3, 3]) * PERIOD_NS * 1e-9
    bound = np.linalg.norm(A) * gap ** 2 / 8
    assert np.all(err > 0) and np.all(err <= bound + 1e-15)


def test_a_wider_gap_is_not_scored():
    p = probe(missing={30, 31, 32})
    t = np.array([29, 30, 31, 32, 33]) * PERIOD_NS * 1e-9
    P_at = p.effector_at(t)
    assert np.isnan(P_at[1:4]).all() and np.isfinite(P_at[[0, 4]]).all()
    p.balls = [(s, np.array([0.0, 0.0, 1.0])) for s in t]
    window = p.window(t[0], t[-1] + 1e-6)
    assert window.frames == 5 and len(window.true) == 2


def test_the_loop_is_not_ready_before_the_probe_receives_a_ball_truth():
    """Every node in the graph is not enough: the probe's own ball truths must be arriving."""
    live = object.__new__(live_tracking.LiveTracking)
    live.node = SimpleNamespace(count_publishers=lambda topic: 1,
                                count_subscribers=lambda topic: 2)
    live.probe = probe(missing=())
    live.probe.now = 0.4
    assert not live.loop_ready()
    live.probe.balls.append((0.4, np.array([0.0, 0.0, 1.0])))
    assert live.loop_ready()
