"""pyrt's version (one place; ``pyrt.__version__`` re-exports it)."""

__version__ = "0.1.0"
