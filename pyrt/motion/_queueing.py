"""The queueing side of :class:`pyrt.motion.Evaluator`: a record planned outside the loop.

:meth:`Queueing.snapshot` copies what a plan needs (bounded: in the loop),
:meth:`Queueing.plan` plans in the caller's thread with a chain of its own,
:meth:`Queueing.commit` (bounded: the loop) checks the snapshot still holds
and hands the pieces over; :meth:`Queueing.queue` does the three at once in
the loop's thread.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pyrt.frames import TransformType
from pyrt.kinematics import Chain
from pyrt.motion._pieces import FrameTracker, Piece
from pyrt.motion.planner import Limits, Planner, Segment, Tail
from pyrt.motion.record import MotionSpec, Move, RecordError

__all__ = ["Planned", "QueueSnapshot", "Queueing", "StalePlan"]


class StalePlan(RecordError):
    """A planned record's snapshot no longer holds (:meth:`Evaluator.commit`)."""


@dataclass(frozen=True)
class QueueSnapshot:
    """What :meth:`Evaluator.plan` needs, copied by :meth:`Evaluator.snapshot`."""

    tail: Tail
    generation: int
    tracker: FrameTracker
    count: int
    stopping: bool
    complying: Move | None


@dataclass(frozen=True)
class Planned:
    """A record planned outside the loop, for :meth:`Evaluator.commit`."""

    snapshot: QueueSnapshot
    segment: Segment
    move: Move


class Queueing:
    """The evaluator's queueing (mixed into :class:`~pyrt.motion.Evaluator`, which
    sets the attributes declared here)."""

    chain: Chain
    limits: Limits
    planner: Planner
    tracker: FrameTracker
    force_sensor: bool
    _lock: threading.Lock
    _plan_lock: threading.Lock
    _side: Planner | None
    _generation: int
    _count: int
    _period: float
    _pieces: list[Piece]
    _segs: list[Segment]
    _k: int
    _q: list[Any]
    _t6: list[Any]
    _tp: list[float]
    _n: int
    _sigma: float | None
    _stop: tuple[str, Move | None] | None
    _equation: Any
    _config: str | None
    _watched: list[Any]

    if TYPE_CHECKING:
        def _splice(self, seg: Segment, tail: Tail) -> None: ...

    def _tail(self) -> Tail:
        last = self._segs[-1] if self._segs else None
        if last is not None and self._k >= len(self._pieces):
            last = None
        return Tail(self._tp[-1], self._n + 1, self._period, self._q[-1].copy(),
                    self._t6[-1].copy(), list(self._pieces), last, self._equation,
                    self._config)

    def snapshot(self, watch: Sequence[Any] = (), lead: int = 0) -> QueueSnapshot:
        """What a plan needs of the queue, copied (bounded: call it in the loop, or
        from any thread): the plan queued so far seen now, the moving frames'
        last values, a generation that changes when anything is queued or
        stopped.  ``watch``: functional transforms a record to come will use
        (they are evaluated every sample from now on, so a plan knows their
        velocity).  ``lead``: trajectory periods a plan from rest leaves before
        it begins (the time its planning and hand-over may take)."""
        with self._lock:
            for tr in watch:
                if all(tr is not w for w in self._watched):
                    self._watched.append(tr)
                    self.tracker.evaluate(tr, self._n)
                    self.tracker.evaluate(tr, self._n + 1)
            tail = self._tail()
            if tail.last is None and lead > 0:  # at rest: the plan begins ``lead`` later
                tail.now += lead * self._period
                tail.sample += lead
            tracker = self.tracker.copy()
            complying = next((s.move for s in self._segs
                              if s.move.code is None and s.move.spec.comply is not None), None)
            return QueueSnapshot(tail, self._generation, tracker, self._count,
                                 self._sigma is not None or self._stop is not None, complying)

    def plan(self, spec: MotionSpec, snap: QueueSnapshot, *, in_loop: bool = False) -> Planned:
        """Plan ``spec`` (copied whole) after ``snap``, in the caller's thread,
        touching nothing the loop uses (a chain and frame values of its own);
        :meth:`commit` queues it.  ``in_loop``: the caller is the loop's thread
        (it plans with the loop's chain, waiting for no other plan).
        RecordError names a refused field or where the path cannot go."""
        if not isinstance(spec, MotionSpec):
            raise RecordError(f"expected a MotionSpec, got {type(spec).__name__}")
        if snap.stopping:
            raise RecordError("the arm is stopping; queue again when it is at rest")
        if snap.complying is not None:
            raise RecordError(f"comply: the complying record {snap.complying.spec.name or ''} "
                              "runs; queue the next one when it has ended (it starts "
                              "where the force put the arm)")
        spec = spec.copy()
        move = Move(spec, snap.count)
        if in_loop:
            planner = self.planner
            seg = planner.plan(spec, snap.tail, move, force_sensor=self.force_sensor)
            return Planned(snap, seg, move)
        side, lock = self.chain.planning_copy()
        with self._plan_lock, lock:
            if self._side is None or self._side.chain is not side:
                self._side = Planner(side, self.limits, snap.tracker)
            self._side.tracker = snap.tracker
            seg = self._side.plan(spec, snap.tail, move, force_sensor=self.force_sensor)
        return Planned(snap, seg, move)

    def commit(self, planned: Planned) -> Move:
        """Queue a planned record (bounded: the loop's side).  :class:`StalePlan`
        (nothing queued) when the snapshot it was planned from no longer holds:
        something was queued or stopped since, or the trajectory has passed the
        plan's first sample."""
        with self._lock:
            snap, seg = planned.snapshot, planned.segment
            if snap.generation != self._generation:
                raise StalePlan("the motion queue changed while the record was planned")
            if self._sigma is not None or self._stop is not None:
                raise StalePlan("the arm is stopping")
            if seg.pieces and self._tp[-1] > seg.pieces[0].t0 + 1e-9:
                raise StalePlan("the trajectory passed the plan's start while it was planned")
            seg.frames.tracker = self.tracker  # the loop's frame values from now on
            self._splice(seg, snap.tail)
            self._count += 1
            self._generation += 1
            eq = planned.move.spec.equation
            if eq is not None:
                self._equation = eq
                eq.start()
            return planned.move

    def queue(self, spec: MotionSpec) -> Move:
        """Copy ``spec`` whole and plan it after what is queued, now, in the loop's
        thread (:meth:`snapshot`, :meth:`plan` with the loop's chain,
        :meth:`commit`; from another thread call the three); returns its
        handle.  RecordError (nothing queued) names a refused field or where
        the path cannot go."""
        if not isinstance(spec, MotionSpec):
            raise RecordError(f"expected a MotionSpec, got {type(spec).__name__}")
        eq = spec.equation if spec.equation is not None else self._equation
        live = [] if eq is None else [t for t in eq.transforms
                                      if t.type is TransformType.FUNCTIONAL]
        for _ in range(3):
            planned = self.plan(spec, self.snapshot(live), in_loop=True)
            try:
                return self.commit(planned)
            except StalePlan:
                continue  # the loop moved on while planning: plan again
        raise RecordError("the loop kept moving while the record was planned; queue it again")

