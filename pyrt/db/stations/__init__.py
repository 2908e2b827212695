"""Packaged stations: one directory of .dat files per station (prototype, sno)."""
