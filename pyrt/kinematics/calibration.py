"""Calibration models: a robot's small geometric errors, applied and identified.

A :class:`CalibrationModel` holds corrections to a nominal chain, each a
named number (metres and radians):

* ``offset.JOINT``: added to the joint's offset (the encoder's zero);
* ``base.x`` ... ``base.rz``: a correction of the base, in the world frame
  (``base' = D(base) @ base``: where the robot really stands);
* ``tool.x`` ... ``tool.rz``: a correction of the tool, in the tool frame
  (``tool' = tool @ D(tool)``);
* ``origin.JOINT.x`` ... ``origin.JOINT.rz``: a correction of the joint's
  origin, in the frame it is given in (``origin' = origin @ D(origin.JOINT)``).

``D(x, y, z, rx, ry, rz)`` is the translation (x, y, z) after the rotation
by the rotation vector (rx, ry, rz).  Joints are named, so one model may be
shared by several chains (004's RCM case: two joint sets of one mechanism
whose misalignment couples them): each chain takes the corrections of the
joints it has, and every chain takes the base and the tool.

:meth:`CalibrationModel.apply` makes the calibrated chain with
``Chain.replace``, so forward kinematics, the Jacobian and the numerical
inverse all use the same corrected geometry; a closed form that can be
rebuilt for a base, tool and offsets (``replace(base=, tool=, offsets=)``,
as the PUMA's) is rebuilt, and when joint origins are corrected too it is
followed by a few steps of the numerical inverse on the calibrated chain,
so ``fk(ik(T, cfg)) = T`` holds for the calibrated arm.

:meth:`CalibrationModel.identify` fits the parameters to measured tool poses
at known joint values: Gauss-Newton with a finite-difference Jacobian, its
columns scaled, the steps taken in the well-determined directions only (a
truncated SVD); parameters the measurements cannot tell apart (joint 1's
offset and a base rotation about joint 1's axis, say) are reported and left
where they were.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from pyrt.kinematics.puma import Unreachable

if TYPE_CHECKING:
    from pyrt.kinematics.chain import Chain

__all__ = [
    "AXES",
    "CalibrationModel",
    "Identification",
    "Observation",
    "correction",
    "observations",
    "pose_error",
]

Matrix = npt.NDArray[np.float64]

#: The six numbers of a transform's correction: translation, rotation vector.
AXES = ("x", "y", "z", "rx", "ry", "rz")


def _rotvec_matrix(v: Sequence[float]) -> Matrix:
    x, y, z = (float(a) for a in v)
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-300:
        return np.eye(3)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]) / angle
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def correction(six: Sequence[float]) -> Matrix:
    """``D(x, y, z, rx, ry, rz)``: rotation by the rotation vector, then the translation."""
    t = np.eye(4)
    t[:3, :3] = _rotvec_matrix(six[3:6])
    t[:3, 3] = [float(v) for v in six[:3]]
    return t


def pose_error(measured: Matrix, model: Matrix) -> Matrix:
    """(position of measured - model; rotation vector of measured @ model^T), 6 numbers."""
    out = np.empty(6)
    out[:3] = measured[:3, 3] - model[:3, 3]
    r = measured[:3, :3] @ model[:3, :3].T
    c = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    angle = math.acos(c)
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-6:
        out[3:] = v / 2.0
    elif math.pi - angle < 1e-6:
        w, vecs = np.linalg.eigh((r + r.T) / 2.0)
        axis = vecs[:, int(np.argmax(w))]
        out[3:] = axis * angle
    else:
        out[3:] = v * angle / (2.0 * math.sin(angle))
    return out


@dataclass(frozen=True)
class Observation:
    """One measurement: the chain, its known joint values and the measured tool pose."""

    chain: Chain
    q: Matrix
    pose: Matrix


def observations(chain: Chain, qs: Iterable[npt.ArrayLike],
                 poses: Iterable[npt.ArrayLike]) -> list[Observation]:
    """Pair joint vectors with measured poses for one chain (refuses a mismatch)."""
    qs, poses = list(qs), list(poses)
    if len(qs) != len(poses):
        raise ValueError(f"observations: {len(qs)} joint vectors but {len(poses)} poses")
    out = []
    for i, (q, pose) in enumerate(zip(qs, poses, strict=True)):
        qa = np.array(q, dtype=np.float64)
        pa = np.array(pose, dtype=np.float64)
        if qa.shape != (chain.n,) or not np.all(np.isfinite(qa)):
            raise ValueError(f"observation {i}: expected {chain.n} finite joint values, "
                             f"got shape {qa.shape}")
        if pa.shape != (4, 4) or not np.all(np.isfinite(pa)):
            raise ValueError(f"observation {i}: expected a finite 4x4 pose, got shape {pa.shape}")
        out.append(Observation(chain, qa, pa))
    return out


@dataclass(frozen=True)
class Identification:
    """What a fit found: the parameters fitted (name: value), the residuals
    (root mean square, metres and radians, before and after), the iterations,
    the rank of the fit, and the parameters it could not determine."""

    params: dict[str, float]
    rms_position: float
    rms_rotation: float
    rms_position_before: float
    rms_rotation_before: float
    iterations: int
    rank: int
    unobservable: tuple[str, ...]
    converged: bool


#: How far (rad or m) beyond a limit the nominal arm's joint may be and the
#: calibrated arm's still be tried within it.
_LIMIT_MARGIN = 0.05


class _Refined:
    """A closed form followed by the numerical inverse on the calibrated chain."""

    def __init__(self, nominal: Any, chain: Chain) -> None:
        self._nominal = nominal
        self._chain = chain
        self.configurations: tuple[str, ...] = tuple(nominal.configurations)

    def solve(self, pose: Matrix, config: str) -> Matrix | None:
        """Joint values of the calibrated arm for ``pose`` in ``config``, or None."""
        return self._solve(pose, config)[0]

    def reason(self, pose: Matrix, config: str) -> str | None:
        """Why ``pose`` cannot be reached in ``config`` (None: it can)."""
        return self._solve(pose, config)[1]

    def solve_all(self, pose: Matrix) -> dict[str, Matrix]:
        """Every configuration that reaches ``pose`` within the limits, by name."""
        out = {}
        for cfg in self.configurations:
            q = self.solve(pose, cfg)
            if q is not None:
                out[cfg] = q
        return out

    def _solve(self, pose: Matrix, config: str) -> tuple[Matrix | None, str | None]:
        inverse = getattr(self._nominal, "inverse", None)
        q0: Matrix | None
        nominal_says: str | None = None
        if inverse is not None:
            # the nominal arm's answer, even a little out of its reach, seeds the calibrated one
            try:
                q0 = np.asarray(inverse(pose, config, limits=False), dtype=float)
            except Unreachable as exc:
                nominal_says = str(exc)
                try:
                    q0 = np.asarray(inverse(pose, config, limits=False, nearest=True), dtype=float)
                except Unreachable:
                    return None, nominal_says
        else:
            q0 = self._nominal.solve(pose, config)
            if q0 is None:
                why = getattr(self._nominal, "reason", None)
                return None, (why(pose, config) if why else None) or f"{config}: out of reach"
        seed = self._into_limits(q0)
        lower, upper = self._chain.lower, self._chain.upper
        beyond = np.maximum(lower - seed, seed - upper)
        if np.max(beyond) > _LIMIT_MARGIN:
            # far beyond a limit for the nominal arm: a small correction cannot bring it in
            return None, nominal_says or f"{config}: {self._chain.limit_violation(seed)}"
        res = self._chain.ik(pose, np.clip(seed, lower, upper))
        q = self._into_limits(np.asarray(res.q, dtype=float))
        if not res.ok:
            return None, nominal_says or (
                f"{config}: out of the calibrated arm's reach (the numerical inverse stopped "
                f"{res.residual:.3g} from the pose)")
        if self.config_of(q) != self._nominal.config_of(q0):
            return None, (f"{config}: the calibrated arm reaches the pose only in another "
                          "configuration")
        limit = self._chain.limit_violation(q)
        if limit is not None:
            return None, f"{config}: {limit}"
        return q, None

    def _into_limits(self, q: Matrix) -> Matrix:
        """Each revolute joint out of its limits moved a turn or two, where that brings it in."""
        q = np.array(q, dtype=float)
        lower, upper = self._chain.lower, self._chain.upper
        for i, j in enumerate(self._chain.joints):
            if j.kind != "revolute" or lower[i] <= q[i] <= upper[i]:
                continue
            for k in (-1.0, 1.0, -2.0, 2.0):
                if lower[i] <= q[i] + 2 * np.pi * k <= upper[i]:
                    q[i] += 2 * np.pi * k
                    break
        return q

    def config_of(self, q: Matrix) -> str:
        return str(self._nominal.config_of(q))


class CalibrationModel:
    """Named corrections to nominal chains; see the module doc.

    ``joints`` names the joints the model corrects (those of one chain, or
    of several chains sharing it); ``params`` gives starting values (all
    others are 0).
    """

    def __init__(self, joints: Iterable[str], params: Mapping[str, float] | None = None) -> None:
        names = list(joints)
        if not names or len(set(names)) != len(names):
            raise ValueError(f"a calibration model needs distinct joint names, got {names}")
        self.joints: tuple[str, ...] = tuple(names)
        keys = [f"offset.{j}" for j in names]
        keys += [f"base.{a}" for a in AXES] + [f"tool.{a}" for a in AXES]
        keys += [f"origin.{j}.{a}" for j in names for a in AXES]
        self._values: dict[str, float] = dict.fromkeys(keys, 0.0)
        if params:
            self.update(params)

    @classmethod
    def for_chains(cls, *chains: Chain) -> CalibrationModel:
        """A zero model over the joints of one or more chains (shared joints once)."""
        names: list[str] = []
        for c in chains:
            names += [n for n in c.joint_names if n not in names]
        return cls(names)

    # -- parameters ---------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Every parameter's name, in order."""
        return tuple(self._values)

    @property
    def params(self) -> dict[str, float]:
        """A copy of every parameter (name: value, metres and radians)."""
        return dict(self._values)

    def __getitem__(self, name: str) -> float:
        if name not in self._values:
            raise KeyError(f"calibration model: no parameter {name!r}")
        return self._values[name]

    def update(self, params: Mapping[str, float]) -> None:
        """Set some parameters; an unknown name or a non-finite value changes nothing."""
        new = {}
        for k, v in params.items():
            if k not in self._values:
                raise ValueError(f"calibration model: no parameter {k!r} "
                                 f"(offset.J, base.A, tool.A, origin.J.A with A in {AXES})")
            fv = float(v)
            if not math.isfinite(fv):
                raise ValueError(f"calibration model: {k} = {v!r} is not a finite number")
            new[k] = fv
        self._values.update(new)

    def select(self, free: Iterable[str]) -> list[str]:
        """The parameter names a selection means: a name, or a prefix of names
        (``offsets``, ``base``, ``tool``, ``origins``, ``origin.JOINT``, ``offset.JOINT``)."""
        groups = {"offsets": "offset.", "origins": "origin."}
        out: list[str] = []
        for item in free:
            prefix = groups.get(item, item)
            stem = prefix if prefix.endswith(".") else prefix + "."
            hits = [n for n in self._values if n == prefix or n.startswith(stem)]
            if not hits:
                raise ValueError(f"calibration model: {item!r} names no parameter "
                                 "(offsets, base, tool, origins, or a parameter's name)")
            out += [h for h in hits if h not in out]
        return out

    def _six(self, prefix: str, values: Mapping[str, float]) -> list[float]:
        return [values[f"{prefix}.{a}"] for a in AXES]

    # -- applying -----------------------------------------------------------------
    def apply(self, chain: Chain) -> Chain:
        """The calibrated chain: ``chain`` (nominal) with this model's corrections."""
        return self._apply(chain, self._values)

    def _apply(self, chain: Chain, values: Mapping[str, float], closed_form: bool = True) -> Chain:
        names = chain.joint_names
        unknown = [n for n in names if n not in self.joints]
        if len(unknown) == len(names):
            raise ValueError(f"calibration model: chain {chain.name!r} has none of its joints "
                             f"({', '.join(names)})")
        base = correction(self._six("base", values)) @ chain.base
        tool = chain.tool @ correction(self._six("tool", values))
        offsets = np.array(chain.offsets, dtype=np.float64)
        origins = []
        moved = False
        for i, j in enumerate(chain.joints):
            if j.name in self.joints:
                offsets[i] += values[f"offset.{j.name}"]
                six = self._six(f"origin.{j.name}", values)
                moved = moved or any(v != 0.0 for v in six)
                origins.append(j.origin @ correction(six))
            else:
                origins.append(j.origin)
        changes: dict[str, Any] = {"base": base, "tool": tool, "offsets": offsets}
        if moved:
            changes["origins"] = origins
        cf = chain.closed_form
        if cf is not None and closed_form:
            rebuild = getattr(cf, "replace", None)
            if rebuild is not None:
                cf = rebuild(base=base, tool=tool, offsets=offsets)
            changes["closed_form"] = None
            calibrated = chain.replace(**changes)
            if moved or rebuild is None:
                cf = _Refined(cf, calibrated)
            return calibrated.replace(closed_form=cf)
        changes["closed_form"] = None
        return chain.replace(**changes)

    # -- identification -------------------------------------------------------------
    def identify(
        self,
        data: Sequence[Observation],
        free: Iterable[str] = ("offsets", "base", "tool"),
        *,
        rotation_weight: float = 0.3,
        max_iter: int = 30,
        tol: float = 1e-10,
        rcond: float = 1e-9,
    ) -> Identification:
        """Fit the ``free`` parameters to ``data``; keep the fit in the model.

        The residual of an observation is its :func:`pose_error` (metres; the
        rotation in radians times ``rotation_weight``, metres per radian).
        Each chain is the nominal one (the model is applied to it).  The
        model is changed only when the fit converged; parameters the data
        cannot determine are named in ``unobservable`` and keep their values.
        """
        data = list(data)
        if not data:
            raise ValueError("identify: no observations")
        names = self.select(free)
        if not names:
            raise ValueError("identify: no free parameter")
        if not (math.isfinite(rotation_weight) and rotation_weight >= 0.0):
            raise ValueError(f"identify: rotation_weight {rotation_weight!r} must be >= 0")
        values = dict(self._values)
        x = np.array([values[n] for n in names])
        chains = {id(o.chain): o.chain for o in data}

        def residual(xv: Matrix) -> Matrix:
            vals = dict(values)
            vals.update(zip(names, (float(v) for v in xv), strict=True))
            cal = {k: self._apply(c, vals, closed_form=False) for k, c in chains.items()}
            out = np.empty(6 * len(data))
            for i, o in enumerate(data):
                e = pose_error(o.pose, cal[id(o.chain)].fk(o.q))
                e[3:] *= rotation_weight
                out[6 * i:6 * i + 6] = e
            return out

        def rms(r: Matrix) -> tuple[float, float]:
            rr = r.reshape(-1, 6)
            pos = float(np.sqrt(np.mean(np.sum(rr[:, :3] ** 2, axis=1))))
            rot = rr[:, 3:] / rotation_weight if rotation_weight > 0 else rr[:, 3:] * 0.0
            return pos, float(np.sqrt(np.mean(np.sum(rot**2, axis=1))))

        r = residual(x)
        before = rms(r)
        cost = float(r @ r)
        rank = 0
        null_names: tuple[str, ...] = ()
        converged = False
        iterations = 0
        h = 1e-7
        for iterations in range(1, max_iter + 1):  # noqa: B007 (reported below)
            jac = np.empty((r.size, x.size))
            for k in range(x.size):
                dx = np.zeros_like(x)
                dx[k] = h
                jac[:, k] = (residual(x + dx) - residual(x - dx)) / (2.0 * h)
            scale = np.linalg.norm(jac, axis=0)
            scale[scale == 0.0] = 1.0
            u, s, vt = np.linalg.svd(jac / scale, full_matrices=False)
            keep = s > rcond * s[0] if s.size and s[0] > 0 else np.zeros(s.size, bool)
            rank = int(np.count_nonzero(keep))
            null = vt[~keep]
            null_names = tuple(n for k, n in enumerate(names)
                               if null.size and np.max(np.abs(null[:, k])) > 1e-3)
            step = -(vt[keep].T @ ((u[:, keep].T @ r) / s[keep])) / scale
            t = 1.0
            while True:
                r_new = residual(x + t * step)
                c_new = float(r_new @ r_new)
                if c_new < cost or t < 1e-4:
                    break
                t *= 0.5
            if c_new >= cost:
                # no step lowers the cost: a minimum, to rounding
                converged = True
                break
            x = x + t * step
            gain = cost - c_new
            r, cost = r_new, c_new
            if gain <= tol * cost or math.sqrt(cost / r.size) < 1e-13:
                converged = True
                break
        after = rms(r)
        if converged:
            self._values.update(zip(names, (float(v) for v in x), strict=True))
        return Identification(
            params=dict(zip(names, (float(v) for v in x), strict=True)),
            rms_position=after[0], rms_rotation=after[1],
            rms_position_before=before[0], rms_rotation_before=before[1],
            iterations=iterations, rank=rank, unobservable=null_names, converged=converged,
        )

    def __repr__(self) -> str:
        nonzero = {k: v for k, v in self._values.items() if v != 0.0}
        return f"CalibrationModel({len(self.joints)} joints, {len(nonzero)} non-zero parameters)"
