"""The rope-tension loadcell (000, section 10, Table 9).

``N = SLOPE * adc + OFFSET``.  Calibration: ``calibrate`` enters calibration
mode; each ``point [load]`` records the ADC code with a known load hung on
the rope; ``calibrate`` again fits SLOPE and OFFSET by least squares to two
or more points, leaves calibration mode and hands the fit to the
write-back callback (the database keeps it, with the DATE and the points,
CALIBRATIONPOINT).  A fit no loadcell could give (a negative gain, zero load
outside the ADC's range, points off the line) is refused.  A load is newtons, or a
quantity with a force unit (``10 lb``) or a mass unit (``2 kg``, the hung
mass, weighed with standard gravity).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from pyrt.boards.dataconcentrator import ADC_MAX, AnalogChannel, DataConcentrator
from pyrt.component import Arg, Component, Limits, Param, Signal, command
from pyrt.devices._args import parse_number
from pyrt.errors import CommandError, ConfigError
from pyrt.units import UnitError, factor, split_quantity

if TYPE_CHECKING:
    from pyrt.db import LoadcellRecord

__all__ = ["CAL_RESIDUAL_FRACTION", "CAL_RESIDUAL_N", "STANDARD_GRAVITY", "Loadcell",
           "parse_load"]

STANDARD_GRAVITY = 9.80665
#: A calibration whose points scatter about the fitted line by more than the
#: larger of these (RMS) is refused: 000 finds the loadcells "quite linear"
#: (the bias resistor adds 0.7 % non-linearity), so a worse fit means a wrong
#: load was entered or the load was not hanging free.
CAL_RESIDUAL_N = 1.0
CAL_RESIDUAL_FRACTION = 0.02


def parse_load(value: float | str, command: str) -> float:
    """A calibration load in newtons from a number or ``"2 kg"``/``"10 lb"``/``"20 N"``."""
    if isinstance(value, str):
        try:
            v, unit = split_quantity(value)
        except UnitError as exc:
            raise CommandError(f"{command}: expected a load such as 20 N or 2 kg, "
                               f"got {value!r}") from exc
        if unit is None:
            n = v
        else:
            try:
                n = v * factor(unit, "force")
            except UnitError:
                try:
                    n = v * factor(unit, "mass") * STANDARD_GRAVITY
                except UnitError as exc:
                    raise CommandError(
                        f"{command}: unknown load unit {unit!r}; give newtons, lb or a mass "
                        "such as kg") from exc
    else:
        n = parse_number(value, command, "load in N")
    if not math.isfinite(n) or n < 0:
        raise CommandError(f"{command}: load must be a finite number >= 0 N, got {value!r}")
    return n


class Loadcell(Component):
    """One loadcell (see the module text)."""

    def __init__(
        self,
        name: str,
        channel: AnalogChannel,
        slope: float,
        offset: float,
        *,
        maxload: float = 0.0,
        write_back: Callable[[float, float], None] | None = None,
    ):
        for label, v in (("SLOPE", slope), ("OFFSET", offset)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ConfigError(f"loadcell {name}: {label} must be a number, got {v!r}")
        self.name = name
        self.channel = channel
        self._code = channel.raw  # the ADC's register, bound once (the tick's path)
        self.slope = float(slope)
        self.offset = float(offset)
        self.maxload = float(maxload)
        self.write_back = write_back
        #: The tension's display range and alarm levels (the rope's tension
        #: limits, given by the axis that reads this loadcell), or None.
        self.limits: Limits | None = None
        self.calibrating = False
        #: While calibrating: the rope tension read just before calibration
        #: began.  The rope is off the loadcell then, carrying the known loads,
        #: so the controller (stretch correction, tension supervision) goes on
        #: with the tension the rope last had, not the calibration loads.
        self.held: float | None = None
        self.points: list[tuple[int, float]] = []
        #: The last calibration: its date (DD-MM-YYYY, the form of 000's DATE
        #: field) and its points as written to CALIBRATIONPOINT.
        self.date = ""
        self.calibration_points = ""

    @classmethod
    def from_record(cls, record: LoadcellRecord, board: DataConcentrator, name: str | None = None,
                    **kw) -> Loadcell:
        """A Loadcell from a :class:`pyrt.db.LoadcellRecord`."""
        return cls(name or record.name, AnalogChannel(board, record.channel), record.slope,
                   record.offset, maxload=record.maxload, **kw)

    def adc(self) -> int:
        return self._code()

    def measured(self) -> float:
        """What the loadcell reads now, in newtons (through SLOPE and OFFSET)."""
        return self.slope * self._code() + self.offset

    def tension(self) -> float:
        """The rope tension in newtons: the reading, or while calibrating the
        tension held from before calibration began (see :attr:`held`)."""
        if self.held is not None:
            return self.held
        return self.slope * self._code() + self.offset

    # -- calibration ---------------------------------------------------------------

    def params(self) -> list[Param]:
        """SLOPE and OFFSET, the calibration (written back to LOADCELL.dat, as a
        calibration is, when the station gave a write-back)."""

        def slope(v: float) -> None:
            if v == 0:
                raise CommandError(f"set {self.name}.SLOPE: 0 would read every load as "
                                   "OFFSET; nothing changed")
            self.slope = float(v)
            if self.write_back is not None:
                self.write_back(self.slope, self.offset)

        def offset(v: float) -> None:
            self.offset = float(v)
            if self.write_back is not None:
                self.write_back(self.slope, self.offset)

        back = self.write_back is not None
        return [
            Param("SLOPE", "N/count", lambda: self.slope, slope, -100.0, 100.0,
                  "newtons per ADC count", written_back=back),
            Param("OFFSET", "N", lambda: self.offset, offset, -10_000.0, 10_000.0,
                  "newtons at ADC code 0", written_back=back),
        ]

    def signals(self) -> list[Signal]:
        return [Signal("tension", "N", self.tension, "rope tension from the ADC",
                       limits=self.limits)]

    @command(name="calibrate", reply=lambda v: (
        "calibration mode: hang known loads and give 'point LOAD'" if v is None
        else f"SLOPE {v[0]:.10g} OFFSET {v[1]:.10g}"))
    def calibrate(self) -> tuple[float, float] | None:
        """calibrate: toggle calibration mode; leaving it fits SLOPE and OFFSET.

        Leaving calibration mode fits (slope, offset), writes them back to the
        database and returns them.

        Fewer than two points (or points that all share one ADC code) is a
        CommandError, and calibration mode stays on so points can be added.
        """
        self.check_free("calibrate")
        if not self.calibrating:
            self.held = self.measured()
            self.calibrating = True
            self.points = []
            return None
        pts = self.points
        if len(pts) < 2:
            raise CommandError(
                f"{self.name} calibrate: need at least two calibration points, have {len(pts)}"
            )
        n = len(pts)
        mx = sum(c for c, _ in pts) / n
        my = sum(f for _, f in pts) / n
        sxx = sum((c - mx) ** 2 for c, _ in pts)
        if sxx == 0:
            raise CommandError(
                f"{self.name} calibrate: every point reads ADC code {pts[0][0]}; "
                "hang different loads"
            )
        sxy = sum((c - mx) * (f - my) for c, f in pts)
        slope = sxy / sxx
        offset = my - slope * mx
        why = self._implausible(slope, offset, pts)
        if why is not None:
            self.points = []
            raise CommandError(f"{self.name} calibrate: refused, {why}; SLOPE and OFFSET "
                               "unchanged, points cleared (still in calibration mode)")
        self.slope, self.offset = slope, offset
        self.calibrating = False
        self.held = None
        self.points = []
        self.date = time.strftime("%d-%m-%Y")
        self.calibration_points = "; ".join(f"{c} {f:.3f}" for c, f in pts)
        if self.write_back is not None:
            self.write_back(slope, offset)
        return slope, offset

    @staticmethod
    def _implausible(slope: float, offset: float, pts: list[tuple[int, float]]) -> str | None:
        """Why a fit cannot be a loadcell's, or None: the gain must be positive
        (more load, a higher code), zero load must fall inside the ADC's range,
        and the points must lie on the line (CAL_RESIDUAL_N / _FRACTION)."""
        if not (math.isfinite(slope) and math.isfinite(offset)) or slope <= 0:
            return (f"the fitted gain {slope:.4g} N per code is not positive (the ADC code "
                    "must rise with the load)")
        zero = -offset / slope
        if not 0 <= zero <= ADC_MAX:
            return (f"zero load would read ADC code {zero:.0f}, outside the ADC's 0..{ADC_MAX} "
                    f"(OFFSET {offset:.4g} N)")
        rms = math.sqrt(sum((slope * c + offset - f) ** 2 for c, f in pts) / len(pts))
        loads = [f for _, f in pts]
        limit = max(CAL_RESIDUAL_N, CAL_RESIDUAL_FRACTION * (max(loads) - min(loads)))
        if rms > limit:
            return f"the points scatter {rms:.3g} N RMS about the fit (limit {limit:.3g} N)"
        return None

    @property
    def load_range(self) -> tuple[float, float | None]:
        """Calibration loads (N): up to MAXLOAD when the database gives one."""
        return (0.0, self.maxload if self.maxload > 0 else None)

    @command(Arg("LOAD", lambda t: parse_load(t, "point"), rest=True, lo=0.0, units="N",
                 bounds="load_range", what="up to the loadcell's MAXLOAD"), name="point",
             reply=lambda v: f"point: ADC {v[0]} = {v[1]:.4g} N", aliases=("calibrationPoint",))
    def point(self, load: float | str) -> tuple[int, float]:
        """point LOAD: a calibration point with LOAD (N, lb or kg) hung on the rope
        (000's "calibrationPoint")."""
        self.check_free("point")
        if not self.calibrating:
            raise CommandError(f"{self.name} point: not in calibration mode; "
                               "give 'calibrate' first")
        n = parse_load(load, f"{self.name} point")
        hi = self.load_range[1]
        if hi is not None and n > hi:
            raise CommandError(f"{self.name} point: LOAD {n:.4g} N is out of range: "
                               f"0..{hi:.4g} N (the loadcell's MAXLOAD); nothing recorded")
        code = self._code()
        self.points.append((code, n))
        return code, n
