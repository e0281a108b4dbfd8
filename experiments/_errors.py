"""Errors a user's experiment spec or results folder can cause."""


class ExperimentError(ValueError):
    """An experiment spec, results folder or trial number is wrong; the message says where
    and what is accepted."""
