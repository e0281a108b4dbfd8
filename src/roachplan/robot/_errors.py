"""The robot package's error."""

from roachplan._errors import InputError


class RobotError(InputError):
    """A robot setting, file, frame or connection that cannot be used: the message names the
    setting, file or address, the value, and what is accepted."""
