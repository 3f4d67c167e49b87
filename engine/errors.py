"""Errors the engine raises for bad input; each message names the thing and the reason."""


class SpeculumError(Exception):
    """Base of the engine's own errors."""


class AssetError(SpeculumError):
    """A mesh or texture file is missing, unreadable, or holds data the engine cannot use."""


class GLCapabilityError(SpeculumError):
    """The OpenGL context lacks a version or feature the engine needs."""


class ShaderError(SpeculumError):
    """A shader failed to load, include, compile or link."""
