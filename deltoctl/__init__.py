"""deltoctl: configuration-driven bring-up toolkit for robot hardware."""

__version__ = "0.1.0"
