"""Where the source is, and whether that can be trusted: the manipulator's position estimator.

:class:`PositionEstimator` measures (every loadcell and encoder read, the
stretch-corrected lengths, the ring contacts, the prepared position finder
and the residual net force: one C call, :class:`pyrt.native.PolyControl`),
and holds the estimate: ``position``, ``dist_err`` (the RMS length
residual), ``tensions``, ``lengths``, ``net_force``.

Estimate integrity (beyond 000).  After every measure, moving or not, the
estimate is checked (:meth:`PositionEstimator.check`): distErr beyond
DIST_ERR_LIMIT, or distErr rising while an encoder falls out of step with
its motor (a slipping or reset encoder), loses the estimate, naming the
axis; the controller reports it as a fault, and from then every move is
refused and nothing measured is written back until the position is
re-established: :meth:`~PositionEstimator.survey` (the position from every
rope but the suspect one, as the redundant rope lets 000's finder do; that
rope's encoder re-zeroed) or :meth:`~PositionEstimator.setpos` (the
operator has seen the source; every encoder re-zeroed to agree).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from pyrt.errors import CommandError
from pyrt.native import PolyControl, PositionFinder
from pyrt.robots.ropes import RopeModel, Vec, payout

__all__ = ["SLIP_COUNTS", "SNAPSHOT_POLLS", "PositionEstimator"]

#: Control polls between snapshots of a consistent estimate; the older of the
#: last two is the reference of the slip check (so it covers 1-2 s at 50 ms).
SNAPSHOT_POLLS = 20
#: Encoder counts an encoder may fall out of step with its motor since the
#: reference (quantisation makes one) before, with distErr rising by more
#: than FIND_TOLERANCE, its rope's length is taken to be wrong (slip, reset).
SLIP_COUNTS = 2


class PositionEstimator:
    """The position estimate of the manipulator ``name`` over its ``axes`` (see the
    module text); ``ctl`` is the poll kernel that measures, ``finder`` its
    prepared position finder."""

    def __init__(self, name: str, axes: Sequence[Any], model: RopeModel, finder: PositionFinder,
                 ctl: PolyControl, position: Sequence[float], *, find_tolerance: float,
                 dist_err_limit: float):
        self.name = name
        self.axes = list(axes)
        self.n = len(self.axes)
        self.model = model
        self.finder = finder
        self.ctl = ctl
        self.find_tolerance = float(find_tolerance)
        self.dist_err_limit = float(dist_err_limit)
        self._read_tension = [a.loadcell.tension for a in self.axes]
        self._read_length = [a.encoder.length for a in self.axes]
        #: The encoders' unstretched lengths of the last measure (cm).
        self.encoder_lengths = [0.0] * self.n
        self.position: Vec = (float(position[0]), float(position[1]), float(position[2]))
        self.dist_err = 0.0
        self.tensions = [0.0] * self.n
        self.lengths = [0.0] * self.n
        self.net_force: Vec = (0.0, 0.0, 0.0)
        self.net_force_magnitude = 0.0
        #: Why the last poll could not find the position (None: it could).
        self.position_error: str | None = None
        #: Why the position estimate is not trusted (a slipping or reset encoder,
        #: a rope whose length disagrees), or None; moves are refused until
        #: ``survey`` or ``setpos`` re-establishes it.
        self.estimate_lost: str | None = None
        #: The axis the last estimate fault named (index), for ``survey``.
        self.suspect: int | None = None
        # snapshots (distErr, encoder counts, motor steps) of a consistent
        # estimate, the older one the reference of the slip check
        self._snapshots: list[tuple[float, list[int], list[int]]] = []
        self._snapshot_in = 0

    def measure(self) -> None:
        """Read every Axis and find the source position (steps 1-3 of the poll):
        the loadcells and encoders here, the rest in one C call (NativeError when
        the lengths fix no position)."""
        tens = self.tensions
        tens[:] = [f() for f in self._read_tension]
        raw = self.encoder_lengths
        raw[:] = [f() for f in self._read_length]
        x, y, z, self.dist_err, fx, fy, fz, self.net_force_magnitude = self.ctl.measure(
            tens, raw, self.lengths)
        self.position = (x, y, z)
        self.net_force = (fx, fy, fz)

    # -- integrity ---------------------------------------------------------------------

    def check(self) -> str | None:
        """After every measure: the estimate is lost when distErr exceeds
        DIST_ERR_LIMIT, or when it has risen by more than FIND_TOLERANCE since the
        reference while an encoder has fallen SLIP_COUNTS counts out of step with
        its motor (an encoder slipping on its rope, or reset).  Returns the fault
        (naming the axis) when it is lost now, else None."""
        if self.estimate_lost is not None:
            return None
        de = self.dist_err
        snaps = self._snapshots
        disc: list[float] | None = None
        if de > self.dist_err_limit:
            cause = f"distErr {de:.3f} cm above DIST_ERR_LIMIT {self.dist_err_limit:g} cm"
        elif snaps and de > snaps[0][0] + self.find_tolerance:
            disc = self._disagreement()
            i = max(range(self.n), key=lambda k: abs(disc[k]))  # type: ignore[index]
            if abs(disc[i]) < SLIP_COUNTS * self.axes[i].encoder.slope:
                self._snapshot(de)
                return None
            cause = f"distErr rose from {snaps[0][0]:.3f} to {de:.3f} cm"
        else:
            self._snapshot(de)
            return None
        if disc is None:
            disc = self._disagreement() if snaps else [0.0] * self.n
        d = disc
        i = max(range(self.n), key=lambda k: abs(d[k]))
        if abs(d[i]) >= SLIP_COUNTS * self.axes[i].encoder.slope:
            why = (f"its encoder is {d[i]:+.2f} cm out of step with its motor "
                   "(encoder slip or reset)")
        else:
            res = [float(r) for r in self.finder.residuals]
            i = max(range(self.n), key=lambda k: abs(res[k]))
            why = f"its length disagrees most ({res[i]:+.2f} cm)"
        self.suspect = i
        name = self.axes[i].name
        self.estimate_lost = f"{name}: {cause}; {why}"
        return (f"{name}: position estimate lost: {cause}; {why}; moves refused until "
                "'survey' or 'setpos X Y Z'")

    def _snapshot(self, de: float) -> None:
        """Every SNAPSHOT_POLLS polls of a consistent estimate: distErr, encoder
        counts and motor steps (the last two kept)."""
        self._snapshot_in -= 1
        if self._snapshot_in > 0 and self._snapshots:
            return
        self._snapshot_in = SNAPSHOT_POLLS
        snap = (de, [a.encoder.count() for a in self.axes],
                [a.motor.position_steps for a in self.axes])
        self._snapshots.append(snap)
        if len(self._snapshots) > 2:
            del self._snapshots[0]

    def _disagreement(self) -> list[float]:
        """Per axis, rope the encoder saw less the rope the motor moved since the
        reference snapshot (cm)."""
        _, counts, steps = self._snapshots[0]
        return [(a.encoder.count() - c) * a.encoder.slope
                - (a.motor.position_steps - s) / a.motor.steps_per_cm
                for a, c, s in zip(self.axes, counts, steps, strict=True)]

    # -- re-establishing the position ------------------------------------------------------

    def establish(self, x: Sequence[float]) -> list[float]:
        """The source is at ``x``: every encoder re-zeroed so that its corrected
        length is the rope's length there (at the measured tension), the finder
        restarted from ``x``, the estimate trusted again.  Returns each encoder's
        change of zero length (cm)."""
        p: Vec = (float(x[0]), float(x[1]), float(x[2]))
        changes = []
        for i, a in enumerate(self.axes):
            want = payout(self.model.length_at(i, p), self.tensions[i], a.stretch,
                          a.dead_length)
            enc = a.encoder
            new = want - enc.slope * enc.count()
            changes.append(new - enc.zero_length)
            enc.zero_length = new
        self.ctl.set_position(p)
        self.position = p
        self.estimate_lost = None
        self.suspect = None
        self.position_error = None
        self._snapshots.clear()
        self._snapshot_in = 0
        self.measure()
        return changes

    def setpos(self, x: float, y: float, z: float) -> str:
        """The source is at (x, y, z) cm (the operator has seen it): every encoder
        re-zeroed to agree; CommandError (nothing changed) for a point where the
        source may not be."""
        p = (x, y, z)
        why = self.model.refusal(p) or self.model.plane_refusal(p)
        if why is not None:
            raise CommandError(f"{self.name} setpos: ({x:g}, {y:g}, {z:g}) is {why}; "
                               "nothing changed")
        changes = self.establish(p)
        moved = ", ".join(f"{a.name} {c:+.2f}" for a, c in zip(self.axes, changes, strict=True))
        return (f"{self.name}: position set to ({x:g}, {y:g}, {z:g}); encoders re-zeroed "
                f"({moved} cm); distErr {self.dist_err:.3f} cm; moves allowed")

    def survey(self) -> str:
        """The position from every rope but the one the last estimate fault named
        (or the one whose length disagrees most), that rope's encoder re-zeroed;
        CommandError (nothing changed) when the others cannot fix it."""
        if self.suspect is not None:
            bad = self.suspect
        else:
            res = [float(r) for r in self.finder.residuals]
            bad = max(range(self.n), key=lambda k: abs(res[k]))
        others = [k for k in range(self.n) if k != bad]
        free = self.model.free
        name = self.axes[bad].name
        if len(others) < len(free):
            raise CommandError(f"{self.name} survey: without {name} {len(others)} ropes cannot "
                               f"fix {len(free)} directions; use 'setpos X Y Z'; nothing changed")
        x, rms = self.model.position_from_lengths(self.position, self.lengths, others)
        why = self.model.refusal(x) or self.model.plane_refusal(x)
        if rms > self.dist_err_limit or why is not None or not all(map(math.isfinite, x)):
            raise CommandError(
                f"{self.name} survey: the ropes but {name} do not agree on a position "
                f"(residual {rms:.3f} cm{'; ' + why if why else ''}); use 'setpos X Y Z'; "
                "nothing changed")
        change = self.establish(x)[bad]
        return (f"{self.name}: survey: position ({x[0]:.2f}, {x[1]:.2f}, {x[2]:.2f}) from every "
                f"rope but {name} (residual {rms:.3f} cm); {name}'s encoder re-zeroed by "
                f"{change:+.2f} cm; distErr {self.dist_err:.3f} cm; moves allowed")
