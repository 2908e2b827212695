"""pyrt.frames: transforms, position equations and their two solve functions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.frames import FrameError, PositionEquation, Transform, check_rigid, inverse

finite = st.floats(-2.0, 2.0, allow_nan=False)


@st.composite
def rigid(draw) -> np.ndarray:
    """A random rigid transform (a unit quaternion and a translation)."""
    q = np.array([draw(st.floats(-1, 1)) for _ in range(4)])
    if np.linalg.norm(q) < 0.1:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    w, x, y, z = q / np.linalg.norm(q)
    t = np.eye(4)
    t[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    t[:3, 3] = [draw(finite) for _ in range(3)]
    return t


@st.composite
def equations(draw):
    """A random equation: T6 and 0-3 more lhs terms, 1-4 rhs terms, all varb, random values."""
    n_lhs = draw(st.integers(0, 3))
    n_rhs = draw(st.integers(1, 4))
    i6 = draw(st.integers(0, n_lhs))
    lhs = [Transform.varb(f"L{i}", draw(rigid())) for i in range(n_lhs)]
    lhs.insert(i6, Transform.varb("T6", draw(rigid())))
    rhs = [Transform.varb(f"R{i}", draw(rigid())) for i in range(n_rhs)]
    return PositionEquation("eq", lhs, rhs), lhs, rhs


def product(ts) -> np.ndarray:
    out = np.eye(4)
    for t in ts:
        out = out @ t.value
    return out


@settings(max_examples=60, deadline=None)
@given(equations(), st.data())
def test_solving_for_any_term_and_substituting_back_gives_the_identity(eq_lhs_rhs, data):
    """Solving for any term and setting it to the result makes lhs = rhs (the ring's product the identity)."""
    eq, lhs, rhs = eq_lhs_rhs
    target = data.draw(st.sampled_from(lhs + rhs))
    target.set(eq.solve(target))
    np.testing.assert_allclose(product(lhs), product(rhs), atol=1e-9)
    np.testing.assert_allclose(eq.residual(), np.eye(4), atol=1e-9)
    np.testing.assert_allclose(eq.lhs_value(), eq.rhs_value(), atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(equations(), st.data())
def test_a_holding_equation_solved_for_any_term_gives_its_value(eq_lhs_rhs, data):
    """When the equation holds, solving for any term gives back that term's own value."""
    eq, lhs, rhs = eq_lhs_rhs
    eq.t6.set(eq.solve("T6"))
    for t in lhs + rhs:
        np.testing.assert_allclose(eq.solve(t), t.value, atol=1e-9)
        assert eq.side(t) == ("lhs" if t in lhs else "rhs")


@settings(max_examples=60, deadline=None)
@given(equations(), st.data())
def test_direct_is_the_partial_path_between_two_terms(eq_lhs_rhs, data):
    """direct(a, b) is the product of the ring's factors strictly between a and b; inverse() is its inverse."""
    eq, lhs, rhs = eq_lhs_rhs
    ring = [(t, t.value) for t in lhs] + [(t, inverse(t.value)) for t in reversed(rhs)]
    ia = data.draw(st.integers(0, len(ring) - 1))
    ib = data.draw(st.integers(0, len(ring) - 1))
    expect = np.eye(4)
    i = (ia + 1) % len(ring)
    while i != ib:
        expect = expect @ ring[i][1]
        i = (i + 1) % len(ring)
    a, b = ring[ia][0], ring[ib][0]
    np.testing.assert_allclose(eq.direct(a, b), expect, atol=1e-12)
    np.testing.assert_allclose(eq.inverse(a.name, b.name) @ expect, np.eye(4), atol=1e-9)


def test_the_canonical_equation_solves_t6_and_pos():
    """T6 · TOOL = COORD · POS: T6 = COORD POS TOOL⁻¹ and POS = COORD⁻¹ T6 TOOL."""
    rng = np.random.default_rng(1)
    vals = [check_rigid(_random_rigid(rng)) for _ in range(3)]
    t6, tool, coord = Transform.varb("T6"), Transform.const("TOOL", vals[0]), Transform.varb("COORD", vals[1])
    pos = Transform.hold("POS", vals[2])
    eq = PositionEquation("p", [t6, tool], [coord, pos])
    assert eq.tool is tool and eq.pos is pos and eq.t6 is t6
    assert eq.has_tool and eq.has_coord and not eq.coord_functional and not eq.tool_functional
    want = vals[1] @ vals[2] @ np.linalg.inv(vals[0])
    np.testing.assert_allclose(eq.solve(t6), want, atol=1e-12)
    t6.set(want)
    np.testing.assert_allclose(eq.solve("POS"), vals[2], atol=1e-12)
    np.testing.assert_allclose(eq.direct("COORD", "TOOL"), want, atol=1e-12)
    assert repr(eq) == "PositionEquation('p': T6 TOOL = COORD POS)"


def _random_rigid(rng) -> np.ndarray:
    a, b, c = rng.uniform(-np.pi, np.pi, 3)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rx = np.array([[1, 0, 0], [0, np.cos(c), -np.sin(c)], [0, np.sin(c), np.cos(c)]])
    t = np.eye(4)
    t[:3, :3] = rz @ ry @ rx
    t[:3, 3] = rng.uniform(-1, 1, 3)
    return t


def test_a_functional_transform_is_evaluated_once_per_sample():
    """A functional transform's function runs once per sample however often the equation is solved; its age is the sample."""
    calls = []

    def belt(sample: int) -> np.ndarray:
        calls.append(sample)
        t = np.eye(4)
        t[0, 3] = 0.01 * sample
        return t

    conveyor = Transform.functional("CONV", belt)
    t6, pos = Transform.varb("T6"), Transform.hold("POS")
    eq = PositionEquation("track", [t6], [conveyor, pos])
    assert eq.coord_functional
    for sample in (5, 5, 6):
        eq.evaluate(sample)
        for _ in range(3):
            got = eq.solve(t6, sample)
        assert conveyor.age == sample
    assert calls == [5, 6]
    assert conveyor.evaluations == 2
    assert got[0, 3] == pytest.approx(0.06)
    # shared by two equations: still once per sample
    eq2 = PositionEquation("other", [Transform.varb("T6")], [conveyor, Transform.varb("P2")])
    eq.evaluate(7)
    eq2.evaluate(7)
    eq2.solve("T6", 7)
    assert calls == [5, 6, 7]


def test_hold_keeps_its_value_until_the_segment_ends_and_queues_successive_values():
    """A hold transform's change reaches the equation only at the end of a path segment, one queued value per segment; user, alternate and old are distinct."""
    a, b, c = (_shift(x) for x in (1.0, 2.0, 3.0))
    pos = Transform.hold("POS", a)
    t6 = Transform.varb("T6")
    eq = PositionEquation("p", [t6], [pos])
    pos.set(b)
    eq.evaluate(1)
    pos.set(c)
    eq.evaluate(2)
    user, alternate, old = eq.values(pos)
    np.testing.assert_array_equal(user, c)
    np.testing.assert_array_equal(alternate, a)
    np.testing.assert_allclose(eq.solve(t6), a)  # the equation still moves with a
    assert eq.end_segment() == ["POS"]
    user, alternate, old = eq.values(pos)
    np.testing.assert_array_equal(alternate, b)
    np.testing.assert_array_equal(old, a)
    assert eq.end_segment() == ["POS"]
    np.testing.assert_allclose(eq.solve(t6), c)
    np.testing.assert_array_equal(eq.values(pos)[2], b)
    assert eq.end_segment() == []


def test_varb_is_seen_at_once_and_its_three_values_are_one():
    """A varb change reaches the equation at once; its user, alternate and old values are the same array."""
    coord = Transform.varb("COORD", _shift(1.0))
    eq = PositionEquation("p", [Transform.varb("T6")], [coord, Transform.varb("POS")])
    coord.set(_shift(2.0))
    np.testing.assert_allclose(eq.solve("T6"), _shift(2.0))
    user, alternate, old = eq.values("COORD")
    assert user is alternate is old


def _shift(x: float) -> np.ndarray:
    t = np.eye(4)
    t[0, 3] = x
    return t


def test_const_and_functional_refuse_a_new_value_and_keep_theirs():
    """Setting a const or a functional transform is refused and its value is unchanged."""
    k = Transform.const("BASE", _shift(1.0))
    f = Transform.functional("F", lambda s: np.eye(4))
    with pytest.raises(FrameError, match="const"):
        k.set(np.eye(4))
    with pytest.raises(FrameError, match="functional"):
        f.set(np.eye(4))
    assert k.value[0, 3] == 1.0 and k.version == 0


BAD_MATRICES = [
    (np.diag([2.0, 1.0, 1.0, 1.0]), "orthonormal"),
    (np.diag([-1.0, 1.0, 1.0, 1.0]), "reflection"),
    (np.eye(3), "shape"),
    (np.full((4, 4), np.nan), "non-finite"),
    (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]), "bottom row"),
    ("eye", "not a 4x4"),
]


@pytest.mark.parametrize(("value", "why"), BAD_MATRICES)
def test_a_non_rigid_matrix_is_refused_with_the_reason(value, why):
    """A value that is not a rigid transform is refused, naming the transform and the reason, and nothing changes."""
    t = Transform.varb("TOOL", _shift(1.0))
    with pytest.raises(FrameError, match=why) as err:
        t.set(value)
    assert "'TOOL'" in str(err.value)
    assert t.value[0, 3] == 1.0 and t.version == 0


def test_a_functional_returning_a_non_rigid_matrix_is_refused():
    """A functional transform whose function returns a non-rigid matrix raises, naming it and the sample."""
    f = Transform.functional("BAD", lambda s: np.diag([1.0, 1.0, 3.0, 1.0]))
    eq = PositionEquation("p", [Transform.varb("T6")], [f, Transform.varb("POS")])
    with pytest.raises(FrameError, match="'BAD' at sample 4"):
        eq.evaluate(4)


def test_bad_equations_are_refused_clearly():
    """An equation without T6, with an empty rhs, a repeated or functional POS, or an unknown term, is refused with the reason."""
    t6, tool, pos = Transform.varb("T6"), Transform.varb("TOOL"), Transform.varb("POS")
    with pytest.raises(FrameError, match="no T6"):
        PositionEquation("p", [tool], [pos])
    with pytest.raises(FrameError, match="rhs needs"):
        PositionEquation("p", [t6], [])
    with pytest.raises(FrameError, match="twice"):
        PositionEquation("p", [t6, tool], [tool])
    with pytest.raises(FrameError, match="cannot be functional"):
        PositionEquation("p", [t6], [Transform.functional("POS", lambda s: np.eye(4))])
    with pytest.raises(FrameError, match="must be an lhs"):
        PositionEquation("p", [t6], [pos], tool=pos)
    with pytest.raises(FrameError, match="not a Transform"):
        PositionEquation("p", [t6], [np.eye(4)])
    with pytest.raises(FrameError, match="const"):
        PositionEquation("p", [Transform.const("T6", np.eye(4))], [pos])
    with pytest.raises(FrameError, match="unknown type"):
        Transform("X", "sticky")
    eq = PositionEquation("p", [t6, tool], [pos])
    with pytest.raises(FrameError, match=r"no term 'COORD' \(terms: T6, TOOL, POS\)"):
        eq.solve("COORD")
    with pytest.raises(FrameError, match="no term"):
        eq.direct(Transform.varb("POS"), t6)  # same name, another transform


def test_t6_may_be_named_otherwise_when_given():
    """An equation's T6 may be any varb lhs transform passed as t6=."""
    flange = Transform.varb("FLANGE")
    eq = PositionEquation("p", [flange], [Transform.varb("POS", _shift(0.5))], t6=flange)
    np.testing.assert_allclose(eq.solve(flange), _shift(0.5))


def test_termination_code_progress_and_the_reached_event():
    """Moving to an equation: progress from 0 towards 1, then finish sets the code, progress 1 and the reached event, and calls the listeners."""
    eq = PositionEquation("p", [Transform.varb("T6")], [Transform.varb("POS")])
    seen = []
    eq.on_reached(lambda e: seen.append((e.name, e.code)))
    eq.start()
    assert eq.progress == 0.0 and eq.code is None and not eq.reached.is_set()
    eq.progress = 0.5
    with pytest.raises(FrameError, match="outside"):
        eq.progress = 1.5
    assert eq.progress == 0.5
    eq.finish("OK")
    assert eq.reached.wait(0) and eq.code == "OK" and eq.progress == 1.0
    assert seen == [("p", "OK")]
    eq.start()
    assert not eq.reached.is_set() and eq.code is None


def test_frames_does_not_import_the_scheduler():
    """pyrt.frames is pure numpy: importing it alone loads no scheduler module."""
    import subprocess
    import sys

    code = "import sys, pyrt.frames; print(any(m.startswith('pyrt.scheduler') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "False", out.stderr
