"""Loads GLSL from the ``shaders`` package, resolves ``#include``, and caches programs.

Shared GLSL (camera block, lights, GGX, colour encoding) lives in ``shaders/include`` and is
included, never pasted.  Defines are inserted after the ``#version`` line: a program's own
switches, and for every program the numbers GLSL shares with Python, generated from the
Python that owns them (``engine_defines``: the material slot indices, the cube-face table,
the clip-distance indices, the visibility code's kind bits, the
blocks' array sizes, the tone curves' numbers).

Compile errors name the file and line a person edits, not the line of the expanded text the
driver saw.  Every file of a program gets a number k, and a ``#line`` directive starts each
file and resumes the includer after each ``#include`` with line numbers counted from
k x ``LINE_STRIDE``, so the driver's log says line 300008 for line 8 of file 3.  The file is
carried in the line number, not in GLSL's source-string number, because Mesa drops the
latter from semantic errors (an undeclared name is reported in source 0).  File 0 is the
generated header (the defines).  The numbering is resumed after every ``#else``, ``#elif``
and ``#endif`` too: the preprocessor skips a ``#line`` inside a branch it drops but still
counts that branch's lines, so an ``#include`` inside an ``#ifdef`` a variant leaves
undefined would otherwise shift every later line of that variant.

Every driver words its log its own way; each message is rewritten into the engine's one
form, ``file:line[:column]: error|warning: text`` (``Diagnostic``; the column where the
driver gives one)::

    Mesa (llvmpipe, radeonsi, Intel on Linux)   0:300008(5): error: `x' undeclared
    NVIDIA                                      0(300008) : error C1503: undefined variable "x"
    AMD, Intel on Windows, Apple, ANGLE,        ERROR: 0:300008: 'x' : undeclared identifier
      glslang (old AMD: "error(#143) ...")
                                   all become   include/ggx.glsl:8[:5]: error: ...

Shader files are read as bytes and must be UTF-8; only regular files are opened (a named
pipe or a directory in the shaders folder is refused by ``os.stat`` before any ``open``,
which would wait for a writer forever).

Hot reload (windowed runs): ``ShaderLibrary.poll`` looks at the files every program was
built from (size and modification time, then the bytes) at most every ``POLL_INTERVAL``
seconds, and rebuilds the programs that used a changed file.  A rebuild that fails keeps
the old program drawing and records the error (``ShaderLibrary.errors``, file:line as
above); ``poll`` says each change once: one line for the programs rebuilt, one message for
the errors (each distinct error line once, however many variants of a program share it).
A variant first needed while an edit does not build (a batch that comes after the edit:
new defines, a new material slot) is built from the files as they were before the edit
(the last contents every program built from), so the frame draws it as the old program
would and the game goes on; it is recorded in ``errors`` and said by the next ``poll``, and
rebuilt from the files like any other once they are fixed.
One that builds is swapped in under the old program's own GL name: the new shaders are
attached to the old program object and it is relinked, with each vertex input
bound to its old location, so every vertex array, cached program and uniform a pass holds
keeps working without knowing of the reload; moderngl's uniform objects get their new
locations, and the values the engine set once (sampler units, uniform-block bindings) are
written back.

Programs outlive the library that built them, on its context (``FreePrograms``): a library
that is released hands its programs to the context's free list, each uniform put back to
the 0 a link gives it and each block to binding 0, and a library on the same context that
needs a program of the same key, from the same expanded sources, takes it instead of
compiling and linking again.  An engine closed and another opened on one context (a level
reloaded, an editor's preview, the test suite's thousands of engines) pays for each variant
once: on llvmpipe a link is 1 ms from Mesa's shader cache and 30 ms or more without it.  The
list keeps at most as many programs as the fullest library given back held (a program is
megabytes of machine code on a software rasteriser; ``FreePrograms.keep`` sets another
number), the longest unused going first.
"""
from __future__ import annotations

import ctypes
import os
import re
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path

import moderngl

import shaders
from components.limits import MAX_CONTACT_LAMPS, MAX_FOG_VOLUMES, MAX_IRRADIANCE_VOLUMES, MAX_RECT_LIGHTS
from components.post import TONEMAP_CURVES
from components.rendering import MATERIAL_IMAGES
from engine.core import cube_faces, material_slots
from engine.core.errors import ShaderError
from engine.render import object_motion, pose_rows, views
from engine.render.bindings import clip_glsl_defines
from engine.render.context_kept import kept_on
from engine.render.environment_brdf import ENVIRONMENT_BRDF_SIZE
from engine.render.ltc_fit import LTC_SIZE
from engine.render.raw_gl import _load as load_gl_function
from engine.render.sky import EARTHSHINE
from engine.render.subsurface import SUBSURFACE_BANDS_COLUMN
from engine.rules import lens_rules, shadow_rules, visibility_rules

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')
_BRANCH = re.compile(r"^\s*#\s*(else|elif|endif)\b")  # after these the line numbering is resumed
# A ``#line`` resuming a file's numbering with no line of it left to number: a stage file
# ending with ``#endif`` leaves one at the end of the program's text, which NVIDIA's compiler
# refuses ("#line line number invalid", C0115: particle.vert on the H200, driver 580).
# (Looked for from the end: a regular expression anchored at the end is tried at each of the
# text's ~350 ``#line`` lines, 2-5 ms a program, a tenth of a fresh process's first frame.)
_LINE_DIRECTIVE = re.compile(r"#line \d+")
_CONDITION = re.compile(r"^\s*#\s*(ifdef|ifndef|if|elif|else|endif)\b\s*(\w*)")
_DEFINITION = re.compile(r"^\s*#\s*(define|undef)\s+(\w+)")
POLL_INTERVAL = 0.5  # seconds between two looks at the shader files (hot reload)
_VERSION = "#version 410 core"
HEADER = "(generated defines)"
LINE_STRIDE = 100_000  # file k's line n is reported as line k x LINE_STRIDE + n
# One line of a driver's compile or link log, by vendor: source-string number (ignored: the file
# is in the line number), line, column where given, severity and text.
_DRIVER_LINES = (
    # Mesa: "0:12(5): error: `x' undeclared"; its preprocessor: "0:3(1): preprocessor error: ..."
    re.compile(r"^\s*(?P<source>\d+):(?P<line>\d+)\((?P<column>\d+)\):\s*"
               r"(?:preprocessor\s+)?(?P<severity>error|warning):\s*(?P<text>.*)$", re.IGNORECASE),
    # NVIDIA: "0(12) : error C1503: undefined variable "x"", "(0) : error C5145: ..." in a link log
    re.compile(r"^\s*(?P<source>\d+)?\((?P<line>\d+)\)\s*:\s*(?:fatal\s+)?(?P<severity>error|warning)"
               r"(?:\s+(?P<code>C\d+))?\s*:\s*(?P<text>.*)$", re.IGNORECASE),
    # AMD, Intel on Windows, Apple, ANGLE, glslang: "ERROR: 0:12: 'x' : undeclared identifier"
    re.compile(r"^\s*(?P<severity>ERROR|WARNING):\s*(?P<source>\d+):(?P<line>\d+):\s*(?P<text>.*)$"),
)
_OLD_AMD_CODE = re.compile(r"^(?:error|warning)\((?P<code>#\d+)\)\s*(?P<text>.*)$")  # "error(#143) Undeclared ..."
_NVIDIA_REFERENCE = re.compile(r"(?<=\bat )(?P<source>\d+)?\((?P<line>\d+)\)")  # "... previous declaration at 0(16)"
_RULE = re.compile(r"^\s*[=-]+\s*$")  # moderngl's "=====" under the stage, NVIDIA's "-----" under "Vertex info"


@dataclass(frozen=True)
class Diagnostic:
    """One compiler message in the engine's form: ``file:line[:column]: severity: text``
    (``file`` and ``line`` None for a message about no line, as most link errors are)."""

    file: str | None
    line: int | None
    column: int | None
    severity: str  # "error" or "warning"
    text: str

    def __str__(self) -> str:
        if self.file is None:
            return f"{self.severity}: {self.text}"
        column = f":{self.column}" if self.column is not None else ""
        return f"{self.file}:{self.line}{column}: {self.severity}: {self.text}"


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

    def place(self, reported: int) -> tuple[str, int] | None:
        """The (file, line) of a line number the driver reported; None for line 0 (no line)
        or a number no file of this program has."""
        number, line = divmod(reported, LINE_STRIDE)
        if reported <= 0 or number >= len(self.names):
            return None
        return self.names[number], line

    def diagnostic(self, log_line: str) -> Diagnostic | None:
        """``log_line`` of any driver's log as a ``Diagnostic``; None for a line that is no
        message (a header, a rule, a count of errors) or names a line no file has."""
        for pattern in _DRIVER_LINES:
            match = pattern.match(log_line)
            if match is not None:
                break
        else:
            return None
        text = match.group("text").strip()
        code = match.groupdict().get("code")
        old_amd = _OLD_AMD_CODE.match(text)
        if old_amd is not None:
            code, text = old_amd.group("code"), old_amd.group("text")
        if pattern is _DRIVER_LINES[1]:
            text = _NVIDIA_REFERENCE.sub(self._reference, text)
        if code:
            text = f"{text} [{code}]"
        severity = match.group("severity").lower()
        reported = int(match.group("line"))
        if reported == 0:
            return Diagnostic(None, None, None, severity, text)
        place = self.place(reported)
        if place is None:
            return None
        column = match.groupdict().get("column")
        return Diagnostic(place[0], place[1], int(column) if column else None, severity, text)

    def _reference(self, match: re.Match[str]) -> str:
        place = self.place(int(match.group("line")))
        return match.group(0) if place is None else f"{place[0]}:{place[1]}"

    def diagnostics(self, log: str) -> list[Diagnostic]:
        """Every message of a driver's ``log``, in the engine's form."""
        return [d for d in map(self.diagnostic, log.splitlines()) if d is not None]

    def readable(self, log: str) -> str:
        """``log`` with every driver message rewritten in the engine's form (``Diagnostic``),
        and the blank lines and rules left out; other lines are kept as they are."""
        out = []
        for line in log.splitlines():
            if not line.strip() or _RULE.match(line):
                continue
            found = self.diagnostic(line)
            out.append(line.rstrip() if found is None else str(found))
        return "\n".join(out)


class ShaderBuildError(ShaderError):
    """A program whose shaders did not compile or link; ``diagnostics`` holds the driver's
    messages in the engine's form."""

    def __init__(self, message: str, diagnostics: list[Diagnostic]) -> None:
        super().__init__(message)
        self.diagnostics = diagnostics


class _NotRegularFile(Exception):
    def __init__(self, kind: str) -> None:
        super().__init__(kind)
        self.kind = kind
        self.mtime_ns: int | None = None  # (its time and size, where ``_read_file`` looked)
        self.size: int | None = None


def _kind(mode: int) -> str:
    for test, kind in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device")):
        if test(mode):
            return kind
    return "not a regular file"


def _read_bytes(path: Path) -> bytes:
    """The bytes of the regular file at ``path``.  Anything else (a named pipe, whose open
    would wait for a writer forever; a directory; a device) raises ``_NotRegularFile``
    without being opened; OSError when it is missing or unreadable."""
    mode = os.stat(path).st_mode
    if not stat.S_ISREG(mode):
        raise _NotRegularFile(_kind(mode))
    # Non-blocking, and looked at again once open: a pipe put there since the stat above
    # opens at once (and is refused) instead of waiting for a writer.
    descriptor = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    with open(descriptor, "rb") as file:
        mode = os.fstat(descriptor).st_mode
        if not stat.S_ISREG(mode):
            raise _NotRegularFile(_kind(mode))
        return file.read()


def _decode(data: bytes, name: str, where: str) -> str:
    """``data`` as text (UTF-8, newlines as ``Path.read_text`` makes them)."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise ShaderError(f"shader file {name!r}{where} is not UTF-8 text: byte 0x{data[exc.start]:02x} "
                          f"at line {line}, column {column} (save it as UTF-8)") from None
    return text.replace("\r\n", "\n").replace("\r", "\n")


def load_source(name: str, defines: dict[str, str] | None = None, *, root: Path | None = None,
                files: SourceFiles | None = None, contents: dict[str, bytes] | None = None) -> str:
    """The full text of shader file ``name`` (relative to ``root``, the ``shaders`` package by
    default) with includes resolved, ``#line`` directives naming each file's own lines, and
    defines added; ``files`` collects the file of each source-string number; ``contents``:
    bytes to use instead of a file's own (a library's last good copies)."""
    root = root or shader_dir()
    files = files if files is not None else SourceFiles()
    all_defines = {**engine_defines(), **(defines or {})}
    text = _expand(name, (), root, files, contents or {}, branches=_Branches(set(all_defines)))
    first, _, rest = text.partition("\n")
    if first.strip() != _VERSION:
        raise ShaderError(f"shader {name!r}: must start with '{_VERSION}' (the 4.1 baseline)")
    header = "".join(f"#define {k} {v}\n" for k, v in all_defines.items())
    rest = _without_trailing_lines(rest)
    return f"{first}\n#line 1\n{header}{_line(2, files.number(name))}\n{rest}"


def _without_trailing_lines(text: str) -> str:
    """``text`` less the ``#line`` directives that end it (and the empty lines after them),
    one newline in their place; ``text`` itself when it does not end with one."""
    end = cut = len(text.rstrip("\n"))
    while (start := text.rfind("\n", 0, cut)) >= 0 and _LINE_DIRECTIVE.fullmatch(text, start + 1, cut):
        cut = start
    return text if cut == end else text[:cut] + "\n"


def engine_defines() -> dict[str, str]:
    """The defines every program is built with: numbers the GLSL shares with Python, each
    made from its one Python owner (the material slot indices, the cube-face table, the
    clip-distance indices of ``engine/render/bindings.py``, the visibility code's kind bits,
    the blocks' array sizes and the tone curves' numbers: ``limit_glsl_defines``; the sky's
    way and the nearest focus: ``lens_rules``)."""
    return {**material_slots.glsl_defines(), **cube_faces.glsl_defines(), **clip_glsl_defines(),
            **visibility_rules.glsl_defines(), **lens_rules.glsl_defines(), **limit_glsl_defines()}


def limit_glsl_defines() -> dict[str, str]:
    """The sizes of the arrays a uniform block or a shader's samplers hold, from the Python
    that packs them (the Lights block: ``views``; the point lights' shadow cubes:
    ``shadows``; the irradiance boxes: ``irradiance``; the environment BRDF's rows:
    ``environment_brdf``; the subsurface band weights' column: ``subsurface``; the virtual lights and the outlines
    each one's line crosses: ``shadow_rules``; where a pose row's morph weights start:
    ``pose_rows``; the motion texture's row: ``object_motion``; the lamps with contact
    shadows: ``components.limits``), each material map's bit in a
    SECOND_UV_MAPS build (its index in ``MATERIAL_IMAGES``: ``UV_BIT_TEXTURE`` ...), and each
    tone curve's number (its index in ``TONEMAP_CURVES``, the number a build's ``TONEMAP_CURVE`` is)."""
    return {"MAX_DIRECTIONAL_LIGHTS": str(views.MAX_DIRECTIONAL_LIGHTS),
            "MAX_POINT_LIGHTS": str(views.MAX_POINT_LIGHTS), "MAX_POINT_SHADOWS": str(views.MAX_POINT_SHADOWS),
            "MAX_SHADOW_RINGS": str(views.MAX_SHADOW_RINGS),
            "MAX_IRRADIANCE_PROBES": str(views.MAX_IRRADIANCE_PROBES),
            "ENVIRONMENT_BRDF_SIZE": str(ENVIRONMENT_BRDF_SIZE),
            "SUBSURFACE_BANDS_COLUMN": str(SUBSURFACE_BANDS_COLUMN), "EARTHSHINE": f"{EARTHSHINE:.9g}",
            "LTC_SIZE": str(LTC_SIZE), "LTC_ROW": str(views.LTC_ROW),
            "MAX_IRRADIANCE_VOLUMES": str(MAX_IRRADIANCE_VOLUMES), "MAX_FOG_VOLUMES": str(MAX_FOG_VOLUMES),
            "MAX_VIRTUAL_LIGHTS": str(shadow_rules.MAX_VIRTUAL_LIGHTS),
            "MAX_APERTURES": str(shadow_rules.MAX_APERTURES),
            "MAX_CONTACT_LAMPS": str(MAX_CONTACT_LAMPS), "MAX_RECT_LIGHTS": str(MAX_RECT_LIGHTS),
            "POSE_WEIGHTS_AT": str(pose_rows.WEIGHTS_AT),
            **object_motion.glsl_defines(),
            **{f"UV_BIT_{name.upper()}": str(1 << index) for index, name in enumerate(MATERIAL_IMAGES)},
            **{f"TONEMAP_{curve.upper()}": str(index) for index, curve in enumerate(TONEMAP_CURVES)}}


def _line(line: int, number: int) -> str:
    """The directive that makes the next line read as ``line`` of file ``number``."""
    return f"#line {number * LINE_STRIDE + line}"


class _Branches:
    """Which ``#ifdef`` branches a build keeps, as far as the names it defines tell, so that an
    ``#include`` in a branch the build leaves out is not expanded: the file is not one of the
    program's (its edits rebuild nothing, a compile error cannot be in it).  A branch is kept
    (True), left out (False) or unknown (None: an ``#if`` expression, or a name defined in an
    unknown branch); an unknown branch's includes are expanded, as the preprocessor may keep
    them.  ``#define`` and ``#undef`` in kept branches are followed, across included files.
    ``defined`` None: the build's names are not known (every branch unknown, every include kept)."""

    def __init__(self, defined: set[str] | None) -> None:
        self.known = defined is not None
        self.defined = defined if defined is not None else set()
        self.unsure: set[str] = set()
        self.open: list[list] = []  # per open #if: [this branch kept?, a branch taken, a branch unknown]

    def kept(self) -> bool | None:
        states = [entry[0] for entry in self.open]
        return False if False in states else None if None in states else True

    def read(self, condition: tuple[str, str] | None, definition: tuple[str, str] | None) -> None:
        """Follow one line of source, as ``_directive`` reads it: an ``#if`` family directive
        and its name, or a ``#define`` or ``#undef`` and its name (other lines change nothing)."""
        if condition is not None:
            self._condition(*condition)
            return
        kept = self.kept()
        if definition is None or kept is False:
            return
        if kept is None:
            self.unsure.add(definition[1])
        elif definition[0] == "define":
            self.defined.add(definition[1])
        else:
            self.defined.discard(definition[1])

    def _condition(self, directive: str, name: str) -> None:
        if directive in ("ifdef", "ifndef", "if"):
            unknown = not self.known or directive == "if" or name in self.unsure
            state = None if unknown else (name in self.defined) == (directive == "ifdef")
            self.open.append([state, state is True, state is None])
        elif not self.open:
            return  # an unbalanced #else or #endif: the driver says so
        elif directive == "endif":
            self.open.pop()
        else:
            entry = self.open[-1]
            if directive == "elif":
                entry[0] = False if entry[1] else None
            else:
                entry[0] = False if entry[1] else None if entry[2] or entry[0] is None else not entry[0]
            entry[2] = entry[2] or entry[0] is None


def _expand(name: str, stack: tuple[str, ...], root: Path, files: SourceFiles,
            contents: dict[str, bytes] | None = None, *, branches: _Branches | None = None) -> str:
    branches = branches if branches is not None else _Branches(None)
    if name in stack:
        raise ShaderError(f"shader include cycle: {' -> '.join(stack + (name,))}")
    where = f" (included from {stack[-1]!r})" if stack else ""
    try:
        data = contents[name] if contents and name in contents else _read_file(os.path.join(str(root), name))[2]
    except _NotRegularFile as exc:
        raise ShaderError(f"shader file {name!r} in {root}{where} is {exc.kind}, not a regular file") from None
    except (FileNotFoundError, NotADirectoryError):
        raise ShaderError(f"shader file {name!r} not found in {root}{where}") from None
    except OSError as exc:
        raise ShaderError(f"shader file {name!r} in {root}{where} could not be read: {exc.strerror}") from None
    number = files.number(name)
    out = []
    for piece in _pieces(data, name, where):
        if isinstance(piece, str):   # (lines with no directive: nothing to follow)
            out.append(piece)
            continue
        index, line, include, branch, condition, definition = piece
        if include is None:
            out.append(line)
            branches.read(condition, definition)
            if branch:
                out.append(_line(index + 1, number))
            continue
        if branches.kept() is False:
            out.append(f"// ({include}: in a branch this build leaves out)")  # (moderngl reads any "#include")
            continue
        included = f"include/{include}"
        out.append(_line(1, files.number(included)))
        out.append(_expand(included, stack + (name,), root, files, contents, branches=branches))
        out.append(_line(index + 1, number))
    return "\n".join(out)


# Each shader file's text cut into pieces once a process, by name: (its bytes, its pieces).
# A program's expansion walks a file's directive lines only; a level builds ~140 programs
# from ~290 sources, each expanding ~13 files, so reading every line in Python again for
# each was most of the time a new process took to expand its programs.
_PIECES: dict[str, tuple[bytes, list]] = {}


def _pieces(data: bytes, name: str, where: str) -> list:
    """File ``name``'s text (``data``) as its runs of lines with no ``#`` (one string each,
    joined) and, between them, each line with one as (its line number, the line, the file it
    includes or None, whether it is an ``#else``, ``#elif`` or ``#endif``, its ``#if`` family
    directive and name or None, its ``#define`` or ``#undef`` and name or None)."""
    known = _PIECES.get(name)
    if known is not None and known[0] == data:
        return known[1]
    pieces: list = []
    run: list[str] = []
    for index, line in enumerate(_decode(data, name, where).split("\n"), start=1):
        if "#" not in line:
            run.append(line)
            continue
        if run:
            pieces.append("\n".join(run))
            run = []
        include, condition, definition = _INCLUDE.match(line), _CONDITION.match(line), _DEFINITION.match(line)
        pieces.append((index, line, include and include.group(1), include is None and _BRANCH.match(line) is not None,
                       condition and condition.group(1, 2), definition and definition.group(1, 2)))
    if run:
        pieces.append("\n".join(run))
    _PIECES[name] = data, pieces
    return pieces


ProgramKey = tuple  # (vertex, fragment, geometry, sorted defines)

# Expanded sources, for the whole process: (root, program key) -> (each stage's source, the
# files it was built from in number order, each one's (mtime_ns, size) when it was read).
# Every Engine has a library of its own (its context's programs), and expanding a program's
# includes in Python was most of a new engine's first frame (~6 ms a program, 36 programs for
# a level with a mirror); a library building a program another built from files that have not
# changed since (the same times and sizes, as the hot reload compares them) takes its sources.
_EXPANDED: dict[tuple, tuple[dict[str, str | None], list[str], list[tuple[int, int]]]] = {}


# The shader files' bytes as last read, for the whole process: path -> (mtime_ns, size, bytes).
# A library remembers every file its programs were built from (the hot reload's last good
# copies); one whose time and size are what another library read is not read again.
_FILE_BYTES: dict[str, tuple[int, int, bytes]] = {}


def _read_file(path: str) -> tuple[int, int, bytes]:
    """(mtime_ns, size, bytes) of the regular file at ``path``, read again only when its time
    or size changed since a library or an expansion last read it (as the hot reload compares
    them); ``_NotRegularFile`` or OSError as ``_read_bytes``."""
    found = os.stat(path)
    known = _FILE_BYTES.get(path)
    if known is not None and known[:2] == (found.st_mtime_ns, found.st_size) and stat.S_ISREG(found.st_mode):
        return known
    try:
        read = found.st_mtime_ns, found.st_size, _read_bytes(Path(path))
    except _NotRegularFile as exc:
        exc.mtime_ns, exc.size = found.st_mtime_ns, found.st_size
        raise
    _FILE_BYTES[path] = read
    return read


def _stamps(root: Path, names: list[str]) -> list[tuple[int, int]] | None:
    """Each file's (mtime_ns, size); None when one cannot be looked at."""
    folder = str(root)
    try:
        return [(found.st_mtime_ns, found.st_size)
                for found in (os.stat(os.path.join(folder, name)) for name in names)]
    except OSError:
        return None


class UniformValues:
    """The values last written to a library's programs' uniforms, so a pass writes one only
    where it differs (a program keeps its uniforms between draws and frames: a level's sizes
    and scales are the same level after level, frame after frame).  The library's own
    (``ShaderLibrary.uniforms``): it hands every writer (the main view's tree, each probe's)
    the same program objects, so they share the one record; it is forgotten when a program
    is rebuilt (a relinked program's uniforms start again from their defaults)."""

    def __init__(self) -> None:
        self.values: dict[tuple[int, str], object] = {}

    def set(self, program: moderngl.Program, name: str, value: object) -> None:
        """``program[name].value = value`` unless that is its value already."""
        key = (program.glo, name)
        if self.values.get(key) != value:
            program[name].value = value
            self.values[key] = value

    def write(self, program: moderngl.Program, name: str, data: bytes) -> None:
        """``program[name].write(data)`` unless those are its bytes already."""
        key = (program.glo, name)
        if self.values.get(key) != data:
            program[name].write(data)
            self.values[key] = data

    def forget(self) -> None:
        """Nothing is known written (after a rebuild or a release)."""
        self.values.clear()


class FreePrograms:
    """The programs of released libraries on one context, by (root, key), waiting for a
    library that needs one built from the same sources (the module's docstring).  Kept in
    the context's ``extra`` (as the samples queries are), so it goes with the context."""

    EXTRA_KEY = "speculum.free_programs"

    def __init__(self) -> None:
        # (root, key) -> [(sources, program)], the longest unused first (dicts keep their order)
        self._free: dict[tuple, list[tuple[dict[str, str | None], moderngl.Program]]] = {}
        self.count = 0  # programs held
        self.most = 0   # the most a library given back held
        # How many the list keeps: None, as many as the fullest library given back held (a
        # level reloaded finds its programs); more where engines with different needs take
        # turns on one context (the test suite keeps 512: a third of its time saved).
        self.keep: int | None = None
        self.taken = 0  # programs handed out instead of built (for tests and benchmarks)
        self.released = False  # after ``release``: a program given is released at once

    @classmethod
    def of(cls, ctx: moderngl.Context) -> FreePrograms:
        """The free list of ``ctx`` (made on first use)."""
        return kept_on(ctx, cls.EXTRA_KEY, cls)

    def take(self, root: Path | None, key: ProgramKey, sources: dict[str, str | None]) -> moderngl.Program | None:
        """A free program of ``key`` linked from ``sources`` (taken off the list), or None."""
        entries = self._free.get((root, key))
        if not entries:
            return None
        for index, (linked, program) in enumerate(entries):
            if linked == sources:
                del entries[index]
                if not entries:
                    del self._free[(root, key)]
                self.count -= 1
                self.taken += 1
                return program
        return None

    def give(self, root: Path | None, key: ProgramKey, sources: dict[str, str | None],
             program: moderngl.Program) -> None:
        """Put ``program`` on the list as a link leaves it: every uniform 0 (no shader gives
        one an initial value) and every block on binding 0, so the library that takes it
        finds what a new program has, whatever the last one wrote."""
        if self.released:
            program.release()
            return
        for member in program._members.values():
            if _is_uniform(member) and member.location >= 0:
                data = member.read()
                if any(data):
                    member.write(bytes(len(data)))
            elif _is_block(member) and member.binding != 0:
                member.binding = 0
        entries = self._free.pop((root, key), [])
        entries.append((sources, program))
        self._free[(root, key)] = entries  # to the end: the most recently used
        self.count += 1

    def trim(self, held: int) -> None:
        """Release the longest unused programs until the list holds at most ``keep`` (by
        default the most any library given back held; ``held``: the one given back now)."""
        self.most = max(self.most, held)
        self.shrink(self.most if self.keep is None else self.keep)

    def shrink(self, keep: int) -> None:
        """Release the longest unused programs until the list holds at most ``keep``: for a
        run that has gone through scenes it will not see again (each set of the scene's
        features, shadow rings, kinds of lamp, fog, is a set of builds of its own: on
        llvmpipe 3-7 MB each, its compiled code), which ``trim``'s rule would keep."""
        while self.count > keep:
            first = next(iter(self._free))
            entries = self._free[first]
            entries.pop(0)[1].release()
            if not entries:
                del self._free[first]
            self.count -= 1

    def release(self) -> None:
        """Release every free program (the context stays) and every one given from now on."""
        self.released = True
        for entries in self._free.values():
            for _, program in entries:
                program.release()
        self._free.clear()
        self.count = 0


class ShaderLibrary:
    """Compiled programs of one context, cached by (files, defines), rebuilt in place when
    a file they were built from changes (``poll``)."""

    def __init__(self, ctx: moderngl.Context, root: Path | None = None,
                 driver_defines: dict[str, str] | None = None) -> None:
        self.ctx = ctx
        self.root = root
        # Defines every program of this context is built with, for what its driver needs
        # (Gpu: BOUNDED_FOOTPRINT on a software rasteriser, shaders/include/footprint.glsl).
        self.driver_defines = dict(driver_defines or {})
        self._programs: dict[ProgramKey, moderngl.Program] = {}
        self._uses: dict[ProgramKey, set[str]] = {}       # the files each program was built from
        self._seen: dict[str, tuple] = {}                # file -> (mtime_ns, size, text) when last read
        self._remembered: dict[ProgramKey, dict[str, tuple]] = {}  # values set once, kept across rebuilds
        self._inputs: dict[ProgramKey, dict[str, int]] = {}  # vertex input locations, kept across rebuilds
        # The sources each program was linked from, where they are the files' own (not a
        # variant built from the files before an edit, not one a reload relinked): those the
        # context's free list may hand to another library (``release``).
        self._built_from: dict[ProgramKey, dict[str, str | None]] = {}
        self.errors: dict[ProgramKey, str] = {}          # programs whose edited files do not build
        self.reloads = 0                                  # programs rebuilt by poll
        self.uniforms = UniformValues()                   # what its programs' uniforms hold, where recorded
        self._good: dict[str, bytes] = {}                # file -> the last contents every program built from
        self._news: list[str] = []                       # said by the next poll (variants built from _good)
        self._next_poll = 0.0
        self._gl: _RelinkGL | None = None
        self.free_programs = FreePrograms.of(ctx)  # taken from and given back to (module docstring)

    def fullscreen(self, fragment: str, defines: dict[str, str] | None = None,
                   **units: int) -> moderngl.VertexArray:
        """A full-screen pass (``fullscreen.vert``'s triangle, three vertices, no buffers) of
        ``fragment``, each sampler named in ``units`` on its unit (one a build does not read is
        passed over): what every post-processing pass draws with."""
        program = self.program("fullscreen.vert", fragment, defines=defines)
        for name, unit in units.items():
            if name in program:
                program[name].value = unit
        return self.ctx.vertex_array(program, [])

    def program(self, vertex: str, fragment: str, geometry: str | None = None,
                defines: dict[str, str] | None = None) -> moderngl.Program:
        key = (vertex, fragment, geometry, tuple(sorted({**self.driver_defines, **(defines or {})}.items())))
        program = self._programs.get(key)
        if program is None:
            files = SourceFiles()
            try:
                program = self._build(key, files, free=self.free_programs)
            except ShaderError as exc:
                program = self._build_before_the_edit(key, files, exc)
            self._programs[key] = program
            self._uses[key] = self._uses.get(key, set()) | set(files.names[1:])
        return program

    def _build_before_the_edit(self, key: ProgramKey, files: SourceFiles, error: ShaderError) -> moderngl.Program:
        """A new variant whose build failed: built from the files as they were before an
        edit that does not build (``_good``), when the failure reached an edited file;
        otherwise (a first build that fails, a missing feature) the error stands."""
        edited = {name for name, good in self._good.items() if self._seen.get(name, (None, None, None))[2] != good}
        if not edited & set(files.names[1:]):
            raise error
        kept = SourceFiles()
        program = self._build(key, kept, contents={name: self._good[name] for name in edited})
        self._uses[key] = set(files.names[1:]) | set(kept.names[1:])
        self.errors[key] = f"{error} (a variant first needed since the edit: built from the files before it)"
        names = ", ".join(f for f in key[:3] if f)
        self._news.append(f"shader error: a new variant of ({names}) is built from the files before the edit, "
                          f"which does not build: {_reasons(error)[0] if _reasons(error) else error}")
        return program

    def _build(self, key: ProgramKey, files: SourceFiles, contents: dict[str, bytes] | None = None,
               free: FreePrograms | None = None) -> moderngl.Program:
        """A new program of ``key``; ``files`` gets the files it was built from (also those
        read before a failure, so a fix to any of them is seen); ``contents``: bytes to build
        some files from instead of their own (``_build_before_the_edit``); ``free``: the
        context's free programs, one of which built from the same sources is taken instead."""
        sources = self._sources(key, files, contents)
        if free is not None:
            program = free.take(self.root, key, sources)
            if program is not None:
                self._built_from[key] = sources
                return program
        vertex, fragment, geometry, _ = key
        try:
            program = self.ctx.program(**sources)
        except moderngl.Error as exc:
            names = ", ".join(f for f in (vertex, geometry, fragment) if f)
            log = str(exc)
            raise ShaderBuildError(f"shader program ({names}) failed to build:\n{files.readable(log)}",
                                   files.diagnostics(log)) from exc
        if contents is None:
            self._built_from[key] = sources
        return program

    def _sources(self, key: ProgramKey, files: SourceFiles, contents: dict[str, bytes] | None) -> dict[str, str | None]:
        """Each stage's expanded source of ``key`` (``_build``'s arguments)."""
        vertex, fragment, geometry, defines = key
        root = self.root or shader_dir()
        expanded = _EXPANDED.get((root, key)) if contents is None else None
        if expanded is not None and _stamps(root, expanded[1]) == expanded[2]:
            sources = expanded[0]
            for name in expanded[1]:
                files.number(name)
            for name in files.names[1:]:
                self._remember_file(name)
        else:
            try:  # one numbering for every stage, so a log line names one file
                sources = {stage: load_source(name, dict(defines), root=self.root, files=files, contents=contents)
                           if name else None
                           for stage, name in (("vertex_shader", vertex), ("fragment_shader", fragment),
                                               ("geometry_shader", geometry))}
            finally:
                for name in files.names[1:]:
                    self._remember_file(name)
            if contents is None:
                stamps = _stamps(root, files.names[1:])
                if stamps is not None and stamps == [self._seen[name][:2] for name in files.names[1:]]:
                    _EXPANDED[(root, key)] = (sources, files.names[1:], stamps)
        return sources

    # --- hot reload ---------------------------------------------------------------------------
    def _path(self, name: str) -> Path:
        return (self.root or shader_dir()) / name

    def _remember_file(self, name: str) -> None:
        if name not in self._seen:
            self._seen[name] = self._read(name)
            contents = self._seen[name][2]
            if isinstance(contents, bytes):
                self._good.setdefault(name, contents)

    def _read(self, name: str) -> tuple:
        """(mtime_ns, size, contents) of file ``name``: its bytes, or for something that is
        not a regular file what it is (never opened), or all None when it is gone (an editor
        saving by rename: rebuilt, and refused, until it is back)."""
        path = os.path.join(str(self.root or shader_dir()), name)
        try:
            return _read_file(path)
        except _NotRegularFile as exc:
            return exc.mtime_ns, exc.size, exc.kind
        except OSError:
            return None, None, None

    def changed_files(self) -> set[str]:
        """Files some program was built from whose bytes changed since they were last read
        (the size and modification time are looked at first, so an unchanged file is not
        read)."""
        changed = set()
        for name, (mtime, size, contents) in list(self._seen.items()):
            try:
                found = os.stat(self._path(name))
                if (found.st_mtime_ns, found.st_size) == (mtime, size):
                    continue
            except OSError:
                if contents is None:
                    continue
            now = self._read(name)
            self._seen[name] = now
            if now[2] != contents:
                changed.add(name)
        return changed

    def poll(self, now: float | None = None) -> list[str]:
        """Rebuild the programs whose files changed, at most every ``POLL_INTERVAL`` seconds
        (the window shell calls it each frame).  Returns what ``reload`` says, so each change
        is reported once."""
        now = time.monotonic() if now is None else now
        news, self._news = self._news, []
        if now < self._next_poll:
            return news
        self._next_poll = now + POLL_INTERVAL
        return news + self.reload(self.changed_files())

    def reload(self, changed: set[str]) -> list[str]:
        """Rebuild every program built from one of ``changed``; a program whose new build
        fails keeps drawing with its old one and its error goes to ``errors``.  Returns at
        most two messages: one for the errors (each distinct error line once, however many
        programs and variants share it), one line for the programs rebuilt."""
        rebuilt, failed, edited = [], {}, set()
        for key, program in list(self._programs.items()):
            touched = self._uses[key] & changed
            if not touched:
                continue
            files = SourceFiles()
            self._built_from.pop(key, None)  # relinked in place: its own library's to the end
            try:
                built = self._build(key, files)
                self._built_from.pop(key, None)
                self._uses[key] = set(files.names[1:])
                self._swap_in(key, program, built)
            except ShaderError as exc:
                self._uses[key] |= set(files.names[1:])  # a file the broken build reached, the fix may be in
                self.errors[key] = str(exc)
                failed[key] = _reasons(exc)
                continue
            self.errors.pop(key, None)
            self.reloads += 1
            self.uniforms.forget()
            rebuilt.append(key)
            edited |= touched
        broken = set().union(*(self._uses[key] for key in failed)) if failed else set()
        for name in changed - broken:  # every program built from it builds: its contents are good now
            contents = self._seen.get(name, (None, None, None))[2]
            if isinstance(contents, bytes):
                self._good[name] = contents
        messages = []
        if failed:
            reasons = list(dict.fromkeys(line for lines in failed.values() for line in lines))
            head = f"shader error, previous build kept for {_programs(failed)}"
            messages.append(f"{head}: {reasons[0]}" if len(reasons) == 1 else "\n".join([f"{head}:", *reasons]))
        if rebuilt:
            kept = f"; {len(failed)} kept the previous build" if failed else ""
            messages.append(f"shader reloaded: {', '.join(sorted(edited))} "
                            f"({_count(len(rebuilt), 'program')} rebuilt{kept})")
        return messages

    def _swap_in(self, key: ProgramKey, program: moderngl.Program, built: moderngl.Program) -> None:
        """Relink ``program``'s GL object with ``built``'s shaders (see the module's docstring)
        and make moderngl's view of it (uniforms, blocks, vertex inputs) the new build's."""
        if self._gl is None:
            self._gl = _RelinkGL(self.ctx)
        gl = self._gl
        remembered = self._remembered.setdefault(key, {})
        for name, member in program._members.items():
            if _is_uniform(member) and member.location >= 0:
                try:
                    remembered[name] = ("uniform", member.gl_type, member.array_length, member.value)
                except Exception:  # noqa: BLE001 - a type moderngl cannot read back: the passes write it again
                    pass
            elif _is_block(member):
                remembered[name] = ("block", member.binding)
        # Vertex inputs stay where the first build put them (the vertex arrays were made for
        # those), also through a build that dropped one: it may come back.
        inputs = self._inputs.setdefault(key, {})
        inputs.update({name: at for name, at in program._attribute_locations.items() if at >= 0 and name not in inputs})
        glo = program.glo
        try:
            gl.relink(glo, built.glo, inputs)
        except ShaderError:
            built.release()
            self._locate(program)  # the old shaders were linked again: their values start from 0
            self._restore(program, remembered)
            raise
        members = {}
        for name, member in built._members.items():
            target = program._members.get(name)
            if target is None or type(target) is not type(member):
                target = member
            else:
                extra = target.extra
                target.__dict__.update(member.__dict__)
                target.extra = extra
            target.program_obj = glo
            members[name] = target
        for name, member in program._members.items():
            if name not in members and (_is_uniform(member) or _is_block(member)):
                members[name] = member  # the new build dropped it: _locate makes it harmless
        program._members = members
        program._geom, program._subroutines = built._geom, built._subroutines
        self._locate(program)
        self._restore(program, remembered)
        built.release()  # its shaders stay alive attached to the relinked program

    def _locate(self, program: moderngl.Program) -> None:
        """Read every uniform's location, block's index and vertex input's location of the
        (relinked) ``program`` into moderngl's objects; a uniform it no longer has gets -1,
        whose writes GL ignores."""
        gl, glo = self._gl, program.glo
        for name, member in program._members.items():
            if _is_uniform(member):
                member.location = gl.uniform_location(glo, name)
            elif _is_block(member):
                index = gl.block_index(glo, name)
                if index < 0:
                    program._members[name] = _DroppedBlock(name)
                else:
                    member.index = index
            elif _is_attribute(member):
                member.location = gl.attribute_location(glo, name)
        inputs = [m for m in program._members.values() if _is_attribute(m) and m.location >= 0]
        program._attribute_locations = {m.name: m.location for m in inputs}
        program._attribute_types = {m.location: m for m in inputs}

    @staticmethod
    def _restore(program: moderngl.Program, remembered: dict[str, tuple]) -> None:
        """Write back the values of ``remembered`` (what the engine set, even in a build that
        dropped the uniform) into the uniforms and blocks of the same name and type."""
        for name, member in program._members.items():
            value = remembered.get(name)
            if value is None:
                continue
            if value[0] == "uniform" and _is_uniform(member) and member.location >= 0 \
                    and (member.gl_type, member.array_length) == value[1:3]:
                member.value = value[3]
            elif value[0] == "block" and _is_block(member):
                member.binding = value[1]

    def release(self) -> None:
        """Hand every program built from the files' own sources to the context's free list
        (``FreePrograms``); release the others."""
        free = self.free_programs
        for key, program in self._programs.items():
            sources = self._built_from.get(key)
            if sources is None or key in self.errors:
                program.release()
            else:
                free.give(self.root, key, sources, program)
        free.trim(len(self._programs))
        self._programs.clear()
        self._built_from.clear()
        self.uniforms.forget()
        self._uses.clear()
        self._seen.clear()


def _reasons(error: ShaderError) -> list[str]:
    """The lines that say why a build failed: its error messages in the engine's form (not
    the warnings, which differ between the variants of one program), else the whole text."""
    found = [str(d) for d in getattr(error, "diagnostics", ()) if d.severity == "error"]
    return found or [line for line in str(error).splitlines() if line.strip()]


def _programs(keys) -> str:
    """``keys`` named by their files, variants of one program counted, not listed."""
    variants: dict[str, int] = {}
    for key in keys:
        name = " + ".join(f for f in (key[0], key[2], key[1]) if f)
        variants[name] = variants.get(name, 0) + 1
    named = [name + (f" ({count} variants)" if count > 1 else "") for name, count in variants.items()]
    return ", ".join(named[:3]) + (f" and {_count(len(named) - 3, 'other program')}" if len(named) > 3 else "")


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _is_uniform(member) -> bool:
    return type(member).__name__ == "Uniform"


def _is_attribute(member) -> bool:
    return type(member).__name__ == "Attribute"


def _is_block(member) -> bool:
    return type(member).__name__ == "UniformBlock"


class _DroppedBlock:
    """Stands for a uniform block a rebuilt program no longer has: binding it does nothing
    (as GL does with a uniform at location -1), so the pass that binds it keeps running."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.binding = 0
        self.value = 0
        self.extra = None


_u = ctypes.c_uint
_i = ctypes.c_int
_RELINK_SIGNATURES = {
    "glCreateProgram": (_u,),
    "glDeleteProgram": (None, _u),
    "glAttachShader": (None, _u, _u),
    "glDetachShader": (None, _u, _u),
    "glGetAttachedShaders": (None, _u, _i, ctypes.POINTER(_i), ctypes.POINTER(_u)),
    "glBindAttribLocation": (None, _u, _u, ctypes.c_char_p),
    "glLinkProgram": (None, _u),
    "glGetProgramiv": (None, _u, _u, ctypes.POINTER(_i)),
    "glGetProgramInfoLog": (None, _u, _i, ctypes.POINTER(_i), ctypes.c_char_p),
    "glGetUniformLocation": (_i, _u, ctypes.c_char_p),
    "glGetUniformBlockIndex": (_u, _u, ctypes.c_char_p),
    "glGetAttribLocation": (_i, _u, ctypes.c_char_p),
}
GL_LINK_STATUS = 0x8B82
GL_INVALID_INDEX = 0xFFFFFFFF


class _RelinkGL:
    """The raw GL calls of a relink (moderngl can only make new programs)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.gl = {name: load_gl_function(ctx, name, ctypes.CFUNCTYPE(*sig))
                   for name, sig in _RELINK_SIGNATURES.items()}
        missing = [name for name, fn in self.gl.items() if fn is None]
        if missing:
            raise ShaderError(f"shader hot reload needs GL entry points the loader lacks: {missing}")

    def attached(self, program: int) -> list[int]:
        count, names = _i(0), (_u * 8)()
        self.gl["glGetAttachedShaders"](program, 8, ctypes.byref(count), names)
        return list(names)[:count.value]

    def relink(self, program: int, source: int, attributes: dict[str, int]) -> None:
        """Give ``program`` the shaders of ``source`` and link it, each of ``attributes`` at its
        old location; if that link fails the old shaders are put back and relinked."""
        gl = self.gl
        old, new = self.attached(program), self.attached(source)
        holder = gl["glCreateProgram"]()  # keeps the old shaders alive (moderngl flagged them for deletion)
        try:
            for shader in old:
                gl["glAttachShader"](holder, shader)
                gl["glDetachShader"](program, shader)
            for shader in new:
                gl["glAttachShader"](program, shader)
            for name, location in attributes.items():
                gl["glBindAttribLocation"](program, location, name.encode())
            gl["glLinkProgram"](program)
            if self._linked(program):
                return
            log = self._log(program)
            for shader in new:
                gl["glDetachShader"](program, shader)
            for shader in old:
                gl["glAttachShader"](program, shader)
            gl["glLinkProgram"](program)
            raise ShaderError(f"shader program could not keep its vertex inputs at their locations "
                              f"(restart to use the new build): {log}")
        finally:
            gl["glDeleteProgram"](holder)

    def _linked(self, program: int) -> bool:
        status = _i(0)
        self.gl["glGetProgramiv"](program, GL_LINK_STATUS, ctypes.byref(status))
        return bool(status.value)

    def _log(self, program: int) -> str:
        text = ctypes.create_string_buffer(4096)
        self.gl["glGetProgramInfoLog"](program, len(text), None, text)
        return text.value.decode(errors="replace").strip()

    def uniform_location(self, program: int, name: str) -> int:
        return self.gl["glGetUniformLocation"](program, name.encode())

    def block_index(self, program: int, name: str) -> int:
        index = self.gl["glGetUniformBlockIndex"](program, name.encode())
        return -1 if index == GL_INVALID_INDEX else index

    def attribute_location(self, program: int, name: str) -> int:
        return self.gl["glGetAttribLocation"](program, name.encode())
