"""cffi build script for pyrt._native (API, out-of-line mode).

The cdef mirrors the headers in csrc/ (pyrt_native.h first, then the others
in name order); constants are declared with ``...`` so the compiler supplies
their values.  Every csrc/*.c is compiled in.  setup.py names this module in
``cffi_modules``; the pyrt.native package is the only importer of the result.
"""

from __future__ import annotations

import os
import re

from cffi import FFI

HERE = os.path.dirname(os.path.abspath(__file__))
HEADERS = [
    "pyrt_native.h",
    *sorted(name for name in os.listdir(HERE) if name.endswith(".h") and name != "pyrt_native.h"),
]
SOURCES = sorted(os.path.join("csrc", name) for name in os.listdir(HERE) if name.endswith(".c"))


def _cdef_from_header(text: str) -> str:
    """Return the header's declarations in a form cffi's cdef accepts.

    Preprocessor guards and includes are dropped; ``#define NAME value`` lines
    become ``#define NAME ...`` so the C compiler, not this script, supplies
    every constant.
    """
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    out = []
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("#define"):
            parts = stripped.split()
            if len(parts) >= 3 and not parts[1].endswith("_H"):
                out.append(f"#define {parts[1]} ...")
            continue
        if stripped.startswith("#"):
            continue
        out.append(line)
    return "\n".join(out)


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
