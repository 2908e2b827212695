"""The fuzzy Axis controller of 000, section 6 (csrc/fuzzy.c).

Ten rules turn each axis's state into a change of motor velocity per poll;
fuzzy AND is the product, NOT is ``1 - x``, and the output is the sum of
premise truth x velocity change over the rules (see ``csrc/fuzzy.h`` for the
rule table).  Positive velocity pays rope out; errors are actual - desired.

Inputs are one row per axis with the columns of :class:`FuzzyInput`; outputs
are ``dv`` (N,) cm/s and ``rules`` (N, 10), each rule's contribution, in the
column order of :class:`FuzzyRule` (the document's a0rules.dat columns).

:func:`fuzzy_step` converts its arguments explicitly; :class:`FuzzyBatch`,
the form for the control poll, owns its input and output arrays so that a
poll only writes numbers into ``batch.inputs`` and calls ``batch.step()``.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from pyrt.errors import NativeError
from pyrt.native._arrays import F64, as_f64
from pyrt.native._errors import NativeInputError, NonFiniteError, raise_for_status
from pyrt.native._lib import ffi, lib

__all__ = ["FuzzyBatch", "FuzzyInput", "FuzzyParams", "FuzzyRule", "fuzzy_step"]

MAX_AXES: int = lib.PYRT_FUZZY_MAX_AXES
NINPUTS: int = lib.PYRT_FUZZY_NINPUTS
NRULES: int = lib.PYRT_FUZZY_NRULES

#: The poll period (s) the default velocity changes are tuned for.
REFERENCE_POLL_S: float = lib.PYRT_FUZZY_REFERENCE_POLL_S


class FuzzyInput(enum.IntEnum):
    """Column of the per-axis input row (values from ``csrc/fuzzy.h``)."""

    TENSION = lib.PYRT_FUZZY_IN_TENSION                        # N
    DESIRED_TENSION = lib.PYRT_FUZZY_IN_DESIRED_TENSION        # N
    FREE = lib.PYRT_FUZZY_IN_FREE                              # truth 0..1
    LENGTH_ERROR = lib.PYRT_FUZZY_IN_LENGTH_ERROR              # cm, actual - desired
    VELOCITY = lib.PYRT_FUZZY_IN_VELOCITY                      # cm/s, + pays out
    LENGTH_ERROR_RATE = lib.PYRT_FUZZY_IN_LENGTH_ERROR_RATE    # cm/s
    TENSION_ERROR_RATE = lib.PYRT_FUZZY_IN_TENSION_ERROR_RATE  # N/s
    LAST_DV = lib.PYRT_FUZZY_IN_LAST_DV                        # cm/s
    NEAR_END = lib.PYRT_FUZZY_IN_NEAR_END                      # truth 0..1
    TENSION_LOW = lib.PYRT_FUZZY_IN_TENSION_LOW                # N
    TENSION_HIGH = lib.PYRT_FUZZY_IN_TENSION_HIGH              # N


class FuzzyRule(enum.IntEnum):
    """Column of the rule outputs: the ten rules of 000 section 6, in its order."""

    TENSION_LOW = 0               # if tension is low then increase tension
    TENSION_HIGH = 1              # if tension is high then decrease tension
    LENGTH_SHORT = 2              # if corrected length is short then increase length
    LENGTH_LONG = 3               # if corrected length is long then decrease length
    REL_TENSION_LOW = 4           # if not near end and relative tension is low ...
    REL_TENSION_HIGH = 5          # if not near end and relative tension is high ...
    VELOCITY_HIGH = 6             # if velocity is high then decrease velocity
    LENGTH_ERROR_RATE_HIGH = 7    # if errorLengthVelocity is high then decrease it
    TENSION_ERROR_RATE_HIGH = 8   # if errorTensionVelocity is high then decrease it
    DV_HIGH = 9                   # if dv is high then decrease dv


if len(FuzzyRule) != NRULES:  # pragma: no cover - a build out of step with this module
    raise ImportError(f"csrc/fuzzy.h has {NRULES} rules, pyrt.native knows {len(FuzzyRule)}")

# Velocity-change fields that are "per poll" and scale with the poll period.
_PER_POLL = ("dv_zero", "dv_full", "dv_tension", "dv_length", "dv_rel_tension",
             "dv_velocity", "dv_len_rate", "dv_t_rate")


@dataclass(frozen=True)
class FuzzyParams:
    """Breakpoints and velocity changes of the ten rules for one axis.

    Figure 3 of 000 (the fuzzy sets) did not survive; these are pyrt's sets.
    Shoulders: a set is 0 at its ``*_zero`` point and 1 at its ``*_full``
    point, linear between.  Velocity changes are magnitudes in cm/s **per
    poll**, tuned for a :data:`REFERENCE_POLL_S` poll on the prototype;
    :meth:`for_poll_period` rescales them for another poll.  The field
    order is ``pyrt_fuzzy_params``'s and every default is read from
    ``csrc/fuzzy.h`` (``PYRT_FUZZY_DEFAULT_*``), where the numbers and the
    reasoning for each, and the closed-loop check they passed, are written
    out once.
    """

    #: The poll period (s) the per-poll defaults are tuned for.
    REFERENCE_POLL_S: ClassVar[float] = REFERENCE_POLL_S

    #: LowT (rules 0, 1: the guards) is 1 at or below tension_low + low_t_full ...
    low_t_full: float = lib.PYRT_FUZZY_DEFAULT_LOW_T_FULL
    #: ... and 0 at tension_low + low_t_zero.
    low_t_zero: float = lib.PYRT_FUZZY_DEFAULT_LOW_T_ZERO
    #: HighT is 0 at tension_high - high_t_zero ...
    high_t_zero: float = lib.PYRT_FUZZY_DEFAULT_HIGH_T_ZERO
    #: ... and 1 at tension_high - high_t_full.
    high_t_full: float = lib.PYRT_FUZZY_DEFAULT_HIGH_T_FULL
    #: Short/Long (rules 2, 3) on the corrected length error, cm.
    len_zero: float = lib.PYRT_FUZZY_DEFAULT_LEN_ZERO
    len_full: float = lib.PYRT_FUZZY_DEFAULT_LEN_FULL
    #: RelLow/RelHigh (rules 4, 5) on tension - desired, N.
    rel_zero: float = lib.PYRT_FUZZY_DEFAULT_REL_ZERO
    rel_full: float = lib.PYRT_FUZZY_DEFAULT_REL_FULL
    #: Fraction of the relative-tension rules removed when near the end
    #: (the document relaxes them only partially).
    near_end_relax: float = lib.PYRT_FUZZY_DEFAULT_NEAR_END_RELAX
    #: HighV (rule 6): a soft speed limit, cm/s.
    vel_zero: float = lib.PYRT_FUZZY_DEFAULT_VEL_ZERO
    vel_full: float = lib.PYRT_FUZZY_DEFAULT_VEL_FULL
    #: HighELV (rule 7), |d(length error)/dt|, cm/s.
    len_rate_zero: float = lib.PYRT_FUZZY_DEFAULT_LEN_RATE_ZERO
    len_rate_full: float = lib.PYRT_FUZZY_DEFAULT_LEN_RATE_FULL
    #: HighETV (rule 8), |d(tension error)/dt|, N/s.
    t_rate_zero: float = lib.PYRT_FUZZY_DEFAULT_T_RATE_ZERO
    t_rate_full: float = lib.PYRT_FUZZY_DEFAULT_T_RATE_FULL
    #: HighDV (rule 9), |last dv|, cm/s per poll.
    dv_zero: float = lib.PYRT_FUZZY_DEFAULT_DV_ZERO
    dv_full: float = lib.PYRT_FUZZY_DEFAULT_DV_FULL
    #: Rules 0/1: the document's "increase tension".
    dv_tension: float = lib.PYRT_FUZZY_DEFAULT_DV_TENSION
    #: Rules 2/3: the proportional term of the length loop.
    dv_length: float = lib.PYRT_FUZZY_DEFAULT_DV_LENGTH
    #: Rules 4/5: stronger than the length rules on any tensioned rope, so an
    #: off-side rope is an idler.
    dv_rel_tension: float = lib.PYRT_FUZZY_DEFAULT_DV_REL_TENSION
    #: Rule 6: pull back a run-away velocity.
    dv_velocity: float = lib.PYRT_FUZZY_DEFAULT_DV_VELOCITY
    #: Rule 7: the damping of the length loop.
    dv_len_rate: float = lib.PYRT_FUZZY_DEFAULT_DV_LEN_RATE
    #: Rule 8: damps two ropes trading tension (the document's oscillation).
    dv_t_rate: float = lib.PYRT_FUZZY_DEFAULT_DV_T_RATE
    #: Rule 9: fraction of the last dv taken back when it was high.
    dv_damping: float = lib.PYRT_FUZZY_DEFAULT_DV_DAMPING

    if TYPE_CHECKING:
        @property
        def _c(self) -> Any:
            """The ``pyrt_fuzzy_params *`` these values were checked in (set once built)."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise NativeInputError(f"FuzzyParams.{f.name}: expected a number, got {value!r}")
            object.__setattr__(self, f.name, float(value))
        c = ffi.new("pyrt_fuzzy_params *", dataclasses.asdict(self))
        raise_for_status(lib.pyrt_fuzzy_check_params(c),
                         f"FuzzyParams: inconsistent breakpoints or changes ({self})")
        object.__setattr__(self, "_c", c)

    def __reduce__(self) -> tuple[type[FuzzyParams], tuple[float, ...]]:
        # Pickle and copy by value; the bound C struct is rebuilt on load.
        return (self.__class__, dataclasses.astuple(self))

    @classmethod
    def from_mapping(cls, values: Mapping[str, object], base: FuzzyParams | None = None
                     ) -> FuzzyParams:
        """Parameters from *base* (default: the defaults) with *values* overriding.

        Keys are field names, case-insensitive (``DV_LENGTH`` or
        ``dv_length``); values are numbers or numeric strings.  An unknown key
        or a bad value raises :class:`NativeInputError` naming it.
        """
        names = {f.name for f in dataclasses.fields(cls)}
        changes: dict[str, float] = {}
        for key, raw in values.items():
            name = str(key).strip().lower()
            if name not in names:
                raise NativeInputError(f"unknown fuzzy parameter {key!r}")
            try:
                changes[name] = float(raw)  # type: ignore[arg-type]
            except (TypeError, ValueError):
                raise NativeInputError(f"fuzzy parameter {key!r}: not a number: {raw!r}") from None
        return dataclasses.replace(base if base is not None else cls(), **changes)

    def replace(self, **overrides: float) -> FuzzyParams:
        """A copy with some fields changed (validated like the constructor)."""
        return self.from_mapping(overrides, base=self)

    def for_poll_period(self, seconds: float) -> FuzzyParams:
        """These parameters rescaled for an axis poll of *seconds*.

        The per-poll velocity changes (and the dv breakpoints) scale with the
        period so that accelerations stay what they are at 50 ms.
        """
        if not (isinstance(seconds, (int, float)) and 0.0 < seconds < float("inf")):
            raise NativeInputError(
                f"poll period must be a positive number of seconds, got {seconds!r}"
            )
        k = seconds / REFERENCE_POLL_S
        return dataclasses.replace(self, **{n: getattr(self, n) * k for n in _PER_POLL})


def c_default_params() -> dict[str, float]:
    """The defaults as ``pyrt_fuzzy_default_params`` sets them (field -> value)."""
    c = ffi.new("pyrt_fuzzy_params *")
    raise_for_status(lib.pyrt_fuzzy_default_params(c), "pyrt_fuzzy_default_params")
    return {name: getattr(c, name) for name, _ in ffi.typeof("pyrt_fuzzy_params").fields}


def _params_array(params: object, n: int) -> tuple[Any, int]:
    """(cdata array, count) for one shared FuzzyParams or one per axis."""
    if isinstance(params, FuzzyParams):
        return params._c, 1
    if not isinstance(params, Sequence) or len(params) != n:
        raise NativeInputError(
            f"params: expected one FuzzyParams or a sequence of {n}, got {params!r}"
        )
    arr = ffi.new("pyrt_fuzzy_params[]", n)
    for i, p in enumerate(params):
        if not isinstance(p, FuzzyParams):
            raise NativeInputError(f"params[{i}]: expected FuzzyParams, got {type(p).__name__}")
        arr[i] = p._c[0]
    return arr, n


def _detail(inputs: np.ndarray, exc: NativeError) -> str | None:
    """The axis and input out of range or not finite, when that is why *exc*
    was raised."""
    if isinstance(exc, NonFiniteError):
        bad = np.argwhere(~np.isfinite(inputs))
        if bad.size:
            i, j = bad[0]
            return f"axis {i} {FuzzyInput(j).name}"
    elif isinstance(exc, NativeInputError):
        free = inputs[:, FuzzyInput.FREE]
        near = inputs[:, FuzzyInput.NEAR_END]
        lo, hi = inputs[:, FuzzyInput.TENSION_LOW], inputs[:, FuzzyInput.TENSION_HIGH]
        for i in range(inputs.shape[0]):
            if not 0.0 <= free[i] <= 1.0:
                return f"axis {i}: FREE must be a truth value 0..1"
            if not 0.0 <= near[i] <= 1.0:
                return f"axis {i}: NEAR_END must be a truth value 0..1"
            if not lo[i] < hi[i]:
                return f"axis {i}: TENSION_LOW must be < TENSION_HIGH"
    return None


def fuzzy_step(params: FuzzyParams | Sequence[FuzzyParams], inputs: ArrayLike
               ) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate the ten rules for every axis (row) of *inputs*.

    *params* is one :class:`FuzzyParams` for every axis or a sequence with one
    per axis; *inputs* is array-like (N, 11) (or one row of 11), converted to
    float64.  Returns ``(dv, rules)`` with shapes (N,) and (N, 10).
    """
    x = as_f64("inputs", inputs, (None, NINPUTS) if np.ndim(inputs) == 2 else (NINPUTS,))
    x = x.reshape(-1, NINPUTS)
    n = x.shape[0]
    if not 1 <= n <= MAX_AXES:
        raise NativeInputError(f"inputs: expected 1 to {MAX_AXES} axes, got {n}")
    c, count = _params_array(params, n)
    dv = np.empty(n, F64)
    rules = np.empty((n, NRULES), F64)
    rc = lib.pyrt_fuzzy_step(
        n, c, count,
        ffi.from_buffer("double[]", x), ffi.from_buffer("double[]", dv),
        ffi.from_buffer("double[]", rules),
    )
    raise_for_status(rc, f"fuzzy_step ({n} axes)", functools.partial(_detail, x))
    return dv, rules


class FuzzyBatch:
    """All axes of a PolyAxis, prepared for one C call per poll.

    ``batch.inputs`` is an (N, 11) float64 array owned by the batch: the poll
    writes its numbers into it (index columns with :class:`FuzzyInput`) and
    calls :meth:`step`, which returns ``batch.dv``; ``batch.rules`` holds the
    ten rule outputs per axis.  Both outputs are read-only views overwritten
    by every successful step; a refused step raises and changes neither.
    """

    #: Axes per batch (csrc/fuzzy.h PYRT_FUZZY_MAX_AXES).
    MAX_AXES: ClassVar[int] = MAX_AXES

    def __init__(self, params_per_axis: FuzzyParams | Sequence[FuzzyParams], n_axes: int):
        if isinstance(n_axes, bool) or not isinstance(n_axes, (int, np.integer)):
            raise NativeInputError(f"n_axes: expected an integer, got {n_axes!r}")
        if not 1 <= n_axes <= MAX_AXES:
            raise NativeInputError(f"n_axes: expected 1 to {MAX_AXES}, got {n_axes}")
        n = int(n_axes)
        self.n = n
        self._params = ffi.new("pyrt_fuzzy_params[]", n)
        if isinstance(params_per_axis, FuzzyParams):
            params_per_axis = [params_per_axis] * n
        c, _ = _params_array(params_per_axis, n)
        for i in range(n):
            self._params[i] = c[i]
        self._axis_params: list[FuzzyParams] = list(params_per_axis)
        self._inputs = np.zeros((n, NINPUTS), F64)
        self._dv = np.zeros(n, F64)
        self._rules = np.zeros((n, NRULES), F64)
        self._bufs = [ffi.from_buffer("double[]", a)
                      for a in (self._inputs, self._dv, self._rules)]
        self._b = ffi.new("pyrt_fuzzy_batch *", {
            "n": n, "params": self._params, "inputs": self._bufs[0], "dv": self._bufs[1],
            "rules": self._bufs[2],
        })
        self._share_params()
        self._run = lib.pyrt_fuzzy_run
        self._what = f"FuzzyBatch.step ({n} axes)"
        self._detail = functools.partial(_detail, self._inputs)
        self.dv = self._dv.view()
        self.dv.flags.writeable = False
        self.rules = self._rules.view()
        self.rules.flags.writeable = False

    @property
    def params(self) -> tuple[FuzzyParams, ...]:
        """The parameters of each axis (change them with :meth:`set_params`)."""
        return tuple(self._axis_params)

    @property
    def inputs(self) -> np.ndarray:
        """The bound (N, 11) input array; write into it, do not rebind it."""
        return self._inputs

    def set_params(self, axis: int, params: FuzzyParams) -> None:
        """Replace the parameters of one axis (e.g. from the AXIS database)."""
        if not -self.n <= axis < self.n:
            raise NativeInputError(f"axis {axis} out of range for {self.n} axes")
        if not isinstance(params, FuzzyParams):
            raise NativeInputError(f"expected FuzzyParams, got {type(params).__name__}")
        self._params[axis] = params._c[0]
        self._axis_params[axis] = params
        self._share_params()

    def _share_params(self) -> None:
        # One parameter set checked once per step when every axis has the same.
        first = self._axis_params[0]
        self._b.nparams = 1 if all(p == first for p in self._axis_params) else self.n

    def step(self) -> np.ndarray:
        """Evaluate every axis from :attr:`inputs`; returns :attr:`dv`."""
        raise_for_status(self._run(self._b), self._what, self._detail)
        return self.dv
