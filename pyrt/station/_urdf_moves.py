"""The commands of ``pyrt urdf``'s arm: moves, options, the inverse, TOOL, COORD, conveyor.

:class:`ArmMoves` is the part of :class:`pyrt.station._urdf_arm.UrdfArm` that
turns the operator's words into records of the motion layer and queues them
on the arm's evaluator: ``movej`` (joint values), ``moveto`` (a tool pose by a
joint move; the numerical inverse or the closed form in a named
configuration), ``movel`` (a Cartesian record in ``T6 . TOOL = COORD .
POS``), their OPTIONS (speed, blend tolerance, force limit, PLCopen's
buffer mode), ``tool`` / ``coord``, the frames those targets are given in,
and ``conveyor``: COORD made a moving frame (001's functional transform)
that ``movel`` targets ride on.  A mixin of the arm, not a
part it holds: the commands are the arm's own records (named after it, their
ranges shown from its signals), and the arm's moving state is theirs to read.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pyrt.component import PREPARE_TRIES, Arg, Command, Limits, Stale, command
from pyrt.errors import CommandError
from pyrt.frames import PositionEquation, Transform, inverse
from pyrt.kinematics import Chain, transform
from pyrt.motion import Comply, Evaluator, MotionSpec, Move, RecordError
from pyrt.motion.evaluator import Planned, QueueSnapshot, StalePlan

if TYPE_CHECKING:
    from pyrt.station.base import Station
    from pyrt.station.domain import Robot

__all__ = ["COMPLY_HELP", "OPTIONS_HELP", "ArmMoves"]

#: What a blend's tolerance keeps back for the servo's tracking of the planned path
#: at the tool (mm; measured on the PUMA: at most 0.35 mm in a blend at full speed).
BLEND_SERVO_MM = 0.5

#: What OPTIONS of movej, moveto and movel may say.
OPTIONS_HELP = ("OPTIONS: speed=F (a fraction 0 < F <= 1 of every velocity limit), blend=MM "
                "(the most the blend from the running move into this one may take the tool "
                "from the two moves' unblended path, mm, in truth: the servo's tracking is "
                f"allowed for, so {BLEND_SERVO_MM:g} mm or less is an exact stop; 0: the "
                "running move first stops exactly at its target), force=N (a guarded move: "
                "braked to rest when the wrist feels "
                "more than N newtons along any of its axes), buffer=MODE (PLCopen's buffer "
                "mode, what this move does to the one running: blending (the default: it "
                "starts from a blend at the end of the running one), buffered (it starts "
                "when the running one is at rest on its target, as blend=0) or aborting (it "
                "replaces the running one and what is queued at once, braking into the new "
                "path within the limits; the replaced moves end 'aborted')).")

#: What movel's comply option says.
COMPLY_HELP = ("movel's OPTIONS may say comply AXES N[,N..]: the tool frame's AXES (some of x "
               "y z) held at N newtons each (the force the tool exerts along +axis, from the "
               "wrist sensor; one N for every axis, or one per axis), the others on the line: "
               "e.g. comply z 5 presses 5 N along the tool's z while it moves in x and y; "
               "the next move is given once it has ended.")

#: The fastest conveyor ``NAME conveyor`` takes, per axis (mm/s).
CONVEYOR_MAX_MM_S = 500.0
_OPTIONS = Arg("OPTIONS", str, optional=True, rest=True)
_BUFFER_MODES = ("aborting", "buffered", "blending")
#: Trajectory periods a move from rest leaves for its planning and hand-over before
#: it begins (a plan the trajectory has overtaken is made again).
PLAN_LEAD = 2


@dataclass(frozen=True)
class MoveSnapshot:
    """What planning a move needs of the arm, copied in the loop (bounded):
    the queue's end (the evaluator's :class:`QueueSnapshot`; None while the
    amplifiers are off: the hand-over powers on and the move is planned
    again), where the arm is heading, and the frames (the arm's own arrays,
    replaced and never changed in place, so the hand-over can tell they are
    the same)."""

    evaluator: Evaluator | None
    queue: QueueSnapshot | None
    heading: np.ndarray
    tool_frame: np.ndarray
    coord_frame: np.ndarray
    conveyor: Conveyor | None
    #: COORD when the snapshot was taken (a running conveyor's pose then).
    coord_now: np.ndarray
    #: Taken for a move planned in the loop's own thread (a sequence's step): it
    #: plans with the loop's chain, not the preparation's.
    in_loop: bool = False


@dataclass(frozen=True)
class MoveWork:
    """A move prepared in the caller's thread: its plan, what the reply says."""

    snapshot: MoveSnapshot
    what: str
    planned: Planned | None
    end: np.ndarray | None
    to: str


class ArmMoves:
    """The arm's commands and the queueing of its moves (mixed into the arm, which
    sets the attributes declared here)."""

    station: Station | Robot  # what answers for its fault: the station, or its robot
    name: str
    n: int
    q: np.ndarray
    chain: Chain
    scales: np.ndarray
    units: list[str]
    prismatic: list[bool]
    evaluator: Evaluator | None
    powered: bool
    state: str
    last_stop: str
    tool_frame: np.ndarray
    coord_frame: np.ndarray
    #: The running conveyor (``NAME conveyor``), or None.
    conveyor: Conveyor | None
    #: The record queued last (the one that may track a conveyor).
    _latest: Move | None
    _heading: np.ndarray | None
    _wrench_of: Callable[[Sequence[int]], np.ndarray] | None

    if TYPE_CHECKING:
        def power_on(self) -> None: ...
        def joint_limits(self, i: int) -> Limits: ...
        def tool(self) -> np.ndarray: ...
        def config(self, q: np.ndarray | None = None) -> str: ...
        def joints_text(self, q: np.ndarray) -> str: ...
        def pose_text(self, t: np.ndarray) -> str: ...
        def _time_now(self) -> float: ...
        def _sample_time(self, sample: int) -> float: ...

    def _powered_evaluator(self, what: str) -> Evaluator:
        fault = self.station.fault
        if fault is not None:
            raise CommandError(f"{self.name} {what}: refused: stopped by a fault ({fault.cause});"
                               " give 'ack' first; nothing moved")
        if not self.powered or self.evaluator is None:
            self.power_on()
        ev = self.evaluator
        assert ev is not None
        return ev

    # -- moves: snapshot (loop), prepare (caller's thread), commit (loop) -------------------
    _prep_chain: Chain | None = None

    def move_snapshot(self, what: str = "move", in_loop: bool = False) -> MoveSnapshot:
        """What a move's planning needs, copied (the loop's side, bounded);
        refused while faulted.  ``in_loop``: the move is planned in the loop's
        own thread, at once (no lead for its planning; the loop's chain)."""
        lead = 0 if in_loop else PLAN_LEAD
        fault = self.station.fault
        if fault is not None:
            raise CommandError(f"{self.name} {what}: refused: stopped by a fault ({fault.cause});"
                               " give 'ack' first; nothing moved")
        ev = self.evaluator if self.powered else None
        belt = self.conveyor
        queue = None
        if ev is not None:
            queue = ev.snapshot((belt.transform,) if belt is not None else (), lead=lead)
        return MoveSnapshot(ev, queue, self.heading(), self.tool_frame, self.coord_frame, belt,
                            belt.pose_now() if belt is not None else self.coord_frame.copy(),
                            in_loop)

    def planning(self) -> tuple[threading.Lock, Chain]:
        """The lock one preparation at a time holds, and its chain (the loop's is
        the loop's alone)."""
        lock: threading.Lock = self.__dict__.setdefault("_prep_lock", threading.Lock())
        with lock:
            if self._prep_chain is None:
                self._prep_chain = self.chain.replace()
        return lock, self._prep_chain

    def _chain_for(self, snap: MoveSnapshot) -> tuple[Any, Chain]:
        """The chain a preparation uses, with what it holds meanwhile: in the loop's
        thread the loop's own chain; elsewhere the preparation's, under its lock."""
        if snap.in_loop:
            return contextlib.nullcontext(), self.chain
        return self.planning()

    def _prepare(self, snap: MoveSnapshot, spec: MotionSpec, what: str, end: np.ndarray | None,
                 to: str) -> MoveWork:
        """Plan ``spec`` against ``snap`` (the caller's thread); refused with the reason."""
        ev, queue = snap.evaluator, snap.queue
        if ev is None or queue is None:
            return MoveWork(snap, what, None, end, to)
        try:
            planned = ev.plan(spec, queue, in_loop=snap.in_loop)
        except RecordError as exc:
            why = str(exc).removeprefix(f"{what}: ").removeprefix("refused: ")
            raise CommandError(f"{self.name} {what}: refused: {why}; nothing moved") from None
        return MoveWork(snap, what, planned, end, to)

    def commit_move(self, work: MoveWork) -> str:
        """Queue a prepared move (the loop's side, bounded): :class:`Stale` if the
        arm changed since its snapshot (it is planned again), else the reply."""
        snap, what = work.snapshot, work.what
        if work.planned is None:  # the amplifiers were off: on now, then planned again
            self._powered_evaluator(what)
            raise Stale(f"{self.name} {what}: planned again with the amplifiers on")
        if (self.evaluator is not snap.evaluator or not self.powered
                or self.tool_frame is not snap.tool_frame
                or self.coord_frame is not snap.coord_frame or self.conveyor is not snap.conveyor):
            raise Stale(f"{self.name} {what}: the arm changed while the move was planned")
        ev = self._powered_evaluator(what)
        busy = self.state != "idle"
        try:
            self._latest = ev.commit(work.planned)
        except StalePlan as exc:
            raise Stale(f"{self.name} {what}: {exc}") from None
        return self._queued(work.planned.move, work.end, work.to, busy)

    def _queued(self, move: Move, end: np.ndarray | None, to: str, busy: bool) -> str:
        spec = move.spec
        tracking = self.state == "tracking"
        self.last_stop = ""
        self._heading = end
        if self.state in ("idle", "tracking"):
            self.state = "moving"
        if tracking:
            return f"leaving the moving frame: moving to {to}"
        if not busy:
            return f"moving to {to}"
        if spec.buffer == "aborting":
            return f"aborting the running move: braking into the move to {to}"
        if spec.buffer == "buffered":
            return f"queued: {to}; it starts when the running move is at rest on its target"
        if move.buffer == "buffered" and move.note:  # a blend the planner could not make
            return (f"queued: {to}; it starts when the running move is at rest on its target: "
                    f"no blend ({move.note})")
        return f"queued: {to}; it blends into the running move"

    def _joint_spec(self, q: np.ndarray, what: str, options: dict[str, Any] | None,
                    chain: Chain, tool_frame: np.ndarray) -> tuple[MotionSpec, str]:
        """A joint move's record and its words; refused beyond a limit."""
        if chain.limit_violation(q):
            raise CommandError(f"{self.name} {what}: refused: the target is beyond a joint "
                               f"limit ({self._limit_words(q)}); nothing moved")
        to = (f"joints {self.joints_text(q)}; "
              f"tool {self.pose_text(chain.fk(q) @ tool_frame)}")
        closed = chain.closed_form
        cfg = "" if closed is None else str(closed.config_of(q))
        to += f"; {cfg}" if cfg else ""
        return MotionSpec(target=tuple(float(v) for v in q), name=what, **(options or {})), to

    def _limit_words(self, q: np.ndarray) -> str:
        for i, (v, jt) in enumerate(zip(q, self.chain.joints, strict=True)):
            if not jt.lower <= v <= jt.upper:
                k, u = float(self.scales[i]), self.units[i]
                return (f"joint {jt.name}: {v * k:.3f} {u} is outside "
                        f"{jt.lower * k:.3f} .. {jt.upper * k:.3f} {u}")
        return "none"

    def _movej_record(self) -> Command:
        args = []
        for i, jt in enumerate(self.chain.joints):
            lim = self.joint_limits(i)
            args.append(Arg(f"Q{i + 1}", float, lo=lim.lopr, hi=lim.hopr, units=self.units[i],
                            what=f"{jt.name} limits"))
        units = "degrees" if not any(self.prismatic) else "degrees, or mm for a prismatic joint"
        doc = (f"{self.name} movej {' '.join(a.name for a in args)} [OPTIONS]: a joint move to "
               f"the joint values ({units}); queued moves blend.\n\n"
               "A target beyond a joint limit is refused with the limit; nothing moves.\n"
               f"{OPTIONS_HELP}\n"
               "Range: " + "; ".join(a.range_text for a in args) + ".")
        return Command("movej", self.commit_move, (*args, _OPTIONS), doc, moves=True,
                       while_faulted=False, owner=self.name, prepare=self.prepare_movej,
                       snapshot=lambda: self.move_snapshot("movej"))

    def prepare_movej(self, snap: MoveSnapshot, *values: float | str) -> MoveWork:
        """``movej`` in the caller's thread: its record planned against ``snap``."""
        q, opts = self._joint_values(values)
        lock, chain = self._chain_for(snap)
        with lock:
            spec, to = self._joint_spec(q, "movej", opts, chain, snap.tool_frame)
            return self._prepare(snap, spec, "movej", q.copy(), to)

    def _joint_values(self, values: Sequence[float | str]) -> tuple[np.ndarray, dict[str, Any]]:
        opts = values[self.n] if len(values) == self.n + 1 else None
        if len(values) not in (self.n, self.n + 1) or not (opts is None or isinstance(opts, str)):
            raise CommandError(f"{self.name} movej: {self.n} joint values, got {len(values)}")
        q = np.array([float(v) for v in values[: self.n]]) / self.scales
        return q, self._options("movej", opts)

    def move_joints(self, *values: float | str) -> str:
        """``movej`` planned in the calling thread (the loop's: a sequence's step):
        one value per joint (operator units), then the options' text if any."""
        return self._here("movej", self.prepare_movej, *values)

    def _options(self, what: str, text: str | None) -> dict[str, Any]:
        """The motion record's fields that OPTIONS set (see :data:`OPTIONS_HELP`)."""
        out: dict[str, Any] = {}
        words = (text or "").split()
        while words:
            word = words.pop(0)
            if word.lower() == "comply":
                out["comply"] = self._comply_words(what, words[:2])
                del words[:2]
                continue
            key, eq, value = word.partition("=")
            key = key.lower()
            try:
                v = float(value) if eq else math.nan
            except ValueError:
                v = math.nan
            if key == "speed" and 0.0 < v <= 1.0:
                out["speed"] = v
            elif key == "force" and 0.0 < v <= 1e5 and self._wrench_of is not None:
                out["force_limits"] = (v, v, v, math.inf, math.inf, math.inf)
            elif key == "blend" and 0.0 <= v <= 1e4:
                if v <= BLEND_SERVO_MM:  # no room left beside the servo's tracking
                    out["buffer"] = "buffered"
                else:
                    out["tolerance"] = (v - BLEND_SERVO_MM) * 1e-3
            elif key == "buffer" and value.lower() in _BUFFER_MODES:
                out["buffer"] = value.lower()
            else:
                raise CommandError(f"{self.name} {what}: {word[:40]!r} is not an option: "
                                   f"{OPTIONS_HELP} nothing moved")
        return out

    def _comply_words(self, what: str, words: list[str]) -> Comply:
        """``comply AXES N[,N..]`` of movel's OPTIONS (see :data:`COMPLY_HELP`)."""
        who = f"{self.name} {what}: comply"
        if what != "movel":
            raise CommandError(f"{who}: only movel complies (its directions are the tool "
                               "frame's on a straight line); nothing moved")
        if self._wrench_of is None:
            raise CommandError(f"{who}: refused: this arm has no wrist force sensor; "
                               "nothing moved")
        if len(words) != 2:
            raise CommandError(f"{who}: {COMPLY_HELP} nothing moved")
        axes, forces = words
        try:
            values = [float(v) for v in forces.split(",")]
            if not all(math.isfinite(v) for v in values):
                raise ValueError(forces)
            force: float | list[float] = values[0] if len(values) == 1 else values
            return Comply(axes, force)
        except ValueError as exc:
            why = str(exc).removeprefix("comply: ") if isinstance(exc, RecordError) else (
                f"{forces[:40]!r} is not newtons")
            raise CommandError(f"{who}: {why}; {COMPLY_HELP} nothing moved") from None

    def solve(self, target: np.ndarray, config: str | None, seed: np.ndarray | None = None,
              chain: Chain | None = None) -> np.ndarray:
        """Joint values putting the tool at ``target`` (4, 4): the closed form in
        ``config``, or the numerical inverse seeded at ``seed`` (default: the
        joints the arm is heading to; then, if the chain has a closed form, the
        solution nearest those joints among its configurations, the present one
        first); CommandError with the reason if none.  ``chain``: the arm's chain
        or, in another thread than the loop's, a copy of its own."""
        chain = self.chain if chain is None else chain
        closed = chain.closed_form
        seed = self.heading() if seed is None else seed
        if config is not None:
            if closed is None:
                raise CommandError(f"{self.name} moveto: {chain.name} has no closed-form "
                                   "inverse with named configurations; leave CONFIG out; "
                                   "nothing moved")
            from pyrt.kinematics.puma import parse_config

            try:
                cfg = parse_config(config)
            except ValueError as exc:
                raise CommandError(f"{self.name} moveto: {exc}; nothing moved") from None
            if cfg not in closed.configurations:
                raise CommandError(f"{self.name} moveto: {config!r} is not one of "
                                   f"{', '.join(closed.configurations)}; nothing moved")
            q = closed.solve(target, cfg)
            if q is None:
                why = getattr(closed, "reason", lambda t, c: None)(target, cfg)
                raise CommandError(f"{self.name} moveto: refused: unreachable: "
                                   f"{why or cfg}; nothing moved")
            return self._nearest_turn(np.asarray(q, dtype=float), seed)
        r = chain.ik(target, seed)
        if r.ok and chain.limit_violation(r.q) is None:
            return r.q.copy()
        if closed is not None:
            # the closed form: the present configuration first, then the one nearest
            cfg = str(closed.config_of(seed))
            found: list[tuple[float, int, np.ndarray]] = []
            for name in (cfg, *(c for c in closed.configurations if c != cfg)):
                q = closed.solve(target, name)
                if q is not None:
                    q = self._nearest_turn(np.asarray(q, dtype=float), seed)
                    found.append((float(np.max(np.abs(q - seed))), len(found), q))
            if found:
                return min(found, key=lambda f: (f[0], f[1]))[2]
            why = getattr(closed, "reason", lambda t, c: None)(target, cfg)
            if why:
                raise CommandError(f"{self.name} moveto: refused: unreachable in every "
                                   f"configuration: {why}; nothing moved")
        raise CommandError(f"{self.name} moveto: refused: unreachable: no joint values within "
                           f"the limits reach it (the numerical inverse from the present "
                           f"joints ends {r.residual * 1e3:.3g} mm/mrad away after "
                           f"{r.iterations} iterations); nothing moved")

    def _nearest_turn(self, q: np.ndarray, seed: np.ndarray) -> np.ndarray:
        """``q`` with each revolute joint turned by whole turns to lie nearest ``seed``
        within the limits."""
        out = q.copy()
        for i, jt in enumerate(self.chain.joints):
            if self.prismatic[i]:
                continue
            best = out[i]
            for turns in (-2, -1, 1, 2):
                v = q[i] + turns * 2.0 * math.pi
                if jt.lower <= v <= jt.upper and abs(v - seed[i]) < abs(best - seed[i]):
                    best = v
            out[i] = best
        return out

    def heading(self) -> np.ndarray:
        """Where the arm is heading: the last queued target while it moves, else the
        encoders."""
        if self.state != "idle" and self._heading is not None:
            return self._heading.copy()
        return self.q.copy()

    @command(Arg("X", float, units="mm"), Arg("Y", float, units="mm"),
             Arg("Z", float, units="mm"), Arg("RX", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RY", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RZ", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("CONFIG", str, optional=True), _OPTIONS, name="moveto", moves=True,
             prepare="prepare_moveto", snapshot="_snapshot_moveto")
    def commit_moveto(self, work: MoveWork) -> str:
        """NAME moveto X Y Z RX RY RZ [CONFIG] [OPTIONS]: the tool to a pose by a joint move.

        X Y Z in mm, RX RY RZ in degrees: fixed-axis rotations about the
        base's x, then y, then z (URDF's rpy).  The joints come from the
        numerical inverse seeded at the present joints, or, with CONFIG (e.g.
        lefty-above-noflip), from the arm's closed form in that
        configuration.  An unreachable pose is refused with the reason;
        nothing moves.  OPTIONS as movej's."""
        return self.commit_move(work)

    def _snapshot_moveto(self) -> MoveSnapshot:
        return self.move_snapshot("moveto")

    def move_to(self, x: float, y: float, z: float, rx: float, ry: float, rz: float,
                config: str | None = None, options: str | None = None) -> str:
        """``moveto`` planned in the calling thread (the loop's, for a sequence)."""
        return self._here("moveto", self.prepare_moveto, x, y, z, rx, ry, rz, config, options)

    def prepare_moveto(self, snap: MoveSnapshot, x: float, y: float, z: float, rx: float,
                       ry: float, rz: float, config: str | None = None,
                       options: str | None = None) -> MoveWork:
        """``moveto`` in the caller's thread: the inverse and the plan against ``snap``."""
        if config is not None and "=" in config:  # no configuration: the options begin
            config, options = None, f"{config} {options or ''}"
        opts = self._options("moveto", options)
        pose = _pose("moveto", self.name, x, y, z, rx, ry, rz)
        lock, chain = self._chain_for(snap)
        with lock:
            q = self.solve(snap.coord_now @ pose @ inverse(snap.tool_frame), config,
                           snap.heading, chain)
            spec, to = self._joint_spec(q, "moveto", opts, chain, snap.tool_frame)
            return self._prepare(snap, spec, "moveto", q.copy(), to)

    @command(Arg("X", float, units="mm"), Arg("Y", float, units="mm"),
             Arg("Z", float, units="mm"), Arg("RX", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RY", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RZ", float, lo=-360.0, hi=360.0, units="deg"), _OPTIONS, name="movel",
             moves=True, prepare="prepare_movel", snapshot="_snapshot_movel")
    def commit_movel(self, work: MoveWork) -> str:
        """NAME movel X Y Z RX RY RZ [OPTIONS]: the tool on a straight line to a pose.

        Same units and rotations as moveto; the orientation turns about one
        axis on the way (Paul's drive transform); Cartesian and joint limits
        both kept.  A line that leaves the reach, crosses a joint limit or
        passes a singularity is refused before it starts, naming where;
        nothing moves.  Queued moves blend.  OPTIONS as movej's, and
        comply AXES N[,N..]: the tool frame's AXES (some of x y z) held at N
        newtons (the force the tool exerts along +axis; the wrist sensor
        measures it), the other directions on the line (comply z 5 presses
        5 N along the tool's z while moving in x and y); the next move is
        given when it has ended.  While the conveyor runs (NAME conveyor),
        the target is a point on it: the tool reaches it and then follows
        it ('tracking')."""
        return self.commit_move(work)

    def _snapshot_movel(self) -> MoveSnapshot:
        return self.move_snapshot("movel")

    def move_line(self, x: float, y: float, z: float, rx: float, ry: float, rz: float,
                  options: str | None = None) -> str:
        """``movel`` planned in the calling thread (the loop's, for a sequence)."""
        return self._here("movel", self.prepare_movel, x, y, z, rx, ry, rz, options)

    def _here(self, what: str, prepare: Callable[..., MoveWork], *args: Any) -> str:
        """Snapshot, prepare and commit in the calling thread (a stale snapshot
        prepared again, as :func:`~pyrt.component.run_prepared` does)."""
        for _ in range(PREPARE_TRIES):
            try:
                return self.commit_move(prepare(self.move_snapshot(what, in_loop=True), *args))
            except Stale:
                continue
        raise CommandError(f"{self.name} {what}: refused: the motion queue kept changing "
                           "while it was planned; give it again; nothing moved")

    def prepare_movel(self, snap: MoveSnapshot, x: float, y: float, z: float, rx: float,
                      ry: float, rz: float, options: str | None = None) -> MoveWork:
        """``movel`` in the caller's thread: its equation, the inverse at its end and
        the plan against ``snap``."""
        opts = self._options("movel", options)
        pose = _pose("movel", self.name, x, y, z, rx, ry, rz)
        belt = snap.conveyor
        coord = (belt.transform if belt is not None
                 else Transform.const("COORD", snap.coord_frame))
        eq = PositionEquation("movel", [Transform.varb("T6"), Transform.const("TOOL",
                                                                               snap.tool_frame)],
                              [coord, Transform.varb("POS", pose)])
        here = snap.coord_now
        lock, chain = self._chain_for(snap)
        with lock:
            end = chain.ik(here @ pose @ inverse(snap.tool_frame), snap.heading)
            to = (f"tool {self.pose_text(here @ pose)}"
                  + (" on the moving conveyor" if belt is not None else ""))
            return self._prepare(snap, MotionSpec(mode="cart", equation=eq, name="movel",
                                                  **opts),
                                 "movel", end.q.copy() if end.ok else None, to)

    @command(Arg("X", float, lo=-5000.0, hi=5000.0, units="mm"),
             Arg("Y", float, lo=-5000.0, hi=5000.0, units="mm"),
             Arg("Z", float, lo=-5000.0, hi=5000.0, units="mm"),
             Arg("RX", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RY", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RZ", float, lo=-360.0, hi=360.0, units="deg"), name="tool")
    def set_tool(self, x: float, y: float, z: float, rx: float, ry: float, rz: float) -> str:
        """NAME tool X Y Z RX RY RZ: the tool's frame on the arm's flange (001's TOOL).

        mm and degrees (URDF rpy) in the chain's tool frame; 0 0 0 0 0 0 takes
        it off.  The signals, where, moveto and movel use it from now on.
        Refused while a move runs."""
        self._frames_free("tool")
        self.tool_frame = _pose("tool", self.name, x, y, z, rx, ry, rz)
        return (f"tool frame {self.pose_text(self.tool_frame)}; the tool now at "
                f"{self.pose_text(self.tool())}")

    @command(Arg("X", float, lo=-5000.0, hi=5000.0, units="mm"),
             Arg("Y", float, lo=-5000.0, hi=5000.0, units="mm"),
             Arg("Z", float, lo=-5000.0, hi=5000.0, units="mm"),
             Arg("RX", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RY", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RZ", float, lo=-360.0, hi=360.0, units="deg"), name="coord")
    def set_coord(self, x: float, y: float, z: float, rx: float, ry: float, rz: float) -> str:
        """NAME coord X Y Z RX RY RZ: the frame moveto and movel targets are given in (001's COORD).

        Its pose in the base's frame, mm and degrees (URDF rpy); 0 0 0 0 0 0
        is the base.  Refused while a move runs; a running conveyor stops
        (its frame is the one given now)."""
        self._frames_free("coord")
        self.coord_frame = _pose("coord", self.name, x, y, z, rx, ry, rz)
        self.conveyor = None
        return f"coordinate frame {self.pose_text(self.coord_frame)} (in the base's frame)"

    @command(Arg("VX", float, lo=-CONVEYOR_MAX_MM_S, hi=CONVEYOR_MAX_MM_S, units="mm/s"),
             Arg("VY", float, lo=-CONVEYOR_MAX_MM_S, hi=CONVEYOR_MAX_MM_S, units="mm/s"),
             Arg("VZ", float, lo=-CONVEYOR_MAX_MM_S, hi=CONVEYOR_MAX_MM_S, units="mm/s"),
             name="conveyor")
    def set_conveyor(self, vx: float, vy: float, vz: float) -> str:
        """NAME conveyor VX VY VZ: COORD moves at (VX, VY, VZ) mm/s in the base's frame (a belt).

        A moving frame (001's functional COORD), starting where COORD is
        (NAME coord).  movel targets are then points on the belt: the tool
        reaches its point and follows it, 'tracking' (wait returns then; a
        new move leaves the belt, stop brakes the joints to rest).  moveto
        and movej stay joint moves to where the frame is when they are
        given.  0 0 0 stops the belt where it is (COORD keeps that pose).
        A point carried where the arm cannot follow (out of reach, or a
        joint beyond its velocity limit) brakes the arm to rest, saying so.
        Refused while a move runs or the tool tracks."""
        self._frames_free("conveyor")
        for axis, value in (("VX", vx), ("VY", vy), ("VZ", vz)):
            if not math.isfinite(value):
                raise CommandError(f"{self.name} conveyor: {axis} must be a finite number of "
                                   "mm/s; nothing changed")
        belt = self.conveyor
        if belt is not None:  # the belt's frame where it is now
            self.coord_frame = belt.pose_now()
            self.conveyor = None
        velocity = np.array([vx, vy, vz]) * 1e-3
        if not velocity.any():
            return (f"conveyor stopped; coordinate frame {self.pose_text(self.coord_frame)} "
                    "(in the base's frame)")
        self.conveyor = Conveyor(self.coord_frame, velocity, self)
        return (f"conveyor at ({vx:g}, {vy:g}, {vz:g}) mm/s from "
                f"{self.pose_text(self.coord_frame)}: movel targets ride on it")

    def _frames_free(self, what: str) -> None:
        if self.state != "idle":
            raise CommandError(f"{self.name} {what}: refused while a move runs or the tool "
                               "tracks the conveyor (the queued targets were given in the "
                               "frames as they are); wait or stop first; nothing changed")


def _pose(verb: str, name: str, x: float, y: float, z: float, rx: float, ry: float,
          rz: float) -> np.ndarray:
    """A pose from the operator's words: mm, and degrees as URDF's rpy."""
    for axis, v in (("X", x), ("Y", y), ("Z", z)):
        if not math.isfinite(v):
            raise CommandError(f"{name} {verb}: {axis} must be a finite number of mm")
    return transform(np.array([x, y, z]) * 1e-3, np.radians([rx, ry, rz]))


class Conveyor:
    """A conveyor: COORD translating at ``velocity`` (m/s, base frame) from
    ``origin`` (4, 4) at loop time ``start`` (s).  Its :attr:`transform` is a
    functional transform of the evaluator's sample, whose loop time (s) the
    arm gives (``arm._sample_time(sample)``; ``arm._time_now()`` is the loop
    time).  Plain data and the arm: a black box's snapshot carries it whole
    (its function is an object of its own, :class:`BeltPose`, not code)."""

    def __init__(self, origin: np.ndarray, velocity: np.ndarray, arm: Any) -> None:
        self.origin = origin.copy()
        self.velocity = np.asarray(velocity, dtype=float).copy()
        self.arm = arm
        self.start = float(arm._time_now())
        self.transform = Transform.functional("COORD", BeltPose(self), self.origin)

    def pose_at(self, t: float) -> np.ndarray:
        """COORD at loop time ``t`` (s)."""
        out = self.origin.copy()
        out[:3, 3] += self.velocity * (t - self.start)
        return out

    def pose_now(self) -> np.ndarray:
        return self.pose_at(self.arm._time_now())


class BeltPose:
    """A conveyor's COORD at the evaluator's sample (its functional transform's
    function): ``belt.pose_at`` the loop time the arm gives that sample."""

    def __init__(self, belt: Conveyor) -> None:
        self.belt = belt

    def __call__(self, sample: int) -> np.ndarray:
        belt = self.belt
        return belt.pose_at(belt.arm._sample_time(sample))
