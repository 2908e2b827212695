"""The manipulator's run-time parameters that belong to the station's
configuration rather than to one device: each rope's fuzzy gains (the
``dv_*`` changes of its rules, held by the PolyAxis's batched fuzzy
controller), as :class:`Param` records for ``get``/``set``
(:meth:`ManipulatorStation.params_of`).  The PolyAxis's MAX_TENSION and
END_ERROR are its own (:meth:`pyrt.robots.polyaxis.PolyAxis.params`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pyrt.component import Param
from pyrt.errors import CommandError, NativeError

__all__ = ["FUZZY_GAINS", "axis_fuzzy_params"]

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
