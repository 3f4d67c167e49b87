"""GLSL sources, shipped as package data; see engine.shader_library for how they load."""
