"""Loads GLSL from the ``shaders`` package, resolves ``#include``, and caches programs.

Shared GLSL (camera block, lights, GGX, colour encoding) lives in ``shaders/include`` and is
included, never pasted.  Defines (the material slot indices, per-program switches) are
inserted after the ``#version`` line.  Compile errors name the files involved.
"""
from __future__ import annotations

import re
from pathlib import Path

import moderngl

import shaders
from engine.errors import ShaderError
from engine.material_slots import glsl_defines

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


def shader_dir() -> Path:
    return Path(shaders.__file__).parent


def load_source(name: str, defines: dict[str, str] | None = None) -> str:
    """The full text of shader file ``name`` with includes resolved and defines added."""
    text = _resolve(name, stack=())
    lines = text.split("\n", 1)
    if not lines[0].startswith("#version 410 core"):
        raise ShaderError(f"shader {name!r}: must start with '#version 410 core' (the 4.1 baseline)")
    all_defines = {**glsl_defines(), **(defines or {})}
    header = "".join(f"#define {k} {v}\n" for k, v in all_defines.items())
    return f"{lines[0]}\n{header}#line 2\n{lines[1] if len(lines) > 1 else ''}"


def _resolve(name: str, stack: tuple[str, ...]) -> str:
    if name in stack:
        raise ShaderError(f"shader include cycle: {' -> '.join(stack + (name,))}")
    path = shader_dir() / name
    if not path.is_file():
        where = f" (included from {stack[-1]!r})" if stack else ""
        raise ShaderError(f"shader file {name!r} not found in {shader_dir()}{where}")
    text = path.read_text()

    def include(match: re.Match[str]) -> str:
        return _resolve(f"include/{match.group(1)}", stack + (name,))

    return _INCLUDE.sub(include, text)


class ShaderLibrary:
    """Compiled programs of one context, cached by (files, defines)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._programs: dict[tuple, moderngl.Program] = {}

    def program(self, vertex: str, fragment: str, geometry: str | None = None,
                defines: dict[str, str] | None = None) -> moderngl.Program:
        key = (vertex, fragment, geometry, tuple(sorted((defines or {}).items())))
        program = self._programs.get(key)
        if program is None:
            try:
                program = self.ctx.program(
                    vertex_shader=load_source(vertex, defines),
                    fragment_shader=load_source(fragment, defines),
                    geometry_shader=load_source(geometry, defines) if geometry else None,
                )
            except moderngl.Error as exc:
                files = ", ".join(f for f in (vertex, geometry, fragment) if f)
                raise ShaderError(f"shader program ({files}) failed to build:\n{exc}") from exc
            self._programs[key] = program
        return program

    def release(self) -> None:
        for program in self._programs.values():
            program.release()
        self._programs.clear()
