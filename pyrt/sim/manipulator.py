"""The rope manipulator's world: motors, ropes, source carriage, encoders, loadcells.

:class:`ManipulatorPlant` sits behind a TIO10's and a dataConcentrator's
register files (:class:`~pyrt.boards.registers.RegisterBoard`; what it does
to them: :mod:`pyrt.sim.cards`).  Each
:meth:`ManipulatorPlant.step` (attach it to the :class:`~pyrt.scheduler.Loop`
before the control tasks) advances by the time that really passed:

1. every armed motor channel issues pulses at its period (the channel's
   pulse counter counts them); a motor whose windings are on takes a
   half-step per pulse in its direction bit's sense, paying rope out or in;
2. when any payed-out length changed (or a rope broke), the source
   carriage's static equilibrium is solved again
   (:class:`pyrt.native.StaticsSolver`, warm started from the last one; a
   few microseconds for five ropes).  Nothing else moves the equilibrium,
   so a step in which no rope moved keeps the last solution exactly;
3. the encoders count the rope that passed them and the loadcells' ADCs
   convert the rope tensions, with the imperfections of
   :class:`~pyrt.sim.sensors.Imperfections`.

Faults can be injected per rope: encoder slip, loadcell dead or stuck, motor
stall, rope break.  The geometry is the world's truth (:class:`RopeRig`,
global co-ordinates): it may differ from what the control code believes.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from pyrt.boards.dataconcentrator import ADC_MAX, COUNTER_BITS
from pyrt.boards.registers import RegisterBoard
from pyrt.boards.tio10 import (
    AWO_BITS,
    CLOCK_HZ,
    DIR_BITS,
    PULSE_COUNTER_MODULUS,
    RTC_MODULUS,
    TIO10,
)
from pyrt.errors import NativeError
from pyrt.native import StaticsSolver
from pyrt.sim.sensors import Imperfections, loadcell_response

if TYPE_CHECKING:
    from pyrt.db import Station

__all__ = [
    "D2O_DENSITY",
    "GRAVITY",
    "ManipulatorPlant",
    "ManipulatorRig",
    "RopeRig",
    "rig_from_station",
    "rotation_xyz",
]

#: Standard gravity, N per kg.
GRAVITY = 9.80665
#: The dataConcentrator's counters wrap at 24 bits.
_COUNTER_MASK = (1 << COUNTER_BITS) - 1
#: 000, section 5: "The density of D2O is taken to be 1.10 g/cm3".
D2O_DENSITY = 1.10

Vec = tuple[float, float, float]
#: A loadcell in these states converts no load (dead: 0; stuck: its last code).
_NOT_CONVERTING = frozenset(("dead", "stuck"))


@dataclass(frozen=True)
class RopeRig:
    """One rope as the world has it: its motor, sensors and geometry."""

    name: str
    channel: int
    steps_per_cm: float
    encoder_address: int
    encoder_cm_per_count: float
    adc_channel: int
    loadcell_slope: float
    loadcell_offset: float
    loadcell_maxload: float
    top: Vec
    bottom: Vec | None
    offset: Vec = (0.0, 0.0, 0.0)
    dead: float = 0.0
    stretch: float = 2.0e-5


@dataclass(frozen=True)
class ManipulatorRig:
    """The whole world: ropes, source, vessel (global co-ordinates, cm, kg, cm3).

    ``ring``: neck ring ``(centre, axis, radius)`` or ``None``; ``floor_z``:
    the vessel bottom; ``liquid_level``: z of the D2O surface (``None``: the
    source is in air); ``position``: where the source starts.
    """

    ropes: tuple[RopeRig, ...]
    mass: float
    volume: float
    position: Vec
    ring: tuple[Vec, Vec, float] | None = None
    floor_z: float = -1e6
    liquid_level: float | None = None
    density: float = D2O_DENSITY
    vessel_centre: Vec = (0.0, 0.0, 0.0)
    vessel_radius: float = 0.0


def _vec(v: Sequence[float] | np.ndarray) -> Vec:
    """``v`` (three numbers) as a point of floats."""
    x, y, z = v
    return (float(x), float(y), float(z))


def rotation_xyz(angles_deg: Sequence[float]) -> np.ndarray:
    """Rotation matrix for rotations about global x, then y, then z (degrees)."""
    ax, ay, az = (math.radians(float(a)) for a in angles_deg)
    cx, sx, cy, sy, cz, sz = (math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay),
                              math.cos(az), math.sin(az))
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def rig_from_station(
    station: Station,
    polyaxis: str | None = None,
    *,
    vessel_position: Sequence[float] | None = None,
    vessel_orientation: Sequence[float] | None = None,
    liquid_level: float | str | None = "neck",
    position: Sequence[float] | None = None,
) -> ManipulatorRig:
    """The world described by a :class:`pyrt.db.Station`'s records.

    The vessel pose defaults to the AV record's POSITION/ORIENTATION; pass
    another to put the real vessel somewhere the database does not know.
    Bottom attachments and the neck ring are carried with the vessel
    (000, section 20).  The source starts at the POLYAXIS POSITION unless
    ``position`` is given.

    ``liquid_level``: the z of the D2O surface; the default ``"neck"`` fills
    the vessel up to the neck ring (000, Table 1: a source in air is given
    volume 0, so a source with a volume is in the D2O); ``None``: no liquid.
    """
    pa = station.polyaxis(polyaxis)
    av = station.av_of(pa)
    pos = np.asarray(vessel_position if vessel_position is not None else av.position, float)
    rot = rotation_xyz(vessel_orientation if vessel_orientation is not None
                       else av.orientation)

    def vtog(v: Sequence[float]) -> Vec:
        g = rot @ np.asarray(v, float) + pos
        return (float(g[0]), float(g[1]), float(g[2]))

    ropes = []
    for ax in station.axes_of(pa):
        mo = station.motor_of(ax)
        en = station.encoder_of(ax)
        lc = station.loadcell_of(ax)
        ropes.append(RopeRig(
            name=ax.name,
            channel=mo.channel,
            steps_per_cm=mo.steps_per_cm,
            encoder_address=en.address,
            encoder_cm_per_count=en.slope,
            adc_channel=lc.channel,
            loadcell_slope=lc.slope,
            loadcell_offset=lc.offset,
            loadcell_maxload=lc.maxload,
            top=_vec(ax.top),
            bottom=None if ax.bottom is None else vtog(ax.bottom),
            offset=_vec(ax.offset),
            dead=ax.deadlength,
            stretch=ax.stretch,
        ))
    axis = rot @ np.array([0.0, 0.0, 1.0])
    ring = (vtog(av.neck_ring_static_position), _vec(axis), av.neck_ring_radius)
    centre = vtog((0.0, 0.0, 0.0))
    if liquid_level == "neck":
        liquid_level = ring[0][2]
    elif isinstance(liquid_level, str):
        raise ValueError(f"liquid_level must be a z in cm, None or 'neck', got {liquid_level!r}")
    return ManipulatorRig(
        ropes=tuple(ropes),
        mass=pa.source_mass,
        volume=pa.source_volume,
        position=_vec(position if position is not None else pa.position),
        ring=ring,
        floor_z=centre[2] - av.vessel_radius,
        liquid_level=liquid_level,
        density=getattr(pa, "d2o_density", D2O_DENSITY),
        vessel_centre=centre,
        vessel_radius=av.vessel_radius,
    )


@dataclass
class _RopeState:
    rig: RopeRig
    payout: float
    phase: float = 0.0
    wheel: float = 0.0  # encoder wheel position in counts (real valued)
    counted: int = 0  # counts delivered to the counter register
    zero_error: float = 0.0
    slip: float = 0.0
    stalled: bool = False
    loadcell: str = "ok"  # ok | dead | stuck
    stuck_code: int = 0
    intact: bool = True
    first: bool = True
    dir_bit: tuple[int, int] = (0, 0)
    awo_bit: tuple[int, int] = (1, 0)
    steps: int = field(default=0)
    #: A known load hung on the loadcell for calibration (N), or None.
    load: float | None = None


class ManipulatorPlant:
    """The physics of one rope manipulator (see the module text).

    ``payouts``: the unstretched rope lengths from each spindle at the
    start; by default they are chosen so that the source hangs in
    equilibrium at ``rig.position`` with ``side_tension`` on each side rope.
    """

    def __init__(
        self,
        rig: ManipulatorRig,
        tio10: RegisterBoard,
        dc: RegisterBoard,
        *,
        imperfections: Imperfections | None = None,
        payouts: Sequence[float] | None = None,
        side_tension: float = 10.0,
    ):
        self.rig = rig
        self.tio10 = tio10
        self.dc = dc
        # the registers the step reads and sets, bound once
        self._src, self._per, self._armed = (tio10.cells(n) for n in ("src", "per", "armed"))
        self._port, self._pulses = tio10.cells("port"), tio10.cells("pulses")
        self._rtc = tio10.cells("rtc")
        self._cnt, self._adc = dc.cells("cnt"), dc.cells("adc")
        self.imp = imperfections if imperfections is not None else Imperfections()
        self._rng = random.Random(self.imp.seed)
        self._np_rng = np.random.default_rng(self.imp.seed)
        self._noise_block: list[float] = []
        self._noise_i = 0
        for r in rig.ropes:
            TIO10.check_channel(r.channel)
        n = len(rig.ropes)
        self.solver = StaticsSolver(
            [r.top for r in rig.ropes],
            [r.bottom for r in rig.ropes],
            [r.offset for r in rig.ropes],
            [r.dead for r in rig.ropes],
            [r.stretch for r in rig.ropes],
            [r.dead + 1000.0 for r in rig.ropes],
            ring=rig.ring,
            weight=self._weight(rig.position[2]),
            floor_z=rig.floor_z,
            position=rig.position,
        )
        if payouts is None:
            payouts = self.settle_payouts(rig.position, side_tension)
        if len(payouts) != n:
            raise ValueError(f"{len(payouts)} payouts for {n} ropes")
        self.ropes = [
            _RopeState(rig=r, payout=float(p), dir_bit=DIR_BITS[r.channel],
                       awo_bit=AWO_BITS[r.channel])
            for r, p in zip(rig.ropes, payouts, strict=True)
        ]
        #: Each rope's loadcell as the step converts it: (state, MAXLOAD, OFFSET,
        #: SLOPE, ADC channel), the rig's constants gathered once.
        self._loadcells = [(st, st.rig.loadcell_maxload, st.rig.loadcell_offset,
                            st.rig.loadcell_slope, st.rig.adc_channel) for st in self.ropes]
        for st in self.ropes:
            if self.imp.loadcell_zero_error:
                st.zero_error = self._rng.gauss(0.0, self.imp.loadcell_zero_error)
        self.solver.set_payouts([st.payout for st in self.ropes])
        self.solver.set_position(rig.position)
        self.converged = self.solver.solve()
        self._solved_payouts = [st.payout for st in self.ropes]
        #: Set when a motor drew the carriage into a pulley (it stalled there).
        self.jammed = False
        self._dirty = False
        #: No channel was armed at the last step (every rope's phase is 0).
        self._still = False
        self._last_ns: int | None = None
        self.solves = 0
        self._write_sensors()

    # -- setup -----------------------------------------------------------------

    def _weight(self, z: float) -> float:
        rig = self.rig
        mass = rig.mass
        if rig.volume > 0 and rig.liquid_level is not None and z < rig.liquid_level:
            mass -= rig.density * 1e-3 * rig.volume  # g/cm3 * cm3 -> kg
        return mass * GRAVITY

    def settle_payouts(self, position: Sequence[float], side_tension: float = 10.0) -> list[float]:
        """Payouts that hold the source in equilibrium at ``position``.

        Tensions balance the net weight exactly and stay as close as they
        can to ``side_tension`` on the side ropes (a weighted least change,
        the central ropes taking up the difference first); a tension that
        would come out below 1 N is held at 1 N.
        """
        x = np.asarray(position, float)
        g, _, _ = self.solver.evaluate(x)
        h = 1e-4
        grads = np.zeros((3, len(g)))
        for k in range(3):
            e = np.zeros(3)
            e[k] = h
            gp, _, _ = self.solver.evaluate(x + e)
            gm, _, _ = self.solver.evaluate(x - e)
            grads[k] = (np.asarray(gp) - np.asarray(gm)) / (2 * h)
        # force of rope i on the source = -T_i grad g_i; balance: sum = (0, 0, W)
        a = -grads
        w = self._weight(x[2])
        b = np.array([0.0, 0.0, w])
        central = np.array([r.bottom is None for r in self.rig.ropes])
        pref = np.where(central, w / max(1, central.sum()), side_tension)
        # weighted least change: central ropes take up the difference first
        winv = np.where(central, 1.0, 0.01)
        aw = a * winv
        t = pref + aw.T @ np.linalg.pinv(aw @ a.T) @ (b - a @ pref)
        t = np.maximum(t, 1.0)
        return [
            (r.dead + gi) / (1.0 + r.stretch * ti)
            for r, gi, ti in zip(self.rig.ropes, g, t, strict=True)
        ]

    # -- the step ----------------------------------------------------------------

    def step(self, now_ns: int) -> None:
        """Advance the world to ``now_ns`` (the loop's time)."""
        last = self._last_ns
        self._last_ns = now_ns
        self._rtc[0] = (now_ns * CLOCK_HZ // 1_000_000_000) % RTC_MODULUS  # (cards.set_rtc)
        dt_ns = 0 if last is None else now_ns - last
        if dt_ns > 0:
            self._move(dt_ns)
        if self._dirty:
            self._dirty = False
            solver = self.solver
            solver.weight = self._weight(solver.position[2])
            solver.set_payouts([st.payout for st in self.ropes])
            try:
                self.converged = solver.solve()
            except NativeError:
                # The carriage pulley has been drawn into a top pulley (or an
                # attachment): the motor stalls against it.  Take back the
                # rope that could not move and keep the last equilibrium.
                self.jammed = True
                for st, before in zip(self.ropes, self._solved_payouts, strict=True):
                    st.payout = before
                solver.set_payouts(self._solved_payouts)
            else:
                self._solved_payouts = [st.payout for st in self.ropes]
                # a long swing (a rope broke, a rope went slack) may need more
                # iterations than one step allows: carry on at the next step
                self._dirty = not self.converged
            self.solves += 1
        self._write_sensors()

    def _move(self, dt_ns: int) -> None:
        armed = self._armed
        if self._still and not any(armed):
            return  # no channel counts, and every rope's phase is 0 already
        self._still = False
        dt_ticks = dt_ns * (CLOCK_HZ / 1e9)
        src, per, port = self._src, self._per, self._port
        pulses, cnt = self._pulses, self._cnt
        quant = self.imp.encoder_quantisation
        for st in self.ropes:
            ch = st.rig.channel
            if not armed[ch]:
                st.phase = 0.0
                continue
            period = per[ch] * 10 ** (src[ch] - 1)
            if period <= 0:
                st.phase = 0.0
                continue
            st.phase += dt_ticks
            n = int(st.phase // period)
            if n <= 0:
                continue
            st.phase -= n * period
            pulses[ch] = (pulses[ch] + n) % PULSE_COUNTER_MODULUS
            p, b = st.awo_bit
            if st.stalled or port[p] >> b & 1:
                continue
            p, b = st.dir_bit
            sign = 1 if port[p] >> b & 1 else -1
            st.steps += sign * n
            d = sign * n / st.rig.steps_per_cm
            st.payout += d
            self._dirty = True
            st.wheel += d * (1.0 - st.slip) / st.rig.encoder_cm_per_count
            whole = math.floor(st.wheel) if quant else round(st.wheel)
            if whole != st.counted:
                a = st.rig.encoder_address
                cnt[a] = (cnt[a] + whole - st.counted) & _COUNTER_MASK
                st.counted = whole
        # nothing counted: every rope's phase was set to 0 above; until a channel is
        # armed again a step has nothing to move
        self._still = not any(armed)

    def _write_sensors(self) -> None:
        adc = self._adc
        imp = self.imp
        sigma = imp.loadcell_noise
        simple = imp.bias_resistor
        nl4 = 4.0 * imp.loadcell_nonlinearity
        tensions = self.solver.tensions()
        # standard-normal noise, drawn in seeded blocks of 4096 (cheap per load
        # cell): the block and the place in it held here for the loop; a block
        # with fewer left than loadcells is followed by the next one now (the
        # same numbers in the same order as a block drawn when the last ran out)
        block, i = self._noise_block, self._noise_i
        if sigma and len(block) - i < len(tensions):
            block = self._noise_block = (
                block[i:] + self._np_rng.standard_normal(4096).tolist())
            i = 0
        for (st, m, offset, slope, channel), t in zip(self._loadcells, tensions, strict=True):
            if st.load is not None:  # the calibration load, not the source, pulls on it
                t = st.load
            state = st.loadcell
            if state == "ok" or state not in _NOT_CONVERTING:
                if simple:
                    f = t / m if m > 0 else 0.0
                    f = 0.0 if f < 0.0 else (1.0 if f > 1.0 else f)
                    load = t + nl4 * m * f * (1.0 - f)
                else:
                    load = loadcell_response(t, m, imp)
                load += st.zero_error
                if sigma:
                    load += sigma * block[i]
                    i += 1
                code = round((load - offset) / slope)
                code = 0 if code < 0 else (ADC_MAX if code > ADC_MAX else code)
            else:
                code = 0 if state == "dead" else st.stuck_code
            if code != st.stuck_code or st.first:
                st.first = False
                st.stuck_code = code
                adc[channel] = code  # an int 0..ADC_MAX (cards.set_adc)
        self._noise_i = i

    def invalidate(self) -> None:
        """Solve the statics again at the next step even if no rope moved."""
        self._dirty = True

    # -- truth -------------------------------------------------------------------

    @property
    def position(self) -> Vec:
        """Where the source really is."""
        return self.solver.position

    def tensions(self) -> list[float]:
        """The rope tensions (N)."""
        return self.solver.tensions()

    def payout(self, i: int) -> float:
        """Unstretched rope ``i`` payed out from its spindle (cm)."""
        return self.ropes[i].payout

    def lengths(self) -> list[float]:
        """Geometric rope lengths beyond the top pulleys at the source's position."""
        g, _, _ = self.solver.evaluate(self.solver.position)
        return g

    def wrapped(self) -> list[bool]:
        """Which ropes bear on the neck ring."""
        return self.solver.wrapped()

    @property
    def weight(self) -> float:
        """Net downward force on the source now (N)."""
        return self._weight(self.solver.position[2])

    def index(self, rope: int | str) -> int:
        """A rope's index from its index or (case-insensitive) name."""
        if isinstance(rope, int) and not isinstance(rope, bool):
            if not 0 <= rope < len(self.ropes):
                raise ValueError(f"no rope {rope}: the plant has {len(self.ropes)}")
            return rope
        for i, st in enumerate(self.ropes):
            if st.rig.name.lower() == str(rope).lower():
                return i
        raise ValueError(f"no rope named {rope!r}")

    # -- faults ------------------------------------------------------------------

    def inject_slip(self, rope: int | str, fraction: float = 1.0) -> None:
        """The encoder wheel slips on the rope: it registers only
        ``1 - fraction`` of the rope that passes it (1.0: none)."""
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"slip fraction must be 0..1, got {fraction!r}")
        self.ropes[self.index(rope)].slip = float(fraction)

    def inject_loadcell_dead(self, rope: int | str) -> None:
        """The loadcell's electronics die: its ADC reads 0."""
        self.ropes[self.index(rope)].loadcell = "dead"

    def inject_loadcell_stuck(self, rope: int | str) -> None:
        """The loadcell's ADC freezes at its present code."""
        self.ropes[self.index(rope)].loadcell = "stuck"

    def inject_stall(self, rope: int | str) -> None:
        """The motor stalls: its clock still pulses but the spindle stays put."""
        self.ropes[self.index(rope)].stalled = True

    def break_rope(self, rope: int | str) -> None:
        """The rope breaks: it carries nothing from now on (permanent)."""
        i = self.index(rope)
        self.ropes[i].intact = False
        self.solver.set_intact(i, False)
        self._dirty = True

    def hang_load(self, rope: int | str, newtons: float | None) -> None:
        """Calibration as on the rig: a known load of ``newtons`` hangs on the
        rope's loadcell (its response, offset error and noise as for any load)
        instead of the source's tension; None takes it off."""
        if newtons is not None and not (math.isfinite(newtons) and newtons >= 0):
            raise ValueError(f"a hung load must be a finite number of N >= 0, got {newtons!r}")
        self.ropes[self.index(rope)].load = None if newtons is None else float(newtons)

    def clear_faults(self, rope: int | str) -> None:
        """Undo slip, stall and loadcell faults (a broken rope stays broken)."""
        st = self.ropes[self.index(rope)]
        st.slip = 0.0
        st.stalled = False
        st.loadcell = "ok"
