"""The PolyAxis control poll's numeric work in two C calls (csrc/polyctl.c).

:class:`PolyControl` binds a manipulator's geometry, its prepared
:class:`~pyrt.native.PositionFinder` and its :class:`~pyrt.native.FuzzyBatch`
once; every poll the caller hands in the sensor readings as plain lists and
gets plain floats and lists back:

* :meth:`PolyControl.measure`: corrected lengths, neck-ring contacts as
  effective tops and bottoms (csrc/neck.h, Newton from last poll's rim
  angles), the position solve, distErr and the residual net force;
* :meth:`PolyControl.drive`: the error signals against the hare (off-side
  ropes toward OFFSIDE_TENSION, the others free, or tensions set by the
  caller for errorSignalAll), the fuzzy inputs and one batched fuzzy step.

Inputs are checked here; C status codes become
:class:`~pyrt.errors.NativeError`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, ClassVar

from pyrt.native._errors import NativeInputError, raise_for_status
from pyrt.native._findpos import PositionFinder
from pyrt.native._fuzzy import FuzzyBatch
from pyrt.native._lib import ffi, lib
from pyrt.native._neck import NeckRing

__all__ = ["PolyControl"]

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


def _neck_ring(ring: NeckRing | Sequence[float] | None) -> Any:
    """The ``pyrt_neck_ring`` struct for *ring* (checked by C)."""
    if isinstance(ring, NeckRing):
        return ring._c
    if ring is None:
        return ffi.new("pyrt_neck_ring *", {"radius": 0.0})
    r = [float(c) for c in ring]
    if len(r) != 13:
        raise NativeInputError("PolyControl: ring must be a NeckRing or 13 numbers "
                               "(centre, unit axis, e1, e2, radius)")
    c = ffi.new("pyrt_neck_ring *", {"centre": r[0:3], "axis": r[3:6], "e1": r[6:9],
                                     "e2": r[9:12], "radius": r[12]})
    raise_for_status(lib.pyrt_neck_check(c), "PolyControl: ring (an orthonormal frame)")
    return c


def _io_layout(n: int) -> tuple[dict[str, tuple[int, int]], int]:
    """Where each per-poll array lies in the exchange block: name -> (offset,
    size), and the block's size.  Each call's inputs are contiguous, and so
    are its outputs, so that a call copies its inputs in with one slice
    assignment and its outputs out with one unpack."""
    sizes = [
        ("tension", n), ("encoder_length", n),                          # measure: in
        ("length", n), ("position", 3), ("result", 5),                  # measure: out
        ("hare", 3), ("velocity", n), ("desired_tension", n), ("is_free", n),  # drive: in
        ("error_length", n), ("error_tension", n), ("last_dv", n),      # drive: out
    ]
    layout, k = {}, 0
    for name, size in sizes:
        layout[name] = (k, size)
        k += size
    return layout, k


class PolyControl:
    """Two C calls per control poll for one manipulator (see the module text).

    ``tops``, ``offsets``: per rope, points (cm); ``bottoms``: points or None
    (no bottom attachment); ``stretch`` per newton and ``dead`` lengths (cm);
    ``ring``: the neck ring, a :class:`~pyrt.native.NeckRing` or its frame
    as 13 numbers (centre, unit axis pointing out of the vessel, two unit
    vectors spanning the ring plane, interior radius), or None;
    ``axis_point``: (x, y) of the central axis; ``weight_air`` and
    ``weight_liquid`` (N) with ``liquid_level`` (z, None in air);
    ``position``: the start of the first solve.
    """

    #: The segments of a rope the controller lets bear on the neck ring by
    #: default: both, as the world does (``csrc/polyctl.h``).  The
    #: ``ring_segments`` argument is the named place where a controller
    #: deliberately knows less (``UPPER`` alone: lower segments straight).
    RING_SEGMENTS: ClassVar[int] = lib.PYRT_POLYCTL_RING_SEGMENTS

    def __init__(self, finder: PositionFinder, batch: FuzzyBatch, *,
                 tops: Sequence[Sequence[float]], bottoms: Sequence[Sequence[float] | None],
                 offsets: Sequence[Sequence[float]], stretch: Sequence[float],
                 dead: Sequence[float], ring: NeckRing | Sequence[float] | None,
                 axis_point: Sequence[float], weight_air: float, weight_liquid: float,
                 liquid_level: float | None, offside_tension: float, near_end_cm: float,
                 position: Sequence[float], ring_segments: int | None = None):
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
        segs = self.RING_SEGMENTS if ring_segments is None else int(ring_segments)
        if segs & ~(lib.PYRT_NECK_UPPER | lib.PYRT_NECK_LOWER):
            raise NativeInputError(f"PolyControl: ring_segments must be a mask of UPPER and "
                                   f"LOWER, got {ring_segments!r}")
        self.ring_segments = segs
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
        self._phi_lower = new("double[]", [_NAN] * n)
        self._hare_phi = new("double[]", [_NAN] * n)
        self._hare_phi_lower = new("double[]", [_NAN] * n)
        self._prev_error_length = new("double[]", n)
        self._prev_error_tension = new("double[]", n)
        # the finder's and the batch's bound buffers: solved and run from C
        self._views = [ffi.from_buffer("double[]", a)
                       for a in (finder.tops, finder.lengths, batch.inputs,
                                 finder._bottoms)]
        layout, size = _io_layout(n)
        io = self._io = new("double[]", size)
        self._c = new("pyrt_polyctl *", {
            "n": n, "tops": self._tops, "bottoms": self._bottoms, "offsets": self._offsets,
            "stretch": self._stretch, "dead": self._dead, "ring": _neck_ring(ring)[0],
            "ring_segments": segs,
            "axis_point": _finite("axis_point", axis_point, 2),
            "weight_air": float(weight_air), "weight_liquid": float(weight_liquid),
            "liquid_level": -math.inf if liquid_level is None else float(liquid_level),
            "offside_tension": float(offside_tension), "near_end_cm": float(near_end_cm),
            "finder": finder._p, "finder_tops": self._views[0],
            "finder_lengths": self._views[1], "finder_bottoms": self._views[3],
            "fuzzy": batch._b,
            "fuzzy_inputs": self._views[2], "phi": self._phi, "phi_lower": self._phi_lower,
            "hare_phi": self._hare_phi, "hare_phi_lower": self._hare_phi_lower,
            "prev_error_length": self._prev_error_length,
            "prev_error_tension": self._prev_error_tension, "use_start": 1,
            **{name: ffi.addressof(io, offset) for name, (offset, _) in layout.items()},
        })

        def span(first: str, last: str) -> slice:
            return slice(layout[first][0], layout[last][0] + layout[last][1])

        def block(first: str, last: str) -> tuple[object, int]:
            sl = span(first, last)
            return ffi.addressof(io, sl.start), sl.stop - sl.start

        self._position = span("position", "position")
        self._measure_in = span("tension", "encoder_length")
        self._measured = block("length", "result")
        self._drive_in = span("hare", "velocity")
        self._drive_in_all = span("hare", "is_free")      # with signal_all
        self._driven = block("desired_tension", "last_dv")
        self._last_dv = span("last_dv", "last_dv")
        io[self._position] = _finite("position", position, 3)
        self._rate = 0.0
        self._signal_all = False
        self._what_measure = f"PolyControl.measure ({n} ropes)"
        self._what_drive = f"PolyControl.drive ({n} ropes)"
        self._measure = lib.pyrt_polyctl_measure
        self._drive = lib.pyrt_polyctl_drive
        self._unpack = ffi.unpack

    # -- state -------------------------------------------------------------------

    def set_position(self, position: Sequence[float]) -> None:
        """Start the next solve from ``position`` (and find ring contacts there)."""
        self._io[self._position] = _finite("position", position, 3)
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
        self._c.have_prev = 0
        self._io[self._last_dv] = [0.0] * self.n

    @property
    def rim_angles(self) -> list[float | None]:
        """Per rope, the rim angle its upper segment bore on the ring at the last
        measure (None: free)."""
        return [None if v != v else v for v in self._unpack(self._phi, self.n)]

    @property
    def lower_rim_angles(self) -> list[float | None]:
        """Per rope, the rim angle its lower segment bore on the ring at the last
        measure (None: free, or no bottom attachment)."""
        return [None if v != v else v for v in self._unpack(self._phi_lower, self.n)]

    # -- the two calls -------------------------------------------------------------

    def measure(self, tensions: list[float], encoder_lengths: list[float],
                lengths: list[float]) -> list[float]:
        """Steps 1-3: ``lengths`` (corrected, filled in place); returns
        ``[x, y, z, dist_err, fx, fy, fz, |f|]``.  NativeError when the
        position cannot be found (the lengths are still filled in; the
        position is kept)."""
        n = self.n
        self._io[self._measure_in] = tensions + encoder_lengths
        rc = self._measure(self._c)
        out = self._unpack(*self._measured)
        lengths[:] = out[:n]
        raise_for_status(rc, self._what_measure)
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
        if signal_all:
            self._io[self._drive_in_all] = [*hare, *velocities, *desired, *free]
        else:
            self._io[self._drive_in] = [*hare, *velocities]
        raise_for_status(self._drive(c), self._what_drive)
        out = self._unpack(*self._driven)
        if not signal_all:
            desired[:] = out[:n]
            free[:] = out[n:2 * n]
        error_lengths[:] = out[2 * n:3 * n]
        error_tensions[:] = out[3 * n:4 * n]
        return out[4 * n:]
