"""Readers and writers that turn files into one validated :class:`~identification.flight.Flight`."""

from .csv_log import read_csv_flight, read_servo_csv, sticks_from_servos, write_csv_flight

__all__ = ["read_csv_flight", "read_servo_csv", "sticks_from_servos", "write_csv_flight", "read_flight"]


def read_flight(path):
    """Read a flight log of any supported format (by extension)."""
    return read_csv_flight(path)
