"""Errors a user's capture file can cause."""

from roachplan._errors import InputError


class CaptureError(InputError):
    """A capture (point cloud, depth image, bag) or its settings are wrong; the message names
    the file or setting and what is accepted."""
