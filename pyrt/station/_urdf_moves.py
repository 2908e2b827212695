"""The commands of ``pyrt urdf``'s arm: its moves, their options, the inverse, TOOL and COORD.

:class:`ArmMoves` is the part of :class:`pyrt.station._urdf_arm.UrdfArm` that
turns the operator's words into records of the motion layer and queues them
on the arm's evaluator: ``movej`` (joint values), ``moveto`` (a tool pose by a
joint move; the numerical inverse or the closed form in a named
configuration), ``movel`` (a Cartesian record in ``T6 . TOOL = COORD .
POS``), their OPTIONS (speed, blend tolerance, force limit), and ``tool`` /
``coord``, the frames those targets are given in.  A mixin of the arm, not a
part it holds: the commands are the arm's own records (named after it, their
ranges shown from its signals), and the arm's moving state is theirs to read.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from pyrt.component import Arg, Command, Limits, command
from pyrt.errors import CommandError
from pyrt.frames import PositionEquation, Transform, inverse
from pyrt.kinematics import Chain, transform
from pyrt.motion import Evaluator, MotionSpec, RecordError

if TYPE_CHECKING:
    from pyrt.station.base import Station
    from pyrt.station.domain import Robot

__all__ = ["OPTIONS_HELP", "ArmMoves"]

#: What OPTIONS of movej, moveto and movel may say.
OPTIONS_HELP = ("OPTIONS: speed=F (a fraction 0 < F <= 1 of every velocity limit), blend=MM "
                "(the most a blend into the next move may cut the corner, mm; 0: stop exactly "
                "at the target), force=N (a guarded move: braked to rest when the wrist feels "
                "more than N newtons along any of its axes).")
_OPTIONS = Arg("OPTIONS", str, optional=True, rest=True)


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
    _heading: np.ndarray | None
    _wrench_of: Callable[[Sequence[int]], np.ndarray] | None

    if TYPE_CHECKING:
        def power_on(self) -> None: ...
        def joint_limits(self, i: int) -> Limits: ...
        def tool(self) -> np.ndarray: ...
        def config(self, q: np.ndarray | None = None) -> str: ...
        def joints_text(self, q: np.ndarray) -> str: ...
        def pose_text(self, t: np.ndarray) -> str: ...

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

    def _queue_spec(self, spec: MotionSpec, what: str, end: np.ndarray | None, to: str) -> str:
        """Queue ``spec`` (its joints at the end ``end`` if known); refused with the
        reason, nothing moved."""
        ev = self._powered_evaluator(what)
        busy = self.state != "idle"
        try:
            ev.queue(spec)
        except RecordError as exc:
            why = str(exc).removeprefix(f"{what}: ").removeprefix("refused: ")
            raise CommandError(f"{self.name} {what}: refused: {why}; nothing moved") from None
        self.last_stop = ""
        self._heading = end
        if self.state == "idle":
            self.state = "moving"
        return f"queued: {to}; it blends into the running move" if busy else f"moving to {to}"

    def _queue(self, q: np.ndarray, what: str, options: dict[str, Any] | None = None) -> str:
        """Queue a joint move to ``q`` (rad, m); refused with the reason, nothing moved."""
        if self.chain.limit_violation(q):
            raise CommandError(f"{self.name} {what}: refused: the target is beyond a joint "
                               f"limit ({self._limit_words(q)}); nothing moved")
        to = (f"joints {self.joints_text(q)}; "
              f"tool {self.pose_text(self.chain.fk(q) @ self.tool_frame)}")
        cfg = self.config(q)
        to += f"; {cfg}" if cfg else ""
        spec = MotionSpec(target=tuple(float(v) for v in q), name=what, **(options or {}))
        return self._queue_spec(spec, what, q.copy(), to)

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
        return Command("movej", self.move_joints, (*args, _OPTIONS), doc, moves=True,
                       while_faulted=False, owner=self.name)

    def move_joints(self, *values: float | str) -> str:
        """The handler of ``movej``: one value per joint (operator units), then the
        options' text if any."""
        opts = values[self.n] if len(values) == self.n + 1 else None
        if len(values) not in (self.n, self.n + 1) or not (opts is None or isinstance(opts, str)):
            raise CommandError(f"{self.name} movej: {self.n} joint values, got {len(values)}")
        q = np.array([float(v) for v in values[: self.n]]) / self.scales
        return self._queue(q, "movej", self._options("movej", opts))

    def _options(self, what: str, text: str | None) -> dict[str, Any]:
        """The motion record's fields that OPTIONS set (see :data:`OPTIONS_HELP`)."""
        out: dict[str, Any] = {}
        for word in (text or "").split():
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
                if v == 0.0:
                    out["buffer"] = "buffered"
                else:
                    out["tolerance"] = v * 1e-3
            else:
                raise CommandError(f"{self.name} {what}: {word[:40]!r} is not an option: "
                                   f"{OPTIONS_HELP} nothing moved")
        return out

    def solve(self, target: np.ndarray, config: str | None) -> np.ndarray:
        """Joint values putting the tool at ``target`` (4, 4): the closed form in
        ``config``, or the numerical inverse seeded at the joints the arm is
        heading to (then, if the chain has a closed form, the solution nearest
        those joints among its configurations, the present one first);
        CommandError with the reason if none."""
        chain = self.chain
        closed = chain.closed_form
        seed = self.heading()
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
             Arg("CONFIG", str, optional=True), _OPTIONS, name="moveto", moves=True)
    def move_to(self, x: float, y: float, z: float, rx: float, ry: float, rz: float,
                config: str | None = None, options: str | None = None) -> str:
        """NAME moveto X Y Z RX RY RZ [CONFIG] [OPTIONS]: the tool to a pose by a joint move.

        X Y Z in mm, RX RY RZ in degrees: fixed-axis rotations about the
        base's x, then y, then z (URDF's rpy).  The joints come from the
        numerical inverse seeded at the present joints, or, with CONFIG (e.g.
        lefty-above-noflip), from the arm's closed form in that
        configuration.  An unreachable pose is refused with the reason;
        nothing moves.  OPTIONS as movej's."""
        if config is not None and "=" in config:  # no configuration: the options begin
            config, options = None, f"{config} {options or ''}"
        opts = self._options("moveto", options)
        pose = _pose("moveto", self.name, x, y, z, rx, ry, rz)
        q = self.solve(self.coord_frame @ pose @ inverse(self.tool_frame), config)
        return self._queue(q, "moveto", opts)

    @command(Arg("X", float, units="mm"), Arg("Y", float, units="mm"),
             Arg("Z", float, units="mm"), Arg("RX", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RY", float, lo=-360.0, hi=360.0, units="deg"),
             Arg("RZ", float, lo=-360.0, hi=360.0, units="deg"), _OPTIONS, name="movel",
             moves=True)
    def move_line(self, x: float, y: float, z: float, rx: float, ry: float, rz: float,
                  options: str | None = None) -> str:
        """NAME movel X Y Z RX RY RZ [OPTIONS]: the tool on a straight line to a pose.

        Same units and rotations as moveto; the orientation turns about one
        axis on the way (Paul's drive transform); Cartesian and joint limits
        both kept.  A line that leaves the reach, crosses a joint limit or
        passes a singularity is refused before it starts, naming where;
        nothing moves.  Queued moves blend.  OPTIONS as movej's."""
        opts = self._options("movel", options)
        pose = _pose("movel", self.name, x, y, z, rx, ry, rz)
        eq = PositionEquation("movel", [Transform.varb("T6"), Transform.const("TOOL",
                                                                               self.tool_frame)],
                              [Transform.const("COORD", self.coord_frame),
                               Transform.varb("POS", pose)])
        t6 = self.coord_frame @ pose @ inverse(self.tool_frame)
        end = self.chain.ik(t6, self.heading())
        return self._queue_spec(MotionSpec(mode="cart", equation=eq, name="movel", **opts),
                                "movel",
                                end.q.copy() if end.ok else None,
                                f"tool {self.pose_text(self.coord_frame @ pose)}")

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
        is the base.  Refused while a move runs."""
        self._frames_free("coord")
        self.coord_frame = _pose("coord", self.name, x, y, z, rx, ry, rz)
        return f"coordinate frame {self.pose_text(self.coord_frame)} (in the base's frame)"

    def _frames_free(self, what: str) -> None:
        if self.state != "idle":
            raise CommandError(f"{self.name} {what}: refused while a move runs (the queued "
                               "targets were given in the frames as they are); wait or stop "
                               "first; nothing changed")


def _pose(verb: str, name: str, x: float, y: float, z: float, rx: float, ry: float,
          rz: float) -> np.ndarray:
    """A pose from the operator's words: mm, and degrees as URDF's rpy."""
    for axis, v in (("X", x), ("Y", y), ("Z", z)):
        if not math.isfinite(v):
            raise CommandError(f"{name} {verb}: {axis} must be a finite number of mm")
    return transform(np.array([x, y, z]) * 1e-3, np.radians([rx, ry, rz]))
