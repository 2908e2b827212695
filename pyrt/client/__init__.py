"""A blocking client of the pyrt TCP server, for scripts and tests."""
