"""Typed records of the object databases (Tables 1, 3, 5, 6, 7, 9 of 000).

One frozen dataclass per object type, base units cm / kg / cm3 / N (speeds
cm/s, times s), field names the lower-cased table keys.  Each record carries
``where``: the file and the line of every key, so code that refuses a value
later can still point at its line (``record.where.error("CHANNEL", ...)``).

Keys of the document's tables are required.  A few constants that 000 keeps
in the code (PolyAxis.h, Motor, Axis) but that a station must be able to
change are optional keys with the defaults documented on each record; the
schema (:mod:`pyrt.db._schema`) is the one home of every default
(:func:`pyrt.db.defaults`): it fills them in, so a record has none of its own.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from pyrt.errors import ConfigError

__all__ = [
    "AVRecord",
    "AxisRecord",
    "EncoderRecord",
    "LoadcellRecord",
    "Location",
    "MotorRecord",
    "PolyAxisRecord",
    "Vector",
]

#: A 3-vector (x, y, z) in cm unless said otherwise.
Vector = tuple[float, float, float]


@dataclass(frozen=True)
class Location:
    """Where a record was read: file, the entry's line, and the line of each key."""

    file: str
    line: int
    keys: Mapping[str, int] = field(default_factory=dict, hash=False)

    def line_of(self, key: str) -> int:
        """The line of ``key`` in the entry (the entry's own line if it is not written)."""
        return self.keys.get(key.upper(), self.line)

    def error(self, key: str | None, message: str) -> ConfigError:
        """A :class:`ConfigError` pointing at ``key``'s line (or the entry's)."""
        return ConfigError(message, self.file, self.line if key is None else self.line_of(key))


_NOWHERE = Location("<memory>", 0)


@dataclass(frozen=True)
class PolyAxisRecord:
    """POLYAXIS.dat (Table 1): the source, its ropes and the manipulator limits.

    ``axes`` are the AXIS names in file order (that order is the axis index).
    ``position`` is the last known source position (global, cm), rewritten
    every 1 s while moving and 10 s stationary.  ``source_mass`` (kg) and
    ``source_volume`` (cm3) must be written with their units; volume 0 means
    no buoyancy.

    The optional keys are 000's PolyAxis.h constants (the document names them
    but gives no value: the defaults are pyrt's choice for the prototype) and
    the numbers 000 states in the text, so that a full-scale station can
    change them:

    * ``END_ERROR`` 1.0 cm: ENDPOINT_STOP radius (the lesser of it and the RMS
      length residual, never below ``FIND_TOLERANCE``) and the station's
      endpoint tolerance: ENDPOINT_STOP also needs distErr within it.
    * ``LOW_TENSION`` 2.0 N: LOW_TENSION_STOP (well under the 10 N off-side
      idler tension, so only a rope going slack trips it).
    * ``MAX_TENSION`` 200.0 N: HIGH_TENSION_STOP (under the 50 lb = 222 N
      loadcell range of Table 9).
    * ``NET_FORCELIMIT`` 25.0 N: NET_FORCE_STOP on the residual force on the
      source (about half the prototype source's 52 N weight).
    * ``OFFSIDE_TENSION`` 10.0 N: tension asked of off-side ropes (section 5).
    * ``HARE_SPEED`` 2.0 cm/s and ``HARE_RAMP`` 20.0 cm: the hare's profile.
    * ``STUCK_TIME`` 10.0 s: STUCK_STOP when no closer for this long.
    * ``FIND_TOLERANCE`` 0.1 cm: position finder convergence and the
      tightest endpoint condition.
    * ``D2O_DENSITY`` 1.10 g/cm3: buoyancy of a submerged source.
    * ``DIST_ERR_LIMIT`` 0.5 cm (not in 000): distErr above this (about twice
      the most seen in fault-free moves) is a fault naming the axis; moves
      are then refused until the position is re-established.
    * ``TENSION_MARGIN`` 5.0 N (not in 000): a target is refused unless the
      tensions that hold it lie this far inside LOW_TENSION .. MAX_TENSION.
    * ``AV``: the AV.dat entry; may be left out when AV.dat holds one entry.
    """

    name: str
    axes: tuple[str, ...]
    position: Vector
    source_mass: float
    source_volume: float
    av: str | None
    end_error: float
    low_tension: float
    max_tension: float
    net_forcelimit: float
    offside_tension: float
    hare_speed: float
    hare_ramp: float
    stuck_time: float
    find_tolerance: float
    d2o_density: float
    dist_err_limit: float
    tension_margin: float
    where: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True)
class AxisRecord:
    """AXIS.dat (Table 3): one rope with its Motor, Loadcell and Encoder.

    ``length`` is the rope from the top pulley to the bottom end (rewritten
    every 1 s moving / 10 s stationary); ``deadlength`` the rope between
    spindle and top pulley (used by the stretch correction); ``offset`` the
    carriage pulley from the carriage centre (Delta of Equation 1); ``top``
    where the rope leaves the top pulley (global); ``bottom`` the bottom
    attachment in vessel co-ordinates, ``None`` for the central rope.

    Optional: ``STRETCH`` (default 2.0e-5 per N): the rope's elastic strain
    per newton of tension, used by the stretch correction of 000's ``getLength`` (000
    keeps it in the code and gives no number; 2e-5/N is a braided rope that
    stretches 1 % at 500 N).  ``FUZZY_<NAME>: value`` keys override one
    fuzzy-controller parameter for this axis: ``fuzzy`` maps the lower-cased
    ``<name>`` to the value; the controller validates the names.
    """

    name: str
    motor: str
    loadcell: str
    encoder: str
    length: float
    deadlength: float
    offset: Vector
    top: Vector
    bottom: Vector | None
    stretch: float
    fuzzy: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}),
                                       hash=False)
    where: Location = field(default=_NOWHERE, compare=False, repr=False)

    @property
    def central(self) -> bool:
        """True for the central rope (no bottom attachment)."""
        return self.bottom is None


@dataclass(frozen=True)
class MotorRecord:
    """MOTOR.dat (Table 6): a stepping motor on a TIO10 clock channel.

    ``channel`` 0..9 except 4 and 5 (the real-time clock); ``start_speed``
    and ``cruise_speed`` in cm/s with 0.07 <= start <= cruise <= 7.0.

    Optional (constants of 000's Motor code): ``STEPS_PER_CM`` (default 40.0
    half-steps per cm of rope: 400 half-steps a turn on a 10 cm spool;
    000 names the constant but not its value), ``DV_LIMIT`` (0.5 cm/s per
    poll, as 000 states) and ``RAMP_DECREMENT`` (10 clock counts per step in
    STEP_MODE, as 000 states).
    """

    name: str
    channel: int
    start_speed: float
    cruise_speed: float
    steps_per_cm: float
    dv_limit: float
    ramp_decrement: int
    where: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True)
class EncoderRecord:
    """ENCODER.dat (Table 7): a shaft encoder on the dataConcentrator chain.

    ``slope`` cm per count; ``zerolength`` the total rope length (dead length
    included, unstretched) when the counter reads zero.  The counter is reset
    at start-up, so ZEROLENGTH is rewritten once a second while the length
    changes with the *current* length: the next start begins from there.
    A running Encoder keeps the zero length it started with.
    """

    name: str
    slope: float
    address: int
    zerolength: float
    date: str
    where: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True)
class LoadcellRecord:
    """LOADCELL.dat (Table 9): ``N = slope * adc + offset`` on ADC ``channel``.

    ``maxload`` in N (the table writes ``50 lb``).  SLOPE, OFFSET, DATE and
    CALIBRATIONPOINT (``calibration_points``: the last calibration's points,
    ``"ADC N; ADC N; ..."``, optional) are rewritten after a calibration.
    """

    name: str
    maxload: float
    slope: float
    offset: float
    channel: int
    date: str
    calibration_points: str
    where: Location = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(frozen=True)
class AVRecord:
    """AV.dat (Table 5): acrylic vessel geometry (cm).

    ``neck_ring_static_position``: centre of the neck ring with the vessel
    centre at the origin and the neck straight up; ``neck_ring_radius`` the
    ring's interior radius; ``neck_radius`` the allowed region of the neck.

    Optional: ``POSITION`` (default 0 0 0 cm) and ``ORIENTATION`` (default
    0 0 0: rotations in degrees about the global x, y, z axes, applied in that
    order): the vessel's pose in the global system used by ``vtog``/``gtov``
    until the AVPsense hardware measures it (section 7).
    """

    name: str
    neck_ring_static_position: Vector
    neck_ring_radius: float
    neck_radius: float
    neck_length: float
    vessel_radius: float
    position: Vector
    orientation: Vector
    where: Location = field(default=_NOWHERE, compare=False, repr=False)
