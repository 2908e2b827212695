"""What a station is asked besides commands: parameters (``get``/``set``) and
motion records; :class:`StationRequests` is that part of
:class:`~pyrt.station.base.Station`.  Parameters are only the components' own
(:meth:`~pyrt.component.Component.params`); a motion record is checked by its
type and by the station (``check_motion``) and queued on the motion queue."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, final

from pyrt.component import Component, Param
from pyrt.errors import CommandError
from pyrt.scheduler.motion import MotionType, motion_types_for

if TYPE_CHECKING:
    from pyrt.errors import Fault
    from pyrt.scheduler.runner import MotionQueue

__all__ = ["StationRequests"]


class StationRequests:
    """Parameters and motion records (see the module text); a part of ``Station``."""

    if TYPE_CHECKING:  # the Station's, used here
        name: str
        root: Component
        motion: MotionQueue

        @property
        def fault(self) -> Fault | None: ...

        def busy(self) -> bool: ...
        def check_motion(self, record: Any) -> None: ...
        def component(self, name: str) -> Component: ...

    # -- parameters (get/set) ---------------------------------------------------------

    @final
    def params_of(self, component: Component) -> list[Param]:
        """The run-time parameters of ``component``: its own, and only its own
        (:meth:`Component.params`); ``get``/``set`` and the server read these."""
        return list(component.params())

    @final
    def param(self, name: str) -> tuple[Component, Param]:
        """``OBJECT.FIELD`` as (component, parameter); CommandError naming what there is."""
        obj, dot, field = name.strip().partition(".")
        comp = self.component(obj)
        params = self.params_of(comp)
        if not dot or not field:
            raise CommandError(f"{name[:60]!r}: give OBJECT.FIELD (get {comp.name} lists "
                               "its parameters)")
        key = field.lower()
        for p in params:
            if p.name.lower() == key:
                return comp, p
        raise CommandError(f"{comp.name} has no parameter {field[:40]!r}; it has "
                           f"{', '.join(p.name for p in params) or 'none'}")

    @final
    def set_param(self, component: Component, param: Param, value: Any) -> str:
        """Change ``param`` of ``component`` to a checked ``value`` (loop thread):
        refused if it is read only, or while a move runs when changing it then
        is unsafe; the line says what changed and whether it is written back."""
        who = f"set {component.name}.{param.name}"
        if param.write is None:
            raise CommandError(f"{who}: read only; nothing changed")
        if not param.safe_while_moving and self.busy():
            raise CommandError(f"{who}: refused while a move runs (changing it then is "
                               "unsafe); stop or wait first; nothing changed")
        old = param.read()
        said = param.write(value)
        new = param.read()
        u = f" {param.units}" if param.units else ""
        back = ("written back" if param.written_back
                else "not written back: lost at exit")
        line = f"{component.name}.{param.name} {param.text(old)} -> {param.text(new)}{u} ({back})"
        return f"{line}; {said}" if isinstance(said, str) and said else line

    @final
    def submit_motion(self, record: Any) -> tuple[int, bool]:
        """Check a motion record and put it on the motion queue (loop thread):
        refused while faulted; a type's ``check(robot, params)`` runs first.
        Returns (records waiting, whether a move was already running)."""
        fault = self.fault
        if fault is not None:
            raise CommandError(f"motion {record.type}: refused: {self.name} is stopped by a "
                               f"fault ({fault.cause}); give 'ack' first; nothing moved")
        cls = self.motion_type(record.type)
        self.check_motion(record)
        cls.check(self.motion_robot(), record.params)
        waiting = self.busy()
        self.motion.put(record)
        return len(self.motion), waiting

    @final
    def motion_types(self) -> dict[str, type[MotionType]]:
        """The motion types this station runs, by name: every registered type
        (built-in and plug-in) that drives :meth:`motion_robot`.  ``motion``
        lists these and queues no other."""
        return motion_types_for(self.motion_robot())

    @final
    def motion_type(self, name: str) -> type[MotionType]:
        """The motion type ``name`` of this station; CommandError naming this
        station's types if it runs none by that name."""
        types = self.motion_types()
        cls = types.get(name.lower())
        if cls is None:
            raise CommandError(f"motion {name[:40]}: not a motion type of {self.name} (it has "
                               f"{', '.join(types) or 'none'}); nothing queued")
        return cls

    @final
    def motion_robot(self) -> Any:
        """The object motion types drive (the root component by default)."""
        return self.root

