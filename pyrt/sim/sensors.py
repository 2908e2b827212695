"""Sensor imperfections of the simulated manipulator, each one switchable.

* Encoder quantisation: the counter follows the rope in whole counts the way
  a quadrature counter does (it changes on an edge, so it lags by up to one
  count).  Switched off, the count is the nearest integer (the least error
  an integer register can have).
* Loadcell zero error: each loadcell's true zero differs from the
  database OFFSET by a fixed, seeded amount (N, normal with this spread).
* Loadcell noise: white noise on every conversion (N rms).
* Loadcell non-linearity (000, section 10): the 75 k bias resistor keeps
  the amplifier out of its low-load non-linear regime at the price of about
  0.7 % non-linearity of the whole response (a bow of that fraction of full
  scale at mid-range).  Without the resistor (``bias_resistor=False``) the
  amplifier's low-load region is modelled: below ``knee`` of full scale the
  response falls off quadratically to zero.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Imperfections", "loadcell_response"]


@dataclass(frozen=True)
class Imperfections:
    """Which sensor imperfections the plant applies (see the module text)."""

    encoder_quantisation: bool = True
    loadcell_zero_error: float = 1.0
    loadcell_noise: float = 0.3
    loadcell_nonlinearity: float = 0.007
    bias_resistor: bool = True
    knee: float = 0.02
    seed: int = 0

    @classmethod
    def ideal(cls, seed: int = 0) -> Imperfections:
        """Every imperfection off: sensors read the truth to their resolution."""
        return cls(
            encoder_quantisation=False,
            loadcell_zero_error=0.0,
            loadcell_noise=0.0,
            loadcell_nonlinearity=0.0,
            bias_resistor=True,
            seed=seed,
        )


def loadcell_response(load: float, maxload: float, imp: Imperfections) -> float:
    """What the loadcell electronics report (N) for a true ``load`` (N),
    before zero error and noise."""
    if maxload <= 0:
        return load
    f = load / maxload
    out = load
    if imp.loadcell_nonlinearity:
        fc = 0.0 if f < 0 else (1.0 if f > 1 else f)
        out += imp.loadcell_nonlinearity * maxload * 4.0 * fc * (1.0 - fc)
    if not imp.bias_resistor:
        knee = imp.knee * maxload
        if 0 <= load < knee:
            out -= load - knee * (load / knee) ** 2
    return out
