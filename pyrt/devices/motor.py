"""The stepping motor of one manipulator rope (000, section 8), on a TIO10 channel.

The motor takes a half-step per output pulse of its clock channel, so speed
is set through the channel's count-down period.  The channel counts the
AM9513's F3 source (the 5 MHz clock divided by 100): with 40 half-steps per
cm that spans the document's whole 0.07..7.0 cm/s range inside the 16-bit
load register, and makes the document's ramp (the period shortened by 10
counts a step) take a few centimetres rather than metres.

Two control modes (000, section 8):

* ``STEP_MODE``: take a number of steps in one direction (never reversing).
  The period starts at the start speed's and shrinks by ``ramp_decrement``
  for every step taken until the cruise period is reached; when the steps
  left are no more than the steps used to accelerate, it grows by the same
  amount a step, so the ramp down mirrors the ramp up.  The move's total may
  be changed while it runs (:meth:`Motor.set_desired_steps`); the motor
  stops itself when it has taken them.
* ``VELOCITY_MODE``: follow a desired signed velocity (positive pays rope
  out), changing the velocity by at most ``dv_limit`` per poll, through
  standby to reverse.  States ``OFF`` (needs a new command), ``ON`` and
  ``STANDBY`` (halted, may restart).

Whenever the motor is not stepping its windings are off: no drive current is
left applied without movement.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from pyrt.boards.tio10 import (
    AWO_BITS,
    DIR_BITS,
    MAX_PERIOD,
    MIN_PERIOD,
    PULSE_COUNTER_MODULUS,
    RTC_CHANNELS,
    TIO10,
    source_hz,
)
from pyrt.component import Arg, Component, Limits, Param, Signal, command
from pyrt.devices._args import parse_number
from pyrt.errors import CommandError, ConfigError
from pyrt.scope import Source

if TYPE_CHECKING:
    from pyrt.db import MotorRecord

__all__ = [
    "MAX_CRUISE_SPEED",
    "MIN_START_SPEED",
    "MOTOR_SOURCE",
    "OFF",
    "ON",
    "STANDBY",
    "STEP_MODE",
    "VELOCITY_MODE",
    "Motor",
]

#: 000, section 8: "7.0 cm/s is the maximum allowed cruise speed and 0.07
#: cm/s is about the minimum allowed start speed.  These limits are enforced."
MAX_CRUISE_SPEED = 7.0
MIN_START_SPEED = 0.07
#: AM9513 source the motor channels count: F3 = 50 kHz.
MOTOR_SOURCE = 3

STEP_MODE = "STEP_MODE"
VELOCITY_MODE = "VELOCITY_MODE"
OFF, ON, STANDBY = 0, 1, 2
_STATE_NAMES = {OFF: "off", ON: "on", STANDBY: "standby"}


class Motor(Component):
    """One stepping motor (see the module text).

    ``name`` is the name used in commands (``axis0Motor``); ``channel`` the
    TIO10 clock channel (not 4 or 5); speeds in cm/s.  :meth:`poll` must be
    called periodically (every motor poll of the loop).
    """

    def __init__(
        self,
        name: str,
        tio10: TIO10,
        channel: int,
        start_speed: float,
        cruise_speed: float,
        *,
        steps_per_cm: float = 40.0,
        dv_limit: float = 0.5,
        ramp_decrement: int = 10,
    ):
        if channel in RTC_CHANNELS:
            raise ConfigError(
                f"motor {name}: TIO10 channel {channel} is reserved for the real-time clock "
                "(channels 4 and 5); choose another CHANNEL"
            )
        if isinstance(channel, bool) or not isinstance(channel, int) or channel not in DIR_BITS:
            raise ConfigError(
                f"motor {name}: CHANNEL must be a TIO10 motor channel "
                f"({', '.join(map(str, sorted(DIR_BITS)))}), got {channel!r}"
            )
        _check_speeds(name, start_speed, cruise_speed, ConfigError)
        if not (steps_per_cm > 0 and math.isfinite(steps_per_cm)):
            raise ConfigError(f"motor {name}: STEPS_PER_CM must be positive, got {steps_per_cm}")
        if not (dv_limit > 0 and math.isfinite(dv_limit)):
            raise ConfigError(f"motor {name}: DV_LIMIT must be positive, got {dv_limit}")
        if isinstance(ramp_decrement, bool) or not isinstance(ramp_decrement, int) \
                or ramp_decrement < 1:
            raise ConfigError(
                f"motor {name}: RAMP_DECREMENT must be a whole number of counts >= 1, "
                f"got {ramp_decrement!r}"
            )
        self.name = name
        self.tio10 = tio10
        self.channel = channel
        self.start_speed = float(start_speed)
        self.cruise_speed = float(cruise_speed)
        self.steps_per_cm = float(steps_per_cm)
        self.dv_limit = float(dv_limit)
        self.ramp_decrement = ramp_decrement
        self._source_hz = source_hz(MOTOR_SOURCE)
        #: The channel's armed register (1 while it steps), read through a reader
        #: bound once, when the motor is made: a call of no argument, no checks.
        self.armed = tio10.armed_reader(channel)
        self._pulses = tio10.pulses_reader(channel)
        self._dir = DIR_BITS[channel]
        self._awo = AWO_BITS[channel]
        if self.period_for(MIN_START_SPEED) > MAX_PERIOD:
            raise ConfigError(
                f"motor {name}: {MIN_START_SPEED} cm/s needs a period beyond the 16-bit "
                f"register with STEPS_PER_CM {steps_per_cm}"
            )

        self.mode = STEP_MODE
        self.state = OFF
        self.direction = 1
        #: STEP_MODE: steps of the current move wanted and taken.
        self.desired_steps = 0
        self.steps_taken = 0
        #: Signed half-steps since construction (paying out counts up).
        self.position_steps = 0
        #: VELOCITY_MODE: the velocity asked for and the one commanded (cm/s).
        self.desired_velocity = 0.0
        self.velocity = 0.0
        self._period = 0

        # Power-up: windings off, channel stopped, counting F3.
        tio10.set_bit(*self._awo, True)
        tio10.disarm(channel)
        tio10.select_source(channel, MOTOR_SOURCE)
        self._last_pulses = self._pulses()

    @classmethod
    def from_record(cls, record: MotorRecord, tio10: TIO10, name: str | None = None) -> Motor:
        """A Motor from a :class:`pyrt.db.MotorRecord`."""
        return cls(
            name or record.name, tio10, record.channel, record.start_speed,
            record.cruise_speed, steps_per_cm=record.steps_per_cm,
            dv_limit=record.dv_limit, ramp_decrement=record.ramp_decrement,
        )

    # -- conversions -------------------------------------------------------------

    def period_for(self, speed: float) -> int:
        """Count-down period (source counts) for ``speed`` cm/s, unclamped."""
        return round(self._source_hz / (abs(speed) * self.steps_per_cm))

    def speed_for(self, period: int) -> float:
        """Speed (cm/s) of a period in source counts."""
        return self._source_hz / (period * self.steps_per_cm)

    @property
    def start_period(self) -> int:
        return min(MAX_PERIOD, self.period_for(self.start_speed))

    @property
    def cruise_period(self) -> int:
        # rounded up: never faster than the cruise speed
        return max(MIN_PERIOD,
                   math.ceil(self._source_hz / (self.cruise_speed * self.steps_per_cm)))

    @property
    def period(self) -> int:
        """The period last loaded (0 when stopped)."""
        return self._period if self.armed() else 0

    def _running(self) -> bool:
        return self.armed() != 0

    #: Whether the channel is stepping (:attr:`armed`).
    running = property(_running)

    @property
    def state_name(self) -> str:
        return _STATE_NAMES[self.state]

    def speed(self) -> float:
        """Present signed speed in cm/s (0 when not stepping)."""
        period = self._period
        if not self.armed() or period <= 0:
            return 0.0
        return self.direction * self.speed_for(period)

    # -- hardware ------------------------------------------------------------------

    def _drive(self, direction: int, period: int) -> None:
        tio = self.tio10
        period = max(MIN_PERIOD, min(MAX_PERIOD, int(period)))
        armed = self.armed()  # neither the period nor a port bit changes it
        if period != self._period or not armed:
            tio.load_period(self.channel, period)
            self._period = period
        if direction != self.direction or not armed:
            tio.set_bit(*self._dir, direction > 0)
            self.direction = direction
        if not armed:
            tio.set_bit(*self._awo, False)
            tio.arm(self.channel)

    def _halt(self) -> None:
        tio = self.tio10
        tio.disarm(self.channel)
        tio.set_bit(*self._awo, True)
        self._period = 0
        self.velocity = 0.0

    def _count(self) -> int:
        p = self._pulses()
        delta = (p - self._last_pulses) % PULSE_COUNTER_MODULUS
        self._last_pulses = p
        return delta

    # -- STEP_MODE -----------------------------------------------------------------

    def move(self, steps: int) -> None:
        """Start a STEP_MODE move of ``steps`` half-steps (sign: direction)."""
        if isinstance(steps, bool) or not isinstance(steps, int):
            raise CommandError(f"{self.name}: steps must be a whole number, got {steps!r}")
        self._count()
        self.mode = STEP_MODE
        self.steps_taken = 0
        self.desired_steps = abs(steps)
        if steps == 0:
            self.stop()
            return
        self.state = ON
        self._drive(1 if steps > 0 else -1, self.start_period)

    def set_desired_steps(self, total: int) -> None:
        """Change the current move's total (steps from its start, same direction)."""
        if isinstance(total, bool) or not isinstance(total, int) or total < 0:
            raise CommandError(f"{self.name}: step total must be a whole number >= 0")
        self.desired_steps = total

    @property
    def steps_remaining(self) -> int:
        return max(0, self.desired_steps - self.steps_taken) if self.state == ON else 0

    # -- VELOCITY_MODE -------------------------------------------------------------

    def velocity_mode(self) -> None:
        """Enter VELOCITY_MODE in standby (000: ``polyActivate``)."""
        self._count()
        self._halt()
        self.mode = VELOCITY_MODE
        self.state = STANDBY
        self.desired_velocity = 0.0

    def set_desired_velocity(self, v: float) -> None:
        """Ask for ``v`` cm/s (signed; clamped to the cruise speed)."""
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            raise CommandError(f"{self.name}: velocity must be a finite number, got {v!r}")
        c = self.cruise_speed
        self.desired_velocity = max(-c, min(c, float(v)))

    def change_desired_velocity(self, dv: float) -> None:
        """Add ``dv`` cm/s to the desired velocity."""
        self.set_desired_velocity(self.desired_velocity + dv)

    # -- common --------------------------------------------------------------------

    def stop(self) -> None:
        """Stop now: channel stopped, windings off, state OFF.  The motor's own
        state is cleared whatever the board writes do (a dead link raises
        BoardError after it)."""
        try:
            self._halt()
        finally:
            self._period = 0
            self.velocity = 0.0
            self.state = OFF
            self.desired_velocity = 0.0
            self.desired_steps = self.steps_taken

    @property
    def speed_limits(self) -> Limits:
        """A velocity's display range: +-CRUISE_SPEED of MOTOR.dat."""
        v = self.cruise_speed
        return Limits(-v, v)

    def signals(self) -> list[Signal]:
        lim = self.speed_limits
        return [
            Signal.attr("velocity", "cm/s", self, "velocity", "commanded velocity (velocity mode)",
                        limits=lim),
            Signal.attr("desiredVelocity", "cm/s", self, "desired_velocity",
                        "velocity the controller asks for", limits=lim),
            Signal("speed", "cm/s", self.speed, "present signed speed (0 when not stepping)",
                   limits=lim),
            # sampled as the armed register itself (1 or 0: the bool's number)
            Signal("running", "bool", self._running, "the channel is stepping", "d",
                   source=Source.call(self.armed)),
        ]

    def params(self) -> list[Param]:
        """CRUISE_SPEED, START_SPEED and DV_LIMIT of MOTOR.dat (not written back),
        with the checks of ``maxspeed`` and of the database."""

        def cruise(v: float) -> None:
            self.check_free("CRUISE_SPEED")
            _check_speeds(self.name, self.start_speed, v, CommandError, what="CRUISE_SPEED")
            self.cruise_speed = float(v)

        def start(v: float) -> None:
            self.check_free("START_SPEED")
            _check_speeds(self.name, v, self.cruise_speed, CommandError, what="START_SPEED")
            self.start_speed = float(v)

        def dv(v: float) -> None:
            self.check_free("DV_LIMIT")
            self.dv_limit = float(v)

        return [
            Param("CRUISE_SPEED", "cm/s", lambda: self.cruise_speed, cruise, MIN_START_SPEED,
                  MAX_CRUISE_SPEED, "the maximum speed (maxspeed)"),
            Param("START_SPEED", "cm/s", lambda: self.start_speed, start, MIN_START_SPEED,
                  MAX_CRUISE_SPEED, "the speed a step-mode move starts and ends at"),
            Param("DV_LIMIT", "cm/s per poll", lambda: self.dv_limit, dv, 0.01, 5.0,
                  "the largest velocity change of one control poll"),
        ]

    def reflex(self) -> None:
        """Channel stopped, windings off."""
        self.stop()

    @command(Arg("SPEED", str, lo=MIN_START_SPEED, hi=MAX_CRUISE_SPEED, units="cm/s",
                 what="000's motor speeds"), name="maxspeed",
             reply=lambda v: f"maximum speed {v:g} cm/s")
    def maxspeed(self, speed: float | str) -> float:
        """maxspeed SPEED: set the maximum (cruise) speed in cm/s."""
        self.check_free("maxspeed")
        v = parse_number(speed, f"{self.name} maxspeed", "speed in cm/s")
        _check_speeds(self.name, self.start_speed, v, CommandError, what="maxspeed")
        self.cruise_speed = v
        return v

    def poll(self) -> None:
        """Count the steps taken and set the next period (every motor poll)."""
        p = self._pulses()  # (_count, in line: the tick's path)
        delta = (p - self._last_pulses) % PULSE_COUNTER_MODULUS
        self._last_pulses = p
        if self.mode == STEP_MODE:
            if self.state != ON:
                return
            self.steps_taken += delta
            self.position_steps += self.direction * delta
            remaining = self.desired_steps - self.steps_taken
            if remaining <= 0:
                self._halt()
                self.state = OFF
                return
            k = min(self.steps_taken, remaining)
            period = max(self.cruise_period, self.start_period - self.ramp_decrement * k)
            self._drive(self.direction, period)
            return
        # VELOCITY_MODE
        self.position_steps += self.direction * delta
        if self.state == OFF:
            return
        v = self.velocity
        dv = self.desired_velocity - v
        lim = self.dv_limit
        v_new = v + (lim if dv > lim else (-lim if dv < -lim else dv))
        if v != 0.0 and (v_new == 0.0 or (v_new > 0) != (v > 0)):
            v_new = 0.0  # reverse only through standby
        if abs(v_new) < MIN_START_SPEED:
            if self.armed():
                self._halt()
            self.state = STANDBY
            self.velocity = 0.0
            return
        self.state = ON
        self.velocity = v_new
        self._drive(1 if v_new > 0 else -1, self.period_for(v_new))

    def describe(self) -> str:
        return (f"{self.name}: {self.mode} {self.state_name} channel {self.channel} "
                f"speed {self.speed():.3f} cm/s max {self.cruise_speed:.3f} cm/s")


def _check_speeds(name: str, start: float, cruise: float, exc: type[Exception],
                  what: str = "speeds") -> None:
    for label, v in (("start speed", start), ("cruise speed", cruise)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise exc(f"motor {name}: {label} must be a finite number of cm/s, got {v!r}")
    if start < MIN_START_SPEED:
        raise exc(f"motor {name}: start speed {start} cm/s is below the minimum "
                  f"{MIN_START_SPEED} cm/s")
    if cruise > MAX_CRUISE_SPEED:
        raise exc(f"motor {name}: {'maximum' if what == 'maxspeed' else 'cruise'} speed "
                  f"{cruise} cm/s is above the limit {MAX_CRUISE_SPEED} cm/s")
    if cruise < start:
        raise exc(f"motor {name}: {'maximum' if what == 'maxspeed' else 'cruise'} speed "
                  f"{cruise} cm/s is below the start speed {start} cm/s")
