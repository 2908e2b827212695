"""One rope of the manipulator: Motor, Encoder and Loadcell together (000, section 6).

Lengths: :meth:`Axis.length` (000's ``getLength``) is the rope from the top pulley to its end,
corrected for stretch; the encoder gives the total unstretched length from
the spindle (dead length included) and the rope stretches in proportion to
tension and length (STRETCH, strain per newton), so

    length = encoder length * (1 + STRETCH * tension) - DEADLENGTH

(:func:`pyrt.robots.ropes.corrected_length`, the one stretch formula).

Standalone control (``STEP_MODE``, Table 4 commands ``up``, ``down``,
``to``): each poll recalculates the steps left to the wanted length and
hands them to the Motor; within :data:`END_ZONE` (1 cm) of the end it stops
recalculating and lets the Motor finish the move.

PolyAxis control (``VELOCITY_MODE``) is driven from above:
:meth:`Axis.poly_activate` (000's ``polyActivate``) puts the Motor in velocity mode on standby and
refuses keyboard commands; the PolyAxis then computes the error signals
and sets the Motor's velocity each poll (its rates of change are kept in
the C controller, :class:`pyrt.native.PolyControl`), and polls the axis's
encoder; axis-poll (:mod:`pyrt.tasks.axis_poll`) leaves the axis alone
until :meth:`Axis.poly_deactivate` (``polyDeactivate``) hands it back.

LENGTH write-back is the station's (:class:`pyrt.tasks.WriteBack`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any, Protocol

from pyrt.boards.dataconcentrator import ADC_MAX, DataConcentrator
from pyrt.boards.tio10 import TIO10
from pyrt.component import Arg, Component, Limits, Param, Signal, command
from pyrt.db import defaults
from pyrt.devices._args import parse_number
from pyrt.devices.encoder import Encoder
from pyrt.devices.loadcell import Loadcell, parse_load
from pyrt.devices.motor import MAX_CRUISE_SPEED, MIN_START_SPEED, STEP_MODE, Motor
from pyrt.errors import CommandError, ConfigError, PyrtError
from pyrt.robots.av import AV
from pyrt.robots.fuzzy_gains import fuzzy_gain_params
from pyrt.robots.ropes import corrected_length
from pyrt.scope import Source
from pyrt.tasks.axis_poll import POLYAXIS, STANDALONE

if TYPE_CHECKING:
    from pyrt.db import AxisRecord, Station

__all__ = [
    "END_ZONE",
    "LOADCELL_STUCK_S",
    "POLYAXIS",
    "STANDALONE",
    "TRACKING_CHECK",
    "TRACKING_MIN_FRACTION",
    "Axis",
    "RopeGroup",
    "TrackingError",
]

#: 000, section 6: within 1 cm of the end the Motor finishes on its own.
END_ZONE = 1.0

#: Every TRACKING_CHECK cm of motor travel the encoder must have seen at least
#: TRACKING_MIN_FRACTION of it, in the same sense; otherwise the motor has
#: stalled or the encoder shaft slips (000, section 3) and the axis stops.
TRACKING_CHECK = 2.0
TRACKING_MIN_FRACTION = 0.5

#: A loadcell whose ADC code has not changed for this long while a motor runs
#: is stuck: the conversion noise of a live one (000, section 10: the bias
#: resistor keeps the amplifiers in their linear, noisy range) moves it by a
#: code every few polls.  Half a second is 50 axis polls.
LOADCELL_STUCK_S = 0.5
LOADCELL_STUCK_READS = 50
#: ... and while the motor has moved at least this much rope (cm): a taut
#: rope's tension changes by tens of newtons per centimetre (STRETCH 2e-5/N),
#: hundreds of codes, so an unchanged code then is a stuck loadcell, even
#: one without conversion noise (``--ideal-sensors``) or on a slow creep.
LOADCELL_STUCK_ROPE_CM = 1.0
#: Supervision calls further apart than this belong to different moves.
_SUPERVISION_GAP_S = 0.1


class RopeGroup(Protocol):
    """What an Axis knows of the PolyAxis that drives it (its ``group``)."""

    @property
    def name(self) -> str: ...

    @property
    def active(self) -> bool: ...

    @property
    def lengths(self) -> list[float]: ...

    @property
    def tensions(self) -> list[float]: ...

    @property
    def estimate_lost(self) -> str | None: ...

    def end_move(self, reason: Any, detail: str) -> Any: ...


class TrackingError(PyrtError):
    """The encoder does not follow the motor: a stalled motor or a slipping encoder.

    Raised from :meth:`Axis.poll` after the motor has been stopped, so the
    control loop turns it into a fault (every motor of the robot stopped).
    """


def tension_alarms(limits: tuple[float, float] | None) -> Limits | None:
    """A rope tension's display range and alarms from (LOW_TENSION, MAX_TENSION):
    LOLO/HIHI are the stops (a MAJOR alarm); LOW/HIGH warn a little before them
    (1.5 x LOW_TENSION and 90 % of MAX_TENSION: pyrt's choice, the documents
    give only the stops).  None without limits."""
    if limits is None:
        return None
    lo, hi = limits
    return Limits(0.0, hi, lolo=lo, low=1.5 * lo, high=0.9 * hi, hihi=hi)


def _zero() -> float:
    return 0.0


def _true() -> bool:
    return True


def _polled(axis: Axis, name: str, units: str, values: str, fresh: Callable[[], float],
            doc: str, limits: Limits | None = None) -> Signal:
    """An axis's signal of the value the controller acts on: the PolyAxis's last
    poll when the axis is one of its ropes (an item of its list, which the poll
    fills in place: the scope samples the item), else a fresh read of the device."""
    group, i = axis.group, axis.group_index
    if group is None or i is None:
        return Signal(name, units, fresh, doc, limits=limits)
    array = getattr(group, values)
    return Signal(name, units, partial(array.__getitem__, i), doc,
                  source=Source.item(array, i), limits=limits)


def _moving(length: float) -> str:
    return f"moving to length {length:.3f} cm"


class Axis(Component):
    """One rope (see the module text).

    ``top`` and ``offset`` are global / carriage co-ordinates; ``bottom`` is in
    vessel co-ordinates and is carried to global through ``av.vtog`` (when an
    AV is given) before anything uses it.
    """

    def __init__(
        self,
        name: str,
        motor: Motor,
        encoder: Encoder,
        loadcell: Loadcell,
        *,
        dead_length: float,
        top: Sequence[float],
        offset: Sequence[float] = (0.0, 0.0, 0.0),
        bottom: Sequence[float] | None = None,
        av: AV | None = None,
        stretch: float = defaults("AXIS")["stretch"],
    ):
        if not (math.isfinite(dead_length) and dead_length >= 0):
            raise ConfigError(f"axis {name}: DEADLENGTH must be >= 0 cm, got {dead_length!r}")
        if not (math.isfinite(stretch) and stretch >= 0):
            raise ConfigError(f"axis {name}: STRETCH must be >= 0 per N, got {stretch!r}")
        self.name = name
        self.motor = motor
        self.encoder = encoder
        self.loadcell = loadcell
        #: The PolyAxis this axis belongs to (it sets this), for ``stop``.
        self.group: RopeGroup | None = None
        #: The rope's index in its PolyAxis (set with ``group``).
        self.group_index: int | None = None
        for device in (motor, encoder, loadcell):
            device.owner_busy = self._device_busy  # type: ignore[union-attr]
        self.dead_length = float(dead_length)
        self.stretch = float(stretch)
        self.av = av
        self.top = tuple(float(c) for c in top)
        self.offset = tuple(float(c) for c in offset)
        self.bottom_vessel: tuple[float, float, float] | None = (
            None if bottom is None else (float(bottom[0]), float(bottom[1]), float(bottom[2])))

        self.mode = STANDALONE
        self.target: float | None = None
        #: A standalone move (up, down, to) was started and has not been
        #: reported ended yet (the station reports it when the motion stops).
        self.moved = False
        #: The rope's physical length range (cm), set by the station from the
        #: geometry (:meth:`set_supervision`); None: lengths > 0 only.
        self.length_range: tuple[float, float] | None = None
        #: Tension limits (N) and whether they apply now (``tensionStop``), set
        #: by the station; None: unsupervised (an Axis on its own, in tests).
        self.tension_limits: tuple[float, float] | None = None
        self.tension_stops: Callable[[], bool] = _true
        self._track_reset()
        self._adc_last = -1
        self._adc_since: float | None = None
        self._adc_seen = 0.0
        self._adc_same = 0
        self._adc_steps = 0

    @classmethod
    def from_records(
        cls,
        name: str,
        record: AxisRecord,
        station: Station,
        tio10: TIO10,
        dc: DataConcentrator,
        *,
        av: AV | None = None,
        persist: Callable[[str, str, str, float], None] | None = None,
    ) -> Axis:
        """An Axis and its devices from a :class:`pyrt.db.AxisRecord` and its
        :class:`pyrt.db.Station`.  Sub-objects are named ``<name>Motor``,
        ``<name>Encoder``, ``<name>Loadcell`` (000, section 6).  ``persist(type,
        db name, key, value)`` receives the devices' write-back (ZEROLENGTH,
        SLOPE/OFFSET); LENGTH is the station's (:class:`pyrt.tasks.WriteBack`)."""
        mrec = station.motor_of(record)
        erec = station.encoder_of(record)
        lrec = station.loadcell_of(record)

        def put(type_: str, db_name: str, key: str) -> Callable[[float], None] | None:
            if persist is None:
                return None
            return lambda v: persist(type_, db_name, key, v)

        def put_cal(slope: float, offset: float) -> None:
            if persist is not None:
                persist("LOADCELL", lrec.name, "SLOPE", slope)
                persist("LOADCELL", lrec.name, "OFFSET", offset)

        motor = Motor.from_record(mrec, tio10, name=f"{name}Motor")
        encoder = Encoder.from_record(erec, dc, name=f"{name}Encoder",
                                      write_back=put("ENCODER", erec.name, "ZEROLENGTH"))
        loadcell = Loadcell.from_record(lrec, dc, name=f"{name}Loadcell",
                                        write_back=put_cal if persist is not None else None)
        return cls(
            name, motor, encoder, loadcell,
            dead_length=record.deadlength, top=record.top, offset=record.offset,
            bottom=record.bottom, av=av, stretch=record.stretch,
        )

    # -- geometry --------------------------------------------------------------------

    @property
    def bottom(self) -> tuple[float, float, float] | None:
        """The bottom attachment in global co-ordinates (through the AV's pose)."""
        if self.bottom_vessel is None:
            return None
        if self.av is None:
            return self.bottom_vessel
        return self.av.vtog(self.bottom_vessel)

    # -- measurements ------------------------------------------------------------------

    def tension(self) -> float:
        return self.loadcell.tension()

    def length(self) -> float:
        """Rope length from the top pulley to its end, stretch corrected (cm)."""
        return corrected_length(self.encoder.length(), self.loadcell.tension(), self.stretch,
                                self.dead_length)

    # -- the component contract ----------------------------------------------------------

    def children(self) -> list[Component]:
        return [self.motor, self.encoder, self.loadcell]

    def signals(self) -> list[Signal]:
        r = self.length_range
        return [
            _polled(self, "tension", "N", "tensions", self.tension,
                    "rope tension the controller acts on (loadcell)",
                    limits=tension_alarms(self.tension_limits)),
            _polled(self, "length", "cm", "lengths", self.length,
                    "rope length the controller acts on, stretch corrected",
                    limits=None if r is None else Limits(r[0], r[1])),
            _polled(self, "errorLength", "cm", "error_lengths", _zero,
                    "fuzzy input: length error (PolyAxis control; 0 standalone)"),
            _polled(self, "errorTension", "N", "error_tensions", _zero,
                    "fuzzy input: tension error (PolyAxis control; 0 standalone)"),
            Signal.attr("velocity", "cm/s", self.motor, "velocity", "motor velocity",
                        limits=self.motor.speed_limits),
        ]

    def reflex(self) -> None:
        """The axis's motor stops with its own reflex; the axis forgets its target."""
        self.target = None

    def _controller(self) -> str:
        return getattr(self.group, "name", "PolyAxis")

    def _device_busy(self) -> str | None:
        if self.mode == POLYAXIS:
            return (f"{self.name} is under {self._controller()} control (000: polyActivate "
                    "turns off its commands); stop the move first")
        return None

    # -- Table 4 commands ------------------------------------------------------------------

    def _standalone(self, command: str) -> None:
        if self.mode != STANDALONE:
            raise CommandError(f"{self.name} {command}: the axis is under "
                               f"{self._controller()} control; stop it first")

    def _distance(self, value: float | str, command: str) -> float:
        d = parse_number(value, f"{self.name} {command}", "distance in cm")
        if d < 0:
            raise CommandError(f"{self.name} {command}: distance must be >= 0 cm, got {d}; "
                               f"use {'down' if command == 'up' else 'up'} for the other way")
        hi = self.travel_range[1]
        if hi is not None and d > hi:
            raise CommandError(f"{self.name} {command}: DIST {d:g} cm is out of range: "
                               f"DIST 0..{hi:g} cm (the rope's length range); nothing moved")
        return d

    @property
    def travel_range(self) -> tuple[float, float | None]:
        """The range of an ``up``/``down`` distance (cm): up to the span of the
        rope's length range."""
        r = self.length_range
        return (0.0, None) if r is None else (0.0, round(r[1] - r[0], 1))

    @property
    def target_range(self) -> tuple[float, float | None]:
        """The range of a ``to`` length (cm): the rope's length range."""
        r = self.length_range
        return (0.0, None) if r is None else r

    def params(self) -> list[Param]:
        """The limits every move of this rope is held to, read only (the PolyAxis
        sets them: ``set POLYAXIS.MAX_TENSION``); under a PolyAxis, the rope's
        fuzzy gains (:mod:`pyrt.robots.fuzzy_gains`)."""
        def limit(which: int, attr: str) -> Callable[[], float | None]:
            return lambda: (getattr(self, attr) or (None, None))[which]

        batch = getattr(self.group, "batch", None)
        gains = ([] if batch is None or self.group_index is None
                 else fuzzy_gain_params(batch, self.group_index, self.name))
        return [
            Param("LENGTH_MIN", "cm", limit(0, "length_range"), doc="shortest rope length"),
            Param("LENGTH_MAX", "cm", limit(1, "length_range"), doc="longest rope length"),
            Param("LOW_TENSION", "N", limit(0, "tension_limits"), doc="lowest tension"),
            Param("HIGH_TENSION", "N", limit(1, "tension_limits"), doc="highest tension"),
            *gains,
        ]

    def set_supervision(self, length_range: tuple[float, float],
                        tension_limits: tuple[float, float],
                        tension_stops: Callable[[], bool] = _true) -> None:
        """The limits every move of this rope is held to (see :meth:`supervise`):
        its physical length range (cm), LOW_TENSION and MAX_TENSION (N), and
        whether the tension limits apply now (the PolyAxis's ``tensionStop``)."""
        lo, hi = (float(v) for v in length_range)
        tl, th = (float(v) for v in tension_limits)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
            raise ConfigError(f"axis {self.name}: length range must be 0 <= lo < hi cm, "
                              f"got {length_range!r}")
        if not (math.isfinite(tl) and math.isfinite(th) and tl < th):
            raise ConfigError(f"axis {self.name}: tension limits must be low < high N, "
                              f"got {tension_limits!r}")
        self.length_range = (lo, hi)
        self.encoder.length_range = (lo + self.dead_length, hi + self.dead_length)
        self.tension_limits = (tl, th)
        self.loadcell.limits = tension_alarms(self.tension_limits)
        self.tension_stops = tension_stops

    @command(Arg("DIST", str, lo=0.0, units="cm", bounds="travel_range",
                 what="the span of the rope's length range"),
             name="up", moves=True, reply=_moving)
    def cmd_up(self, dist: float | str) -> float:
        """up DIST: move up DIST cm (shorten the rope; the source goes up)."""
        d = self._distance(dist, "up")
        self._standalone("up")
        return self._go(self.length() - d, "up")

    @command(Arg("DIST", str, lo=0.0, units="cm", bounds="travel_range",
                 what="the span of the rope's length range"),
             name="down", moves=True, reply=_moving)
    def cmd_down(self, dist: float | str) -> float:
        """down DIST: move down DIST cm (lengthen the rope)."""
        d = self._distance(dist, "down")
        self._standalone("down")
        return self._go(self.length() + d, "down")

    @command(Arg("LEN", str, lo=0.0, units="cm", bounds="target_range",
                 what="the rope's physical length range"),
             name="to", moves=True, reply=_moving)
    def cmd_to(self, length: float | str) -> float:
        """to LEN: change the rope length to LEN cm."""
        v = parse_number(length, f"{self.name} to", "length in cm")
        if v <= 0:
            raise CommandError(f"{self.name} to: length must be > 0 cm, got {v}")
        self._standalone("to")
        return self._go(v, "to")

    def _go(self, target: float, command: str) -> float:
        lost = getattr(self.group, "estimate_lost", None)
        if lost is not None:  # an encoder that slipped or was reset: lengths not trusted
            raise CommandError(f"{self.name} {command}: refused: the position estimate is not "
                               f"trusted ({lost}); re-establish it with "
                               f"'{self._controller()} survey' or "
                               f"'{self._controller()} setpos X Y Z' first; nothing moved")
        if target <= 0:
            raise CommandError(f"{self.name} {command}: that would leave the rope at "
                               f"{target:.3f} cm; lengths must stay > 0")
        r = self.length_range
        if r is not None and not r[0] <= target <= r[1]:
            raise CommandError(f"{self.name} {command}: that would take the rope to "
                               f"{target:.3f} cm, outside its physical length range "
                               f"{r[0]:g}..{r[1]:g} cm; nothing moved")
        err = target - self.length()
        steps = round(err * self.motor.steps_per_cm)
        m = self.motor
        if m.mode == STEP_MODE and m.running and steps != 0 and (steps > 0) != (m.direction > 0):
            raise CommandError(f"{self.name} {command}: the motor is moving the other way; "
                               "stop it first (STEP_MODE never reverses)")
        self.target = target
        self.moved = True
        if m.mode == STEP_MODE and m.running and steps != 0:
            m.set_desired_steps(m.steps_taken + abs(steps))
        else:
            m.move(steps)
        return target

    @command(name="calibrate", reply=lambda v: (
        "loadcell calibration mode: hang known loads and give 'point LOAD'" if v is None
        else f"loadcell SLOPE {v[0]:.10g} OFFSET {v[1]:.10g}"))
    def cmd_calibrate(self) -> tuple[float, float] | None:
        """calibrate: toggle loadcell calibration mode (leaving it fits)."""
        self._standalone("calibrate")
        return self.loadcell.calibrate()

    @property
    def load_range(self) -> tuple[float, float | None]:
        """Calibration loads (N): the loadcell's."""
        return self.loadcell.load_range

    @command(Arg("LOAD", lambda t: parse_load(t, "point"), rest=True, lo=0.0, units="N",
                 bounds="load_range", what="up to the loadcell's MAXLOAD"), name="point",
             reply=lambda v: f"loadcell point: ADC {v[0]} = {v[1]:.4g} N")
    def cmd_point(self, load: float | str) -> tuple[int, float]:
        """point LOAD: enter a loadcell calibration point (LOAD in N, lb or kg)."""
        self._standalone("point")
        return self.loadcell.point(load)

    @command(Arg("SPEED", str, lo=MIN_START_SPEED, hi=MAX_CRUISE_SPEED, units="cm/s",
                 what="000's motor speeds"), name="maxspeed",
             reply=lambda v: f"maximum speed {v:g} cm/s")
    def cmd_maxspeed(self, speed: float | str) -> float:
        """maxspeed SPEED: set the maximum motor speed in cm/s."""
        self._standalone("maxspeed")
        return self.motor.maxspeed(speed)

    @command(name="zero", reply=lambda _v: "encoder counter reset")
    def cmd_zero(self) -> None:
        """zero: reset the encoder counter."""
        self._standalone("zero")
        self.encoder.reset()
        self._track_reset()

    def stop(self) -> None:
        """Stop the motor (windings off); accepted in any mode."""
        self.motor.stop()
        self.target = None

    @command(name="stop", anyone=True)
    def cmd_stop(self) -> str:
        """stop: stop the motor; during a PolyAxis move, the whole move stops with it."""
        group = self.group
        if group is not None and getattr(group, "active", False):
            # one joint stopped stops the whole manipulator
            from pyrt.robots.stops import StopReason

            group.end_move(StopReason.STOP, f"{self.name} stop command")
            return f"stopped; the {group.name} move is stopped with it"
        self.stop()
        return "stopped"

    # -- PolyAxis hooks ---------------------------------------------------------------

    def poly_activate(self) -> None:
        """Hand the axis to PolyAxis control: Motor in VELOCITY_MODE on standby,
        commands refused (000, section 5)."""
        self.target = None
        self.motor.velocity_mode()
        self.mode = POLYAXIS
        self._track_reset()

    def poly_deactivate(self) -> None:
        """Stop the motor and return the axis to standalone control."""
        self.motor.stop()
        self.motor.mode = STEP_MODE
        self.mode = STANDALONE

    # -- polling -------------------------------------------------------------------------

    def poll(self, now_s: float) -> None:
        """One poll: standalone control, then the Motor, then the Encoder."""
        encoder = self.encoder
        measured = encoder.length()  # (length(), in line: the encoder's is kept)
        m = self.motor
        if self.mode == STANDALONE and self.target is not None and m.armed():
            err = self.target - corrected_length(measured, self.loadcell.tension(),
                                                 self.stretch, self.dead_length)
            if abs(err) > END_ZONE:
                if (err > 0) == (m.direction > 0):
                    m.set_desired_steps(m.steps_taken + round(abs(err) * m.steps_per_cm))
                else:
                    m.set_desired_steps(m.steps_taken)
        m.poll()
        # the tracking check, once the motor has moved TRACKING_CHECK (_track_check's test)
        if abs((m.position_steps - self._track_steps) / m.steps_per_cm) >= TRACKING_CHECK:
            self._track()
        if self.mode == STANDALONE and self.target is not None and not m.armed():
            self.target = None
        # the encoder's counter as read above: nothing in this poll moves it
        encoder.poll(now_s, measured)

    # -- supervision (every move of every kind; pyrt.tasks.axis_poll) ----------------

    def supervise(self, now_s: float, standalone_move: bool) -> str | None:
        """Why every motor must stop now, or None; called every axis poll while
        any motor of the manipulator runs (``standalone_move``: one runs under
        standalone control).  In order:

        * the loadcell: an ADC code at either end of its range (dead,
          disconnected, saturated; in a PolyAxis move the tension stops see
          that first), or one that has not changed for
          :data:`LOADCELL_STUCK_S` while this rope's motor runs and has moved
          :data:`LOADCELL_STUCK_ROPE_CM` of rope (stuck);
        * the rope's physical length range, when the motor drives it further out;
        * under PolyAxis control, the encoder must follow the motor (stall or
          slip, as :meth:`poll` checks standalone moves);
        * during a standalone move, with ``tensionStop`` on: every rope's
          tension within LOW_TENSION..MAX_TENSION, unless this rope's own motor
          is moving it back inside (a PolyAxis move has its own tension stops).
        """
        m = self.motor
        running = m.armed() != 0  # (m.running, through its reader)
        group, i = self.group, self.group_index
        poly = self.mode == POLYAXIS and group is not None and i is not None
        lc = self.loadcell
        code = lc.channel.raw()
        if not poly and (code <= 0 or code >= ADC_MAX):  # (a PolyAxis move: its tension stops)
            return (f"LOADCELL_FAULT: {lc.name} reads ADC code {code}, the end of its "
                    "range (dead, disconnected or saturated)")
        since = self._adc_since
        if (code != self._adc_last or not running or since is None
                or now_s - self._adc_seen > _SUPERVISION_GAP_S):  # a new move: a new clock
            self._adc_last = code
            since = self._adc_since = now_s
            self._adc_same = 0
            self._adc_steps = m.position_steps
        self._adc_seen = now_s
        self._adc_same += 1
        # both: half a second, and as many reads as half a second of axis polls
        # (late ticks on a loaded machine must not make two reads look stuck)
        if (now_s - since >= LOADCELL_STUCK_S and self._adc_same > LOADCELL_STUCK_READS
                and abs(m.position_steps - self._adc_steps)
                >= LOADCELL_STUCK_ROPE_CM * m.steps_per_cm):
            return (f"LOADCELL_FAULT: {lc.name} has read ADC code {code} for "
                    f"{now_s - since:.1f} s while {m.name} moved "
                    f"{abs(m.position_steps - self._adc_steps) / m.steps_per_cm:.1f} cm of rope "
                    "(stuck)")
        if poly:
            assert group is not None and i is not None
            length = group.lengths[i]
            tension = group.tensions[i]
            lengthening = m.velocity > 0
        else:
            tension = lc.tension()
            length = self._length_at(tension)
            lengthening = m.direction > 0
        r = self.length_range
        if running and r is not None and ((lengthening and length > r[1])
                                          or (not lengthening and length < r[0])):
            return (f"LENGTH_RANGE_STOP: {self.name} length {length:.2f} cm is outside its "
                    f"physical range {r[0]:g}..{r[1]:g} cm and {m.name} drives it further")
        if poly and running:
            why = self._track_check()
            if why is not None:
                return f"TRACKING_FAULT: {why}"
        lim = self.tension_limits
        if standalone_move and lim is not None and self.tension_stops():
            own = running and not poly
            if tension < lim[0] and not (own and not lengthening):
                return (f"LOW_TENSION_STOP: {self.name} tension {tension:.2f} N below "
                        f"LOW_TENSION {lim[0]:g} N during an axis move")
            if tension > lim[1] and not (own and lengthening):
                return (f"HIGH_TENSION_STOP: {self.name} tension {tension:.2f} N above "
                        f"MAX_TENSION {lim[1]:g} N during an axis move")
        return None

    def fail(self, cause: str, source: str = "") -> None:
        """A fault of the robot found on this rope; during a PolyAxis move the
        move ends first with a FAULT stop that says why (``last_stop``)."""
        group = self.group
        if self.mode == POLYAXIS and group is not None and getattr(group, "active", False):
            from pyrt.robots.stops import StopReason

            group.end_move(StopReason.FAULT, cause)
        super().fail(cause, source)

    def _length_at(self, tension: float) -> float:
        return corrected_length(self.encoder.length(), tension, self.stretch, self.dead_length)

    def _track_reset(self) -> None:
        self._track_steps = self.motor.position_steps
        self._track_count = self.encoder.count()

    def _track(self) -> None:
        why = self._track_check()
        if why is not None:
            self.motor.stop()
            self.target = None
            raise TrackingError(f"TRACKING_FAULT: {why}; motor stopped")

    def _track_check(self) -> str | None:
        """Every TRACKING_CHECK cm of motor travel: why the encoder does not
        follow the motor, or None."""
        m = self.motor
        moved = (m.position_steps - self._track_steps) / m.steps_per_cm
        if abs(moved) < TRACKING_CHECK:
            return None
        count = self.encoder.count()
        seen = (count - self._track_count) * self.encoder.slope
        self._track_steps = m.position_steps
        self._track_count = count
        if seen * moved <= 0 or abs(seen) < TRACKING_MIN_FRACTION * abs(moved):
            return (f"{self.name}: the motor moved {moved:+.2f} cm but the encoder saw "
                    f"{seen:+.2f} cm: motor stall or encoder slip")
        return None
