"""Where a rope bears on the neck ring (000, section 5, ``neckIntersection``).

The one model of ``csrc/neck.h``, shared by the controller's poll kernel,
the simulated world and every Python caller; this module names it for the
robots package (:class:`~pyrt.native.NeckRing`: the ring with its frame and
:meth:`~pyrt.native.NeckRing.contact`; :func:`~pyrt.native.ring_contact`:
the one-call form for a ring given as ``(centre, axis, radius)``).

The PolyAxis uses the contact point as the rope's *effective top* (upper
segment) or *effective bottom* (lower segment): the position finder sees a
rope from the contact with the measured length less the piece beyond it.
The world (csrc/statics.c) and the controller (csrc/polyctl.c) let the same
segments bear (both); ``PolyAxis.ring_segments`` is the one named place a
controller may deliberately know less.
"""

from __future__ import annotations

from pyrt.native import NeckRing, ring_contact

__all__ = ["NeckRing", "ring_contact"]
