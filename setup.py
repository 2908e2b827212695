"""Build pyrt's C kernels through cffi (API, out-of-line mode); metadata is in pyproject.toml."""

from setuptools import setup

setup(cffi_modules=["csrc/build_native.py:ffibuilder"])
