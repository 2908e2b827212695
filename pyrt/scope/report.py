"""What a scope is doing, in words (004): its state, the pre-trigger fill, the
trigger, the events the fill did not take, and why no frame is there yet.  A
part of :class:`~pyrt.scope.scope.Scope` (application side: read through the
runner's mailbox, as every method but ``sample``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pyrt.scope.scope import Frame, Trigger
    from pyrt.scope.sources import Source

__all__ = ["ScopeReport"]


class ScopeReport:
    """The scope's state in words (see the module text); a part of ``Scope``."""

    if TYPE_CHECKING:  # the Scope's, read here
        capacity: int
        mode: str
        state: str
        trigger: Trigger | None
        frames: int
        missed: int
        missed_t_ns: int | None
        sample_ns: int | None
        tick_ns: int | None
        error: str | None
        every: int
        _frame: Frame | None
        _names: list[str]
        _sources: list[Source]
        _g: int
        _staged: int
        _arm_g: int
        _trig_g: int | None

    @property
    def pre_samples(self) -> int:
        """Samples of a frame before its trigger point (0 without a trigger)."""
        return round(self.trigger.pre * self.capacity) if self.trigger is not None else 0

    def pre_fill(self) -> float | None:
        """How full the pre-trigger part is, 0..1, while the scope waits for a
        trigger (armed in normal, single or auto mode with a trigger); None otherwise.
        The trigger is armed only when it is full (1.0)."""
        if self.state != "armed" or self.trigger is None:
            return None
        pre = self.pre_samples
        if pre == 0:
            return 1.0
        taken = self._g + self._staged - self._arm_g
        return min(1.0, max(0, taken) / pre)

    def seconds(self, samples: int, every: int | None = None) -> str:
        """``samples`` as loop time (" (3.2 s)") at ``every`` ticks a sample (default:
        the scope's), or "" while neither the tick nor the sample interval is known."""
        if every is None and self.sample_ns is not None:
            dt = self.sample_ns
        elif self.tick_ns is not None:
            dt = self.tick_ns * (self.every if every is None else every)
        else:
            return ""
        return f" ({samples * dt / 1e9:.4g} s)"

    def describe_trigger(self) -> str:
        """The trigger in words: ``encoder falling through -3000``."""
        t = self.trigger
        if t is None:
            return "no trigger"
        return f"{t.channel} {'rising' if t.edge == 'rising' else 'falling'} through {t.level:g}"

    def missed_note(self) -> str:
        """What came during the pre-trigger fill and was not taken ("" if nothing)."""
        if not self.missed:
            return ""
        when = (f" (the last at t={self.missed_t_ns / 1e9:.3f} s)"
                if self.missed_t_ns is not None else "")
        many = "s" if self.missed > 1 else ""
        return (f"{self.missed} trigger event{many} came while the pre-trigger part filled "
                f"and {'were' if many else 'was'} not taken{when}")

    def waiting(self) -> str:
        """What the scope waits for, in one sentence (why no frame is there yet)."""
        state, mode = self.state, self.mode
        if state == "stopped" or (state == "done" and self._frame is None):
            if mode in ("normal", "single"):
                return (f"the scope is stopped ({mode}): 'scope single' or 'scope run' arms "
                        "it; then make the trigger event happen")
            return f"the scope is stopped ({mode}): 'scope run' starts it, then let time pass"
        if state == "rolling":
            return "rolling: samples are there as soon as time passes (wait, sleep)"
        if state == "triggered":
            left = max(0, (self._trig_g or 0) + self.capacity - self.pre_samples - self._g)
            return (f"triggered ({mode}): the frame fills, {left} samples "
                    f"more{self.seconds(left)}")
        fill = self.pre_fill()
        if self.trigger is None:
            return ("armed (auto, no trigger): samples show as they come, as soon as time "
                    "passes (wait, sleep)")
        note = self.missed_note()
        note = f"; {note}" if note else ""
        auto = ", or after one frame length without one" if mode == "auto" else ""
        if fill is not None and fill < 1.0:
            left = self.pre_samples - round(fill * self.pre_samples)
            return (f"armed ({mode}), pre-trigger {fill * 100:.0f} % filled: the trigger arms "
                    f"when it is full, in {left} samples{self.seconds(left)}; then it waits "
                    f"for {self.describe_trigger()}{auto}{note}")
        return (f"armed ({mode}), pre-trigger full: waiting for "
                f"{self.describe_trigger()}{auto}{note}")

    def status(self) -> str:
        """One line: state (and the pre-trigger fill), mode, channels, trigger,
        frames captured, and any trigger events the fill did not take."""
        trig = "none"
        if self.trigger is not None:
            t = self.trigger
            trig = f"{t.channel} {t.edge} {t.level:g} pre {t.pre:g}"
        state = f"{self.state} ({self.mode})"
        fill = self.pre_fill()
        if fill is not None:
            state += (f", pre-trigger {fill * 100:.0f} % filled (the trigger arms when it is "
                      "full)" if fill < 1.0 else ", pre-trigger full")
        chans = ", ".join(f"{n} [{s.units}]" if s.units else n
                          for n, s in zip(self._names, self._sources, strict=True))
        line = (
            f"scope {state}, every {self.every} tick(s), "
            f"{self.capacity} samples{self.seconds(self.capacity)}, channels: {chans or '-'}; "
            f"trigger: {trig}; frames: {self.frames}"
        )
        note = self.missed_note()
        line += f"; {note}" if note else ""
        return line + (f"; {self.error}" if self.error else "")
