"""Errors a user's scene, terrain or capture can cause."""


class SceneError(ValueError):
    """A scene file, terrain file or OpenSCAD model is wrong; the message says where and how."""
