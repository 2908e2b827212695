"""The PolyAxis control poll's numeric work in two C calls (csrc/polyctl.c).

:class:`PolyControl` binds a manipulator's geometry, its prepared
:class:`~pyrt.native.PositionFinder` and its :class:`~pyrt.native.FuzzyBatch`
once; every poll the caller hands in the sensor readings as plain lists and
gets plain floats and lists back:

* :meth:`PolyControl.measure`: corrected lengths, neck-ring contacts as
  effective tops (Newton from last poll's rim angle), the position solve,
  distErr and the residual net force;
* :meth:`PolyControl.drive`: the error signals against the hare (off-side
  ropes toward OFFSIDE_TENSION, the others free, or tensions set by the
  caller for errorSignalAll), the fuzzy inputs and one batched fuzzy step.

:func:`ring_contact` is the C rim-contact search for one rope.  Inputs are
checked here; C status codes become :class:`~pyrt.errors.NativeError`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._findpos import PositionFinder
from pyrt.native._fuzzy import FuzzyBatch
from pyrt.native._lib import ffi, lib

__all__ = ["PolyControl", "ring_contact"]

MAX_ROPES = lib.PYRT_POLYCTL_MAX_ROPES
_NAN = math.nan

Vec = tuple[float, float, float]


def _points(name: str, rows: Sequence[Sequence[float] | None], n: int, *, nan_rows: bool = False
            ) -> list[float]:
    if len(rows) != n:
        raise NativeInputError(f"PolyControl: {name} has {len(rows)} rows for {n} ropes")
    flat: list[float] = []
    for i, r in enumerate(rows):
        if r is None and nan_rows:
            flat.extend((_NAN, _NAN, _NAN))
            continue
        if r is None or len(r) != 3:
            raise NativeInputError(f"PolyControl: {name}[{i}] must be a point (x, y, z)")
        v = [float(c) for c in r]
        if not all(math.isfinite(c) for c in v):
            raise NativeInputError(f"PolyControl: {name}[{i}] must be finite, got {v}")
        flat.extend(v)
    return flat


def _finite(name: str, values: Sequence[float], n: int) -> list[float]:
    v = [float(c) for c in values]
    if len(v) != n or not all(math.isfinite(c) for c in v):
        raise NativeInputError(f"PolyControl: {name} must be {n} finite numbers, got {values!r}")
    return v


def _ring_array(ring: Sequence[float] | None) -> list[float]:
    if ring is None:
        return [0.0] * 12 + [0.0]
    r = [float(c) for c in ring]
    if len(r) != 13 or not all(math.isfinite(c) for c in r):
        raise NativeInputError("PolyControl: ring must be 13 finite numbers "
                               "(centre, unit axis, e1, e2, radius)")
    return r


def ring_contact(ring: Sequence[float], top: Sequence[float], carriage: Sequence[float],
                 hint: float | None = None) -> tuple[Vec, float] | None:
    """``(rim point, rim angle)`` where the rope ``top -> carriage`` bears on the
    ring (centre, unit axis, e1, e2, radius: 13 numbers), or None."""
    r = ffi.new("double[13]", _ring_array(ring))
    t = ffi.new("double[3]", [float(c) for c in top])
    q = ffi.new("double[3]", [float(c) for c in carriage])
    cp = ffi.new("double[3]")
    phi = ffi.new("double *")
    bears = ffi.new("int32_t *")
    rc = lib.pyrt_ring_contact(r, t, q, _NAN if hint is None else float(hint), cp, phi, bears)
    if rc:
        raise_for_status(rc, "ring_contact")
    if not bears[0]:
        return None
    return (cp[0], cp[1], cp[2]), phi[0]


class PolyControl:
    """Two C calls per control poll for one manipulator (see the module text).

    ``tops``, ``offsets``: per rope, points (cm); ``bottoms``: points or None
    (no bottom attachment); ``stretch`` per newton and ``dead`` lengths (cm);
    ``ring``: 13 numbers (centre, unit axis pointing out of the vessel, two
    unit vectors spanning the ring plane, interior radius) or None;
    ``axis_point``: (x, y) of the central axis; ``weight_air`` and
    ``weight_liquid`` (N) with ``liquid_level`` (z, None in air);
    ``position``: the start of the first solve.
    """

    def __init__(self, finder: PositionFinder, batch: FuzzyBatch, *,
                 tops: Sequence[Sequence[float]], bottoms: Sequence[Sequence[float] | None],
                 offsets: Sequence[Sequence[float]], stretch: Sequence[float],
                 dead: Sequence[float], ring: Sequence[float] | None,
                 axis_point: Sequence[float], weight_air: float, weight_liquid: float,
                 liquid_level: float | None, offside_tension: float, near_end_cm: float,
                 position: Sequence[float]):
        n = finder.n
        if not 1 <= n <= MAX_ROPES:
            raise NativeInputError(f"PolyControl: {n} ropes; 1..{MAX_ROPES} allowed")
        if batch.n != n:
            raise NativeInputError(f"PolyControl: a fuzzy batch of {batch.n} axes for {n} ropes")
        scalars = {"weight_air": weight_air, "weight_liquid": weight_liquid,
                   "offside_tension": offside_tension, "near_end_cm": near_end_cm}
        for name, v in scalars.items():
            if not math.isfinite(float(v)):
                raise NativeInputError(f"PolyControl: {name} must be finite, got {v!r}")
        if not float(near_end_cm) > 0:
            raise NativeInputError(f"PolyControl: near_end_cm must be > 0, got {near_end_cm!r}")
        self.n = n
        self._finder = finder
        self._batch = batch
        new = ffi.new
        self._tops = new("double[]", _points("tops", tops, n))
        self._bottoms = new("double[]", _points("bottoms", bottoms, n, nan_rows=True))
        self._offsets = new("double[]", _points("offsets", offsets, n))
        self._stretch = new("double[]", _finite("stretch", stretch, n))
        self._dead = new("double[]", _finite("dead", dead, n))
        self._phi = new("double[]", [_NAN] * n)
        self._hare_phi = new("double[]", [_NAN] * n)
        self._prev = new("double[]", 2 * n)
        # Every per-poll input and output in one block, so that each call
        # copies its inputs in with one slice assignment and its outputs out
        # with one unpack:
        #   measure: tension, encoder_length | length, position[3], result[5]
        #   drive:   hare[3], velocity | desired, is_free, error_length,
        #            error_tension, last_dv (= this poll's dv)
        self._d = d = 3 * n + 8
        io = self._io = new("double[]", d + 3 + 6 * n)
        c = new("pyrt_polyctl *")
        c.n = n
        c.tops, c.bottoms, c.offsets = self._tops, self._bottoms, self._offsets
        c.stretch, c.dead = self._stretch, self._dead
        c.ring = _ring_array(ring)
        c.axis_point = _finite("axis_point", axis_point, 2)
        c.weight_air = float(weight_air)
        c.weight_liquid = float(weight_liquid)
        c.liquid_level = -math.inf if liquid_level is None else float(liquid_level)
        c.offside_tension = float(offside_tension)
        c.near_end_cm = float(near_end_cm)
        # the finder's and the batch's bound buffers: solved and run from C
        self._views = [ffi.from_buffer(a) for a in (finder.tops, finder.lengths, batch.inputs)]
        c.finder = finder._p
        c.finder_tops, c.finder_lengths, c.fuzzy_inputs = (
            ffi.cast("double *", v) for v in self._views)
        c.fuzzy = batch._b
        c.tension, c.encoder_length, c.length = io, io + n, io + 2 * n
        c.position, c.result = io + 3 * n, io + 3 * n + 3
        c.hare, c.velocity = io + d, io + d + 3
        c.desired_tension, c.is_free = io + d + 3 + n, io + d + 3 + 2 * n
        c.error_length, c.error_tension = io + d + 3 + 3 * n, io + d + 3 + 4 * n
        c.last_dv = io + d + 3 + 5 * n
        c.phi, c.hare_phi = self._phi, self._hare_phi
        c.prev_error_length, c.prev_error_tension = self._prev, self._prev + n
        io[3 * n:3 * n + 3] = _finite("position", position, 3)
        c.use_start = 1
        c.rate_scale = 0.0
        self._rate = 0.0
        self._signal_all = False
        self._c = c
        self._measured = c.length   # length, position, result: n + 8 doubles
        self._driven = c.desired_tension  # desired .. last_dv: 5 n doubles
        self._measure = lib.pyrt_polyctl_measure
        self._drive = lib.pyrt_polyctl_drive
        self._unpack = ffi.unpack

    # -- state -------------------------------------------------------------------

    def set_position(self, position: Sequence[float]) -> None:
        """Start the next solve from ``position`` (and find ring contacts there)."""
        n = self.n
        self._io[3 * n:3 * n + 3] = _finite("position", position, 3)
        self._c.use_start = 1

    def set_endpoint(self, endpoint: Sequence[float] | None) -> None:
        """The endpoint NEAR_END is measured from (None: NEAR_END is 0)."""
        c = self._c
        if endpoint is None:
            c.has_endpoint = 0
        else:
            c.endpoint = _finite("endpoint", endpoint, 3)
            c.has_endpoint = 1

    def reset_rates(self) -> None:
        """A new move: no error rates at its first poll, no last velocity change."""
        n = self.n
        self._c.have_prev = 0
        self._io[self._d + 3 + 5 * n:self._d + 3 + 6 * n] = [0.0] * n

    @property
    def rim_angles(self) -> list[float | None]:
        """Per rope, the rim angle it bore on the ring at the last measure (None: free)."""
        return [None if v != v else v for v in self._unpack(self._phi, self.n)]

    # -- the two calls -------------------------------------------------------------

    def measure(self, tensions: list[float], encoder_lengths: list[float],
                lengths: list[float]) -> list[float]:
        """Steps 1-3: ``lengths`` (corrected, filled in place); returns
        ``[x, y, z, dist_err, fx, fy, fz, |f|]``.  NativeError when the
        position cannot be found (the lengths are still filled in; the
        position is kept)."""
        n = self.n
        self._io[0:2 * n] = tensions + encoder_lengths
        rc = self._measure(self._c)
        out = self._unpack(self._measured, n + 8)
        lengths[:] = out[:n]
        if rc:
            raise_for_status(rc, f"PolyControl.measure ({n} ropes)")
        return out[n:]

    def drive(self, hare: Sequence[float], velocities: list[float], rate_scale: float,
              error_lengths: list[float], error_tensions: list[float],
              desired: list[float], free: list[float], *, signal_all: bool = False
              ) -> list[float]:
        """Step 4 against the ``hare``: the error signals (filled in place; with
        ``signal_all`` ``desired`` and ``free`` are read instead), the fuzzy
        step with error rates scaled by ``rate_scale`` (1/dt); returns every
        axis's velocity change (cm/s)."""
        n = self.n
        c = self._c
        if rate_scale != self._rate:
            c.rate_scale = self._rate = rate_scale
        if signal_all is not self._signal_all:
            self._signal_all = signal_all = bool(signal_all)
            c.signal_all = signal_all
        d = self._d
        if signal_all:
            self._io[d:d + 3 + 3 * n] = [*hare, *velocities, *desired, *free]
        else:
            self._io[d:d + 3 + n] = [*hare, *velocities]
        rc = self._drive(c)
        if rc:
            raise_for_status(rc, f"PolyControl.drive ({n} ropes)")
        out = self._unpack(self._driven, 5 * n)
        if not signal_all:
            desired[:] = out[:n]
            free[:] = out[n:2 * n]
        error_lengths[:] = out[2 * n:3 * n]
        error_tensions[:] = out[3 * n:4 * n]
        return out[4 * n:]
