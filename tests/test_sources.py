"""Scope sources: an item of an attribute, an item of a call's result (called once), the packed row."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pyrt.scope import Source, compile_sources
from pyrt.scope.sources import compile_sampler


class Holder:
    """An object whose attribute is replaced (a tuple) or changed in place (a list)."""

    def __init__(self):
        self.position = (1.0, 2.0, 3.0)
        self.tensions = [10.0, 20.0]


class Counted:
    """A vector computed whole, counting its calls."""

    def __init__(self, values):
        self.values = list(values)
        self.calls = 0

    def __call__(self):
        self.calls += 1
        return list(self.values)

    def vector(self):
        self.calls += 1
        return list(self.values)


def test_attr_item_reads_the_attribute_each_time():
    """An item of an attribute follows the attribute when it is replaced or changed in place."""
    h = Holder()
    read = compile_sources([Source.attr_item(h, "position", 2), Source.attr_item(h, "tensions", 1)])
    assert read() == (3.0, 20.0)
    h.position = (4.0, 5.0, 6.0)
    h.tensions[1] = 21.5
    assert read() == (6.0, 21.5)
    assert Source.attr_item(h, "position", 0).read() == 4.0


@pytest.mark.parametrize("name, index", [("nope", 0), ("position", 3), ("position", -4),
                                         ("position", True), ("position", 1.0),
                                         ("__class__; import os", 0)])
def test_attr_item_refuses_what_it_cannot_read(name, index):
    """An attribute the object lacks, a bad name or an index outside the sequence is refused."""
    with pytest.raises(ValueError):
        Source.attr_item(Holder(), name, index)


def test_call_item_calls_each_shared_function_once_a_read():
    """Every column of one function's result costs one call a read; two functions, two calls."""
    a, b = Counted([1.0, 2.0, 3.0]), Counted([7.0, 8.0])
    sources = [Source.call_item(a, 2), Source.attr(Holder(), "position"),
               Source.call_item(b, 0), Source.call_item(a, 0), Source.call_item(a, 1),
               Source.call_item(b, 1)]
    read = compile_sources(sources)
    assert read() == (3.0, (1.0, 2.0, 3.0), 7.0, 1.0, 2.0, 8.0)
    assert (a.calls, b.calls) == (1, 1)
    a.values[0] = 9.0
    assert read()[3] == 9.0 and a.calls == 2


def test_call_item_shares_a_bound_method_made_twice():
    """Two bound methods of one object's method are one call (they are equal)."""
    c = Counted([4.0, 5.0])
    read = compile_sources([Source.call_item(c.vector, 0), Source.call_item(c.vector, 1)])
    assert read() == (4.0, 5.0) and c.calls == 1


@pytest.mark.parametrize("fn, index", [(42, 0), (list, True), (list, "0")])
def test_call_item_refuses_what_it_cannot_call(fn, index):
    """Something not callable, or an index that is no integer, is refused."""
    with pytest.raises(ValueError):
        Source.call_item(fn, index)


@given(values=st.lists(st.floats(allow_nan=False) | st.integers(-(1 << 40), 1 << 40)
                       | st.booleans(), max_size=80),
       now=st.integers(-(1 << 62), 1 << 62), offset=st.integers(0, 3))
def test_a_sampler_packs_the_bytes_one_struct_would(values, now, offset):
    """The sampler's row, packed in pieces, is byte for byte what one struct packs."""
    n = len(values)
    packer = struct.Struct("<q" + "d" * n)
    sample = compile_sampler([Source.item(values, i) for i in range(n)], packer.pack_into)
    got = bytearray(offset + packer.size)
    sample(got, offset, now)
    assert bytes(got[offset:]) == packer.pack(now, *values)


def test_a_sampler_with_another_packer_calls_it_once():
    """A packer that is not the row's struct is called as given, with every value at once."""
    seen = []
    sample = compile_sampler([Source.item([1.5, 2.5], 0), Source.call(lambda: 3)],
                             lambda buf, off, now, *vals: seen.append((off, now, vals)))
    sample(None, 8, 77)
    assert seen == [(8, 77, (1.5, 3))]


def test_a_sampler_shares_a_call_between_its_columns():
    """The sampler, too, calls a shared function once a row."""
    c = Counted([0.5, math.pi])
    packer = struct.Struct("<qdd")
    sample = compile_sampler([Source.call_item(c, 1), Source.call_item(c, 0)], packer.pack_into)
    buf = bytearray(packer.size)
    sample(buf, 0, 5)
    assert packer.unpack(buf) == (5, math.pi, 0.5) and c.calls == 1
