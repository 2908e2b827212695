"""The PUMA 560, RCCL's arm: its packaged URDF and Paul's closed-form inverse.

The arm is described by ``data/puma560.urdf``, built from the standard
Denavit-Hartenberg table and the dynamic parameters of P. Corke and
B. Armstrong-Helouvry, "A search for consensus among model parameters
reported for the PUMA 560 robot" (ICRA 1994), as the Robotics Toolbox's
``Puma560`` model gives them (:data:`DH` here; the URDF's comments say how
each number went in).

The inverse is Paul's (R. Paul, B. Shimano, G. Mayer, "Kinematic control
equations for simple manipulators", IEEE SMC 11(6), 1981), worked from this
table: the wrist centre (the flange origin, since d5 = d6 = a4 = a5 = 0) gives
joint 1 from the shoulder offset d3, joints 2 and 3 from the planar triangle
shoulder-elbow-wrist, and the wrist's three from R36 = R03^T R, a ZYZ
product.  Its eight solutions are named as RCCL names them, one word of each
pair (:data:`CONFIGURATIONS`, e.g. ``"righty-above-noflip"``):

* ``righty`` / ``lefty``: the wrist centre in front of / behind the plane of
  joint 1's axis that is normal to the upper arm's plane (the horizontal
  reach ``X = a2 c2 + a3 c23 - d4 s23`` is >= 0 / < 0);
* ``above`` / ``below``: the elbow above / below the line from the shoulder
  to the wrist centre;
* ``noflip`` / ``flip``: joint 5 in (-180, 0] / (0, 180) degrees (mod 360).

These are the Robotics Toolbox's ``ikine_a`` configurations (``r``/``l``,
``u``/``d``, ``n``/``f``) for the same table, which keeps Paul's link twists.

:meth:`PaulInverse.config_of` names the configuration of a joint vector, and
``solve(fk(q), config_of(q))`` gives ``q`` back (joint 4 and 6 up to their
sum when joint 5 is 0, the wrist's singularity).  Joint angles come back
within the chain's limits (a multiple of 360 degrees added where that
brings one inside); a configuration that cannot be reached within them is
refused with the joint and the limit named.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from pyrt.native._puma import (
    PUMA_BELOW,
    PUMA_FLIP,
    PUMA_INSIDE_OFFSET,
    PUMA_LEFTY,
    PUMA_LIMIT,
    PUMA_NEAREST,
    PUMA_NO_LIMITS,
    PUMA_REACHED,
    PUMA_SINGULAR,
    PUMA_TOO_FAR,
    PUMA_TOO_NEAR,
    PumaKernel,
    PumaSolver,
)

if TYPE_CHECKING:
    from pyrt.kinematics.chain import Chain

__all__ = [
    "CONFIGURATIONS",
    "DH",
    "LOWER_DEG",
    "UPPER_DEG",
    "URDF",
    "PaulInverse",
    "Unreachable",
    "parse_config",
    "puma560",
    "puma560_dh",
]

Matrix = npt.NDArray[np.float64]

#: The standard DH table of the PUMA 560, one row per joint: (d, a, alpha)
#: in metres and radians, theta the joint variable (Corke & Armstrong-Helouvry
#: 1994; Robotics Toolbox 1.5 ``Puma560``, whose d1 = 26.45 in is the height of
#: the shoulder axis above the mounting surface).
DH: tuple[tuple[float, float, float], ...] = (
    (0.67183, 0.0, math.pi / 2),  # 26.45 in
    (0.0, 0.4318, 0.0),
    (0.15005, 0.0203, -math.pi / 2),
    (0.4318, 0.0, math.pi / 2),
    (0.0, 0.0, -math.pi / 2),
    (0.0, 0.0, 0.0),
)

#: Joint limits (degrees) of the same model (from Wang & Chen 1991).
LOWER_DEG = (-160.0, -45.0, -225.0, -110.0, -100.0, -266.0)
UPPER_DEG = (160.0, 225.0, 45.0, 170.0, 100.0, 266.0)

#: The eight configurations, one word of each of RCCL's pairs.
CONFIGURATIONS: tuple[str, ...] = tuple(
    f"{arm}-{elbow}-{wrist}"
    for arm in ("righty", "lefty")
    for elbow in ("above", "below")
    for wrist in ("noflip", "flip")
)

_PAIRS = (("righty", "lefty"), ("above", "below"), ("noflip", "flip"))
#: Each configuration's bits for the C kernel.
_BITS: dict[str, int] = {
    f"{arm}-{elbow}-{wrist}": (PUMA_LEFTY if arm == "lefty" else 0)
    | (PUMA_BELOW if elbow == "below" else 0) | (PUMA_FLIP if wrist == "flip" else 0)
    for arm in ("righty", "lefty") for elbow in ("above", "below") for wrist in ("noflip", "flip")
}

#: Joint vectors at which a chain's forward kinematics is compared with the table's.
_PROBES = (np.zeros(6), np.array([0.3, -0.7, 1.1, -0.4, 0.9, 2.0]),
           np.array([-2.0, 1.3, -2.5, 1.7, -1.2, -0.6]))

#: The packaged URDF (a path inside the installed package).
URDF: Path = Path(str(resources.files("pyrt.kinematics") / "data" / "puma560.urdf"))


class Unreachable(ValueError):
    """A pose the arm cannot take in the configuration asked for; says why."""


def parse_config(config: str) -> str:
    """The canonical name of a configuration: one word of each pair, any order.

    Words may be separated by ``-``, ``,``, ``/`` or spaces and are not case
    sensitive (``"flip lefty above"`` is ``"lefty-above-flip"``).
    """
    if not isinstance(config, str):
        raise ValueError(
            f"a configuration is a string such as 'righty-above-noflip', got {config!r}"
        )
    words = config.lower().replace(",", " ").replace("/", " ").replace("-", " ").split()
    picked = []
    for pair in _PAIRS:
        hit = [w for w in words if w in pair]
        if len(hit) != 1:
            raise ValueError(
                f"configuration {config!r}: give exactly one of {pair[0]}/{pair[1]} "
                f"(e.g. {CONFIGURATIONS[0]!r})"
            )
        picked.append(hit[0])
    extra = [w for w in words if all(w not in pair for pair in _PAIRS)]
    if extra or len(words) != 3:
        raise ValueError(
            f"configuration {config!r}: unknown word(s) {extra or words}; "
            f"one of each pair: righty/lefty, above/below, noflip/flip"
        )
    return "-".join(picked)


def _rigid(value: npt.ArrayLike | None, what: str) -> Matrix:
    m = np.eye(4) if value is None else np.array(value, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"{what}: expected a finite 4x4 transform, got shape {m.shape}")
    return m


def _inv(t: Matrix) -> Matrix:
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


class PaulInverse:
    """Paul's closed-form inverse of the PUMA 560, with RCCL's configuration names.

    ``base`` and ``tool`` are the chain's (the pose solved for is
    ``base @ A1 ... A6 @ tool``), ``offsets`` are added to the joint values
    before the DH table (``theta = q + offset``), ``lower`` and ``upper``
    bound q (radians; None: no limits).  The geometry is :data:`DH` unless
    ``dh`` gives another table of the same shape (the same zeros and twists).
    """

    configurations: tuple[str, ...] = CONFIGURATIONS

    def __init__(
        self,
        *,
        base: npt.ArrayLike | None = None,
        tool: npt.ArrayLike | None = None,
        offsets: npt.ArrayLike | None = None,
        lower: npt.ArrayLike | None = None,
        upper: npt.ArrayLike | None = None,
        dh: Sequence[tuple[float, float, float]] = DH,
    ) -> None:
        self.base = _rigid(base, "base")
        self.tool = _rigid(tool, "tool")
        self._base_inv = _inv(self.base)
        self._tool_inv = _inv(self.tool)
        self.offsets = np.zeros(6) if offsets is None else np.array(offsets, dtype=np.float64)
        if self.offsets.shape != (6,):
            raise ValueError(f"offsets: expected 6 values, got {self.offsets.shape}")
        if (lower is None) != (upper is None):
            raise ValueError("lower and upper limits go together")
        self.lower = None if lower is None else np.array(lower, dtype=np.float64)
        self.upper = None if upper is None else np.array(upper, dtype=np.float64)
        if len(dh) != 6 or any(len(r) != 3 for r in dh):
            raise ValueError("dh: expected six rows of (d, a, alpha)")
        dh = tuple((float(r[0]), float(r[1]), float(r[2])) for r in dh)
        shape_ok = all(
            abs(dh[i][2] - DH[i][2]) < 1e-12 for i in range(6)
        ) and dh[1][0] == 0.0 and all(dh[i][1] == 0.0 for i in (0, 3, 4, 5)) and all(
            dh[i][0] == 0.0 for i in (4, 5)
        )
        if not shape_ok:
            raise ValueError(
                "dh: Paul's inverse needs the PUMA's twists and zeros (a spherical wrist)"
            )
        self.dh = dh
        self._d1, self._a2, self._a3 = dh[0][0], dh[1][1], dh[2][1]
        self._d3, self._d4 = dh[2][0], dh[3][0]
        self._lower = np.full(6, -np.inf) if self.lower is None else self.lower
        self._upper = np.full(6, np.inf) if self.upper is None else self.upper
        self._kernel = PumaKernel((self._d1, self._a2, self._a3, self._d3, self._d4),
                                  self._base_inv, self._tool_inv, self.offsets,
                                  self._lower, self._upper)

    @classmethod
    def for_chain(cls, chain: Chain) -> PaulInverse:
        """The inverse for ``chain``'s base, tool, offsets and limits.

        Refuses (ValueError) a chain whose forward kinematics is not this
        table's: the chain and the inverse must describe one arm.
        """
        if chain.n != 6:
            raise ValueError(f"chain {chain.name!r} has {chain.n} joints; Paul's inverse needs 6")
        inv = cls(base=chain.base, tool=chain.tool, offsets=chain.offsets,
                  lower=chain.lower, upper=chain.upper)
        for probe in _PROBES:
            gap = float(np.max(np.abs(chain.fk(probe) - inv.fk(probe))))
            if gap > 1e-9:
                raise ValueError(
                    f"chain {chain.name!r} is not the arm of this DH table: its pose differs "
                    f"by {gap:.3g} at q = {np.round(probe, 3).tolist()}"
                )
        return inv

    def replace(self, **changes: Any) -> PaulInverse:
        """A copy with some of base, tool, offsets, lower, upper or dh changed."""
        kw: dict[str, Any] = {
            "base": self.base, "tool": self.tool, "offsets": self.offsets,
            "lower": self.lower, "upper": self.upper, "dh": self.dh,
        }
        unknown = set(changes) - set(kw)
        if unknown:
            raise TypeError(f"PaulInverse.replace: unknown field(s) {sorted(unknown)}")
        kw.update(changes)
        return PaulInverse(**kw)

    # -- forward (the DH product; the reference the inverse is checked against) ------
    def fk(self, q: npt.ArrayLike) -> Matrix:
        """The pose ``base @ A1(q1 + o1) ... A6(q6 + o6) @ tool``."""
        theta = np.asarray(q, dtype=np.float64) + self.offsets
        t = self.base.copy()
        for (d, a, alpha), th in zip(self.dh, theta, strict=True):
            ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(alpha), math.sin(alpha)
            t = t @ np.array([
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ])
        return t @ self.tool

    # -- the configuration of a joint vector --------------------------------------------
    def config_of(self, q: npt.ArrayLike) -> str:
        """The configuration (e.g. ``"righty-above-noflip"``) the joint vector is in."""
        th = np.asarray(q, dtype=np.float64) + self.offsets
        if th.shape != (6,) or not np.all(np.isfinite(th)):
            raise ValueError(f"config_of: expected 6 finite joint values, got {q!r}")
        a2, a3, d4 = self._a2, self._a3, self._d4
        c2 = math.cos(th[1])
        c23, s23 = math.cos(th[1] + th[2]), math.sin(th[1] + th[2])
        reach = a2 * c2 + a3 * c23 - d4 * s23
        arm = "righty" if reach >= 0.0 else "lefty"
        # the wrist centre's y in frame 2: < 0 puts a righty elbow above the line
        y2 = a3 * math.sin(th[2]) + d4 * math.cos(th[2])
        above = y2 < 0.0 if arm == "righty" else y2 > 0.0
        # at the wrist's singularity (sin q5 = 0 to rounding) flip and noflip are one
        # (half the kernel's band: a q5 named noflip is never solved as a flipped one)
        wrist = "flip" if math.sin(th[4]) > PUMA_SINGULAR / 2 else "noflip"
        return f"{arm}-{'above' if above else 'below'}-{wrist}"

    # -- the inverse ------------------------------------------------------------------
    def inverse(self, target: npt.ArrayLike, config: str, seed: npt.ArrayLike | None = None,
                *, limits: bool = True, nearest: bool = False) -> Matrix:
        """Joint values putting the tool at ``target`` in ``config``; raises Unreachable.

        With ``seed``, each joint is the 360-degree turn of its angle nearest the
        seed's (within the limits); otherwise the one nearest zero.  ``limits=False``
        returns the kinematic solution in (-180, 180] degrees, ignoring limits.
        ``nearest=True`` answers a wrist centre just out of reach with the arm
        stretched (or folded) towards it, as a seed for a numerical inverse.
        The work is done in C (csrc/puma.c).
        """
        bits = _BITS.get(config)  # type: ignore[arg-type]
        if bits is None:
            config = parse_config(config)
            bits = _BITS[config]
        if not limits:
            bits |= PUMA_NO_LIMITS
        if nearest:
            bits |= PUMA_NEAREST
        q, why, detail = self._kernel.inverse(target, bits, seed)
        if q is None:
            raise Unreachable(self._why(config, why, detail))
        return q

    def _why(self, cfg: str, why: int, detail: float) -> str:
        if why == PUMA_INSIDE_OFFSET:
            return (f"{cfg}: the wrist centre is {detail * 1e3:.1f} mm from joint 1's axis, "
                    f"closer than the shoulder offset {abs(self._d3) * 1e3:.1f} mm")
        if why in (PUMA_TOO_FAR, PUMA_TOO_NEAR):
            arm = math.hypot(self._a3, self._d4)
            near, far = abs(self._a2 - arm), self._a2 + arm
            where = "beyond the arm's reach" if why == PUMA_TOO_FAR else "too close to the shoulder"
            return (f"{cfg}: the wrist centre is {detail * 1e3:.1f} mm from the shoulder, {where} "
                    f"(the arm reaches {near * 1e3:.1f} .. {far * 1e3:.1f} mm)")
        i = why - PUMA_LIMIT
        lo, hi = math.degrees(self._lower[i]), math.degrees(self._upper[i])
        return (f"{cfg}: joint q{i + 1} would be at {math.degrees(detail):.2f} deg, beyond its "
                f"limits {lo:.1f} .. {hi:.1f} deg")

    def solve(self, target: npt.ArrayLike, config: str,
              seed: npt.ArrayLike | None = None) -> Matrix | None:
        """Joint values for ``target`` in ``config``, or None when it cannot be reached."""
        try:
            return self.inverse(target, config, seed)
        except Unreachable:
            return None

    def bits(self, config: str) -> int:
        """The kernel's bits of ``config`` (any spelling :func:`parse_config` takes)."""
        bits = _BITS.get(config)
        return bits if bits is not None else _BITS[parse_config(config)]

    def solver(self) -> PumaSolver:
        """A prepared inverse of its own (:class:`~pyrt.native._puma.PumaSolver`) for a
        caller that solves one pose at a time in one thread (a trajectory tick): its
        pose and seed written in place, the configuration's :meth:`bits` given; the
        same answers as :meth:`solve`."""
        return PumaSolver(self._kernel)

    def solve_many(self, poses: np.ndarray, config: str,
                   seed: npt.ArrayLike) -> tuple[np.ndarray, str | None]:
        """The joint values of ``poses`` (m, 4, 4) in ``config``, each seeded at the
        one before (the first at ``seed``), as :meth:`solve` gives them one by one:
        (the rows reached (k, 6), in order, up to the first pose not reached; why that
        one is not, or None when all were)."""
        poses = np.ascontiguousarray(poses, dtype=np.float64)
        out = np.empty((poses.shape[0], 6))
        s = np.ascontiguousarray(seed, dtype=np.float64)
        k, why, detail = self._kernel.inverse_many(poses, self.bits(config), s, out)
        if why == PUMA_REACHED:
            return out, None
        return out[:k], self._why(parse_config(config), why, detail)

    def reason(self, target: npt.ArrayLike, config: str) -> str | None:
        """Why ``target`` cannot be reached in ``config`` (None: it can)."""
        try:
            self.inverse(target, config)
        except Unreachable as exc:
            return str(exc)
        return None

    def solve_all(self, target: npt.ArrayLike,
                  seed: npt.ArrayLike | None = None) -> dict[str, Matrix]:
        """Every configuration that reaches ``target`` within the limits, by name."""
        out = {}
        for cfg in self.configurations:
            q = self.solve(target, cfg, seed)
            if q is not None:
                out[cfg] = q
        return out

    def __iter__(self) -> Iterator[str]:
        return iter(self.configurations)


def puma560(*, closed_form: bool = True) -> Chain:
    """The PUMA 560 as a chain from the packaged URDF, with Paul's inverse attached."""
    from pyrt.kinematics.chain import Chain

    chain = Chain.from_urdf(URDF)
    if closed_form:
        chain = chain.replace(closed_form=PaulInverse.for_chain(chain))
    return chain


def puma560_dh() -> Chain:
    """The same arm from its DH table (and limits) rather than the URDF; no inertials."""
    from pyrt.kinematics.chain import Chain
    from pyrt.kinematics.dh import DHRow

    rows = [
        DHRow(d=d, a=a, alpha=alpha, lower=math.radians(lo), upper=math.radians(hi))
        for (d, a, alpha), lo, hi in zip(DH, LOWER_DEG, UPPER_DEG, strict=True)
    ]
    return Chain.from_dh(rows, name="puma560")
