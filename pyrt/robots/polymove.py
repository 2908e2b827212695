"""The PolyAxis's move controller: begin, step, drive, the stop checks, halt.

One :class:`MoveController` per :class:`~pyrt.robots.polyaxis.PolyAxis`
holds the state of the move (the running motion, the hare, the endpoint,
the stop conditions, the error signals, the last stop) and does every step
of it:

* **checks**: a target (:meth:`MoveController.check_target`: finite, the
  position known and trusted, no rope in calibration, the target holdable)
  and a path (:meth:`~MoveController.plan_path`: every point on the way);
* **begin**: a motion record starts now (:meth:`MoveController.begin`) or
  is taken from the motion queue between moves (:meth:`~MoveController.step`);
  either way every Axis goes to PolyAxis control and the stop conditions
  are armed (:meth:`~MoveController.engage`).  A path motion (``hare_path``:
  ``to``) is checked and planned once, when it starts (``plan_path``: the
  target, the estimate, every point of the path); any other motion type has
  the estimate checked before it engages.
* **step**: the motion executor's turn in the control poll; the hare of a
  plug-in motion is checked (a finite point inside the vessel or neck).
* **drive**: the error signals, the batched fuzzy step, every motor, then
  the five stop conditions (:mod:`pyrt.robots.stops`), here and not in the
  motion, so that no motion type can bypass them.
* **stopping**: :meth:`~MoveController.end` ends the move (every motor
  stopped, windings off, the axes back to standalone, the stop recorded and
  told to the listeners, queued motions dropped on an abnormal stop: a
  ``stop``, a motion done, the reflex); :meth:`~MoveController.halt` ends it
  for a stop condition or a fault and, for a safety stop or a fault, fails
  the manipulator: the one place a move's fault leaves the controller (the
  station's reflex follows in the same tick).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from pyrt.devices.motor import STEP_MODE
from pyrt.errors import CommandError
from pyrt.robots.axis import POLYAXIS
from pyrt.robots.paths import Hare, HarePath, plan_segments
from pyrt.robots.ropes import Vec, dist
from pyrt.robots.stops import SAFETY_STOPS, StopCheck, StopReason, StopRecord
from pyrt.scheduler.motion import MotionExecutor, MotionRecord, MotionType, get_motion_type

if TYPE_CHECKING:
    from pyrt.robots.polyaxis import PolyAxis
    from pyrt.scheduler.runner import MotionQueue

__all__ = ["MoveController"]


class MoveController:
    """The move of one PolyAxis (see the module text).  ``motion`` is the
    queue of motion records (None: moves start only with :meth:`begin`);
    ``on_stop`` the listeners told of every stop."""

    def __init__(self, pa: PolyAxis, motion: MotionQueue | None,
                 on_stop: Sequence[Callable[[StopRecord], None]]):
        self.pa = pa
        self.axes = pa.axes
        self._motors = [a.motor for a in pa.axes]
        # what every drive reads: the estimate, the poll's kernels, the log
        self._est = pa.estimator
        self._ctl = pa.control
        self._status = pa.status
        self._names = pa.model.names
        n = len(pa.axes)
        self.motion = motion
        #: Called with (StopRecord) after every stop.
        self.on_stop: list[Callable[[StopRecord], None]] = list(on_stop)
        #: Starts queued motion records one at a time and steps the running one.
        self.executor = MotionExecutor(pa, self._take_motion, self._motion_done,
                                       self._motion_failed)
        #: The motion driving the source now (None between moves).
        self.running: MotionType | None = None
        self.active = False
        self.hare: Hare | None = None
        self.hare_position: Vec | None = None
        self.endpoint: Vec | None = None
        self.stops: StopCheck | None = None
        self.tension_stop = True
        self.signal_all = False
        self.last_stop: StopRecord | None = None
        self.moves = 0
        # the error signals of the last drive
        self.desired_tensions = [0.0] * n
        self.error_lengths = [0.0] * n
        self.error_tensions = [0.0] * n
        self.free = [1.0] * n

    # -- begin ---------------------------------------------------------------------

    def begin(self, record: MotionRecord) -> MotionType:
        """Start ``record`` now instead of queueing it (a running motion is
        replaced, as a new ``to`` re-targets a move); CommandError if refused,
        and then nothing changes."""
        pa = self.pa
        cls = get_motion_type(record.type)
        if not issubclass(cls, HarePath):  # a path's checks run when it plans
            self.refuse_if_lost(record.type)
        motion = cls()
        try:
            motion.start(pa, record, round(pa.now_s * 1e9))
        except CommandError:
            raise
        except Exception as exc:
            raise CommandError(f"{pa.name} {record.type}: refused: "
                               f"{type(exc).__name__}: {exc}") from None
        tgt = self._endpoint_of(motion)
        old, self.running = self.running, None
        ex = self.executor
        if old is not None and ex.current is old:
            ex.abort(f"replaced by {record.type}")
        ex.current = motion
        ex.record = record
        self.hare_position = None
        self.engage(motion, tgt)
        return motion

    def check_target(self, target: Sequence[float]) -> None:
        """Refuse (CommandError with the reason) a target that cannot be reached."""
        pa = self.pa
        tgt = tuple(float(c) for c in target)
        if len(tgt) != 3 or not all(math.isfinite(c) for c in tgt):
            raise CommandError(f"{pa.name} to: target must be three finite numbers")
        if pa.position_error is not None:
            raise CommandError(f"{pa.name} to: refused: the source position is unknown "
                               f"({pa.position_error}); nothing moved")
        self.refuse_if_lost("to")
        why = pa.model.target_refusal((tgt[0], tgt[1], tgt[2]))
        if why is not None:
            raise CommandError(f"{pa.name} to: refused: {why}; nothing moved")

    def refuse_if_lost(self, word: str) -> None:
        """CommandError while the position estimate is not trusted, or while a
        rope's loadcell is being calibrated (the rope is off it then)."""
        pa = self.pa
        cal = [a.loadcell.name for a in self.axes if a.loadcell.calibrating]
        if cal:
            raise CommandError(f"{pa.name} {word}: refused: {', '.join(cal)} in calibration "
                               f"mode (its rope carries the calibration loads); finish with "
                               f"'{cal[0]} calibrate'; nothing moved")
        if pa.estimate_lost is not None:
            raise CommandError(f"{pa.name} {word}: refused: the position estimate is not "
                               f"trusted ({pa.estimate_lost}); re-establish it with 'survey' "
                               "or 'setpos X Y Z'; nothing moved")

    def plan_path(self, target: Sequence[float], *, blend: bool = False) -> Hare:
        """The hare for a move from here to ``target`` after every check: the
        target's (:meth:`check_target`), then every point on the way inside the
        vessel and, from a start held within the tension bounds, holdable within
        them (CommandError with the reason if refused; nothing changes)."""
        pa = self.pa
        self.check_target(target)
        tgt: Vec = tuple(float(c) for c in target)  # type: ignore[assignment]
        start = pa.position
        model = pa.model
        segs = plan_segments(start, tgt, model.in_neck, model.via)
        hare = Hare(segs, pa.record.hare_speed, pa.record.hare_ramp, blend=blend)
        # the tensions on the way are checked when they are within bounds here (a
        # source held where they are not may always move out: the stops guard it)
        held = model.tension_refusal(start) is None
        for p in hare.sample():
            why = model.refusal(p)
            if why is None and held and dist(p, start) > 2.0 * model.end_error:
                why = model.tension_refusal(p)
            if why is not None and dist(p, start) > 2.0 * model.end_error:
                raise CommandError(
                    f"{pa.name} to: refused: the path passes ({p[0]:.1f}, {p[1]:.1f}, "
                    f"{p[2]:.1f}), {why}; nothing moved")
        return hare

    def _take_motion(self) -> MotionRecord | None:
        q = self.motion
        return None if q is None else q.get()

    def _endpoint_of(self, motion: MotionType) -> Vec | None:
        """The motion's ``endpoint`` (None: it has none); CommandError if it is
        not a finite point."""
        endpoint = getattr(motion, "endpoint", None)
        if endpoint is None:
            return None
        try:
            tgt = tuple(float(c) for c in endpoint)
        except (TypeError, ValueError):
            tgt = ()
        if len(tgt) != 3 or not all(math.isfinite(c) for c in tgt):
            raise CommandError(f"{self.pa.name} {motion.name}: refused: its endpoint "
                               f"{endpoint!r} is not a finite point; nothing moved")
        return tgt  # type: ignore[return-value]

    def engage(self, motion: MotionType, tgt: Vec | None) -> None:
        """A motion has started: every Axis under PolyAxis control, the stop
        conditions armed (tension stops on again), the hare where the source is."""
        pa = self.pa
        for a in self.axes:
            if a.mode != POLYAXIS:
                a.poly_activate()
        hare = getattr(motion, "hare", None)
        self.hare = hare if isinstance(hare, Hare) else None
        if self.hare_position is None:  # not stepped yet: the hare starts at the source
            self.hare_position = self.hare.position if self.hare is not None else pa.position
        self.endpoint = tgt
        self.tension_stop = True
        rec = pa.record
        model = pa.model
        self.stops = StopCheck(pa.position, tgt, end_error=model.end_error,
                               find_tolerance=rec.find_tolerance, stuck_time=rec.stuck_time,
                               low_tension=model.low_tension, max_tension=model.max_tension,
                               net_force_limit=model.net_forcelimit, tension_stops=True)
        pa.control.reset_rates()
        pa.control.set_endpoint(tgt)
        self.running = motion
        self.active = True
        self.moves += 1
        if self.hare is not None and tgt is not None:
            pa.status.line(f"TO {pa.now_s:.3f} {tgt[0]:.4f} {tgt[1]:.4f} {tgt[2]:.4f} "
                           f"{len(self.hare.segments)} {int(self.hare.blend)}")
        else:
            pa.status.line(f"MOTION {pa.now_s:.3f} {motion.name or type(motion).__name__}")

    def _motion_done(self, motion: MotionType) -> None:
        """The executor's on_done: a refused record is reported; a motion that
        ended itself stops the manipulator (DONE)."""
        reason = motion.stop_reason or ""
        if motion is not self.running:
            if reason.startswith("refused"):
                self.pa.say(f"queued move dropped: {reason.removeprefix('refused: ')}",
                            "warning")
            return
        self.running = None
        if self.active and not reason.startswith("failed"):
            self.end(StopReason.DONE, reason or f"{motion.name} done")

    def _motion_failed(self, cause: str, motion: MotionType) -> None:
        """The executor's on_error: a motion raised; a fault of the manipulator."""
        self.fault(f"motion {motion.name or type(motion).__name__} failed: {cause}")

    # -- step and drive --------------------------------------------------------------

    def step(self, now_s: float) -> None:
        """The motion executor's turn in the poll: start the next queued motion
        record between moves, step the running one (it sets the hare), check
        a plug-in motion's hare."""
        ex = self.executor
        if ex.current is not None or (self.motion is not None and len(self.motion)):
            if ex.current is None:  # a new motion sets the hare in its first step
                self.hare_position = None
            ex.poll(round(now_s * 1e9))
            m = ex.current
            if m is not None and m is not self.running:
                try:
                    tgt = self._endpoint_of(m)
                    if not isinstance(m, HarePath):  # a path was checked when it planned
                        self.refuse_if_lost(m.name or type(m).__name__)
                    self.engage(m, tgt)
                except CommandError as exc:  # nothing moved: dropped as a refusal
                    ex.abort(f"refused: {exc}")
            if self.active and self.running is not None and not isinstance(self.running,
                                                                            HarePath):
                why = self._hare_refusal(self.hare_position)
                if why is not None:
                    self.fault(f"motion {self.running.name} {why}")

    def _hare_refusal(self, hp: object) -> str | None:
        """Why a plug-in motion's hare may not be chased, or None."""
        try:
            x = tuple(float(c) for c in hp)  # type: ignore[attr-defined]
        except (TypeError, ValueError):
            return f"set the hare to {hp!r}, not a point"
        if len(x) != 3 or not all(math.isfinite(c) for c in x):
            return f"set the hare to {hp!r}, not a finite point"
        why = self.pa.model.refusal(x)
        if why is not None:
            return f"put the hare at ({x[0]:.1f}, {x[1]:.1f}, {x[2]:.1f}), {why}"
        self.hare_position = x  # type: ignore[assignment]
        return None

    def drive(self, now_s: float, dt: float) -> None:
        """During a move: error signals, the batched fuzzy step, every motor, the stops."""
        pa = self.pa
        stops = self.stops
        assert stops is not None
        est = self._est
        hp = self.hare_position
        if hp is None:
            hp = self.hare_position = est.position
        motors = self._motors
        if self.signal_all:
            want, _ = pa.model.equilibrium_tensions(hp)
            self.desired_tensions[:] = want
            self.free[:] = [0.0] * len(motors)
        dvs = self._ctl.drive(
            hp, [m.velocity for m in motors], 1.0 / (dt if dt > 0 else pa.poll_s),
            self.error_lengths, self.error_tensions,
            self.desired_tensions, self.free, signal_all=self.signal_all)
        for m, dv in zip(motors, dvs, strict=True):
            m.set_desired_velocity((m.velocity if m.running else m.desired_velocity) + dv)
            m.poll()
        if self._status.log is not None:
            self._status.state(now_s, dvs)
        hit = stops.check(now_s, est.position, est.dist_err, est.tensions,
                          est.net_force_magnitude, self._names)
        if hit is not None:
            self.halt(*hit)

    # -- stopping ----------------------------------------------------------------------

    def stop_motors(self) -> None:
        """Every motor off (windings off) and every axis back to standalone."""
        for a in self.axes:
            a.motor.stop()
            if a.mode == POLYAXIS:
                a.poly_deactivate()
            a.target = None
            a.motor.mode = STEP_MODE

    def end(self, reason: StopReason, detail: str) -> StopRecord:
        """End the move: stop every motor, record and report why (a stop
        command, a motion done, the reflex; faults come through :meth:`halt`)."""
        pa = self.pa
        was_active = self.active
        self.active = False
        running, self.running = self.running, None
        if running is not None and self.executor.current is running:
            self.executor.abort(f"{reason.value}: {detail}")
        self.stop_motors()
        rec = StopRecord(reason, detail, pa.position, pa.now_s, self.endpoint)
        if was_active or reason in (StopReason.STOP, StopReason.FAULT):
            self.last_stop = rec
            pa.status.line(f"STOP {pa.now_s:.3f} {reason.value} {detail}")
            for fn in self.on_stop:
                fn(rec)
        if reason in SAFETY_STOPS or reason in (StopReason.STOP, StopReason.FAULT):
            dropped = self.motion.clear() if self.motion is not None else 0
            if dropped:
                pa.say(f"{pa.name}: {dropped} queued move(s) dropped", "warning")
        return rec

    def halt(self, reason: StopReason, detail: str, *, moving: bool = True) -> None:
        """End the move for ``reason`` (a stop condition or a fault); a safety
        stop or a fault then fails the manipulator
        (:meth:`~pyrt.component.Component.fail`: the station's reflex stops
        every actuator in this tick).  The only caller of ``fail``.  With
        ``moving`` False a fault was found between moves: there is no move
        to end, and the reflex stops the motors."""
        if moving:
            self.end(reason, detail)
        if reason in SAFETY_STOPS:
            self.pa.fail(f"{reason.value}: {detail}")
        elif reason is StopReason.FAULT:
            self.pa.fail(detail)

    def fault(self, detail: str) -> None:
        """A fault of the move itself (its motion failed or set a bad hare,
        the estimate was lost while moving): the motion is over, the move
        halted (the reflex ends a motion still on the executor)."""
        self.running = None
        self.halt(StopReason.FAULT, detail)

    def position_lost(self, cause: str) -> None:
        """The position finder failed (``cause``): keep the last position, refuse
        moves; during a move it is a fault of the whole manipulator."""
        self.pa.estimator.position_error = cause
        if self.active:
            self.halt(StopReason.FAULT, cause)

    def estimate_lost(self, detail: str) -> None:
        """The estimator found the estimate lost (checked after every measure,
        moving or not): a fault of the manipulator naming the axis; moves are
        refused from then until ``survey`` or ``setpos`` re-establishes it."""
        if self.active:
            self.fault(detail)
        else:
            self.halt(StopReason.FAULT, detail, moving=False)
