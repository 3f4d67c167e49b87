"""GLSL sources, shipped as package data; see engine.render.shader_library for how they load."""
