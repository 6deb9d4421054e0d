"""
Checkerboards rendered by Mitsuba 3 with and without the ball (test/data/mitsuba-empty).

Six scenes whose frame without the ball the detector measured as a ball before detector._pattern
refused balls round over less than PATTERN_SHARE of their outline with a rough limb or straight
sides; from a list that neither the benchmark nor the tuning of those limits used. Their frames
with the ball must still be measured on the ball.
"""
import os

import mitsuba_data
import numpy as np
import pytest
from robotenis_vision import detector

DATA = os.path.join(os.path.dirname(__file__), 'data', 'mitsuba-empty')
R = 0.019                       # m: the paper's ball radius R_B


def entries():
    return mitsuba_data.index(DATA)


def load(entry):
    """Return the truth, the camera, the frame with the ball and the frame without it."""
    truth, cam = mitsuba_data.truth_and_camera(DATA, entry['id'])
    return (truth, cam, mitsuba_data.image(DATA, truth['image']),
            mitsuba_data.image(DATA, entry['empty']))


def test_most_checkerboards_without_the_ball_are_refused_as_patterns():
    """At least 5 of the 6 frames without the ball are refused, each as a pattern."""
    refused, reported = [], []
    for entry in entries():
        truth, cam, _, empty = load(entry)
        try:
            det = detector.detect(empty, cam, R, gamma=truth['scene']['exposure']['gamma'])
        except detector.DetectionError as e:
            assert 'a pattern of the background' in str(e), str(e)
            refused.append(entry['id'])
            continue
        reported.append((entry['id'], cam.project(det.position).round(0).tolist()))
    assert len(refused) + len(reported) == 6
    assert len(refused) >= 5, f'false balls: {reported}'


@pytest.mark.parametrize('entry', entries(), ids=lambda e: str(e['id']))
def test_the_ball_on_the_same_checkerboard_is_never_a_square(entry):
    """With the ball, a measured sphere lies on the ball's ray (a square's would miss the ball)."""
    truth, cam, ball, _ = load(entry)
    c = np.array(truth['ball']['center_m'])
    try:
        det = detector.detect(ball, cam, R, gamma=truth['scene']['exposure']['gamma'])
    except detector.DetectionError as e:
        # a frame whose square was measured instead of the ball before the check (088) may be
        # refused; the others must be measured
        assert entry['id'] == '088', str(e)
        return
    ray = c / np.linalg.norm(c)
    assert np.linalg.norm(np.cross(det.position, ray)) < R / 10
