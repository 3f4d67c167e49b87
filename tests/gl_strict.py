"""A test-only GL 4.1 spec checker for what llvmpipe forgives and a GPU driver may not.

``strict_draws(ctx)`` wraps ``moderngl.VertexArray.render`` and ``moderngl.Framebuffer.clear``
for as long as it is entered (never in product code paths: tests only) and, after every
draw, reads back from the driver (glGet calls) the state the draw used:

- every active sampler uniform of the current program, its unit and its type, and the
  texture bound on that unit for the sampler's target, with the sampler object bound there;
- **texture completeness** (GL 4.1 core 3.8.14): the base level defined, every level a
  mipmapped minification filter reaches (base .. min(max level, base + log2 size)) defined
  at the right size and format, an integer-format texture filtered NEAREST (magnification)
  and NEAREST or NEAREST_MIPMAP_NEAREST (minification), with the filter of the sampler
  object on the unit if there is one; a cube map's six faces alike.  An incomplete texture
  reads (0, 0, 0, 1) on a GPU;
- **sampler type against format** (GLSL 4.10 8.9): ``usampler*`` on an unsigned-integer
  format, ``isampler*`` on a signed one, a float ``sampler*`` on neither; a shadow sampler
  on a depth texture with TEXTURE_COMPARE_MODE on, a non-shadow one on a depth texture
  with it off (either way round: undefined);
- two samplers of different types on one unit in one program (GL 4.1 2.11.7: the draw is
  GL_INVALID_OPERATION on drivers that validate);
- **rendering feedback loops** (GL 4.1 4.4.3): an image of a texture the draw may sample
  (the levels its filter reaches) attached to the bound draw framebuffer, colour or depth,
  whether or not the draw writes that attachment;
- **uniform blocks**: each active block of the program has a buffer bound at its binding,
  the bound range at least the block's std140 size, inside the buffer, its offset a
  multiple of GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT (GL 4.1 2.11.7);
- **clip distances**: every enabled GL_CLIP_DISTANCEi is written by the program's last
  stage before rasterisation (geometry, else vertex: GL 4.1 2.20, an enabled distance not
  written is undefined), read from the sources of programs made while the check is on
  (``ctx.program`` is wrapped too: the shader library's #defines and #ifdefs resolved);
- **fragment outputs against draw buffers** (GL 4.1 4.2.1, 3.9.2): every draw buffer with a
  colour attachment and its write mask on gets a fragment output at its location (else
  the value written is undefined), of the attachment's kind (float for float and
  normalised formats, uint for unsigned-integer ones, int for signed);
- **GL 4.1's minimum limits** (what every 4.1 driver gives; Apple's is near them): at most
  16 samplers a program (GL_MAX_TEXTURE_IMAGE_UNITS), 12 uniform blocks (per stage, so
  this counts the program's), each at most 16384 bytes (GL_MAX_UNIFORM_BLOCK_SIZE), and
  at most 1024 components of default-block uniforms (GL_MAX_FRAGMENT_UNIFORM_COMPONENTS,
  counted over the program: conservative);
- **clears**: ``Framebuffer.clear`` (glClear with float clear values) on a framebuffer with
  an integer colour attachment in its draw buffers (GL 4.1 4.2.3: undefined).

Problems are collected, each once, with the engine function (file, line) that drew, in
``StrictGL.problems``.  ``noisy_textures()`` is the other half: inside it, every texture moderngl makes without data
is made full of NaN or noise, and every buffer made with room only full of random bytes
(where llvmpipe zero-fills and a GPU hands back whatever its memory held), so a frame that
reads what no pass wrote differs from the frame drawn without it.

A sampler whose unit holds no texture of its target (texture 0, the
default texture: incomplete, reads (0, 0, 0, 1)) is defined behaviour and may be a branch
never taken: it is collected apart, in ``StrictGL.unbound``.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import re
import sys
from collections.abc import Iterator

import moderngl
import numpy as np

from engine.render.free_depth_images import FreeDepthImages

_u = ctypes.c_uint
_i = ctypes.c_int
_P = ctypes.POINTER

_SIGNATURES = {
    "glGetIntegerv": (None, _u, _P(_i)),
    "glGetProgramiv": (None, _u, _u, _P(_i)),
    "glGetActiveUniform": (None, _u, _u, _i, _P(_i), _P(_i), _P(_u), ctypes.c_char_p),
    "glGetUniformLocation": (_i, _u, ctypes.c_char_p),
    "glGetUniformiv": (None, _u, _i, _P(_i)),
    "glActiveTexture": (None, _u),
    "glGetTexParameteriv": (None, _u, _u, _P(_i)),
    "glGetTexLevelParameteriv": (None, _u, _i, _u, _P(_i)),
    "glGetSamplerParameteriv": (None, _u, _u, _P(_i)),
    "glGetFramebufferAttachmentParameteriv": (None, _u, _u, _u, _P(_i)),
    "glGetActiveUniformBlockiv": (None, _u, _u, _u, _P(_i)),
    "glGetActiveUniformBlockName": (None, _u, _u, _i, _P(_i), ctypes.c_char_p),
    "glGetIntegeri_v": (None, _u, _u, _P(_i)),
    "glGetNamedBufferParameteriv": (None, _u, _u, _P(_i)),  # 4.5, the test context's (never the engine's)
    "glIsEnabled": (ctypes.c_ubyte, _u),
    "glGetBooleani_v": (None, _u, _u, _P(ctypes.c_ubyte)),
    # program interface queries (4.3; the test context's only): the fragment outputs
    "glGetProgramInterfaceiv": (None, _u, _u, _u, _P(_i)),
    "glGetProgramResourceiv": (None, _u, _u, _u, _i, _P(_u), _i, _P(_i), _P(_i)),
    "glGetProgramResourceName": (None, _u, _u, _u, _i, _P(_i), ctypes.c_char_p),
}

# what the checks read beyond OpenGL 4.1 (the test context's; skipped where it has none)
_LATER_THAN_41 = ("glGetNamedBufferParameteriv", "glGetProgramInterfaceiv", "glGetProgramResourceiv",
                  "glGetProgramResourceName")
GL_CURRENT_PROGRAM = 0x8B8D
GL_ACTIVE_UNIFORMS = 0x8B86
GL_ACTIVE_TEXTURE = 0x84E0
GL_TEXTURE0 = 0x84C0
GL_SAMPLER_BINDING = 0x8919
GL_DRAW_FRAMEBUFFER = 0x8CA9
GL_DRAW_FRAMEBUFFER_BINDING = 0x8CA6
GL_MAX_COLOR_ATTACHMENTS = 0x8CDF
GL_DRAW_BUFFER0 = 0x8825
GL_COLOR_ATTACHMENT0 = 0x8CE0
GL_DEPTH_ATTACHMENT = 0x8D00
GL_FRAMEBUFFER_ATTACHMENT_OBJECT_TYPE = 0x8CD0
GL_FRAMEBUFFER_ATTACHMENT_OBJECT_NAME = 0x8CD1
GL_FRAMEBUFFER_ATTACHMENT_TEXTURE_LEVEL = 0x8CD2
GL_FRAMEBUFFER_ATTACHMENT_TEXTURE_LAYER = 0x8CD4
GL_FRAMEBUFFER_ATTACHMENT_COMPONENT_TYPE = 0x8211
GL_TEXTURE = 0x1702
GL_INT = 0x1404
GL_UNSIGNED_INT = 0x1405
GL_TEXTURE_MIN_FILTER = 0x2801
GL_TEXTURE_MAG_FILTER = 0x2800
GL_TEXTURE_BASE_LEVEL = 0x813C
GL_TEXTURE_MAX_LEVEL = 0x813D
GL_TEXTURE_COMPARE_MODE = 0x884C
GL_TEXTURE_WIDTH = 0x1000
GL_TEXTURE_HEIGHT = 0x1001
GL_TEXTURE_DEPTH = 0x8071
GL_TEXTURE_INTERNAL_FORMAT = 0x1003
GL_NEAREST = 0x2600
GL_LINEAR = 0x2601
GL_NEAREST_MIPMAP_NEAREST = 0x2700
GL_NONE = 0
GL_ACTIVE_UNIFORM_BLOCKS = 0x8A36
GL_UNIFORM_BLOCK_BINDING = 0x8A3F
GL_UNIFORM_BLOCK_DATA_SIZE = 0x8A40
GL_UNIFORM_BUFFER_BINDING = 0x8A28
GL_UNIFORM_BUFFER_START = 0x8A29
GL_UNIFORM_BUFFER_SIZE = 0x8A2A
GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT = 0x8A34
GL_BUFFER_SIZE = 0x8764
GL_CLIP_DISTANCE0 = 0x3000
GL_PROGRAM_OUTPUT = 0x92E4
GL_ACTIVE_RESOURCES = 0x92F5
GL_LOCATION = 0x930E
GL_TYPE = 0x92FA
GL_ARRAY_SIZE = 0x92FB
GL_COLOR_WRITEMASK = 0x0C23
GL_MAX_DRAW_BUFFERS = 0x8824
GL_UNSIGNED_NORMALIZED = 0x8C17
GL_SIGNED_NORMALIZED = 0x8F9C
# an output's GLSL type -> "float", "int" or "uint"
_OUTPUT_KIND = {**{t: "float" for t in (0x1406, 0x8B50, 0x8B51, 0x8B52)},
                **{t: "int" for t in (0x1404, 0x8B53, 0x8B54, 0x8B55)},
                **{t: "uint" for t in (0x1405, 0x8DC6, 0x8DC7, 0x8DC8)}}
CLIP_DISTANCES = 8

GL_TEXTURE_2D, GL_TEXTURE_3D, GL_TEXTURE_CUBE_MAP, GL_TEXTURE_2D_ARRAY = 0x0DE1, 0x806F, 0x8513, 0x8C1A
GL_TEXTURE_CUBE_MAP_POSITIVE_X = 0x8515
_BINDING = {GL_TEXTURE_2D: 0x8069, GL_TEXTURE_3D: 0x806A, GL_TEXTURE_CUBE_MAP: 0x8514, GL_TEXTURE_2D_ARRAY: 0x8C1D}
_TARGET_NAME = {GL_TEXTURE_2D: "2D", GL_TEXTURE_3D: "3D", GL_TEXTURE_CUBE_MAP: "cube", GL_TEXTURE_2D_ARRAY: "2D array"}

# sampler type -> (name, target, kind: "float" / "int" / "uint", shadow)
_SAMPLERS = {
    0x8B5E: ("sampler2D", GL_TEXTURE_2D, "float", False),
    0x8B5F: ("sampler3D", GL_TEXTURE_3D, "float", False),
    0x8B60: ("samplerCube", GL_TEXTURE_CUBE_MAP, "float", False),
    0x8B62: ("sampler2DShadow", GL_TEXTURE_2D, "float", True),
    0x8DC1: ("sampler2DArray", GL_TEXTURE_2D_ARRAY, "float", False),
    0x8DC4: ("sampler2DArrayShadow", GL_TEXTURE_2D_ARRAY, "float", True),
    0x8DC5: ("samplerCubeShadow", GL_TEXTURE_CUBE_MAP, "float", True),
    0x8DCA: ("isampler2D", GL_TEXTURE_2D, "int", False),
    0x8DCB: ("isampler3D", GL_TEXTURE_3D, "int", False),
    0x8DCC: ("isamplerCube", GL_TEXTURE_CUBE_MAP, "int", False),
    0x8DCF: ("isampler2DArray", GL_TEXTURE_2D_ARRAY, "int", False),
    0x8DD2: ("usampler2D", GL_TEXTURE_2D, "uint", False),
    0x8DD3: ("usampler3D", GL_TEXTURE_3D, "uint", False),
    0x8DD4: ("usamplerCube", GL_TEXTURE_CUBE_MAP, "uint", False),
    0x8DD7: ("usampler2DArray", GL_TEXTURE_2D_ARRAY, "uint", False),
}

_UINT_FORMATS = {0x8232: "R8UI", 0x8234: "R16UI", 0x8236: "R32UI", 0x8238: "RG8UI", 0x823A: "RG16UI",
                 0x823C: "RG32UI", 0x8D7D: "RGB8UI", 0x8D77: "RGB16UI", 0x8D71: "RGB32UI", 0x8D7C: "RGBA8UI",
                 0x8D76: "RGBA16UI", 0x8D70: "RGBA32UI", 0x906F: "RGB10_A2UI"}
_INT_FORMATS = {0x8231: "R8I", 0x8233: "R16I", 0x8235: "R32I", 0x8237: "RG8I", 0x8239: "RG16I", 0x823B: "RG32I",
                0x8D8F: "RGB8I", 0x8D89: "RGB16I", 0x8D83: "RGB32I", 0x8D8E: "RGBA8I", 0x8D88: "RGBA16I",
                0x8D82: "RGBA32I"}
_DEPTH_FORMATS = {0x1902: "DEPTH_COMPONENT", 0x81A5: "DEPTH_COMPONENT16", 0x81A6: "DEPTH_COMPONENT24",
                  0x81A7: "DEPTH_COMPONENT32", 0x8CAC: "DEPTH_COMPONENT32F", 0x88F0: "DEPTH24_STENCIL8",
                  0x8CAD: "DEPTH32F_STENCIL8"}
# a uniform's GLSL type -> its components (matrices: columns x rows)
_UNIFORM_COMPONENTS = {0x1406: 1, 0x8B50: 2, 0x8B51: 3, 0x8B52: 4, 0x1404: 1, 0x8B53: 2, 0x8B54: 3, 0x8B55: 4,
                       0x1405: 1, 0x8DC6: 2, 0x8DC7: 3, 0x8DC8: 4, 0x8B56: 1, 0x8B57: 2, 0x8B58: 3, 0x8B59: 4,
                       0x8B5A: 4, 0x8B5B: 9, 0x8B5C: 16, 0x8B65: 6, 0x8B66: 8, 0x8B67: 6, 0x8B68: 12,
                       0x8B69: 8, 0x8B6A: 12}
_MIPMAPPED = {0x2700, 0x2701, 0x2702, 0x2703}
_ENGINE_ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), ".."))


def _kind(internal_format: int) -> str:
    if internal_format in _UINT_FORMATS:
        return "uint"
    if internal_format in _INT_FORMATS:
        return "int"
    return "float"


def _format_name(internal_format: int) -> str:
    return (_UINT_FORMATS.get(internal_format) or _INT_FORMATS.get(internal_format)
            or _DEPTH_FORMATS.get(internal_format) or hex(internal_format))


def _where() -> str:
    """The innermost engine or shell function on the stack (the pass that drew), as file:line."""
    frame = sys._getframe(2)
    while frame is not None:
        path = os.path.normpath(frame.f_code.co_filename)
        relative = os.path.relpath(path, _ENGINE_ROOT)
        if relative.startswith(("engine", "shell")) and "bindings.py" not in relative:
            return f"{relative}:{frame.f_lineno} ({frame.f_code.co_name})"
        frame = frame.f_back
    return "outside the engine"


_DIRECTIVE = re.compile(r"^\s*#\s*(\w+)\s*(.*?)\s*(//.*)?$")
_CLIP_WRITE = re.compile(r"gl_ClipDistance\s*\[\s*([^\]]+?)\s*\]\s*=(?!=)")


def _condition(expression: str, defines: dict[str, str]) -> bool:
    """A #if expression of the shaders (defined(X), names, integers, !, &&, ||, comparisons)."""
    text = re.sub(r"defined\s*\(\s*(\w+)\s*\)|defined\s+(\w+)",
                  lambda m: " 1 " if (m.group(1) or m.group(2)) in defines else " 0 ", expression)

    def value(match: re.Match) -> str:
        word = match.group(0)
        if word.isdigit():
            return word
        seen = set()
        while word in defines and word not in seen:
            seen.add(word)
            word = defines[word].strip() or "1"
        return word if re.fullmatch(r"\d+", word) else "0"
    text = re.sub(r"\b\w+\b", value, text)
    text = text.replace("&&", " and ").replace("||", " or ")
    text = re.sub(r"!(?!=)", " not ", text)
    return bool(eval(text, {"__builtins__": {}}))  # noqa: S307 - the engine's own shader text


def clip_writes(source: str) -> set[int] | None:
    """The gl_ClipDistance indices ``source`` (one stage, includes and #defines in place)
    writes outside inactive #if blocks; None where an index is not a constant (a loop)."""
    defines: dict[str, str] = {}
    stack: list[tuple[bool, bool]] = []  # (this branch on, some branch of the group taken)
    written: set[int] = set()
    for line in source.splitlines():
        on = all(active for active, _ in stack)
        directive = _DIRECTIVE.match(line)
        if directive:
            word, rest = directive.group(1), directive.group(2)
            if word in ("ifdef", "ifndef", "if"):
                hit = (rest.split()[0] in defines) if word == "ifdef" else \
                    (rest.split()[0] not in defines) if word == "ifndef" else _condition(rest, defines)
                stack.append((hit, hit))
            elif word == "elif":
                taken = stack[-1][1]
                hit = not taken and _condition(rest, defines)
                stack[-1] = (hit, taken or hit)
            elif word == "else":
                stack[-1] = (not stack[-1][1], True)
            elif word == "endif":
                stack.pop()
            elif word == "define" and on:
                parts = rest.split(None, 1)
                if parts and "(" not in parts[0]:
                    defines[parts[0]] = parts[1] if len(parts) > 1 else ""
            continue
        if not on:
            continue
        for match in _CLIP_WRITE.finditer(line.split("//")[0]):
            index = match.group(1)
            seen = set()
            while index in defines and index not in seen:
                seen.add(index)
                index = defines[index].strip()
            if not index.isdigit():
                return None
            written.add(int(index))
    return written


class StrictGL:
    """The checks of the module docstring on one context."""

    def __init__(self, ctx: moderngl.Context) -> None:
        loader = ctx.mglo._context.load_opengl_function
        self.gl = {}
        for name, signature in _SIGNATURES.items():
            address = loader(name)
            if not address:
                if name in _LATER_THAN_41:
                    continue
                raise RuntimeError(f"the strict GL checker needs {name}, which the loader lacks")
            self.gl[name] = ctypes.CFUNCTYPE(*signature)(address)
        # A context of OpenGL 4.1 exactly (Apple's) has no program interface query nor
        # glGetNamedBufferParameteriv: the output and buffer-size checks are skipped there.
        major_minor = tuple(int(v) for v in str(ctx.info.get("GL_VERSION", "0.0")).split()[0].split(".")[:2])
        self.later_calls = all(name in self.gl for name in _LATER_THAN_41) and major_minor >= (4, 5)
        self.problems: dict[str, str] = {}   # problem (words) -> where first seen
        self.unbound: dict[str, str] = {}
        self.draws = 0
        self.clears = 0
        self._programs: dict[int, list[tuple[str, int, int]]] = {}  # program -> (name, location, type)
        self._blocks: dict[int, list[tuple[str, int]]] = {}  # program -> (block name, its index)
        self.block_sizes: dict[str, set[int]] = {}  # block name -> its std140 sizes in the programs drawn with
        self.sources: dict[int, dict[str, str]] = {}  # program -> its stages' sources (made while checking)
        self._clips: dict[int, set[int] | None] = {}
        self._outputs_of: dict[int, dict[int, tuple[str, str]]] = {}
        self._limits_checked: set[int] = set()
        self.largest: dict[str, tuple[int, str]] = {}  # the most of each limit a program used, and where
        self.unknown_programs: set[int] = set()  # drawn with, made before the check: clips not checked
        self.alignment = self._int(GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT)

    # --- GL read-backs ------------------------------------------------------------------
    def _int(self, pname: int) -> int:
        value = (_i * 4)()
        self.gl["glGetIntegerv"](pname, value)
        return value[0]

    def _tex(self, target: int, pname: int) -> int:
        value = _i(0)
        self.gl["glGetTexParameteriv"](target, pname, ctypes.byref(value))
        return value.value

    def _level(self, target: int, level: int, pname: int) -> int:
        value = _i(0)
        self.gl["glGetTexLevelParameteriv"](target, level, pname, ctypes.byref(value))
        return value.value

    def _sampler_param(self, sampler: int, pname: int) -> int:
        value = _i(0)
        self.gl["glGetSamplerParameteriv"](sampler, pname, ctypes.byref(value))
        return value.value

    def _attachment(self, point: int, pname: int) -> int:
        value = _i(0)
        self.gl["glGetFramebufferAttachmentParameteriv"](GL_DRAW_FRAMEBUFFER, point, pname, ctypes.byref(value))
        return value.value

    def _samplers(self, program: int) -> list[tuple[str, int, int]]:
        known = self._programs.get(program)
        if known is not None:
            return known
        count = _i(0)
        self.gl["glGetProgramiv"](program, GL_ACTIVE_UNIFORMS, ctypes.byref(count))
        found = []
        for index in range(count.value):
            name = ctypes.create_string_buffer(256)
            length, size, kind = _i(0), _i(0), _u(0)
            self.gl["glGetActiveUniform"](program, index, 256, ctypes.byref(length), ctypes.byref(size),
                                          ctypes.byref(kind), name)
            if kind.value not in _SAMPLERS:
                continue
            base = name.value.decode().removesuffix("[0]")
            for element in range(size.value):
                element_name = f"{base}[{element}]" if size.value > 1 else base
                location = self.gl["glGetUniformLocation"](program, element_name.encode())
                found.append((element_name, location, kind.value))
        self._programs[program] = found
        return found

    # --- the checks ---------------------------------------------------------------------
    def _note(self, problem: str, where: str, unbound: bool = False) -> None:
        record = self.unbound if unbound else self.problems
        record.setdefault(problem, where)

    def attachments(self) -> list[tuple[str, int, int, int, int]]:
        """The bound draw framebuffer's texture attachments: (point name, texture, level,
        layer, GL attachment point)."""
        if self._int(GL_DRAW_FRAMEBUFFER_BINDING) == 0:
            return []
        found = []
        points = [(f"colour {i}", GL_COLOR_ATTACHMENT0 + i) for i in range(self._int(GL_MAX_COLOR_ATTACHMENTS))]
        for label, point in (*points, ("depth", GL_DEPTH_ATTACHMENT)):
            if self._attachment(point, GL_FRAMEBUFFER_ATTACHMENT_OBJECT_TYPE) != GL_TEXTURE:
                continue
            found.append((label, self._attachment(point, GL_FRAMEBUFFER_ATTACHMENT_OBJECT_NAME),
                          self._attachment(point, GL_FRAMEBUFFER_ATTACHMENT_TEXTURE_LEVEL),
                          self._attachment(point, GL_FRAMEBUFFER_ATTACHMENT_TEXTURE_LAYER), point))
        return found

    def _block_list(self, program: int) -> list[tuple[str, int]]:
        known = self._blocks.get(program)
        if known is None:
            count = _i(0)
            self.gl["glGetProgramiv"](program, GL_ACTIVE_UNIFORM_BLOCKS, ctypes.byref(count))
            known = []
            for index in range(count.value):
                name = ctypes.create_string_buffer(256)
                length = _i(0)
                self.gl["glGetActiveUniformBlockName"](program, index, 256, ctypes.byref(length), name)
                known.append((name.value.decode(), index))
            self._blocks[program] = known
        return known

    def check_limits(self, program: int, where: str) -> None:
        """GL 4.1's minimum limits (module docstring), once a program."""
        if program in self._limits_checked:
            return
        self._limits_checked.add(program)
        samplers = self._samplers(program)
        if len(samplers) > 16:
            self._note(f"{len(samplers)} samplers in one program: past GL 4.1's minimum of 16 texture image "
                       "units a stage", where)
        blocks = self._block_list(program)
        if len(blocks) > 12:
            self._note(f"{len(blocks)} uniform blocks in one program: past GL 4.1's minimum of 12 a stage", where)
        for name, index in blocks:
            value = _i(0)
            self.gl["glGetActiveUniformBlockiv"](program, index, GL_UNIFORM_BLOCK_DATA_SIZE, ctypes.byref(value))
            if value.value > 16384:
                self._note(f"uniform block {name}: {value.value} bytes, past GL 4.1's minimum "
                           "GL_MAX_UNIFORM_BLOCK_SIZE of 16384", where)
        count = _i(0)
        self.gl["glGetProgramiv"](program, GL_ACTIVE_UNIFORMS, ctypes.byref(count))
        components = 0
        for index in range(count.value):
            name = ctypes.create_string_buffer(256)
            length, size, kind = _i(0), _i(0), _u(0)
            self.gl["glGetActiveUniform"](program, index, 256, ctypes.byref(length), ctypes.byref(size),
                                          ctypes.byref(kind), name)
            location = self.gl["glGetUniformLocation"](program, name.value)
            if location < 0 or kind.value in _SAMPLERS:  # in a block (no location), or a sampler
                continue
            components += size.value * _UNIFORM_COMPONENTS.get(kind.value, 4)
        for what, amount in (("samplers", len(samplers)), ("blocks", len(blocks)), ("uniform components", components)):
            if amount > self.largest.get(what, (0, ""))[0]:
                self.largest[what] = (amount, where)
        if components > 1024:
            self._note(f"{components} components of default-block uniforms: past GL 4.1's minimum of 1024 a stage",
                       where)

    def check_blocks(self, program: int, where: str) -> None:
        """Each active uniform block of ``program``: a buffer bound at its binding point, the
        bound range at least the block's std140 size, inside the buffer, its offset aligned
        (GL 4.1 2.11.7: a smaller range reads undefined values)."""
        for name, index in self._block_list(program):
            value = _i(0)
            self.gl["glGetActiveUniformBlockiv"](program, index, GL_UNIFORM_BLOCK_BINDING, ctypes.byref(value))
            binding = value.value
            self.gl["glGetActiveUniformBlockiv"](program, index, GL_UNIFORM_BLOCK_DATA_SIZE, ctypes.byref(value))
            need = value.value
            self.block_sizes.setdefault(name, set()).add(need)
            self.gl["glGetIntegeri_v"](GL_UNIFORM_BUFFER_BINDING, binding, ctypes.byref(value))
            buffer = value.value
            if buffer == 0:
                self._note(f"uniform block {name} (binding {binding}): no buffer bound", where)
                continue
            self.gl["glGetIntegeri_v"](GL_UNIFORM_BUFFER_START, binding, ctypes.byref(value))
            start = value.value
            self.gl["glGetIntegeri_v"](GL_UNIFORM_BUFFER_SIZE, binding, ctypes.byref(value))
            size = value.value
            if self.later_calls:
                self.gl["glGetNamedBufferParameteriv"](buffer, GL_BUFFER_SIZE, ctypes.byref(value))
                whole = value.value
            else:  # (4.1: the buffer's size is not asked; a range is taken as inside it)
                whole = start + max(size, need)
            if size == 0:  # glBindBufferBase: the whole buffer
                size = whole - start
            if size < need:
                self._note(f"uniform block {name} (binding {binding}): {size} bytes bound, the block is {need} "
                           "(std140): reads past the range are undefined", where)
            if start + size > whole:
                self._note(f"uniform block {name} (binding {binding}): range {start}+{size} past the buffer's "
                           f"{whole} bytes", where)
            if start % self.alignment:
                self._note(f"uniform block {name} (binding {binding}): offset {start} not a multiple of "
                           f"GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT ({self.alignment})", where)

    def forget(self, program: int, source: int) -> None:
        """``program`` was linked again with the shaders of ``source`` (a hot reload)."""
        for known in (self._programs, self._blocks, self._clips, self._outputs_of):
            known.pop(program, None)
        self._limits_checked.discard(program)
        self.sources.pop(program, None)
        if source in self.sources:
            self.sources[program] = self.sources[source]

    def check_clips(self, program: int, where: str) -> None:
        """Every enabled clip distance is written by the program's last stage before
        rasterisation."""
        if program not in self._clips:
            sources = self.sources.get(program)
            if sources is None:
                self.unknown_programs.add(program)
                return
            last = sources.get("geometry_shader") or sources.get("vertex_shader") or ""
            self._clips[program] = clip_writes(last)
        written = self._clips[program]
        if written is None:
            return
        enabled = {i for i in range(CLIP_DISTANCES) if self.gl["glIsEnabled"](GL_CLIP_DISTANCE0 + i)}
        if enabled - written:
            first = (self.sources[program].get("vertex_shader") or "").split("\n", 3)[:3]
            self._note(f"clip distances {sorted(enabled - written)} enabled, the program writes only "
                       f"{sorted(written)} (undefined clipping) [{' / '.join(line.strip() for line in first)}]", where)

    def _outputs(self, program: int) -> dict[int, tuple[str, str]]:
        """The program's active fragment outputs: location -> (name, kind)."""
        known = self._outputs_of.get(program)
        if known is not None:
            return known
        count = _i(0)
        self.gl["glGetProgramInterfaceiv"](program, GL_PROGRAM_OUTPUT, GL_ACTIVE_RESOURCES, ctypes.byref(count))
        known = {}
        props = (_u * 3)(GL_LOCATION, GL_TYPE, GL_ARRAY_SIZE)
        for index in range(count.value):
            values = (_i * 3)()
            self.gl["glGetProgramResourceiv"](program, GL_PROGRAM_OUTPUT, index, 3, props, 3, None, values)
            name = ctypes.create_string_buffer(128)
            self.gl["glGetProgramResourceName"](program, GL_PROGRAM_OUTPUT, index, 128, None, name)
            location, kind, size = values
            if location < 0:
                continue
            for element in range(max(1, size)):
                known[location + element] = (name.value.decode(), _OUTPUT_KIND.get(kind, hex(kind)))
        self._outputs_of[program] = known
        return known

    def check_outputs(self, program: int, where: str, attached) -> None:
        """Each enabled draw buffer with a colour attachment has an output of its kind."""
        if self._int(GL_DRAW_FRAMEBUFFER_BINDING) == 0 or not self.later_calls:
            return
        outputs = self._outputs(program)
        by_point = {point: label for label, _, _, _, point in attached}
        for buffer in range(self._int(GL_MAX_DRAW_BUFFERS)):
            point = self._int(GL_DRAW_BUFFER0 + buffer)
            if point == GL_NONE:
                continue
            if point not in by_point:
                if self._attachment(point, GL_FRAMEBUFFER_ATTACHMENT_OBJECT_TYPE) == GL_NONE:
                    continue
            mask = (ctypes.c_ubyte * 4)()
            self.gl["glGetBooleani_v"](GL_COLOR_WRITEMASK, buffer, mask)
            if not any(mask):
                continue
            component = self._attachment(point, GL_FRAMEBUFFER_ATTACHMENT_COMPONENT_TYPE)
            kind = {GL_UNSIGNED_INT: "uint", GL_INT: "int"}.get(component, "float")
            output = outputs.get(buffer)
            if output is None:
                self._note(f"draw buffer {buffer} ({kind} attachment, write mask on) has no fragment output "
                           f"at location {buffer}: the value written is undefined", where)
            elif output[1] != kind:
                self._note(f"fragment output '{output[0]}' ({output[1]}) at location {buffer} writes a {kind} "
                           "attachment: undefined", where)

    def check_draw(self, where: str) -> None:
        self.draws += 1
        program = self._int(GL_CURRENT_PROGRAM)
        if not program:
            return
        self.check_limits(program, where)
        self.check_blocks(program, where)
        self.check_clips(program, where)
        attached = self.attachments()
        self.check_outputs(program, where, attached)
        samplers = self._samplers(program)
        if not samplers:
            return
        active = self._int(GL_ACTIVE_TEXTURE)
        unit_types: dict[int, tuple[str, int]] = {}
        try:
            for name, location, kind in samplers:
                value = _i(0)
                self.gl["glGetUniformiv"](program, location, ctypes.byref(value))
                unit = value.value
                glsl, target, sampler_kind, shadow = _SAMPLERS[kind]
                other = unit_types.setdefault(unit, (name, kind))
                if other[1] != kind:
                    self._note(f"samplers '{other[0]}' ({_SAMPLERS[other[1]][0]}) and '{name}' ({glsl}) share "
                               f"unit {unit} in one program: GL_INVALID_OPERATION at the draw", where)
                self.gl["glActiveTexture"](GL_TEXTURE0 + unit)
                texture = self._int(_BINDING[target])
                label = f"'{name}' ({glsl}, unit {unit})"
                if texture == 0:
                    self._note(f"{label}: no {_TARGET_NAME[target]} texture bound (reads 0, 0, 0, 1)", where,
                               unbound=True)
                    continue
                self._check_texture(label, target, texture, sampler_kind, shadow, where, attached)
        finally:
            self.gl["glActiveTexture"](active)

    def _check_texture(self, label: str, target: int, texture: int, sampler_kind: str, shadow: bool,
                       where: str, attached) -> None:
        sampler = self._int(GL_SAMPLER_BINDING)
        if sampler:
            min_filter = self._sampler_param(sampler, GL_TEXTURE_MIN_FILTER)
            mag_filter = self._sampler_param(sampler, GL_TEXTURE_MAG_FILTER)
            compare = self._sampler_param(sampler, GL_TEXTURE_COMPARE_MODE)
        else:
            min_filter = self._tex(target, GL_TEXTURE_MIN_FILTER)
            mag_filter = self._tex(target, GL_TEXTURE_MAG_FILTER)
            compare = self._tex(target, GL_TEXTURE_COMPARE_MODE)
        base = self._tex(target, GL_TEXTURE_BASE_LEVEL)
        top = self._tex(target, GL_TEXTURE_MAX_LEVEL)
        faces = [GL_TEXTURE_CUBE_MAP_POSITIVE_X + f for f in range(6)] if target == GL_TEXTURE_CUBE_MAP else [target]
        image = faces[0]
        internal = self._level(image, base, GL_TEXTURE_INTERNAL_FORMAT)
        width, height = self._level(image, base, GL_TEXTURE_WIDTH), self._level(image, base, GL_TEXTURE_HEIGHT)
        depth = self._level(image, base, GL_TEXTURE_DEPTH) if target == GL_TEXTURE_3D else 1
        what = f"{label} holds a {_format_name(internal)} {width}x{height} texture"
        via = " (through a sampler object)" if sampler else ""
        if width == 0 or base > top:
            self._note(f"{what}: base level {base} not defined (incomplete: reads 0, 0, 0, 1)", where)
            return
        kind = _kind(internal)
        if kind != sampler_kind:
            self._note(f"{what}: a {sampler_kind} sampler on a {kind} format (undefined)", where)
        if kind != "float" and (mag_filter != GL_NEAREST or min_filter not in (GL_NEAREST, GL_NEAREST_MIPMAP_NEAREST)):
            self._note(f"{what}: integer format filtered {hex(min_filter)}/{hex(mag_filter)}{via} (incomplete: "
                       "reads 0 on a GPU)", where)
        if internal in _DEPTH_FORMATS:
            if shadow and compare == GL_NONE:
                self._note(f"{what}: shadow sampler with TEXTURE_COMPARE_MODE off{via} (undefined)", where)
            if not shadow and compare != GL_NONE:
                self._note(f"{what}: non-shadow sampler with TEXTURE_COMPARE_MODE on{via} (undefined)", where)
        elif shadow:
            self._note(f"{what}: shadow sampler on a colour format (undefined)", where)
        last = base
        if min_filter in _MIPMAPPED:
            last = min(top, base + max(width, height, depth).bit_length() - 1)
            missing = False
            for level in range(base, last + 1):
                if missing:
                    break
                shift = level - base
                want = (max(1, width >> shift), max(1, height >> shift))
                for face in faces:
                    got = (self._level(face, level, GL_TEXTURE_WIDTH), self._level(face, level, GL_TEXTURE_HEIGHT))
                    if got != want or self._level(face, level, GL_TEXTURE_INTERNAL_FORMAT) != internal:
                        self._note(f"{what}: mipmapped filter {hex(min_filter)}{via} reaches level {level} "
                                   f"(max level {top}), which is {got[0]}x{got[1]}, not {want[0]}x{want[1]} "
                                   "(incomplete: reads 0, 0, 0, 1 on a GPU)", where)
                        missing = True
                        break
        elif target == GL_TEXTURE_CUBE_MAP:
            for face in faces[1:]:
                if self._level(face, base, GL_TEXTURE_WIDTH) != width:
                    self._note(f"{what}: cube face {face - faces[0]} of another size (cube incomplete)", where)
        for point, name, level, layer, _ in attached:
            if name == texture and base <= level <= last:
                self._note(f"{what}: level {level} (layer {layer}) is also the draw framebuffer's {point} "
                           "attachment (rendering feedback loop: undefined)", where)

    def check_clear(self, framebuffer: moderngl.Framebuffer, where: str) -> None:
        """A glClear with float clear values on ``framebuffer`` (moderngl's clear)."""
        self.clears += 1
        if framebuffer.glo == 0:
            return
        for index, texture in enumerate(framebuffer.color_attachments):
            mask = framebuffer.color_mask[index] if isinstance(framebuffer.color_mask[0], tuple) \
                else framebuffer.color_mask
            if not any(mask):
                continue
            dtype = getattr(texture, "dtype", "")
            if dtype[:1] in ("u", "i"):
                self._note(f"Framebuffer.clear (glClear, float clear colour) on integer colour attachment {index} "
                           f"({dtype}): undefined for integer buffers "
                           "(glClearBufferuiv/iv)", where)


@contextlib.contextmanager
def strict_draws(ctx: moderngl.Context) -> Iterator[StrictGL]:
    """Inside: every ``VertexArray.render`` and ``Framebuffer.clear`` is checked (module
    docstring); yields the ``StrictGL`` collecting the problems."""
    checker = StrictGL(ctx)
    render, clear = moderngl.VertexArray.render, moderngl.Framebuffer.clear
    make_program = moderngl.Context.program

    def recorded_program(self, *args, **kwargs):
        program = make_program(self, *args, **kwargs)
        names = ("vertex_shader", "fragment_shader", "geometry_shader")
        given = dict(zip(names, args, strict=False))  # (positional: the stages in moderngl's order)
        checker.sources[program.glo] = {**given, **{k: v for k, v in kwargs.items() if v}}
        return program

    def checked_render(self, *args, **kwargs):
        result = render(self, *args, **kwargs)
        checker.check_draw(_where())
        return result

    def checked_clear(self, *args, **kwargs):
        checker.check_clear(self, _where())
        return clear(self, *args, **kwargs)

    # A hot reload links the same GL program again with new shaders (ShaderLibrary's relink):
    # what is known of it (uniform locations, blocks, outputs, sources) is the old build's.
    from engine.render import shader_library
    from tests.support import programs_linked_anew

    relink = shader_library._RelinkGL.relink

    def forgetting_relink(self, program, source, attributes):
        try:
            return relink(self, program, source, attributes)
        finally:
            checker.forget(program, source)

    moderngl.VertexArray.render = checked_render
    moderngl.Framebuffer.clear = checked_clear
    moderngl.Context.program = recorded_program
    shader_library._RelinkGL.relink = forgetting_relink
    try:
        with programs_linked_anew(ctx):  # every program's sources recorded
            yield checker
    finally:
        moderngl.VertexArray.render, moderngl.Framebuffer.clear = render, clear
        moderngl.Context.program = make_program
        shader_library._RelinkGL.relink = relink


# --- memory never written ---------------------------------------------------------------------
_CONSTRUCTORS = ("texture", "depth_texture", "texture_cube", "texture_array", "texture3d")


def _noise(size: tuple[int, ...], components: int, dtype: str, faces: int, rng: np.random.Generator,
           nan: bool = False) -> bytes:
    count = int(np.prod(size)) * components * faces
    if dtype[0] == "f" and dtype != "f1":
        values = np.full(count, np.nan) if nan else rng.uniform(-40.0, 60.0, count)
        return values.astype(np.float16 if dtype == "f2" else np.float32).tobytes()
    if dtype in ("u4", "i4"):
        return rng.integers(0, 2**32, count, dtype=np.uint32).tobytes()
    itemsize = {"f1": 1, "u1": 1, "i1": 1, "u2": 2, "i2": 2}[dtype]
    return rng.integers(0, 256, count * itemsize, dtype=np.uint8).tobytes()


@contextlib.contextmanager
def noisy_textures(seed: int = 7, nan: bool = False) -> Iterator[list[str]]:
    """Inside: every texture moderngl makes without data is made full of noise (float
    images in [-40, 60), or NaN with ``nan``: what a GPU's garbage may hold, which even a
    lookup weighted 0 carries on; ids random, depth in [0, 1)); yields the list of what was
    filled."""
    rng = np.random.default_rng(seed)
    filled: list[str] = []
    originals = {name: getattr(moderngl.Context, name) for name in _CONSTRUCTORS}

    def wrap(name: str):
        original = originals[name]

        def make(self, size, *args, **kwargs):
            if name == "depth_texture":
                data = kwargs.get("data", args[0] if args else None)
                if data is None and not kwargs.get("samples") and not kwargs.get("renderbuffer"):
                    kwargs.pop("data", None)
                    data = rng.uniform(0.0, 1.0, int(np.prod(size))).astype(np.float32).tobytes()
                    filled.append(f"depth {size}")
                    return original(self, size, data, *args[1:], **kwargs)
                return original(self, size, *args, **kwargs)
            components = kwargs.get("components", args[0] if args else None)
            rest = args[1:]
            data = kwargs.pop("data", rest[0] if rest else None)
            rest = rest[1:]
            if data is None and not kwargs.get("samples") and not kwargs.get("renderbuffer"):
                dtype = kwargs.get("dtype", "f1")
                faces = 6 if name == "texture_cube" else 1
                data = _noise(tuple(size), components, dtype, faces, rng, nan)
                filled.append(f"{name} {tuple(size)} {components}x{dtype}")
            kwargs.pop("components", None)
            return original(self, size, components, data, *rest, **kwargs)
        return make

    make_buffer = moderngl.Context.buffer

    def buffer(self, data=None, *, reserve=0, dynamic=False):
        # A buffer made with room only (``reserve``): its bytes are undefined until written
        # (glBufferData with no data): noise (random bytes: NaNs among them as floats).
        if data is None and reserve:
            data = rng.integers(0, 256, int(reserve), dtype=np.uint8).tobytes()
            filled.append(f"buffer {reserve}")
        return make_buffer(self, data, dynamic=dynamic)

    for name in _CONSTRUCTORS:
        setattr(moderngl.Context, name, wrap(name))
    moderngl.Context.buffer = buffer
    # No shadow atlas of an engine released before (engine/render/free_depth_images.py): each
    # made new, so full of noise too.
    none_free = FreeDepthImages()
    none_free.released = True
    free_of = FreeDepthImages.__dict__["of"]
    FreeDepthImages.of = classmethod(lambda cls, ctx: none_free)
    try:
        yield filled
    finally:
        for name, original in originals.items():
            setattr(moderngl.Context, name, original)
        moderngl.Context.buffer = make_buffer
        FreeDepthImages.of = free_of
