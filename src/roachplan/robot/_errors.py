"""The robot package's error."""


class RobotError(ValueError):
    """A robot setting, file, frame or connection that cannot be used: the message names the
    setting, file or address, the value, and what is accepted."""
