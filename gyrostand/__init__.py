"""gyrostand: CAN-bus field service for gyro thermal test stands."""

from .numerics import pin_numerics

pin_numerics()  # before anything loads numpy: the same numbers in every process

__version__ = "0.1.0"
