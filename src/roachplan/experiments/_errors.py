"""Errors a user's experiment spec or results folder can cause."""

from roachplan._errors import InputError


class ExperimentError(InputError):
    """An experiment spec, results folder or trial number is wrong; the message says where
    and what is accepted."""


class OutputError(InputError):
    """An output file or results folder a command was given cannot be written without losing
    something (an input, a file roachplan did not write) or cannot be written at all; the
    message names the flag, the path and what would be accepted."""


class ChooseError(ExperimentError):
    """A choice that cannot be made as asked (`roachplan choose`, the page's Choose path)."""
