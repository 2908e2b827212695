"""The C kernels, through cffi: the only package that touches ``ffi``/``lib``.

Arguments are validated here, before C sees them; every C status code
becomes a :class:`~pyrt.errors.NativeError` (or a subclass) here, so nothing
above this package ever sees a raw return code or a cdata object.  One
private module per C source file; this ``__init__`` re-exports their API.
"""

from pyrt.native._convert import excess128, excess128_many, from_excess128
from pyrt.native._statics import StaticsSolver

__all__ = ["StaticsSolver", "excess128", "excess128_many", "from_excess128"]
