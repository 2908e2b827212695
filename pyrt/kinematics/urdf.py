"""Reading a serial chain from a URDF.

The standard library's XML parser (expat, under ``xml.etree``) reads the
file: a URDF's kinematics and inertials are a few elements and attributes,
and the URDF libraries (yourdfpy, urchin) bring meshes, trimesh and lxml
for what a controller does not need.  Expat gives the line of every
element, so each complaint names the file and line.

Read: ``<robot name>``; ``<link name>`` with ``<inertial>`` (``<origin
xyz rpy>``, ``<mass value>``, ``<inertia ixx ixy ixz iyy iyz izz>``);
``<joint name type>`` of type revolute, continuous (revolute without
limits), prismatic or fixed, with ``<parent link>``, ``<child link>``,
``<origin xyz rpy>``, ``<axis xyz>`` (default 1 0 0), ``<limit lower upper
effort velocity>`` (required for revolute and prismatic joints, as the
URDF specification has it) and ``<dynamics damping friction>``.  Everything
else (visuals, collisions, materials, transmissions, gazebo, mimic,
safety_controller, calibration) is left alone.

The chain runs from ``base_link`` (default: the root link) to ``tip_link``
(default: the tree's only leaf).  Fixed joints on the way are folded into
the next movable joint's origin, or into the tool after the last one; each
link's inertial, with those of the links fixed to it (on the path or
hanging off it), is moved into the child frame of the movable joint that
carries it.  Links before the first movable joint are the base: their mass
is not the arm's.  A floating or planar joint on the path is refused.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from os import PathLike
from xml.parsers import expat

import numpy as np

from pyrt.errors import ConfigError
from pyrt.kinematics.joint import Inertial, Joint, transform

__all__ = ["UrdfChain", "read_urdf"]

_MOVABLE = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic"}
_KNOWN = {*_MOVABLE, "fixed", "floating", "planar"}


@dataclass
class _Element:
    tag: str
    attrib: dict[str, str]
    line: int
    children: list[_Element] = field(default_factory=list)

    def find(self, tag: str) -> _Element | None:
        return next((c for c in self.children if c.tag == tag), None)


@dataclass(frozen=True)
class UrdfChain:
    """What :func:`read_urdf` found: the robot's name, the movable joints
    base to tip, the tool (the fixed transform after the last movable
    joint) and the links it starts and ends at."""

    name: str
    joints: tuple[Joint, ...]
    tool: np.ndarray
    base_link: str
    tip_link: str


def _parse_xml(text: str, where: str) -> _Element:
    parser = expat.ParserCreate()
    stack: list[_Element] = []
    root: list[_Element] = []

    def start(tag: str, attrib: dict[str, str]) -> None:
        el = _Element(tag, attrib, parser.CurrentLineNumber)
        if stack:
            stack[-1].children.append(el)
        else:
            root.append(el)
        stack.append(el)

    def end(tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise ConfigError(f"not well-formed XML: {expat.ErrorString(exc.code)} "
                          f"(column {exc.offset + 1})", where, exc.lineno) from None
    if not root:
        raise ConfigError("no XML element", where)
    return root[0]


class _Reader:
    def __init__(self, where: str):
        self.where = where

    def fail(self, el: _Element, message: str) -> ConfigError:
        return ConfigError(message, self.where, el.line)

    def numbers(self, el: _Element, attr: str, count: int, what: str,
                default: tuple[float, ...] | None = None) -> tuple[float, ...]:
        raw = el.attrib.get(attr)
        if raw is None:
            if default is None:
                raise self.fail(el, f"{what}: <{el.tag}> needs {attr}=")
            return default
        try:
            vals = tuple(float(v) for v in raw.split())
        except ValueError:
            vals = ()
        if len(vals) != count or not all(math.isfinite(v) for v in vals):
            raise self.fail(el, f"{what}: <{el.tag} {attr}=\"{raw}\">: expected {count} finite "
                                f"number{'s' if count > 1 else ''}")
        return vals

    def number(self, el: _Element, attr: str, what: str, default: float | None = None,
               check: Callable[[float], bool] = math.isfinite, expected: str = "a number"
               ) -> float:
        raw = el.attrib.get(attr)
        if raw is None:
            if default is None:
                raise self.fail(el, f"{what}: <{el.tag}> needs {attr}=")
            return default
        try:
            v = float(raw)
        except ValueError:
            v = math.nan
        if not check(v):
            raise self.fail(el, f"{what}: <{el.tag} {attr}=\"{raw}\">: expected {expected}")
        return v

    def origin(self, parent: _Element, what: str) -> np.ndarray:
        el = parent.find("origin")
        if el is None:
            return np.eye(4)
        return transform(self.numbers(el, "xyz", 3, what, (0.0, 0.0, 0.0)),
                         self.numbers(el, "rpy", 3, what, (0.0, 0.0, 0.0)))

    def inertial(self, link: _Element) -> Inertial:
        what = f"link {link.attrib['name']!r} <inertial>"
        el = link.find("inertial")
        if el is None:
            return Inertial()
        mass_el = el.find("mass")
        if mass_el is None:
            raise self.fail(el, f"{what}: needs <mass value=...>")
        mass = self.number(mass_el, "value", what, check=lambda v: math.isfinite(v) and v >= 0,
                           expected="a mass >= 0 kg")
        in_el = el.find("inertia")
        if in_el is None:
            raise self.fail(el, f"{what}: needs <inertia ixx ixy ixz iyy iyz izz>")
        ixx, ixy, ixz, iyy, iyz, izz = (self.number(in_el, k, what) for k in (
            "ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
        pose = self.origin(el, what)
        try:
            body = Inertial(mass, np.zeros(3),
                            np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]))
        except ValueError as exc:
            raise self.fail(in_el, f"{what}: {exc}") from None
        return body.moved(pose)


def _source(source: str | PathLike[str]) -> tuple[str, str]:
    if isinstance(source, PathLike) or (isinstance(source, str) and "<" not in source):
        path = os.fspath(source)
        try:
            with open(path, encoding="utf-8") as fh:
                return fh.read(), path
        except OSError as exc:
            raise ConfigError(f"cannot read the URDF: {exc.strerror}", path) from None
        except UnicodeDecodeError as exc:
            raise ConfigError(f"not UTF-8 text ({exc.reason})", path) from None
    if not isinstance(source, str):
        raise ConfigError(f"a URDF is its text or a path, got {type(source).__name__}")
    return source, "<urdf>"


def read_urdf(source: str | PathLike[str], base_link: str | None = None,
              tip_link: str | None = None) -> UrdfChain:
    """The serial chain from *base_link* to *tip_link* of a URDF (its text,
    or a path).  Raises :class:`~pyrt.errors.ConfigError` naming the file,
    the line and what is wrong."""
    text, where = _source(source)
    try:
        return _read(text, where, base_link, tip_link)
    except ValueError as exc:  # arithmetic on accepted numbers gone out of range
        raise ConfigError(f"unusable values: {exc}", where) from None


@dataclass(frozen=True)
class _Tree:
    """A URDF's robot element and its link tree, checked (one root, no cycle)."""

    name: str
    links: dict[str, _Element]
    joints: dict[str, _Element]
    parent_of: dict[str, tuple[str, _Element]]  # child link -> (parent link, joint)
    children_of: dict[str, list[tuple[str, _Element]]]
    root: str


def _tree(text: str, where: str) -> _Tree:
    rd = _Reader(where)
    robot = _parse_xml(text, where)
    if robot.tag != "robot":
        raise rd.fail(robot, f"the root element is <{robot.tag}>, expected <robot>")
    name = robot.attrib.get("name")
    if not name:
        raise rd.fail(robot, "<robot> needs a name=")

    links: dict[str, _Element] = {}
    for el in robot.children:
        if el.tag == "link":
            lname = el.attrib.get("name")
            if not lname:
                raise rd.fail(el, "<link> needs a name=")
            if lname in links:
                raise rd.fail(el, f"link {lname!r} is defined twice "
                                  f"(first on line {links[lname].line})")
            links[lname] = el
    if not links:
        raise rd.fail(robot, f"robot {name!r} has no <link>")

    joints: dict[str, _Element] = {}
    parent_of: dict[str, tuple[str, _Element]] = {}  # child link -> (parent link, joint)
    children_of: dict[str, list[tuple[str, _Element]]] = {}
    for el in robot.children:
        if el.tag != "joint":
            continue
        jname = el.attrib.get("name")
        if not jname:
            raise rd.fail(el, "<joint> needs a name=")
        if jname in joints:
            raise rd.fail(el, f"joint {jname!r} is defined twice "
                              f"(first on line {joints[jname].line})")
        joints[jname] = el
        jtype = el.attrib.get("type")
        if jtype not in _KNOWN:
            raise rd.fail(el, f"joint {jname!r}: type {jtype!r} is not one of "
                              f"{', '.join(sorted(_KNOWN))}")
        ends = []
        for tag in ("parent", "child"):
            e = el.find(tag)
            if e is None or not e.attrib.get("link"):
                raise rd.fail(el, f"joint {jname!r} needs <{tag} link=...>")
            if e.attrib["link"] not in links:
                raise rd.fail(e, f"joint {jname!r}: {tag} link {e.attrib['link']!r} is not "
                                 f"defined")
            ends.append(e.attrib["link"])
        parent, child = ends
        if child in parent_of:
            raise rd.fail(el, f"joint {jname!r}: link {child!r} already has a parent joint "
                              f"({parent_of[child][1].attrib['name']!r}): a URDF is a tree")
        parent_of[child] = (parent, el)
        children_of.setdefault(parent, []).append((child, el))

    roots = [ln for ln in links if ln not in parent_of]
    if len(roots) != 1:
        raise rd.fail(robot, f"robot {name!r}: expected one root link, found "
                             f"{len(roots)} ({', '.join(roots) or 'a cycle'})")
    # no cycles: every link reaches the root
    for ln in links:
        seen = set()
        cur = ln
        while cur in parent_of:
            if cur in seen:
                raise rd.fail(parent_of[cur][1], f"the joints form a cycle through link {cur!r}")
            seen.add(cur)
            cur = parent_of[cur][0]

    return _Tree(name, links, joints, parent_of, children_of, roots[0])


def _read(text: str, where: str, base_link: str | None, tip_link: str | None) -> UrdfChain:
    rd = _Reader(where)
    tr = _tree(text, where)
    name, links, parent_of, children_of = tr.name, tr.links, tr.parent_of, tr.children_of
    roots = [tr.root]
    base = base_link if base_link is not None else roots[0]
    if base not in links:
        raise ConfigError(f"base link {base!r} is not a link of robot {name!r}", where)
    if tip_link is None:
        leaves = [ln for ln in links if ln not in children_of and _descends(ln, base, parent_of)]
        if len(leaves) != 1:
            raise ConfigError(f"robot {name!r} has {len(leaves)} leaf links below {base!r} "
                              f"({', '.join(leaves)}): name the tip link", where)
        tip = leaves[0]
    else:
        tip = tip_link
        if tip not in links:
            raise ConfigError(f"tip link {tip!r} is not a link of robot {name!r}", where)
    if not _descends(tip, base, parent_of):
        raise ConfigError(f"link {tip!r} is not below link {base!r}", where)

    path: list[_Element] = []  # joints, base to tip
    cur = tip
    while cur != base:
        parent, el = parent_of[cur]
        path.append(el)
        cur = parent
    path.reverse()

    movable: list[dict] = []
    pending = np.eye(4)  # fixed transforms since the last movable joint
    for el in path:
        jname = el.attrib["name"]
        jtype = el.attrib["type"]
        what = f"joint {jname!r}"
        origin = rd.origin(el, what)
        child = _child(el)
        if jtype in ("floating", "planar"):
            raise rd.fail(el, f"{what}: a {jtype} joint cannot be part of a serial chain")
        if jtype == "fixed":
            pending = pending @ origin
            if movable:
                movable[-1]["inertial"] += _subtree(rd, links, children_of, child, path
                                                    ).moved(pending)
            continue
        axis_el = el.find("axis")
        axis: tuple[float, ...] = (1.0, 0.0, 0.0)
        if axis_el is not None:
            axis = rd.numbers(axis_el, "xyz", 3, what, axis)
            if math.hypot(*axis) < 1e-12:
                raise rd.fail(axis_el, f"{what}: the axis is the zero vector")
        limit = el.find("limit")
        lower, upper, effort, velocity = -math.inf, math.inf, math.inf, math.inf
        if limit is None and jtype != "continuous":
            raise rd.fail(el, f"{what}: a {jtype} joint needs <limit effort velocity "
                              f"lower upper>")
        if limit is not None:
            effort = rd.number(limit, "effort", what, math.inf if jtype == "continuous" else None,
                               lambda v: v >= 0, "an effort >= 0")
            velocity = rd.number(limit, "velocity", what,
                                 math.inf if jtype == "continuous" else None,
                                 lambda v: v >= 0, "a velocity >= 0")
            if jtype != "continuous":
                lower = rd.number(limit, "lower", what, 0.0)
                upper = rd.number(limit, "upper", what, 0.0)
                if lower > upper:
                    raise rd.fail(limit, f"{what}: lower limit {lower} is above upper {upper}")
        dyn = el.find("dynamics")
        damping = friction = 0.0
        if dyn is not None:
            damping = rd.number(dyn, "damping", what, 0.0, lambda v: v >= 0, "a damping >= 0")
            friction = rd.number(dyn, "friction", what, 0.0, lambda v: v >= 0,
                                 "a friction >= 0")
        movable.append(dict(name=jname, kind=_MOVABLE[jtype], origin=pending @ origin,
                            axis=axis, lower=lower, upper=upper, velocity=velocity,
                            effort=effort, damping=damping, friction=friction,
                            inertial=_subtree(rd, links, children_of, child, path), line=el.line))
        pending = np.eye(4)
    if not movable:
        raise ConfigError(f"no movable joint between links {base!r} and {tip!r}", where)
    out = []
    for m in movable:
        line = m.pop("line")
        try:
            out.append(Joint(**m))
        except ValueError as exc:
            raise ConfigError(str(exc), where, line) from None
    return UrdfChain(name, tuple(out), pending, base, tip)


def _child(el: _Element) -> str:
    c = el.find("child")
    assert c is not None
    return c.attrib["link"]


def _descends(link: str, base: str, parent_of: dict[str, tuple[str, _Element]]) -> bool:
    cur = link
    while True:
        if cur == base:
            return True
        if cur not in parent_of:
            return False
        cur = parent_of[cur][0]


def _subtree(rd: _Reader, links: dict[str, _Element],
             children_of: dict[str, list[tuple[str, _Element]]], link: str,
             path: list[_Element]) -> Inertial:
    """The inertial of *link* and the links fixed to it off the path, in
    *link*'s frame."""
    body = rd.inertial(links[link])
    for child, el in children_of.get(link, []):
        if el.attrib.get("type") == "fixed" and all(el is not p for p in path):
            body += _subtree(rd, links, children_of, child, path).moved(
                rd.origin(el, f"joint {el.attrib['name']!r}"))
    return body
