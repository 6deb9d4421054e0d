"""The switch between the fast method while the ball moves and the accurate one at rest."""
import pytest
from robotenis_vision.rest import RestSwitch


def test_rest_after_enough_still_frames_and_again_after_a_move_or_a_lost_frame():
    switch = RestSwitch(motion_px=0.3, frames=3)
    # the first frame has nothing to compare with; then three still frames make it rest
    assert [switch.update((100.0, 50.0 + 0.1 * k)) for k in range(4)] == [False] * 3 + [True]
    assert switch.update((100.0, 50.5))          # moved 0.2 px: still at rest
    assert not switch.update((100.0, 51.0))      # moved 0.5 px: moving again
    assert [switch.update((100.0, 51.0)) for _ in range(3)] == [False, False, True]
    switch.lost()
    assert not switch.update((100.0, 51.0))
    with pytest.raises(ValueError, match='motion_px'):
        RestSwitch(0.0, 3)
