"""Errors a user's capture file can cause."""


class CaptureError(ValueError):
    """A capture (point cloud, depth image, bag) or its settings are wrong; the message names
    the file or setting and what is accepted."""
