"""A rope's fuzzy gains as run-time parameters: the ``dv_*`` changes of its
rules, held by its PolyAxis's batched fuzzy controller, as :class:`Param`
records for ``get``/``set``; they are the rope's (:meth:`pyrt.robots.axis.Axis.params`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pyrt.component import Param
from pyrt.errors import CommandError, NativeError

__all__ = ["FUZZY_GAINS", "fuzzy_gain_params"]

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


def fuzzy_gain_params(batch: Any, k: int, rope: str) -> list[Param]:
    """The fuzzy gains of rope ``k`` (called ``rope``) of the batched fuzzy
    controller ``batch`` (per control poll, as the batch uses them; not written
    back: FUZZY_<NAME> keys of AXIS.dat keep theirs)."""
    start = batch.params[k]
    out = []
    for field, doc in FUZZY_GAINS.items():
        out.append(Param(field.upper(), "cm/s per poll" if field != "dv_damping" else "fraction",
                         _reader(batch, k, field), _writer(batch, k, field, rope), 0.0,
                         max(GAIN_SPAN * getattr(start, field), 1.0), doc))
    return out


def _reader(batch: Any, k: int, field: str) -> Callable[[], float]:
    return lambda: getattr(batch.params[k], field)


def _writer(batch: Any, k: int, field: str, rope: str) -> Callable[[float], None]:
    def write(value: float) -> None:
        try:
            batch.set_params(k, batch.params[k].replace(**{field: value}))
        except NativeError as exc:
            raise CommandError(f"set {rope}.{field.upper()}: {exc}; nothing changed") from None

    return write
