"""cffi build script for pyrt._native (API, out-of-line mode).

The public API is ``pyrt_native.h`` and the one header of each kernel
(``X.h`` beside ``X.c``); the cdef is generated from exactly those headers,
in the order their ``#include`` lines require, so nothing reaches Python
that is not declared public there.  Constants are left to the compiler:
integer ``#define``\\ s become ``#define NAME ...`` and floating ones
``static const double NAME;``.  Every csrc/*.c is compiled in.  setup.py
names this module in ``cffi_modules``; the pyrt.native package is the only
importer of the result.
"""

from __future__ import annotations

import os
import re

from cffi import FFI

HERE = os.path.dirname(os.path.abspath(__file__))
BASE = "pyrt_native.h"
_FLOAT = re.compile(r"^[-+]?(\d+\.\d*|\.\d+|\d+)([eE][-+]?\d+)?$")
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def public_headers() -> list[str]:
    """``pyrt_native.h``, then each kernel's header, included ones first."""
    kernels = sorted(name[:-2] + ".h" for name in os.listdir(HERE) if name.endswith(".c"))
    missing = [h for h in kernels if not os.path.exists(os.path.join(HERE, h))]
    if missing:
        raise RuntimeError(f"csrc: kernels without a public header: {missing}")
    ordered: list[str] = []

    def visit(name: str, path: tuple[str, ...]) -> None:
        if name in ordered:
            return
        if name in path:
            raise RuntimeError(f"csrc: #include cycle {' -> '.join((*path, name))}")
        with open(os.path.join(HERE, name), encoding="utf-8") as fh:
            for dep in _INCLUDE.findall(fh.read()):
                if dep != name and dep in (BASE, *kernels):
                    visit(dep, (*path, name))
        ordered.append(name)

    visit(BASE, ())
    for name in kernels:
        visit(name, ())
    return ordered


def _cdef_from_header(text: str) -> str:
    """Return the header's declarations in a form cffi's cdef accepts.

    Preprocessor guards, includes and ``#if`` lines are dropped; every
    ``#define NAME value`` is declared without its value, so the C compiler,
    not this script, supplies every constant.
    """
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    out = []
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("#define"):
            parts = stripped.split(None, 2)
            if len(parts) == 3 and not parts[1].endswith("_H"):
                value = parts[2].strip()
                if _FLOAT.match(value) and any(c in value for c in ".eE"):
                    out.append(f"static const double {parts[1]};")
                else:
                    out.append(f"#define {parts[1]} ...")
            continue
        if stripped.startswith("#"):
            continue
        out.append(line)
    return "\n".join(out)


HEADERS = public_headers()
SOURCES = sorted(os.path.join("csrc", name) for name in os.listdir(HERE) if name.endswith(".c"))

ffibuilder = FFI()
for _name in HEADERS:
    with open(os.path.join(HERE, _name), encoding="utf-8") as fh:
        ffibuilder.cdef(_cdef_from_header(fh.read()))

ffibuilder.set_source(
    "pyrt._native",
    "\n".join(f'#include "{name}"' for name in HEADERS),
    sources=SOURCES,
    include_dirs=["csrc"],
    extra_compile_args=os.environ.get(
        "PYRT_CFLAGS", "-std=c99 -O2 -Wall -Wextra -Werror=implicit-function-declaration"
    ).split(),
    extra_link_args=os.environ.get("PYRT_LDFLAGS", "").split(),
    libraries=["m"],
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
