"""gyrostand: CAN-bus field service for gyro thermal test stands."""

__version__ = "0.1.0"
