"""Frames: RCCL's transforms, terms and position equations.

A **transform** (:class:`Transform`) has a name, a value (a 4x4 homogeneous
rigid transform), a type and an age:

* ``const``: its value never changes (setting it is refused);
* ``varb``: the user changes it; every equation it belongs to sees the new
  value at once (its :attr:`~Transform.version` counts the changes);
* ``hold``: the user changes it, but an equation keeps the value it moves
  with until the end of the path segment; successive values wait in a queue
  (each equation's term keeps three values: the user's, the alternate the
  equation uses, and the old one it had before the last change);
* ``functional``: a function of the sample number gives the value; it is
  evaluated at most once per sample (the **age** is the last sample the
  transform was evaluated at, as 001 has it).

A **position equation** (:class:`PositionEquation`) is a ring of terms, the
canonical one being ``T6 · TOOL = COORD · POS``: the lhs in order, then the
rhs reversed and inverted, whose product around the ring is the identity.
Terms are internal; the user names transforms.  Two functions give the
value of any partial path of the ring (:meth:`PositionEquation.direct` and
:meth:`PositionEquation.inverse`, 001's two solve functions): with the same
term at both ends, they solve the equation for that term
(:meth:`PositionEquation.solve`).  An equation also carries a name, a
termination code, a progress scalar that goes from 0 towards 1 while it is
moved to, and a *reached* event.

Everything here is pure numpy; lengths are whatever unit the user keeps
(pyrt's arms use metres in their chains).  Bad input is a
:class:`FrameError` (a ``ValueError``) and changes nothing.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from enum import StrEnum

import numpy as np
import numpy.typing as npt

__all__ = [
    "RIGID_TOL",
    "FrameError",
    "PositionEquation",
    "Transform",
    "TransformType",
    "check_rigid",
    "inverse",
]

#: How far a rotation may be from orthonormal (max abs of R^T R - I) and the
#: bottom row from (0, 0, 0, 1), and still count as rigid.
RIGID_TOL = 1e-6

Matrix = npt.NDArray[np.float64]


class FrameError(ValueError):
    """A transform or a position equation was given something it cannot take."""


class TransformType(StrEnum):
    """001's four types of transform."""

    CONST = "const"
    VARB = "varb"
    HOLD = "hold"
    FUNCTIONAL = "functional"


def check_rigid(value: npt.ArrayLike, what: str = "transform") -> Matrix:
    """Return ``value`` as a fresh read-only 4x4 float array, or raise FrameError.

    The value must be finite, its rotation orthonormal with determinant +1
    (to :data:`RIGID_TOL`) and its bottom row ``0 0 0 1``.
    """
    try:
        m = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise FrameError(f"{what}: not a 4x4 matrix of numbers ({exc})") from None
    if m.shape != (4, 4):
        raise FrameError(f"{what}: expected a 4x4 homogeneous transform, got shape {m.shape}")
    rows = m.tolist()  # plain floats: the checks below cost a few microseconds
    if not all(math.isfinite(v) for row in rows for v in row):
        raise FrameError(f"{what}: has a non-finite entry")
    bottom = rows[3]
    if max(abs(bottom[0]), abs(bottom[1]), abs(bottom[2]), abs(bottom[3] - 1.0)) > RIGID_TOL:
        raise FrameError(f"{what}: bottom row is {bottom}, expected [0, 0, 0, 1]")
    (a, b, c, _), (d, e, f, _), (g, h, i, _) = rows[0], rows[1], rows[2]
    cols = ((a, d, g), (b, e, h), (c, f, i))
    err = 0.0
    for j in range(3):
        for k in range(j, 3):
            dot = cols[j][0] * cols[k][0] + cols[j][1] * cols[k][1] + cols[j][2] * cols[k][2]
            err = max(err, abs(dot - (1.0 if j == k else 0.0)))
    if err > RIGID_TOL:
        raise FrameError(f"{what}: rotation is not orthonormal (R^T R - I up to {err:.3g})")
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0:
        raise FrameError(f"{what}: rotation is a reflection (determinant -1)")
    m[3] = (0.0, 0.0, 0.0, 1.0)
    m.setflags(write=False)
    return m


def inverse(t: Matrix) -> Matrix:
    """The inverse of a rigid transform (R^T, -R^T p), without a general solve."""
    out = np.empty((4, 4))
    rt = t[:3, :3].T
    out[:3, :3] = rt
    out[:3, 3] = -rt @ t[:3, 3]
    out[3] = (0.0, 0.0, 0.0, 1.0)
    return out


_IDENTITY = np.eye(4)
_IDENTITY.setflags(write=False)


class Transform:
    """A named rigid transform of one of 001's types; pointed to, never pointing.

    Make one with :meth:`const`, :meth:`varb`, :meth:`hold` or
    :meth:`functional`.  :attr:`value` is a read-only array; :meth:`set`
    changes it (refused for ``const`` and ``functional``).
    """

    __slots__ = ("_fn", "_value", "age", "evaluations", "name", "type", "version")

    def __init__(
        self,
        name: str,
        type: TransformType | str,
        value: npt.ArrayLike | None = None,
        function: Callable[[int], npt.ArrayLike] | None = None,
    ) -> None:
        if not isinstance(name, str) or not name.strip():
            raise FrameError(f"a transform needs a name, got {name!r}")
        try:
            kind = TransformType(type)
        except ValueError:
            kinds = ", ".join(t.value for t in TransformType)
            raise FrameError(
                f"transform {name!r}: unknown type {type!r} (one of {kinds})"
            ) from None
        if (function is not None) != (kind is TransformType.FUNCTIONAL):
            raise FrameError(
                f"transform {name!r}: a function is given for, and only for, a functional transform"
            )
        if function is not None and not callable(function):
            raise FrameError(f"transform {name!r}: function {function!r} is not callable")
        self.name = name
        self.type = kind
        self._value = _IDENTITY if value is None else check_rigid(value, f"transform {name!r}")
        self._fn = function
        #: The last sample at which the transform was used (-1: never).
        self.age = -1
        #: How many times the function of a functional transform ran.
        self.evaluations = 0
        #: Counts the changes of the value (set, or a functional's evaluation).
        self.version = 0

    @classmethod
    def const(cls, name: str, value: npt.ArrayLike) -> Transform:
        """A transform whose value never changes."""
        return cls(name, TransformType.CONST, value)

    @classmethod
    def varb(cls, name: str, value: npt.ArrayLike | None = None) -> Transform:
        """A transform the user changes; equations see each change at once."""
        return cls(name, TransformType.VARB, value)

    @classmethod
    def hold(cls, name: str, value: npt.ArrayLike | None = None) -> Transform:
        """A transform whose changes an equation takes at the end of a path segment."""
        return cls(name, TransformType.HOLD, value)

    @classmethod
    def functional(
        cls, name: str, function: Callable[[int], npt.ArrayLike],
        value: npt.ArrayLike | None = None,
    ) -> Transform:
        """A transform computed by ``function(sample)``, at most once per sample."""
        return cls(name, TransformType.FUNCTIONAL, value, function)

    @property
    def value(self) -> Matrix:
        """The current value (read-only 4x4)."""
        return self._value

    def set(self, value: npt.ArrayLike) -> None:
        """Give the transform a new value (``varb`` and ``hold`` only)."""
        if self.type is TransformType.CONST:
            raise FrameError(f"transform {self.name!r} is const: its value cannot change")
        if self.type is TransformType.FUNCTIONAL:
            raise FrameError(
                f"transform {self.name!r} is functional: its function gives its value"
            )
        self._value = check_rigid(value, f"transform {self.name!r}")
        self.version += 1

    def evaluate(self, sample: int) -> Matrix:
        """The value at ``sample``: a functional one runs its function once per sample."""
        if self._fn is not None and self.age != sample:
            got = self._fn(sample)
            self._value = check_rigid(got, f"functional transform {self.name!r} at sample {sample}")
            self.evaluations += 1
            self.version += 1
        self.age = sample
        return self._value

    def __repr__(self) -> str:
        return f"Transform({self.name!r}, {self.type.value})"


class _Term:
    """One element of an equation: a transform, its side, and 001's three values."""

    __slots__ = ("alternate", "lhs", "old", "queue", "seen", "transform")

    def __init__(self, transform: Transform, lhs: bool) -> None:
        self.transform = transform
        self.lhs = lhs
        self.seen = transform.version
        # For a hold term these are distinct arrays; otherwise they follow the user's.
        self.alternate: Matrix = transform.value
        self.old: Matrix = transform.value
        self.queue: deque[Matrix] = deque()

    @property
    def hold(self) -> bool:
        return self.transform.type is TransformType.HOLD

    @property
    def user(self) -> Matrix:
        return self.transform.value

    def refresh(self, sample: int | None) -> None:
        """Take the transform's current value (a hold term queues it instead)."""
        t = self.transform
        if sample is not None:
            t.evaluate(sample)
        if t.version == self.seen:
            return
        self.seen = t.version
        if self.hold:
            self.queue.append(t.value)
        else:
            # varb, const and functional: the three values are the user's one.
            self.alternate = self.old = t.value

    def advance(self) -> bool:
        """End of a path segment: a hold term takes its next queued value."""
        if not self.queue:
            return False
        self.old = self.alternate
        self.alternate = self.queue.popleft()
        return True

    def factor(self) -> Matrix:
        """This term's factor in the ring (lhs: its value; rhs: its inverse)."""
        return self.alternate if self.lhs else inverse(self.alternate)


TermRef = Transform | str


class PositionEquation:
    """001's position equation: a ring of terms ``lhs[0] ... = rhs[0] ...``.

    ``lhs`` must hold the T6 transform (by default the one named ``"T6"``;
    pass ``t6=`` otherwise) and ``rhs`` at least one transform; a transform
    appears at most once.  ``tool`` (default: the lhs term after T6, if any)
    is the term that determines the tool frame on its left; ``pos``
    (default: the last rhs term) is the part between COORD and TOOL and may
    not be functional, since it is solved for.
    """

    def __init__(
        self,
        name: str,
        lhs: Sequence[Transform],
        rhs: Sequence[Transform],
        *,
        t6: Transform | None = None,
        tool: Transform | None = None,
        pos: Transform | None = None,
    ) -> None:
        if not isinstance(name, str) or not name.strip():
            raise FrameError(f"a position equation needs a name, got {name!r}")
        lhs, rhs = list(lhs), list(rhs)
        for t in (*lhs, *rhs):
            if not isinstance(t, Transform):
                raise FrameError(f"equation {name!r}: {t!r} is not a Transform")
        if not rhs:
            raise FrameError(f"equation {name!r}: the rhs needs at least one term")
        if t6 is None:
            named = [t for t in lhs if t.name == "T6"]
            if not named:
                raise FrameError(
                    f"equation {name!r}: no T6 term in the lhs (give a transform named 'T6' "
                    "or pass t6=)"
                )
            t6 = named[0]
        elif t6 not in lhs:
            raise FrameError(f"equation {name!r}: T6 ({t6.name!r}) must be a term of the lhs")
        names = [t.name for t in (*lhs, *rhs)]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup or len({id(t) for t in (*lhs, *rhs)}) != len(names):
            raise FrameError(f"equation {name!r}: a transform appears twice ({', '.join(dup)})")
        if t6.type is TransformType.CONST:
            raise FrameError(f"equation {name!r}: T6 cannot be const (the arm moves it)")
        if tool is None:
            i6 = lhs.index(t6)
            tool = lhs[i6 + 1] if i6 + 1 < len(lhs) else None
        elif tool not in lhs or tool is t6:
            raise FrameError(f"equation {name!r}: TOOL ({tool.name!r}) must be an lhs term, not T6")
        if pos is None:
            pos = rhs[-1]
        elif pos not in rhs:
            raise FrameError(f"equation {name!r}: POS ({pos.name!r}) must be an rhs term")
        if pos.type is TransformType.FUNCTIONAL:
            raise FrameError(
                f"equation {name!r}: POS ({pos.name!r}) cannot be functional: it is solved for"
            )
        self.name = name
        # The ring: the lhs in order, then the rhs reversed (each factor inverted).
        self._ring = [_Term(t, True) for t in lhs] + [_Term(t, False) for t in reversed(rhs)]
        self._by_name = {term.transform.name: i for i, term in enumerate(self._ring)}
        self.t6 = t6
        self.tool = tool
        self.pos = pos
        ipos = rhs.index(pos)
        #: The COORD part: the rhs terms before POS; the TOOL part: lhs terms after T6.
        self.coord_part: tuple[Transform, ...] = tuple(rhs[:ipos])
        self.tool_part: tuple[Transform, ...] = tuple(lhs[lhs.index(t6) + 1:])
        #: How the motion that last moved to this equation ended (None: not yet).
        self.code: str | None = None
        self._progress = 0.0
        #: Set when the equation has been moved to (with :attr:`code`).
        self.reached = threading.Event()
        self._listeners: list[Callable[[PositionEquation], None]] = []

    # -- 001's four predicates ------------------------------------------------------
    @property
    def has_coord(self) -> bool:
        """True when the rhs has a COORD part before POS."""
        return bool(self.coord_part)

    @property
    def has_tool(self) -> bool:
        """True when the lhs has a TOOL part after T6."""
        return bool(self.tool_part)

    @property
    def coord_functional(self) -> bool:
        """True when the COORD part moves by itself (a functional term)."""
        return any(t.type is TransformType.FUNCTIONAL for t in self.coord_part)

    @property
    def tool_functional(self) -> bool:
        """True when the TOOL part moves by itself (a functional term)."""
        return any(t.type is TransformType.FUNCTIONAL for t in self.tool_part)

    # -- the terms ------------------------------------------------------------------
    @property
    def transforms(self) -> tuple[Transform, ...]:
        """The transforms in ring order (the lhs, then the rhs reversed)."""
        return tuple(term.transform for term in self._ring)

    def side(self, ref: TermRef) -> str:
        """``"lhs"`` or ``"rhs"``: the member of the equation the term belongs to."""
        return "lhs" if self._ring[self._index(ref)].lhs else "rhs"

    def values(self, ref: TermRef) -> tuple[Matrix, Matrix, Matrix]:
        """The term's three values: (user, alternate, old).  One array unless hold."""
        term = self._ring[self._index(ref)]
        term.refresh(None)
        return term.user, term.alternate, term.old

    def _index(self, ref: TermRef) -> int:
        key = ref.name if isinstance(ref, Transform) else ref
        i = self._by_name.get(key) if isinstance(key, str) else None
        if i is None or (isinstance(ref, Transform) and self._ring[i].transform is not ref):
            known = ", ".join(self._by_name)
            raise FrameError(f"equation {self.name!r}: no term {key!r} (terms: {known})")
        return i

    # -- a sample ---------------------------------------------------------------------
    def evaluate(self, sample: int) -> None:
        """Bring the terms to ``sample``: functionals run (once per sample), varb
        changes are taken, hold changes are queued."""
        for term in self._ring:
            term.refresh(sample)

    def end_segment(self) -> list[str]:
        """End of a path segment: each hold term takes its next queued value.

        Returns the names of the transforms whose value changed.
        """
        for term in self._ring:
            term.refresh(None)
        return [term.transform.name for term in self._ring if term.advance()]

    # -- 001's two solve functions ------------------------------------------------------
    def direct(self, a: TermRef, b: TermRef, sample: int | None = None) -> Matrix:
        """The value of the partial path from term ``a`` to term ``b``.

        The product of the ring's factors strictly between ``a`` and ``b``,
        going forward round the ring (the lhs in order, then the rhs reversed
        and inverted): the transform from the frame where ``a`` ends to the
        frame where ``b`` begins.  With ``a`` = ``b``: the whole ring but
        ``a``, which is the value of an rhs term ``a`` (and the inverse of an
        lhs one).
        """
        ia, ib = self._index(a), self._index(b)
        for term in self._ring:
            term.refresh(sample)
        n = len(self._ring)
        out = np.eye(4)
        i = (ia + 1) % n
        while i != ib:
            out = out @ self._ring[i].factor()
            i = (i + 1) % n
        if ia == ib and n == 1:
            raise FrameError(f"equation {self.name!r}: a ring of one term has no path")
        return out

    def inverse(self, a: TermRef, b: TermRef, sample: int | None = None) -> Matrix:
        """The inverse of :meth:`direct` (the same path walked the other way)."""
        return inverse(self.direct(a, b, sample))

    def solve(self, ref: TermRef, sample: int | None = None) -> Matrix:
        """The value term ``ref`` must have for the equation to hold, from the others."""
        side = self.side(ref)
        return self.inverse(ref, ref, sample) if side == "lhs" else self.direct(ref, ref, sample)

    def residual(self, sample: int | None = None) -> Matrix:
        """The product round the ring (the identity when the equation holds)."""
        for term in self._ring:
            term.refresh(sample)
        out = np.eye(4)
        for term in self._ring:
            out = out @ term.factor()
        return out

    def lhs_value(self, sample: int | None = None) -> Matrix:
        """The product of the lhs terms."""
        return self._product(True, sample)

    def rhs_value(self, sample: int | None = None) -> Matrix:
        """The product of the rhs terms."""
        return self._product(False, sample)

    def _product(self, lhs: bool, sample: int | None) -> Matrix:
        for term in self._ring:
            term.refresh(sample)
        terms: Iterable[_Term] = [t for t in self._ring if t.lhs == lhs]
        if not lhs:
            terms = reversed(list(terms))
        out = np.eye(4)
        for term in terms:
            out = out @ term.alternate
        return out

    # -- moving to it ---------------------------------------------------------------
    @property
    def progress(self) -> float:
        """0 when the motion to this equation starts, towards 1 while it runs, 1 when reached."""
        return self._progress

    @progress.setter
    def progress(self, value: float) -> None:
        v = float(value)
        if not 0.0 <= v <= 1.0:
            raise FrameError(f"equation {self.name!r}: progress {value!r} is outside 0 .. 1")
        self._progress = v

    def start(self) -> None:
        """A motion towards this equation begins: no code, progress 0, not reached."""
        self.code = None
        self._progress = 0.0
        self.reached.clear()

    def finish(self, code: str) -> None:
        """The motion ended with termination ``code``: progress 1, the event is set."""
        if not isinstance(code, str) or not code:
            raise FrameError(f"equation {self.name!r}: a termination code is a word, got {code!r}")
        self.code = code
        self._progress = 1.0
        self.reached.set()
        for fn in list(self._listeners):
            fn(self)

    def on_reached(self, fn: Callable[[PositionEquation], None]) -> None:
        """Call ``fn(equation)`` each time the equation is reached."""
        self._listeners.append(fn)

    def __repr__(self) -> str:
        lhs = " ".join(t.transform.name for t in self._ring if t.lhs)
        rhs = " ".join(t.transform.name for t in reversed(self._ring) if not t.lhs)
        return f"PositionEquation({self.name!r}: {lhs} = {rhs})"
