"""Errors a user's scene, terrain or capture can cause."""

from roachplan._errors import InputError


class SceneError(InputError):
    """A scene file, terrain file or OpenSCAD model is wrong; the message says where and how."""
