"""The manipulator's run-time parameters that belong to the station's
configuration rather than to one device: the PolyAxis's MAX_TENSION and
END_ERROR, and each rope's fuzzy gains (the ``dv_*`` changes of its rules,
held by the PolyAxis's batched fuzzy controller), as :class:`Param` records
for ``get``/``set`` (:meth:`ManipulatorStation.params_of`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pyrt.component import Param
from pyrt.errors import CommandError, NativeError
from pyrt.native import FuzzyInput

__all__ = ["FUZZY_GAINS", "axis_fuzzy_params", "polyaxis_params"]

#: The fuzzy gains (FuzzyParams fields) ``set`` changes, with what each rule does.
FUZZY_GAINS: dict[str, str] = {
    "dv_tension": "rules 0/1: increase tension",
    "dv_length": "rules 2/3: the proportional term of the length loop",
    "dv_rel_tension": "rules 4/5: relative tension (an off-side rope idles)",
    "dv_velocity": "rule 6: pull back a run-away velocity",
    "dv_len_rate": "rule 7: damping of the length loop",
    "dv_t_rate": "rule 8: damps two ropes trading tension",
    "dv_damping": "rule 9: fraction of a high last dv taken back",
}

#: A gain may be set up to this many times its value at start-up.
GAIN_SPAN = 10.0


def polyaxis_params(pa: Any) -> list[Param]:
    """MAX_TENSION and END_ERROR of the PolyAxis ``pa`` (not written back:
    POLYAXIS.dat keeps its values)."""
    maxloads = [a.loadcell.maxload for a in pa.axes if a.loadcell.maxload > 0]
    top = min(maxloads) if maxloads else 10_000.0
    floor = pa.low_tension + 2.0 * pa.tension_margin

    def set_max(value: float) -> str:
        if value <= floor:
            raise CommandError(f"set {pa.name}.MAX_TENSION: {value:g} N leaves no room above "
                               f"LOW_TENSION {pa.low_tension:g} N and the margins "
                               f"({pa.tension_margin:g} N each); nothing changed")
        pa.max_tension = float(value)
        pa.batch.inputs[:, FuzzyInput.TENSION_HIGH] = pa.max_tension
        for a in pa.axes:
            if a.length_range is not None:
                a.set_supervision(a.length_range, (pa.low_tension, pa.max_tension),
                                  a.tension_stops)
        return "the fuzzy rules and every rope's tension stop use it from now"

    def set_end(value: float) -> None:
        pa.end_error = float(value)

    return [
        Param("MAX_TENSION", "N", lambda: pa.max_tension, set_max, round(floor, 3), top,
              "the highest rope tension a move may need (tension stop, fuzzy TENSION_HIGH)"),
        Param("END_ERROR", "cm", lambda: pa.end_error, set_end, 0.01, 50.0,
              "a move ends within this distance of its target"),
    ]


def axis_fuzzy_params(pa: Any, k: int) -> list[Param]:
    """The fuzzy gains of rope ``k`` of ``pa`` (per control poll, as the batch
    uses them; not written back: FUZZY_<NAME> keys of AXIS.dat keep theirs)."""
    batch = pa.batch
    start = batch.params[k]
    out = []
    for field, doc in FUZZY_GAINS.items():
        out.append(Param(field.upper(), "cm/s per poll" if field != "dv_damping" else "fraction",
                         _reader(batch, k, field), _writer(pa, k, field), 0.0,
                         max(GAIN_SPAN * getattr(start, field), 1.0), doc))
    return out


def _reader(batch: Any, k: int, field: str) -> Callable[[], float]:
    return lambda: getattr(batch.params[k], field)


def _writer(pa: Any, k: int, field: str) -> Callable[[float], None]:
    def write(value: float) -> None:
        try:
            pa.batch.set_params(k, pa.batch.params[k].replace(**{field: value}))
        except NativeError as exc:
            raise CommandError(f"set {pa.axes[k].name}.{field.upper()}: {exc}; "
                               "nothing changed") from None

    return write
