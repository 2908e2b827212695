"""The C kernels, through cffi: the only package that touches ``ffi``/``lib``.

Arguments are validated here, before C sees them; every C status code
becomes a :class:`~pyrt.errors.NativeError` (or a subclass) in one place
(``_errors``), so nothing above this package ever sees a raw return code or
a cdata object.  The kernels' default parameters are read from the C
headers (``lib``), never written down twice.  One private module per C
source file; this ``__init__`` re-exports their API.
"""

from pyrt.native._armworld import ARM_ROWS, ArmKernel
from pyrt.native._convert import excess128, excess128_many, from_excess128
from pyrt.native._drive import (
    DRIVE_ENABLED,
    DRIVE_FAULT,
    DRIVE_LATE,
    DRIVE_REFUSED,
    DriveKernel,
)
from pyrt.native._errors import (
    DegenerateGeometryError,
    NativeInputError,
    NoConvergenceError,
    NonFiniteError,
    SingularError,
    SolverError,
    Status,
)
from pyrt.native._findpos import (
    PositionFinder,
    PositionResult,
    RopeSegments,
    find_position,
    freeze_mask,
    rope_lengths,
    rope_segments,
)
from pyrt.native._fuzzy import FuzzyBatch, FuzzyInput, FuzzyParams, FuzzyRule, fuzzy_step
from pyrt.native._image import (
    HAND_OVER_DUE,
    HAND_OVER_SLOW,
    IMAGE_CLOCK,
    IMAGE_TMAX,
    InputGather,
    RingRows,
    TickHandOver,
    int64_buffer,
    output_changes,
)
from pyrt.native._journal import (
    JOURNAL_CLOCK,
    JOURNAL_TMAX,
    JOURNAL_VMAX,
    JOURNAL_WRITE,
    RecordRefused,
    TickEncoder,
)
from pyrt.native._kinematics import ChainKernels, IKOutcome
from pyrt.native._neck import LOWER as NECK_LOWER
from pyrt.native._neck import UPPER as NECK_UPPER
from pyrt.native._neck import NeckRing, RopePath, ring_contact
from pyrt.native._polyctl import PolyControl
from pyrt.native._readyq import QueueChecker, native_dispatcher
from pyrt.native._servo import (
    Servo,
    ServoBoard,
    ServoTrip,
    check_gains,
    gain_ranges,
    tuned_gains,
)
from pyrt.native._statics import StaticsSolver

__all__ = [
    "ARM_ROWS",
    "DRIVE_ENABLED",
    "DRIVE_FAULT",
    "DRIVE_LATE",
    "DRIVE_REFUSED",
    "HAND_OVER_DUE",
    "HAND_OVER_SLOW",
    "IMAGE_CLOCK",
    "IMAGE_TMAX",
    "JOURNAL_CLOCK",
    "JOURNAL_TMAX",
    "JOURNAL_VMAX",
    "JOURNAL_WRITE",
    "NECK_LOWER",
    "NECK_UPPER",
    "ArmKernel",
    "ChainKernels",
    "DegenerateGeometryError",
    "DriveKernel",
    "FuzzyBatch",
    "FuzzyInput",
    "FuzzyParams",
    "FuzzyRule",
    "IKOutcome",
    "InputGather",
    "NativeInputError",
    "NeckRing",
    "NoConvergenceError",
    "NonFiniteError",
    "PolyControl",
    "PositionFinder",
    "PositionResult",
    "QueueChecker",
    "RecordRefused",
    "RingRows",
    "RopePath",
    "RopeSegments",
    "Servo",
    "ServoBoard",
    "ServoTrip",
    "SingularError",
    "SolverError",
    "StaticsSolver",
    "Status",
    "TickEncoder",
    "TickHandOver",
    "check_gains",
    "excess128",
    "excess128_many",
    "find_position",
    "freeze_mask",
    "from_excess128",
    "fuzzy_step",
    "gain_ranges",
    "int64_buffer",
    "native_dispatcher",
    "output_changes",
    "ring_contact",
    "rope_lengths",
    "rope_segments",
    "tuned_gains",
]
