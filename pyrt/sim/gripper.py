"""The parallel-jaw mechanism behind the simulated gripper board.

Position is kept in encoder counts of the plant's own frame: 0 is the hard
stop at wide open, negative is closing (002's convention; the controller's
counter is relative, so after ``I`` the two frames agree to a count or two).
The jaws touch each other at about ``-CLOSED`` = -2A00 counts, D600 in two's
complement.  (002 says "D600" stands for the negative of "3A00"; the two's
complement of D600 is 2A00: an arithmetic slip in the report.)

Drive: the latched DAC byte, excess-128, is a current ``u`` in -128..127.
The worm drive is heavily damped and not back-drivable, so the jaws'
velocity follows the net drive (current less friction, less the reaction of
whatever the jaws press against) with a short motor lag.  Friction is a
deadband: a current of ``DEADBAND`` or less does not turn the worm.
Contacts are springs (the hard stop at wide open, the jaw surfaces closing
on each other, an optional object): pressing into one stalls the motor at
the depth where the spring balances the drive: it stalls, it does not
teleport, and the worm holds the squeeze when the current is nulled.

Sensors (active low on the 8155 ports): limit within ``LIMIT_BAND`` counts
of the wide-open stop; crossfire while an object is between the jaws; the
inner-face proximity sensors (left +Ya, right -Ya) when a jaw face is within
``PROX_MM`` of the object; overload when the object is squeezed with more
than ``OVERLOAD_FORCE`` (in current units).

Faults to inject: ``limit`` (the limit sensor never fires), ``jam`` (the
motor cannot turn), ``encoder`` (no encoder interrupts), ``port`` (an 8155
sensor port reads a stuck value).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import floor as _floor

from pyrt.boards.gripper import JOG_CLOSE, JOG_OPEN, GripperBoard
from pyrt.boards.registers import RegisterBoard

__all__ = ["FAULTS", "JawParameters", "JawPlant"]

#: Fault names accepted by :meth:`JawPlant.inject`.
FAULTS = ("limit", "jam", "encoder", "port")


@dataclass(frozen=True)
class JawParameters:
    """The mechanism's numbers (counts, seconds, millimetres, current units)."""

    closed: int = 0x2A00  #: counts from wide open to jaws touching
    open_mm: float = 76.0  #: jaw opening at wide open
    deadband: int = 8  #: current units lost to friction
    gain: float = 20.0  #: counts/s per current unit above the deadband
    tau: float = 0.015  #: motor lag, s
    k_open: float = 8.0  #: wide-open stop stiffness, current units per count
    k_closed: float = 1.0  #: jaw surfaces (jaws closed on each other), units per count
    k_object: float = 0.25  #: object stiffness, units per count
    max_open_overtravel: float = 4.0  #: counts the open stop can be pressed past
    max_closed_overtravel: float = 250.0  #: counts the closed jaws can be squeezed
    limit_band: float = 20.0  #: limit sensor fires within this many counts of the stop
    prox_mm: float = 5.0  #: proximity sensor range, mm from a jaw face
    overload_force: float = 60.0  #: overload sensor threshold, current units

    def counts_at_opening(self, mm: float) -> float:
        """Plant position (counts) where the jaw opening is ``mm``."""
        return -(self.open_mm - mm) / self.open_mm * self.closed

    def opening_mm(self, counts: float) -> float:
        """Jaw opening at plant position ``counts``."""
        return max(0.0, self.open_mm * (1.0 + counts / self.closed))


class JawPlant:
    """The jaws, their motor, encoder and sensors; ``step(now_ns)`` every tick.

    Attach :meth:`step` to the loop before the controller's ready queue, so
    each tick's routines see the world as it is after the time that passed.
    """

    def __init__(
        self,
        board: RegisterBoard,
        *,
        start: float = -0x0C00,
        object_mm: float | None = None,
        params: JawParameters | None = None,
    ):
        #: The cage's register file (the world's side) and the cage as a view over it
        #: (what the controller reads there: the latched DAC, the LEDs).
        self.registers = board
        self.board = GripperBoard(board)
        # the cage's registers the step reads and sets, bound once
        self._dac = board.cells("dac")
        self._pa, self._pb, self._pc = (board.cells(n) for n in ("pa", "pb", "pc"))
        self._up, self._down = board.cells("up"), board.cells("down")
        self.p = params if params is not None else JawParameters()
        if not -self.p.closed - self.p.max_closed_overtravel <= start <= 0:
            raise ValueError(f"start position must be 0 (wide open) .. -{self.p.closed:X}")
        #: Jaw position, counts of the plant frame (0 wide open, negative closing).
        self.x = float(start)
        #: Velocity, counts per second.
        self.v = 0.0
        self._enc = _floor(self.x)
        self.object_mm: float | None = None
        self._touch = float("-inf")
        p = self.p
        self._k = (
            p.deadband, p.gain, p.k_open, p.closed, p.k_closed, p.k_object,
            p.max_open_overtravel, -p.closed - p.max_closed_overtravel,
        )
        self._dt_ns = 0
        self._blend = 1.0
        #: Below this position the limit sensor cannot fire.
        self._quiet_below = -p.limit_band - 2.0
        #: True while the ports last read all-off with no object and nothing stuck.
        self._quiet = False
        self.faults: set[str] = set()
        self.stuck: dict[str, int] = {}
        self._jam = False
        self._encoder_dead = False
        self._jog_until: int | None = None
        self._jog: str = "off"
        self._last: int | None = None
        self._dirty = True
        #: Force on the object (current units), for the status line and tests.
        self.squeeze = 0.0
        self.set_object(object_mm)
        self._sense()

    # -- configuration (thread: the loop's) ----------------------------------------

    def set_object(self, width_mm: float | None) -> None:
        """Put an object of ``width_mm`` between the jaws (None: take it away).

        An object wider than the jaws' current opening cannot be put in.
        """
        if width_mm is not None:
            if not 0 < width_mm < self.p.open_mm:
                raise ValueError(f"object width must be between 0 and {self.p.open_mm:g} mm")
            touch = self.p.counts_at_opening(width_mm)
            if self.x < touch - 0.5:
                raise ValueError(
                    f"a {width_mm:g} mm object does not fit: the jaws are open "
                    f"{self.p.opening_mm(self.x):.1f} mm"
                )
            self._touch = touch
        else:
            self._touch = float("-inf")
        self.object_mm = width_mm
        self._dirty = True

    def inject(self, fault: str, value: int | None = None, port: str = "2D") -> None:
        """Inject a fault (:data:`FAULTS`); ``port`` faults need the stuck ``value``."""
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; choose from {', '.join(FAULTS)}")
        if fault == "port":
            if port not in ("2D", "2E"):
                raise ValueError("a stuck sensor port is 2D (proximity) or 2E (other sensors)")
            if value is None or not 0 <= value <= 0xFF:
                raise ValueError("a stuck port needs a value 00..FF")
            self.stuck[port] = value
        self.faults.add(fault)
        self._flags()

    def clear_faults(self) -> None:
        """Remove every injected fault."""
        self.faults.clear()
        self.stuck.clear()
        self._flags()

    def _flags(self) -> None:
        self._jam = "jam" in self.faults
        self._encoder_dead = "encoder" in self.faults
        self._dirty = True

    def jog(self, direction: str, duration_ns: int | None = None) -> None:
        """Hold the jog switch ``open`` or ``close`` (for ``duration_ns``), or ``off``."""
        if direction not in ("open", "close", "off"):
            raise ValueError("jog direction is open, close or off")
        self._jog = direction
        pc = self._pc[0] | (1 << JOG_OPEN) | (1 << JOG_CLOSE)
        if direction == "open":
            pc &= ~(1 << JOG_OPEN)
        elif direction == "close":
            pc &= ~(1 << JOG_CLOSE)
        self._pc[0] = pc & 0xFF
        self._jog_until = None
        if direction != "off" and duration_ns is not None:
            now = self._last if self._last is not None else 0
            self._jog_until = now + duration_ns

    @property
    def jog_state(self) -> str:
        """The jog switch position: open, close or off."""
        return self._jog

    @property
    def current(self) -> int:
        """The drive current the latched DAC byte applies (-128..127)."""
        return self._dac[0] - 0x80

    @property
    def dac(self) -> int:
        """The DAC byte the controller latched (excess-128)."""
        return self._dac[0]

    def pulse_counts(self) -> tuple[int, int]:
        """Encoder pulses counted so far on each interrupt line (up, down), modulo 2**32."""
        return self._up[0], self._down[0]

    @property
    def opening_mm(self) -> float:
        """Jaw opening in mm."""
        return self.p.opening_mm(self.x)

    # -- physics --------------------------------------------------------------------

    def step(self, now_ns: int) -> None:
        """Advance the mechanism to ``now_ns`` (dt = now - last)."""
        last = self._last
        self._last = now_ns
        if self._jog_until is not None and now_ns >= self._jog_until:
            self.jog("off")
        if last is None:
            return
        u = self._dac[0] - 0x80
        v = self.v
        if u == 0 and v == 0.0:
            if self._dirty:
                self._sense()
            return
        dt_ns = now_ns - last
        if dt_ns <= 0:
            return
        if dt_ns != self._dt_ns:  # the lag's blend factor, recomputed when dt changes
            self._dt_ns = dt_ns
            self._blend = min(1.0, dt_ns * 1e-9 / self.p.tau)
        dt = dt_ns * 1e-9
        deadband, gain, k_open, closed, k_closed, k_object, x_max, x_min = self._k
        x = self.x
        if self._jam:
            v = 0.0
        else:
            a = (u if u > 0 else -u) - deadband
            if a <= 0:
                drive = 0.0
            else:
                drive = float(a)
                if u > 0:
                    if x > 0.0:
                        drive -= k_open * x
                else:
                    if x < -closed:
                        drive -= k_closed * (-closed - x)
                    if x < self._touch:  # -inf without an object
                        drive -= k_object * (self._touch - x)
                if drive < 0.0:
                    drive = 0.0  # a worm drive is not back-driven
                if u < 0:
                    drive = -drive
            v_target = gain * drive
            v += (v_target - v) * self._blend
            if -0.5 < v < 0.5 and v_target == 0.0:
                v = 0.0
        x += v * dt
        if x > x_max:
            x = x_max
            v = 0.0
        elif x < x_min:
            x = x_min
            v = 0.0
        self.x = x
        self.v = v
        enc = _floor(x)
        d = enc - self._enc
        if d:
            self._enc = enc
            if not self._encoder_dead:  # one pulse a count on interrupt 0 (up) or 1 (down)
                if d > 0:
                    self._up[0] = (self._up[0] + d) & 0xFFFFFFFF
                else:
                    self._down[0] = (self._down[0] - d) & 0xFFFFFFFF
            # far from the limit band with nothing else to sense, the ports
            # read all-off: write them only when that may have changed
            if x >= self._quiet_below or self._dirty or not self._quiet:
                self._sense()
        elif self._dirty:
            self._sense()

    def _sense(self) -> None:
        """Write the sensor port levels for the present position (active low)."""
        self._dirty = False
        p = self.p
        x = self.x
        prox = 0xFF
        other = 0xFF
        self.squeeze = 0.0
        if self.object_mm is not None:
            other &= ~0x01  # crossfire: something between the jaws
            gap = (p.opening_mm(x) - self.object_mm) / 2.0
            if gap <= p.prox_mm:
                prox &= ~0x01 & ~0x10  # left +Ya, right -Ya: the inner faces
            if x < self._touch:
                self.squeeze = p.k_object * (self._touch - x)
                if self.squeeze > p.overload_force:
                    other &= ~0x02
        if x >= -p.limit_band and "limit" not in self.faults:
            other &= ~0x04
        if self.stuck:
            prox = self.stuck.get("2D", prox)
            other = self.stuck.get("2E", other)
        self._pa[0] = prox & 0xFF
        self._pb[0] = (other | 0xF8) & 0xFF  # PB's bits 3-7 float high
        self._quiet = (
            prox == 0xFF and other == 0xFF and self.object_mm is None and not self.stuck
        )

    def status(self) -> str:
        """One line: position, opening, velocity, current, object, jog, faults."""
        obj = "none" if self.object_mm is None else f"{self.object_mm:g} mm"
        if self.object_mm is not None and self.squeeze:
            obj += f" (squeezed, force {self.squeeze:.0f})"
        faults = ", ".join(sorted(self.faults)) or "none"
        if self.stuck:
            faults += " [" + " ".join(f"{k}={v:02X}" for k, v in sorted(self.stuck.items())) + "]"
        return (
            f"jaws {self.x:.0f} counts ({self.opening_mm:.1f} mm open), "
            f"{self.v:.0f} counts/s, current {self.current:+d}, object {obj}, "
            f"jog {self._jog}, faults {faults}"
        )
