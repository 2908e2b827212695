"""The DAQ link: a TCP line-protocol command and status server."""
