"""Interactive consoles: line editing and history on a terminal, plain lines from a pipe."""
