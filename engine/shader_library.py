"""Loads GLSL from the ``shaders`` package, resolves ``#include``, and caches programs.

Shared GLSL (camera block, lights, GGX, colour encoding) lives in ``shaders/include`` and is
included, never pasted.  Defines (the material slot indices, per-program switches) are
inserted after the ``#version`` line.

Compile errors name the file and line a person edits, not the line of the expanded text the
driver saw.  Every file of a program gets a number k, and a ``#line`` directive starts each
file and resumes the includer after each ``#include`` with line numbers counted from
k x ``LINE_STRIDE``, so the driver's log says "0:300008(5)" for line 8 of file 3 and the
library rewrites that as ``include/ggx.glsl:8:5``.  The file is carried in the line number,
not in GLSL's source-string number, because Mesa drops the latter from semantic errors
(an undeclared name is reported in source 0).  Mesa writes ``S:L(C)``, NVIDIA ``S(L)``,
AMD and Apple ``ERROR: S:L:``; all three are rewritten.  File 0 is the generated header
(the defines).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import moderngl

import shaders
from engine.errors import ShaderError
from engine.material_slots import glsl_defines

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')
_VERSION = "#version 410 core"
HEADER = "(generated defines)"
LINE_STRIDE = 100_000  # file k's line n is reported as line k x LINE_STRIDE + n
# Where drivers put (source-string number, line[, column]) in a compile log.
_LOG_PLACES = (
    re.compile(r"\b(?P<n>\d+):(?P<line>\d+)\((?P<col>\d+)\)"),  # Mesa: 0:12(5)
    re.compile(r"\b(?P<n>\d+)\((?P<line>\d+)\)(?= :)"),  # NVIDIA: 0(12) : error
    re.compile(r"(?<=ERROR: )(?P<n>\d+):(?P<line>\d+)(?=:)"),  # AMD, Apple: ERROR: 0:12: ...
)


def shader_dir() -> Path:
    return Path(shaders.__file__).parent


@dataclass
class SourceFiles:
    """The files of one program, by number (0 is the generated header)."""

    names: list[str] = field(default_factory=lambda: [HEADER])

    def number(self, name: str) -> int:
        if name not in self.names:
            self.names.append(name)
        return self.names.index(name)

    def readable(self, log: str) -> str:
        """``log`` with every driver reference to a line written as ``file:line``."""
        def rename(match: re.Match[str]) -> str:
            number, line = divmod(int(match.group("line")), LINE_STRIDE)
            if number >= len(self.names):
                return match.group(0)
            column = match.groupdict().get("col")
            return f"{self.names[number]}:{line}" + (f":{column}" if column else "")

        for place in _LOG_PLACES:
            log = place.sub(rename, log)
        return log


def load_source(name: str, defines: dict[str, str] | None = None, *, root: Path | None = None,
                files: SourceFiles | None = None) -> str:
    """The full text of shader file ``name`` (relative to ``root``, the ``shaders`` package by
    default) with includes resolved, ``#line`` directives naming each file's own lines, and
    defines added; ``files`` collects the file of each source-string number."""
    root = root or shader_dir()
    files = files if files is not None else SourceFiles()
    text = _expand(name, (), root, files)
    first, _, rest = text.partition("\n")
    if first.strip() != _VERSION:
        raise ShaderError(f"shader {name!r}: must start with '{_VERSION}' (the 4.1 baseline)")
    all_defines = {**glsl_defines(), **(defines or {})}
    header = "".join(f"#define {k} {v}\n" for k, v in all_defines.items())
    return f"{first}\n#line 1\n{header}{_line(2, files.number(name))}\n{rest}"


def _line(line: int, number: int) -> str:
    """The directive that makes the next line read as ``line`` of file ``number``."""
    return f"#line {number * LINE_STRIDE + line}"


def _expand(name: str, stack: tuple[str, ...], root: Path, files: SourceFiles) -> str:
    if name in stack:
        raise ShaderError(f"shader include cycle: {' -> '.join(stack + (name,))}")
    path = root / name
    if not path.is_file():
        where = f" (included from {stack[-1]!r})" if stack else ""
        raise ShaderError(f"shader file {name!r} not found in {root}{where}")
    number = files.number(name)
    out = []
    for index, line in enumerate(path.read_text().split("\n"), start=1):
        match = _INCLUDE.match(line)
        if match is None:
            out.append(line)
            continue
        included = f"include/{match.group(1)}"
        out.append(_line(1, files.number(included)))
        out.append(_expand(included, stack + (name,), root, files))
        out.append(_line(index + 1, number))
    return "\n".join(out)


class ShaderLibrary:
    """Compiled programs of one context, cached by (files, defines)."""

    def __init__(self, ctx: moderngl.Context, root: Path | None = None) -> None:
        self.ctx = ctx
        self.root = root
        self._programs: dict[tuple, moderngl.Program] = {}

    def program(self, vertex: str, fragment: str, geometry: str | None = None,
                defines: dict[str, str] | None = None) -> moderngl.Program:
        key = (vertex, fragment, geometry, tuple(sorted((defines or {}).items())))
        program = self._programs.get(key)
        if program is None:
            files = SourceFiles()  # one numbering for every stage, so a log line names one file
            sources = {stage: load_source(name, defines, root=self.root, files=files) if name else None
                       for stage, name in (("vertex_shader", vertex), ("fragment_shader", fragment),
                                           ("geometry_shader", geometry))}
            try:
                program = self.ctx.program(**sources)
            except moderngl.Error as exc:
                names = ", ".join(f for f in (vertex, geometry, fragment) if f)
                raise ShaderError(f"shader program ({names}) failed to build:\n{files.readable(str(exc))}") from exc
            self._programs[key] = program
        return program

    def release(self) -> None:
        for program in self._programs.values():
            program.release()
        self._programs.clear()
