"""Build pyrt's C kernels through cffi (API, out-of-line mode), and the ready
queue's dispatch (csrc/ext/dispatch.c, the one CPython-API extension);
metadata is in pyproject.toml."""

from setuptools import Extension, setup

setup(
    cffi_modules=["csrc/build_native.py:ffibuilder"],
    ext_modules=[
        Extension(
            "pyrt.native._dispatch",
            sources=["csrc/ext/dispatch.c", "csrc/readyq.c"],
            include_dirs=["csrc"],
            extra_compile_args=["-O2"],
        )
    ],
)
