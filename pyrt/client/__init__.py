"""A blocking client of the pyrt TCP server, for scripts and tests."""

from pyrt.client.client import (
    Client,
    Reply,
    ServerError,
    Status,
    parse_address,
    parse_status,
)

__all__ = ["Client", "Reply", "ServerError", "Status", "parse_address", "parse_status"]
