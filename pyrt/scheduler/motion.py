"""Pluggable motion types (004: "a researcher can plug in a new motion type").

A motion type is a small class: :meth:`MotionType.start` with the robot and
a motion record, :meth:`MotionType.step` every poll, ``done`` when it has
finished, ``stop_reason`` saying why.  Types are registered by name, in
code (:func:`register_motion_type`) or by any installed distribution
through the entry-point group ``pyrt.motion_types``::

    [project.entry-points."pyrt.motion_types"]
    spiral = "mylab.motions:Spiral"

so a new one needs no edit to pyrt.  A type says which robots it drives
(:attr:`MotionType.drives`, or :meth:`MotionType.accepts`); a station offers
the types that drive its robot (:func:`motion_types_for`) and no other, so
one robot's ``motion`` never lists another's.  A :class:`MotionExecutor`, polled in
the loop, takes records from the robot's bounded motion queue in order and
steps one motion at a time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, ClassVar

from pyrt.errors import CommandError

__all__ = [
    "ENTRY_POINT_GROUP",
    "MotionExecutor",
    "MotionRecord",
    "MotionType",
    "get_motion_type",
    "motion_type_names",
    "motion_types_for",
    "register_motion_type",
]

ENTRY_POINT_GROUP = "pyrt.motion_types"


@dataclass(frozen=True)
class MotionRecord:
    """One queued motion: the name of its type and its parameters."""

    type: str
    params: Mapping[str, Any] = field(default_factory=dict)


class MotionType:
    """Base of every motion type.  Subclasses set ``name`` and override the
    methods; they run in the loop thread, once per poll."""

    name: ClassVar[str] = ""
    #: The robot classes this type drives (a station's motion robot is an
    #: instance of one of them); empty: none, unless :meth:`accepts` says more.
    drives: ClassVar[tuple[type, ...]] = ()

    @classmethod
    def accepts(cls, robot: Any) -> bool:
        """Whether this type drives ``robot`` (default: it is one of :attr:`drives`)."""
        return bool(cls.drives) and isinstance(robot, cls.drives)

    def __init__(self) -> None:
        self.done = False
        self.stop_reason: str | None = None

    @classmethod
    def check(cls, robot: Any, params: Mapping[str, Any]) -> None:
        """Refuse now, when it is queued (CommandError), a record that could
        never start on ``robot``; nothing by default."""

    def start(self, robot: Any, record: MotionRecord, now_ns: int) -> None:
        """Begin the motion (validate ``record.params``; raise CommandError to refuse)."""

    def step(self, now_ns: int) -> None:
        """Advance the motion by one poll."""

    def stop(self, reason: str) -> None:
        """End the motion now (a stop condition, a reflex, a user ``stop``)."""
        self.done = True
        if self.stop_reason is None:
            self.stop_reason = reason


_registry: dict[str, type[MotionType]] = {}
_broken: dict[str, str] = {}
_loaded_entry_points = False


def register_motion_type(name: str, cls: type[MotionType], *, replace: bool = False) -> None:
    """Make ``cls`` available as motion type ``name`` (case-insensitive)."""
    key = name.lower()
    if not key.isidentifier():
        raise ValueError(f"motion type name must be an identifier, got {name!r}")
    if not (isinstance(cls, type) and issubclass(cls, MotionType)):
        raise TypeError(f"{cls!r} is not a MotionType subclass")
    if key in _registry and _registry[key] is not cls and not replace:
        raise ValueError(f"motion type {name!r} is already registered ({_registry[key]!r})")
    _registry[key] = cls


def _load_entry_points() -> None:
    global _loaded_entry_points
    _loaded_entry_points = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        key = ep.name.lower()
        if key in _registry:
            continue
        try:
            cls = ep.load()
            register_motion_type(ep.name, cls)
        except Exception as exc:  # a broken plug-in must not break pyrt
            _broken[key] = f"{ep.value}: {type(exc).__name__}: {exc}"



def reload_entry_points() -> None:
    """Look at the installed distributions' entry points again."""
    _load_entry_points()


def get_motion_type(name: str) -> type[MotionType]:
    """The motion type registered as ``name``, loading entry points on first use."""
    key = name.lower()
    if key not in _registry and not _loaded_entry_points:
        _load_entry_points()
    cls = _registry.get(key)
    if cls is None:
        if key in _broken:
            raise CommandError(f"motion type {name!r} failed to load: {_broken[key]}")
        known = ", ".join(motion_type_names()) or "none"
        raise CommandError(f"unknown motion type {name!r}; known: {known}")
    return cls


def motion_type_names() -> list[str]:
    """Names of every motion type known (built-in and plug-in), sorted."""
    if not _loaded_entry_points:
        _load_entry_points()
    return sorted(_registry)


def motion_types_for(robot: Any) -> dict[str, type[MotionType]]:
    """Every registered type (built-in and plug-in) that drives ``robot``, by name, sorted."""
    return {name: _registry[name] for name in motion_type_names()
            if _registry[name].accepts(robot)}


class _Refused(MotionType):
    """Stands for a record that could not even be started (unknown type)."""


class MotionExecutor:
    """Steps queued motions one at a time for one robot (a loop handler).

    ``take`` returns the next record or None (the runner's ``MotionQueue.get``);
    ``on_done(motion)`` is told when a motion finishes, with its stop reason.
    A record that cannot start (unknown type, ``start`` refusing it) ends at
    once with ``stop_reason`` ``"refused: ..."``; an exception in ``step`` is
    passed to ``on_error(cause, motion)`` (the robot trips: a fault, with its
    reflex action) and ends the motion.  The loop itself never sees either.
    """

    def __init__(
        self,
        robot: Any,
        take: Callable[[], MotionRecord | None],
        on_done: Callable[[MotionType], None] | None = None,
        on_error: Callable[[str, MotionType], None] | None = None,
    ):
        self.robot = robot
        self._take = take
        self._on_done = on_done
        self._on_error = on_error
        self.current: MotionType | None = None
        self.last: MotionType | None = None
        #: The record of the current (or last) motion.
        self.record: MotionRecord | None = None

    @property
    def busy(self) -> bool:
        """True while a motion is running."""
        return self.current is not None

    def poll(self, now_ns: int) -> None:
        """Start the next queued motion if idle; step the current one."""
        if self.current is None:
            record = self._take()
            if record is None:
                return
            self.record = record
            try:
                motion = get_motion_type(record.type)()
            except CommandError as exc:
                refused = _Refused()
                refused.stop(f"refused: {exc}")
                self._finish(refused)
                return
            self.current = motion
            try:
                motion.start(self.robot, record, now_ns)
            except Exception as exc:
                motion.stop(f"refused: {exc}")
                self._finish(motion)
                return
        motion = self.current
        if not motion.done:
            try:
                motion.step(now_ns)
            except Exception as exc:
                cause = f"{type(exc).__name__}: {exc}"
                motion.stop(f"failed: {cause}")
                self._finish(motion)
                if self._on_error is None:
                    raise
                self._on_error(cause, motion)
                return
        if motion.done:
            self._finish(motion)

    def abort(self, reason: str) -> None:
        """Stop the current motion (a reflex action calls this)."""
        if self.current is not None:
            self.current.stop(reason)
            self._finish(self.current)

    def _finish(self, motion: MotionType) -> None:
        self.current = None
        self.last = motion
        if self._on_done is not None:
            self._on_done(motion)
