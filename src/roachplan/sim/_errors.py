"""Errors the simulation's input can cause."""

from roachplan._errors import InputError


class SimError(InputError):
    """The simulation cannot be built from what it was given, or a simulation setting (a
    calibration's ratios, a command's duration) is not accepted; the message says which."""
