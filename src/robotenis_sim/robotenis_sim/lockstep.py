"""
When the simulated motors step: on the wall clock, or in lockstep with the nodes answering them.

* Wall clock: as many 1 ms steps as the wall time since the start asks (times ``speed`` on
  simulated time; ``speed`` 0 is as fast as possible), at most ``max_catch_up`` at once, so that a
  stalled process does not burst.
* Lockstep: one step per answered reading. After each published reading the simulator waits (at
  most ``lockstep_timeout`` wall seconds) for the controller's command stamped with it, so a
  controller ticking on joint states runs exactly once per step whatever the load.
* Visual lockstep (``camera_rate`` > 0, with lockstep): the hand camera exposes the first truth
  sample at or after each k / camera_rate (camera_model.FrameClock). The simulator does not step
  past an exposure plus ``visual_delay`` until a visual command stamped with it (or later) has
  arrived, waiting at most ``visual_timeout`` wall seconds: the visual loop then acts within
  visual_delay of simulated time, as a real camera pipeline acts within its frame. It waits only
  while the loop answers: after a frame without an answer (ball lost, tracker off) it lets frames
  go by unwaited until the next answer. The caller may say the robot moves (``due(..., still=
  False)``): its frames then go by unwaited too, the loop's answers still counted (a calibration
  session waits for the detector at rest only, where the detector's accurate fit is slow and a
  simulator running ahead would only make frames for it to drop).

The clock is a parameter (``clock()``: wall seconds, monotonic), so the schedule can be tested
without sleeping.
"""
from collections import deque
from dataclasses import dataclass
import math
import time

from robotenis_sim.camera_model import FrameClock


@dataclass(frozen=True)
class ScheduleParameters:
    """How the simulator steps (see the module docstring); times in s, rates in Hz."""

    dt: float = 1e-3
    simulated: bool = False          # the simulator owns the clock (speed applies)
    speed: float = 1.0               # simulated seconds per wall second; 0: as fast as possible
    lockstep: bool = False
    lockstep_timeout: float = 0.1
    max_catch_up: int = 10
    camera_rate: float = 0.0
    visual_delay: float = 1.0 / 120.0
    visual_timeout: float = 0.1


class StepSchedule:
    """Decides how many steps the simulator runs now; told what was published and answered."""

    def __init__(self, params=ScheduleParameters(), clock=time.monotonic):
        self.p, self.clock = params, clock
        self.start = clock()
        self.answered = True             # the command for the last reading has arrived
        self.waiting_since = None        # wall time the wait for that command began
        visual = params.lockstep and params.camera_rate > 0
        self.frames = FrameClock(params.camera_rate) if visual else None
        self.exposures = deque()         # stamps of frames whose visual command has not arrived
        self.visual_answers = False      # the visual loop answered its last frame
        self.visual_since = None         # wall time the wait for a frame's command began

    def published(self):
        """Record that a reading went out: in lockstep, the next step waits for its command."""
        self.answered = False

    def sampled(self, t):
        """Record that a truth sample at simulated time t went out: the camera may expose it."""
        if self.frames is not None and self.frames.due(t):
            self.exposures.append(t)

    def answer(self):
        """Record that the controller's command for the last reading arrived."""
        self.answered = True

    def visual_answer(self, t):
        """Record a visual command stamped t arriving; return True if a step was waiting for it."""
        while self.exposures and self.exposures[0] <= t + FrameClock.TOLERANCE:
            self.exposures.popleft()
        self.visual_answers = True
        return self.visual_since is not None

    def due(self, t_sim, steps, still=True):
        """
        Return (steps to run now, [log notes]) at simulated time t_sim after ``steps`` steps.

        ``still``: whether the visual lockstep may wait for a frame's answer (see the module).
        """
        n, notes = self._wall_due(steps), []
        if not (n and self.p.lockstep):
            return n, notes
        if not self.answered:
            now = self.clock()
            self.waiting_since = self.waiting_since or now
            if now - self.waiting_since < self.p.lockstep_timeout:
                return 0, notes
            notes.append('lockstep: no command for the last reading, stepping on')
        self.waiting_since = None
        if self.frames is not None and self._waiting_for_camera(t_sim, notes, still):
            return 0, notes
        return 1, notes

    def _wall_due(self, steps):
        if self.p.simulated and self.p.speed <= 0:
            return self.p.max_catch_up
        speed = self.p.speed if self.p.simulated else 1.0
        target = math.floor((self.clock() - self.start) * speed / self.p.dt)
        return max(0, min(target - steps, self.p.max_catch_up))

    def _waiting_for_camera(self, t_sim, notes, still=True):
        """Return True while the next step would pass a frame's deadline before its command."""
        deadline = t_sim + self.p.dt - self.p.visual_delay + 1e-9
        while self.exposures and self.exposures[0] <= deadline:
            if not still:                 # moving: the frame goes by, the loop still answering
                self.exposures.popleft()
                continue
            if self.visual_answers:
                now = self.clock()
                self.visual_since = self.visual_since or now
                if now - self.visual_since < self.p.visual_timeout:
                    return True
                notes.append('visual lockstep: a frame went unanswered, not waiting until the '
                             'next answer')
            self.exposures.popleft()
            self.visual_answers = False
            self.visual_since = None
        self.visual_since = None
        return False
