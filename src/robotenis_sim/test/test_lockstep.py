"""The simulator's step schedule on a clock the test moves: no sleeping."""
import pytest
from robotenis_sim.lockstep import ScheduleParameters, StepSchedule

DT = 1e-3


class FakeClock:
    """Wall seconds that pass only when the test says so."""

    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def make(**kw):
    clock = FakeClock()
    return StepSchedule(ScheduleParameters(dt=DT, **kw), clock), clock


def test_wall_clock_runs_the_steps_due_and_catches_up_at_most_max_catch_up():
    schedule, clock = make(max_catch_up=10)
    clock.t += 0.0035
    assert schedule.due(0.0, 0) == (3, [])
    clock.t += 1.0
    assert schedule.due(0.003, 3)[0] == 10          # a stall does not become a burst


def test_simulated_time_runs_at_its_speed_or_as_fast_as_possible():
    schedule, clock = make(simulated=True, speed=0.5)
    clock.t += 0.01
    assert schedule.due(0.0, 0)[0] == 5
    schedule, _ = make(simulated=True, speed=0.0, max_catch_up=7)
    assert schedule.due(0.0, 0)[0] == 7


def test_lockstep_waits_for_the_answer_then_steps_once_and_gives_up_after_the_timeout():
    schedule, clock = make(simulated=True, speed=0.0, lockstep=True, lockstep_timeout=0.1)
    schedule.published()
    assert schedule.due(0.0, 0) == (0, [])                     # no command yet
    schedule.answer()
    assert schedule.due(0.0, 0) == (1, [])
    schedule.published()
    schedule.due(0.001, 1)
    clock.t += 0.099
    assert schedule.due(0.001, 1) == (0, [])
    clock.t += 0.002
    n, notes = schedule.due(0.001, 1)
    assert n == 1 and 'no command' in notes[0]


def visual(clock):
    schedule = StepSchedule(ScheduleParameters(dt=DT, simulated=True, speed=0.0, lockstep=True,
                                               camera_rate=120.0, visual_delay=1 / 120.0,
                                               visual_timeout=0.05), clock)
    t = 0.0
    for _ in range(40):         # samples every 4 ms: frames at 0, 12, 20, 28 ms
        schedule.sampled(t)
        t += 0.004
    return schedule


def test_visual_lockstep_waits_for_an_answered_loop_only():
    schedule = visual(FakeClock())
    assert list(schedule.exposures)[:5] == pytest.approx([0.0, 0.012, 0.020, 0.028, 0.036])
    # the loop has not answered yet: the frame at 0 goes by (its deadline is 8.3 ms)
    assert schedule.due(0.0075, 0)[0] == 1 and schedule.exposures[0] == pytest.approx(0.012)
    assert schedule.visual_answer(0.0) is False       # an answer, no step was waiting for it
    # the frame at 12 ms must be answered by 20.3 ms: the step from 20 ms waits
    assert schedule.due(0.020, 0) == (0, [])
    assert schedule.visual_answer(0.012) is True      # its command: the waiting step may run
    assert schedule.due(0.020, 0) == (1, [])


def test_an_unanswered_frame_is_given_up_after_the_visual_timeout():
    clock = FakeClock()
    schedule = visual(clock)
    schedule.visual_answer(-1.0)                      # the loop answers, then goes silent
    assert schedule.due(0.0075, 0) == (0, [])         # waits for the frame at 0
    clock.t += 0.049
    assert schedule.due(0.0075, 0) == (0, [])
    clock.t += 0.002
    n, notes = schedule.due(0.0075, 0)
    assert n == 1 and 'unanswered' in notes[0] and not schedule.visual_answers
    assert schedule.due(0.100, 0) == (1, [])          # no more waiting until the next answer


@pytest.mark.parametrize('rate', [0.0, 120.0])
def test_no_visual_lockstep_without_lockstep(rate):
    schedule, _ = make(simulated=True, speed=0.0, camera_rate=rate)
    schedule.sampled(0.0)
    assert schedule.frames is None and not schedule.exposures


def test_while_the_robot_moves_frames_go_by_unwaited_and_the_loop_still_counts_as_answering():
    schedule = visual(FakeClock())
    schedule.visual_answer(-1.0)                      # the detector answers
    assert schedule.due(0.0075, 0, still=False) == (1, [])   # moving: the frame at 0 goes by
    assert schedule.visual_answers and schedule.exposures[0] == pytest.approx(0.012)
    assert schedule.due(0.020, 0, still=True) == (0, [])     # at rest: the frame at 12 ms waits
    assert schedule.visual_answer(0.012) is True
    assert schedule.due(0.020, 0, still=True) == (1, [])
