"""Object databases: the .dat format of the SNO manipulator, read and written back atomically.

Files start with ``VERSION1.00``; entries are ``TYPE: name`` ... ``END;`` with
``KEY: value // comment`` lines.

``load_station(directory)`` reads POLYAXIS.dat, AXIS.dat, MOTOR.dat,
ENCODER.dat, LOADCELL.dat and AV.dat into typed, frozen records (base units
cm, kg, cm3, N) with every cross reference resolved; ``Station.write_back``
rewrites values in place, atomically, keeping every other byte.
``station_directory``/``copy_station`` give the packaged stations
(``prototype``, ``sno``).
"""

from pyrt.db._lock import DirectoryLock, lock_directory
from pyrt.db._schema import FILES, VERSIONS, defaults
from pyrt.db._startup import MAX_STARTUP_CORRECTION_CM, check_startup_correction
from pyrt.db._stations import (
    STATIONS,
    copy_station,
    default_working_directory,
    station_directory,
)
from pyrt.db.records import (
    AVRecord,
    AxisRecord,
    EncoderRecord,
    LoadcellRecord,
    Location,
    MotorRecord,
    PolyAxisRecord,
    Vector,
)
from pyrt.db.station import (
    MAX_DB_BYTES,
    TYPES,
    ObjectRef,
    Station,
    UnknownNameError,
    load_station,
    parse_file,
    parse_records,
    read_regular_file,
)
from pyrt.fileio import atomic_write

__all__ = [
    "FILES",
    "MAX_DB_BYTES",
    "MAX_STARTUP_CORRECTION_CM",
    "STATIONS",
    "TYPES",
    "VERSIONS",
    "AVRecord",
    "AxisRecord",
    "DirectoryLock",
    "EncoderRecord",
    "LoadcellRecord",
    "Location",
    "MotorRecord",
    "ObjectRef",
    "PolyAxisRecord",
    "Station",
    "UnknownNameError",
    "Vector",
    "atomic_write",
    "check_startup_correction",
    "copy_station",
    "default_working_directory",
    "defaults",
    "load_station",
    "lock_directory",
    "parse_file",
    "parse_records",
    "read_regular_file",
    "station_directory",
]
