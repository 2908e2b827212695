"""Joint sets: a robot's joints partitioned into named kinematic chains.

004: "A robot may consist of multiple joint sets (kinematic chains).  This
is reasonable in cases where the kinematics can be decoupled (e.g.,
spherical wrist, RCM, etc.)".  A :class:`JointSets` is that partition.  The
robot has one joint vector; each :class:`JointSet` owns a contiguous run of
joints along one kinematic path (its ``indices`` into that vector) and has
its own :class:`~pyrt.kinematics.Chain` (fk, Jacobian, inverse), mounted
either on the robot's base or on a joint frame of another set (its
``parent``): a wrist on an arm's last link, each arm of a two-arm torso on
the trunk.

Two ways to describe one:

* :meth:`JointSets.split` cuts a serial chain into runs of joints, e.g. the
  PUMA 560 as ``arm`` (joints 1-3) and ``wrist`` (joints 4-6).  The sets'
  chains compose to the whole: ``arm.fk(q[:3]) @ wrist.fk(q[3:]) ==
  chain.fk(q)``; the first set keeps the chain's base, the last its tool.
* :meth:`JointSets.from_urdf` reads a URDF whose tree branches: each set is
  named with the link it ends at (and, optionally, the link it starts from).
  A set owns the movable joints between its start (default: the deepest tip
  of another set on its path, or the root) and its tip; joints that two
  sets would both own (the trunk of a two-arm torso when both arms are
  named from the root) are refused as ambiguous, naming them and the two
  ways out: a set of their own (``trunk`` ending at the chest link), or one
  set owning them (``right=("chest", "right_tool")``).

Every movable joint is in exactly one set: a description with a joint in
two sets, in none, or a name it does not know raises
:class:`~pyrt.errors.ConfigError` naming what is wrong.

Per set, the world pose of its tip (:meth:`JointSets.fk`), the world frame
it is mounted on (:meth:`JointSets.mount`) and its inverse with the other
sets held (:meth:`JointSets.ik`: the whole pose, or only a point's position,
or only the orientation, as a 3-joint set can do).  :meth:`decoupled_ik`
is the classic split of an arm with a spherical wrist: the wrist centre
from the position set, then the orientation from the wrist set.

A :class:`~pyrt.kinematics.calibration.CalibrationModel` names joints, so
one model may cover (and couple) several sets: :meth:`JointSets.calibrated`
applies it to every set (offsets and origins to the joints each owns, the
base correction to the sets mounted on the base, the tool correction to
the sets nothing is mounted on), and fk and ik of the calibrated sets use
the same corrected geometry.

Everything here runs when a motion is planned (outside the loop): it
allocates its results.  Metres, radians.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from pyrt.errors import ConfigError
from pyrt.kinematics.chain import Chain, IKResult

if TYPE_CHECKING:
    from pyrt.kinematics.calibration import CalibrationModel

__all__ = ["JointSet", "JointSets"]

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]

Task = Literal["pose", "position", "orientation"]

#: Residual (m, rad) the partial inverses stop at, and their iteration bound.
_TOL = 1e-10
_MAX_ITER = 100


def _inv(t: Matrix) -> Matrix:
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def _rotvec(r: Matrix) -> Vector:
    """The rotation vector of a rotation matrix."""
    c = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    angle = math.acos(c)
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-6:
        return v / 2.0
    if math.pi - angle < 1e-6:
        w, vecs = np.linalg.eigh((r + r.T) / 2.0)
        return vecs[:, int(np.argmax(w))] * angle
    return v * angle / (2.0 * math.sin(angle))


def _check_name(name: object, what: str) -> str:
    if not isinstance(name, str) or not name or not name.replace("_", "").isalnum():
        raise ConfigError(f"{what}: a joint set's name is letters, digits and _, got {name!r}")
    return name


@dataclass(frozen=True)
class JointSet:
    """One joint set: its ``name``, its ``chain`` (the set's joints, base to
    tip), its ``indices`` into the robot's joint vector, and where it is
    mounted: ``parent`` (a set's name, or None for the robot's base) and
    ``parent_joint`` (the index, within the parent's chain, of the joint
    whose child frame the chain's base is given in)."""

    name: str
    chain: Chain
    indices: tuple[int, ...]
    parent: str | None = None
    parent_joint: int = -1

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The set's joints' names, base to tip."""
        return self.chain.joint_names

    def __len__(self) -> int:
        return len(self.indices)


class JointSets:
    """A robot's joints partitioned into named joint sets; see the module doc.

    ``sets`` are made by :meth:`split` or :meth:`from_urdf` (or given
    directly: every index 0 .. n-1 in exactly one set, each parent named
    before its children).  Attributes: ``name``, ``n`` (joints in the
    robot), ``joint_names`` (the robot's joint vector), ``names`` (the sets').
    """

    def __init__(self, name: str, sets: Iterable[JointSet]) -> None:
        self.name = str(name)
        self._sets: dict[str, JointSet] = {}
        for s in sets:
            _check_name(s.name, f"robot {self.name!r}")
            if s.name in self._sets:
                raise ConfigError(f"robot {self.name!r}: joint set {s.name!r} is named twice")
            if len(s.indices) != s.chain.n:
                raise ConfigError(f"joint set {s.name!r}: {len(s.indices)} indices for "
                                  f"{s.chain.n} joints")
            if s.parent is not None:
                if s.parent not in self._sets:
                    raise ConfigError(f"joint set {s.name!r}: its parent {s.parent!r} is not a "
                                      f"joint set named before it")
                if not 0 <= s.parent_joint < self._sets[s.parent].chain.n:
                    raise ConfigError(f"joint set {s.name!r}: parent joint {s.parent_joint} is "
                                      f"not a joint of set {s.parent!r}")
            self._sets[s.name] = s
        if not self._sets:
            raise ConfigError(f"robot {self.name!r}: no joint set")
        owner: dict[int, str] = {}
        for s in self._sets.values():
            for i in s.indices:
                if i in owner:
                    raise ConfigError(f"robot {self.name!r}: joint {i + 1} is in joint sets "
                                      f"{owner[i]!r} and {s.name!r}; a joint belongs to one set")
                owner[i] = s.name
        self.n = len(owner)
        missing = [i + 1 for i in range(self.n) if i not in owner]
        if missing or max(owner) != self.n - 1:
            raise ConfigError(f"robot {self.name!r}: the sets' indices must cover joints 1 .. "
                              f"{len(owner)} once each; missing {missing or sorted(owner)}")
        names: list[str] = [""] * self.n
        for s in self._sets.values():
            for i, jn in zip(s.indices, s.chain.joint_names, strict=True):
                names[i] = jn
        dup = sorted({x for x in names if names.count(x) > 1})
        if dup:
            raise ConfigError(f"robot {self.name!r}: joint names used twice: {dup}")
        self.joint_names: tuple[str, ...] = tuple(names)
        self._owner = owner
        self._children = {s.name: [c.name for c in self._sets.values() if c.parent == s.name]
                          for s in self._sets.values()}

    # ------------------------------------------------------------ constructors

    @classmethod
    def split(cls, chain: Chain, sets: Mapping[str, Sequence[int | str]]) -> JointSets:
        """A serial *chain* cut into named runs of joints.

        *sets* maps each set's name to its joints, as joint names or 0-based
        indices into the chain, e.g. ``{"arm": [0, 1, 2], "wrist": [3, 4, 5]}``.
        Each run must be contiguous; together they cover every joint once.
        """
        if not sets:
            raise ConfigError(f"chain {chain.name!r}: no joint set given")
        index = {jn: i for i, jn in enumerate(chain.joint_names)}
        owner: dict[int, str] = {}
        runs: list[tuple[int, str, list[int]]] = []
        for sname, members in sets.items():
            _check_name(sname, f"chain {chain.name!r}")
            if isinstance(members, str | int):
                members = [members]
            idx: list[int] = []
            for m in members:
                if isinstance(m, bool):
                    m = str(m)
                if isinstance(m, int | np.integer):
                    if not 0 <= int(m) < chain.n:
                        raise ConfigError(f"joint set {sname!r}: joint index {m} is not one of "
                                          f"0 .. {chain.n - 1} (chain {chain.name!r})")
                    i = int(m)
                elif isinstance(m, str) and m in index:
                    i = index[m]
                else:
                    raise ConfigError(f"joint set {sname!r}: {m!r} is not a joint of chain "
                                      f"{chain.name!r} ({', '.join(chain.joint_names)})")
                if i in owner:
                    raise ConfigError(f"joint {chain.joint_names[i]!r} is in joint sets "
                                      f"{owner[i]!r} and {sname!r}; a joint belongs to one set")
                owner[i] = sname
                idx.append(i)
            if not idx:
                raise ConfigError(f"joint set {sname!r}: no joint")
            idx.sort()
            if idx != list(range(idx[0], idx[-1] + 1)):
                raise ConfigError(f"joint set {sname!r}: joints "
                                  f"{', '.join(chain.joint_names[i] for i in idx)} are not a "
                                  f"contiguous run of chain {chain.name!r} (a set is a "
                                  f"kinematic chain)")
            runs.append((idx[0], sname, idx))
        none = [chain.joint_names[i] for i in range(chain.n) if i not in owner]
        if none:
            raise ConfigError(f"chain {chain.name!r}: joint(s) {', '.join(none)} in no joint set")
        runs.sort()
        out: list[JointSet] = []
        for k, (_first, sname, idx) in enumerate(runs):
            root, leaf = k == 0, k == len(runs) - 1
            sub = Chain(f"{chain.name}.{sname}", [chain.joints[i] for i in idx],
                        base=chain.base if root else None, tool=chain.tool if leaf else None,
                        offsets=chain.offsets[idx])
            parent = None if root else runs[k - 1][1]
            pj = -1 if root else len(runs[k - 1][2]) - 1
            out.append(JointSet(sname, sub, tuple(idx), parent, pj))
        return cls(chain.name, out)

    @classmethod
    def from_urdf(cls, source: str | PathLike[str],
                  sets: Mapping[str, str | tuple[str, str]] | None = None) -> JointSets:
        """The joint sets of a URDF (its text or a path).

        *sets* maps each set's name to its tip link, or to ``(start_link,
        tip_link)``; default: one set per tip link, named after it.  See
        the module doc for who owns which joint.
        """
        from pyrt.kinematics.urdf import _source, _tree, read_urdf

        text, where = _source(source)
        try:
            tree = _tree(text, where)  # checked: one root, no cycle; names file and line
        except ValueError as exc:
            raise ConfigError(f"unusable values: {exc}", where) from None
        rname, root, links = tree.name, tree.root, tree.links
        # child link -> (parent link, joint, movable)
        parent_of = {c: (p, el.attrib["name"], el.attrib["type"] != "fixed")
                     for c, (p, el) in tree.parent_of.items()}
        child_of = {j: ln for ln, (_, j, _) in parent_of.items()}

        def movable_to(link: str) -> tuple[str, ...]:
            """The movable joints from the root down to *link*."""
            out = []
            while link != root:
                p, j, mv = parent_of[link]
                if mv:
                    out.append(j)
                link = p
            return tuple(out[::-1])

        if sets is None:
            # one set per leaf whose movable joints do not just lead on to another's
            # (a camera fixed to the trunk ends no set of its own)
            paths = {ln: movable_to(ln) for ln in links if ln not in tree.children_of}
            ends: dict[tuple[str, ...], str] = {}
            for ln, path in paths.items():
                if not path or any(len(o) > len(path) and o[:len(path)] == path
                                   for o in paths.values()):
                    continue
                if path in ends:
                    raise ConfigError(f"robot {rname!r}: links {ends[path]!r} and {ln!r} end "
                                      f"the same joints: name the joint sets "
                                      f"(sets={{NAME: TIP_LINK, ...}})", where)
                ends[path] = ln
            # named after the tip link (a character a set's name cannot have made _)
            sets = {"".join(c if c.isalnum() else "_" for c in ln): ln for ln in ends.values()}
        if not sets:
            raise ConfigError(f"robot {rname!r}: no joint set given", where)

        def path_to(link: str) -> list[str]:
            """Links from the root down to *link*."""
            out = [link]
            while out[-1] != root:
                out.append(parent_of[out[-1]][0])
            return out[::-1]

        def movable_below(top: str, link: str) -> list[str]:
            """The movable joints from link *top* down to *link*."""
            p = path_to(link)
            return [parent_of[ln][1] for ln in p[p.index(top) + 1:] if parent_of[ln][2]]

        spec: dict[str, tuple[str | None, str]] = {}
        for sname, value in sets.items():
            _check_name(sname, where)
            start: str | None
            if isinstance(value, str):
                start, tip = None, value
            elif isinstance(value, tuple | list) and len(value) == 2 and all(
                    isinstance(v, str) for v in value):
                start, tip = value
            else:
                raise ConfigError(f"joint set {sname!r}: expected a tip link or (start link, "
                                  f"tip link), got {value!r}", where)
            for end in (start, tip):
                if end is not None and end not in links:
                    raise ConfigError(f"joint set {sname!r}: link {end!r} is not a link of "
                                      f"robot {rname!r}", where)
            if start is not None and start not in path_to(tip):
                raise ConfigError(f"joint set {sname!r}: link {tip!r} is not below link "
                                  f"{start!r}", where)
            spec[sname] = (start, tip)
        # each set's start: given, or the deepest other set's tip on its path, or the root
        tips = {tip: s for s, (_, tip) in spec.items()}
        starts: dict[str, str] = {}
        owns: dict[str, list[str]] = {}
        for sname, (start, tip) in spec.items():
            if start is None:
                start = root
                for ln in path_to(tip)[:-1]:
                    if tips.get(ln, sname) != sname:
                        start = ln
            starts[sname] = start
            owns[sname] = movable_below(start, tip)
            if not owns[sname]:
                raise ConfigError(f"joint set {sname!r}: no movable joint between links "
                                  f"{start!r} and {tip!r}", where)
        owner: dict[str, str] = {}
        for sname, joints in owns.items():
            for jn in joints:
                if jn not in owner:
                    owner[jn] = sname
                    continue
                other = owner[jn]
                shared = [j for j in owns[other] if j in joints]
                cut = child_of[shared[-1]]
                raise ConfigError(
                    f"joint sets {other!r} and {sname!r} would both own joint(s) "
                    f"{', '.join(shared)}: ambiguous.  Give them a set of their own (one "
                    f"ending at link {cut!r}), or let one set own them by starting the other "
                    f"at {cut!r} ({sname}=({cut!r}, {spec[sname][1]!r}))", where)
        none = sorted(j for _, j, mv in parent_of.values() if mv and j not in owner)
        if none:
            raise ConfigError(f"robot {rname!r}: joint(s) {', '.join(none)} in no joint set "
                              f"(name a set that ends below them)", where)
        # each set's parent owns the last movable joint above its start; parents first
        mount: dict[str, str | None] = {}
        for sname in spec:
            above = movable_below(root, starts[sname])
            mount[sname] = above[-1] if above else None
        order: list[str] = []
        while len(order) < len(spec):
            for sname in spec:
                j = mount[sname]
                if sname not in order and (j is None or owner[j] in order):
                    order.append(sname)
        out: list[JointSet] = []
        offset = 0
        for sname in order:
            j = mount[sname]
            if j is None:
                parent, pj = None, -1
                u = read_urdf(source, base_link=root, tip_link=spec[sname][1])
            else:
                parent = owner[j]
                pj = next(s for s in out if s.name == parent).chain.joint_names.index(j)
                # from the link that joint moves: the fixed joints after it folded in
                u = read_urdf(source, base_link=child_of[j], tip_link=spec[sname][1])
            sub = Chain(f"{rname}.{sname}", u.joints, tool=u.tool)
            out.append(JointSet(sname, sub, tuple(range(offset, offset + sub.n)), parent, pj))
            offset += sub.n
        return cls(rname, out)

    # ------------------------------------------------------------ description

    @property
    def names(self) -> tuple[str, ...]:
        """The sets' names, parents before children."""
        return tuple(self._sets)

    def __getitem__(self, name: str) -> JointSet:
        try:
            return self._sets[name]
        except KeyError:
            raise ConfigError(f"robot {self.name!r} has no joint set {name!r} (its sets: "
                              f"{', '.join(self._sets)})") from None

    def __iter__(self) -> Iterator[JointSet]:
        return iter(self._sets.values())

    def __len__(self) -> int:
        return len(self._sets)

    def __contains__(self, name: object) -> bool:
        return name in self._sets

    def indices(self, names: Iterable[str] | str) -> tuple[int, ...]:
        """The joint-vector indices of one or more sets, ascending; an unknown
        name raises ConfigError naming it and the sets there are."""
        if isinstance(names, str):
            names = [names]
        idx: set[int] = set()
        for nm in names:
            idx.update(self[nm].indices)
        return tuple(sorted(idx))

    def owner(self, joint: int | str) -> str:
        """The set that owns a joint (its 0-based index or its name)."""
        if isinstance(joint, str) and joint in self.joint_names:
            return self._owner[self.joint_names.index(joint)]
        if isinstance(joint, int) and not isinstance(joint, bool) and joint in self._owner:
            return self._owner[joint]
        raise ConfigError(f"robot {self.name!r} has no joint {joint!r}")

    @property
    def lower(self) -> Vector:
        """The robot's lower joint limits (n,)."""
        out = np.empty(self.n)
        for s in self:
            out[list(s.indices)] = s.chain.lower
        return out

    @property
    def upper(self) -> Vector:
        """The robot's upper joint limits (n,)."""
        out = np.empty(self.n)
        for s in self:
            out[list(s.indices)] = s.chain.upper
        return out

    def __repr__(self) -> str:
        return f"JointSets({self.name!r}: {', '.join(self._ranges(s) for s in self)})"

    @staticmethod
    def _ranges(s: JointSet) -> str:
        """``arm=1-3``: a set and its joints, counted from 1."""
        runs: list[list[int]] = []
        for i in sorted(s.indices):
            if runs and i == runs[-1][1] + 1:
                runs[-1][1] = i
            else:
                runs.append([i, i])
        return s.name + "=" + ",".join(f"{a + 1}" if a == b else f"{a + 1}-{b + 1}"
                                       for a, b in runs)

    # ------------------------------------------------------------ kinematics

    def _q(self, q: npt.ArrayLike) -> Vector:
        qa = np.asarray(q, dtype=float)
        if qa.shape != (self.n,):
            raise ValueError(f"robot {self.name!r}: expected {self.n} joint values, got shape "
                             f"{qa.shape}")
        return qa

    def mount(self, name: str, q: npt.ArrayLike) -> Matrix:
        """The world frame set *name*'s chain is given in (its chain's base is
        relative to it) at robot joint values *q*: the identity for a set on
        the robot's base, else a joint frame of its parent."""
        s = self[name]
        qa = self._q(q)
        if s.parent is None:
            return np.eye(4)
        p = self._sets[s.parent]
        frames = p.chain.frames(qa[list(p.indices)])
        return self.mount(p.name, qa) @ frames[s.parent_joint + 1]

    def fk(self, name: str, q: npt.ArrayLike) -> Matrix:
        """World pose (4, 4) of set *name*'s tip at robot joint values *q*."""
        s = self[name]
        qa = self._q(q)
        return self.mount(name, qa) @ s.chain.fk(qa[list(s.indices)])

    def ik(self, name: str, target: npt.ArrayLike, seed: npt.ArrayLike, *,
           task: Task = "pose", point: npt.ArrayLike | None = None,
           tol: float = _TOL, max_iter: int = _MAX_ITER) -> IKResult:
        """Robot joint values that put set *name*'s tip at *target*, moving
        only that set's joints (the others held at *seed*'s values).

        ``task="pose"``: *target* is a world pose (the chain's numerical
        inverse).  ``"position"``: *target* is a world point (3,) for
        *point* (3,), given in the set's tip frame (default its origin).
        ``"orientation"``: *target* is a world rotation (3, 3) or pose.
        The partial tasks are damped least squares on the matching rows of
        the Jacobian, each step clamped to the joint limits.  The answer's
        ``q`` is the whole joint vector; ``ok`` is False when the residual
        did not reach *tol* (``q`` is then the best point met).
        """
        s = self[name]
        qs = np.array(self._q(seed), dtype=float)
        idx = list(s.indices)
        m = self.mount(name, qs)
        c = s.chain
        if task == "pose":
            t = np.asarray(target, dtype=float)
            if t.shape != (4, 4):
                raise ValueError(f"ik: a pose target is (4, 4), got shape {t.shape}")
            r = c.ik(_inv(m) @ t, qs[idx], tol=max(tol, 1e-12), max_iter=max_iter)
            qs[idx] = r.q
            return IKResult(qs, r.ok, r.iterations, r.residual)
        if task == "position":
            p = np.asarray(target, dtype=float).reshape(-1)
            if p.shape != (3,):
                raise ValueError(f"ik: a position target is 3 numbers, got shape {p.shape}")
            goal = (_inv(m) @ np.append(p, 1.0))[:3]
            off = np.zeros(3) if point is None else np.asarray(point, dtype=float).reshape(3)
            q, ok, it, res = _dls(c, qs[idx], lambda t6: goal - (t6[:3, :3] @ off + t6[:3, 3]),
                                  lambda t6, jac: jac[:3] - _skew(t6[:3, :3] @ off) @ jac[3:],
                                  tol, max_iter)
        elif task == "orientation":
            rt = np.asarray(target, dtype=float)
            if rt.shape == (4, 4):
                rt = rt[:3, :3]
            if rt.shape != (3, 3):
                raise ValueError(f"ik: an orientation target is (3, 3), got shape {rt.shape}")
            goal_r = m[:3, :3].T @ rt
            q, ok, it, res = _dls(c, qs[idx], lambda t6: _rotvec(goal_r @ t6[:3, :3].T),
                                  lambda t6, jac: jac[3:], tol, max_iter)
        else:
            raise ValueError(f"ik: task is 'pose', 'position' or 'orientation', got {task!r}")
        qs[idx] = q
        return IKResult(qs, ok, it, res)

    def wrist_centre(self, name: str) -> Vector:
        """Where the axes of spherical-wrist set *name* meet, in the frame of
        its tip (its chain's tool frame).  Raises ConfigError when its axes
        do not meet in one point (its joints after the first move the
        frame's origin)."""
        s = self[name]
        c = s.chain
        if c.n < 2 or any(np.linalg.norm(j.origin[:3, 3]) > 1e-12 for j in c.joints[1:]):
            raise ConfigError(f"joint set {name!r} is not a spherical wrist: its joints' axes "
                              f"do not meet in one point")
        return (_inv(c.tool) @ np.array([0.0, 0.0, 0.0, 1.0]))[:3]

    def decoupled_ik(self, target: npt.ArrayLike, seed: npt.ArrayLike, *,
                     position: str = "arm", orientation: str = "wrist",
                     tol: float = 1e-9, max_iter: int = _MAX_ITER) -> IKResult:
        """004's decoupled inverse of an arm with a spherical wrist: the
        wrist centre from set *position* (its tip frame holds the wrist set),
        then the orientation from set *orientation*, each its own small
        inverse seeded at *seed* (to a tenth of *tol*).  ``residual`` is the
        whole pose's error (position and rotation, m and rad); ``ok`` when it
        is <= *tol*."""
        t = np.asarray(target, dtype=float)
        if t.shape != (4, 4):
            raise ValueError(f"decoupled_ik: a pose target is (4, 4), got shape {t.shape}")
        w = self[orientation]
        if w.parent != position or w.parent_joint != self[position].chain.n - 1:
            raise ConfigError(f"decoupled_ik: joint set {orientation!r} is not mounted on the "
                              f"tip of joint set {position!r}")
        centre_tip = self.wrist_centre(orientation)
        centre = (t @ np.append(centre_tip, 1.0))[:3]
        # the centre in the position set's tip frame: the wrist is mounted on its last
        # joint's frame (its chain's base, then its first joint's origin)
        p = self[position].chain
        first = _inv(p.tool) @ w.chain.base @ w.chain.joints[0].origin
        r1 = self.ik(position, centre, seed, task="position", point=first[:3, 3],
                     tol=0.1 * tol, max_iter=max_iter)
        r2 = self.ik(orientation, t, r1.q, task="orientation", tol=0.1 * tol,
                     max_iter=max_iter)
        e_p = float(np.linalg.norm(self.fk(orientation, r2.q)[:3, 3] - t[:3, 3]))
        e_r = float(np.linalg.norm(_rotvec(t[:3, :3] @ self.fk(orientation, r2.q)[:3, :3].T)))
        res = math.hypot(e_p, e_r)
        return IKResult(r2.q, res <= tol, r1.iterations + r2.iterations, res)

    # ------------------------------------------------------------ calibration

    def calibrated(self, model: CalibrationModel) -> JointSets:
        """The sets with *model* applied (see the module doc): one model may
        correct joints of several sets."""
        from pyrt.kinematics.calibration import AXES, correction

        d_base = correction([model[f"base.{a}"] for a in AXES])
        d_tool = correction([model[f"tool.{a}"] for a in AXES])
        out = []
        for s in self:
            c = s.chain
            if set(c.joint_names) & set(model.joints):
                c = model.apply(c)  # offsets and origins (and base and tool, set below)
            # the base correction is the robot's base: only a set mounted on it takes
            # it; the tool correction only a set nothing is mounted on
            base = d_base @ s.chain.base if s.parent is None else s.chain.base
            tool = s.chain.tool @ d_tool if not self._children[s.name] else s.chain.tool
            c = c.replace(base=base, tool=tool)
            out.append(JointSet(s.name, c, s.indices, s.parent, s.parent_joint))
        return JointSets(self.name, out)


def _skew(v: Vector) -> Matrix:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _dls(chain: Chain, q0: Vector, error: Callable[[Matrix], Vector],
         rows: Callable[[Matrix, Matrix], Matrix], tol: float,
         max_iter: int) -> tuple[Vector, bool, int, float]:
    """Levenberg-Marquardt on a partial task: ``error(t6)`` the task's error
    (in the chain's base frame), ``rows(t6, jac)`` its Jacobian; each step
    clamped to the joint limits, taken only when it lowers the error."""
    q = np.clip(np.array(q0, dtype=float), chain.lower, chain.upper)
    t6 = chain.fk(q)
    e = error(t6)
    res = float(np.linalg.norm(e))
    lam = 1e-4
    it = 0
    for it in range(1, max_iter + 1):
        if res <= tol:
            return q, True, it - 1, res
        j = rows(t6, chain.jacobian(q))
        jjt = j @ j.T
        while True:
            dq = j.T @ np.linalg.solve(jjt + lam * np.eye(jjt.shape[0]), e)
            q_new = np.clip(q + dq, chain.lower, chain.upper)
            t6_new = chain.fk(q_new)
            e_new = error(t6_new)
            res_new = float(np.linalg.norm(e_new))
            if res_new < res:
                q, t6, e, res = q_new, t6_new, e_new, res_new
                lam = max(lam * 0.1, 1e-12)
                break
            lam *= 10.0
            if lam > 1e6:  # no step lowers the error: a minimum (or a limit) short of it
                return q, res <= tol, it, res
    return q, res <= tol, it, res
