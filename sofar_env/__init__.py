"""SOfAR: safe overtaking for autonomous racing."""

__version__ = "0.1.0"
