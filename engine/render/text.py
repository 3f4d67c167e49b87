"""Text and panels on the screen (``components/screen.py``): a font atlas and one instanced
draw over the finished picture.

**The atlas** is made once a renderer first draws text, with Pillow: its built-in font
(``ImageFont.load_default``: the FreeType face Pillow embeds, at ``FONT_SIZE`` pixels; where
Pillow has no FreeType, its old bitmap font), each printable ASCII character rendered into a
cell of a 16-column grid, anti-aliased coverage in one 8-bit channel.  Every cell is the same
size (the widest glyph's ink, the font's line height); a glyph's ``advance`` (Pillow's
``getlength``, rounded to whole pixels so every glyph lands on the pixel grid) moves the pen.
The cell after ``~`` is filled: panels sample it, so a panel and a glyph are the same quad.

**Layout** (``layout``, numpy, no GL) turns each ``ScreenText`` and ``ScreenPanel`` into
quads in output pixels from the top-left: (x, y, w, h) on the screen, the atlas cell's
(x, y, w, h) in texels, and the colour, sRGB-encoded (the output holds encoded values: the
present stage encoded them), alpha kept.  Every corner is a whole pixel and a glyph's cell is
``scale`` pixels a texel, so each pixel shows exactly one texel (``texelFetch``, no filtering).

**Pictures.**  A panel with a ``Monitor`` on its entity (a rear-view mirror, a minimap) is
filled with the monitor's picture (``engine/render/monitors.py``): its quad's atlas rect is
(index, 0, -1, 0), the index into the frame's pictures, its colour linear, and the shader
(its PICTURE build) reads the picture filtered across the quad, times the colour, then
exposes, grades and tone-maps it as the present did the frame under it (``PresentPass.look``:
the exposure, the adapted automatic exposure, the colour grade and its table, the tone curve;
not the lens's bloom, flare, vignette, aberration or grain: the panel lies over the lens's
image, as a HUD does) and sRGB-encodes it there: the picture is the camera's linear light, as the screens in the
world show it, and on the HUD it looks as the view does.

**The pass** (``TextPass.draw``) runs after the present stage, into the output: one instanced
draw of a unit quad, a row of attributes a quad, in order (later quads blend over earlier
ones: GL draws instances in order), blended ``src * a + dst * (1 - a)`` with ``a`` the colour's
alpha times the texel's coverage; a picture panel is a draw of its own between the runs of
quads before and after it (its picture bound).  It is drawn over the final image, so mirrors, portals and
probes (drawn before it, into their own images) never show it, and ids are untouched.
Limit: ``MAX_QUADS`` quads a frame (glyphs and panels); past it the rest are left out and a
warning says how many.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import moderngl
import numpy as np

from components.post import TONEMAP_CURVES
from engine.core.color import linear_to_srgb
from engine.render.bindings import (
    EXPOSURE_UNIT,
    LUT_UNIT,
    PICTURE_UNIT,
    TEXT_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.grading import grade_uniforms, grades, lut_lookup
from engine.render.present import PictureLook
from engine.render.shader_library import ShaderLibrary

FONT_SIZE = 16              # pixels of the atlas's font (ScreenText.scale multiplies them)
FIRST_CHAR, LAST_CHAR = 32, 126
COLUMNS = 16
SOLID = LAST_CHAR + 1        # the filled cell panels sample
FALLBACK = "?"
MAX_QUADS = 16384
QUAD_FLOATS = 12             # screen rect 4, atlas rect 4, colour 4
_BLEND_OVER = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA)
_TEXT = PassState(blend=_BLEND_OVER)
PLAIN_LOOK = PictureLook()   # exposure 1, no tone curve: a picture panel clamped and encoded as it is


@dataclass(frozen=True)
class FontAtlas:
    """Coverage (``pixels``: uint8 rows from the top) of every glyph in its cell; ``cell``
    (w, h) in texels; ``origin_x`` where the pen is in a cell (the ink left of the pen, a
    texel or so); ``advances`` by character code; ``line_height`` in pixels."""

    pixels: np.ndarray
    cell: tuple[int, int]
    origin_x: int
    advances: dict[int, int]
    line_height: int

    def cell_of(self, code: int) -> tuple[int, int]:
        """The top-left texel of ``code``'s cell."""
        index = code - FIRST_CHAR
        return (index % COLUMNS) * self.cell[0], (index // COLUMNS) * self.cell[1]

    def glyph(self, code: int) -> np.ndarray:
        """``code``'s cell of coverage (rows from the top)."""
        x, y = self.cell_of(code)
        return self.pixels[y:y + self.cell[1], x:x + self.cell[0]]


def make_atlas(size: int = FONT_SIZE) -> FontAtlas:
    """Pillow's built-in font rendered into a grid of cells (see the module's docstring)."""
    from PIL import Image, ImageDraw, ImageFont

    try:
        font = ImageFont.load_default(size=size)
    except (TypeError, OSError, ImportError):  # Pillow without FreeType: its bitmap font
        font = ImageFont.load_default()
    chars = [chr(code) for code in range(FIRST_CHAR, LAST_CHAR + 1)]
    boxes = [font.getbbox(ch) for ch in chars]
    left = min(0, min(int(b[0]) for b in boxes))
    right = max(int(b[2]) for b in boxes)
    try:
        ascent, descent = font.getmetrics()
    except AttributeError:
        ascent, descent = max(int(b[3]) for b in boxes), 0
    line = max(ascent + descent, max(int(b[3]) for b in boxes))
    cell = (right - left + 1, line)
    rows = -(-(SOLID - FIRST_CHAR + 1) // COLUMNS)
    image = Image.new("L", (cell[0] * COLUMNS, cell[1] * rows), 0)
    atlas = FontAtlas(np.zeros(0, np.uint8), cell, -left, {}, line)
    draw = ImageDraw.Draw(image)
    for ch in chars:
        x, y = atlas.cell_of(ord(ch))
        glyph = Image.new("L", cell, 0)
        ImageDraw.Draw(glyph).text((-left, 0), ch, font=font, fill=255)
        image.paste(glyph, (x, y))
        atlas.advances[ord(ch)] = int(round(font.getlength(ch)))
    x, y = atlas.cell_of(SOLID)
    draw.rectangle((x, y, x + cell[0] - 1, y + cell[1] - 1), fill=255)
    return FontAtlas(np.asarray(image, np.uint8).copy(), cell, -left, atlas.advances, line)


@dataclass(frozen=True)
class ScreenItem:
    """One ScreenText (``text`` not None) or ScreenPanel, as layout reads it (plain values)."""

    text: str | None
    position: tuple[float, float]
    anchor: tuple[float, float]      # fractions (SCREEN_ANCHORS)
    color: tuple[float, float, float, float]
    scale: int = 1
    size: tuple[float, float] = (0.0, 0.0)  # a panel's
    background: tuple[float, float, float, float] | None = None  # a text's panel (ScreenText.background)
    padding: float = 0.0
    picture: int = 0   # a panel filled with a monitor's picture: 1 + its index in the draw's pictures (0: none)


def text_size(atlas: FontAtlas, text: str, scale: int = 1) -> tuple[int, int]:
    """The box ``text`` takes, in pixels (the widest line's advances, lines x line height)."""
    lines = text.split("\n")
    width = max(sum(atlas.advances.get(ord(c), atlas.advances[ord(FALLBACK)]) for c in line) for line in lines)
    return width * scale, len(lines) * atlas.line_height * scale


def box_corner(item: ScreenItem, box: tuple[float, float], output: tuple[int, int]) -> tuple[int, int]:
    """The top-left pixel of ``item``'s box: the anchor's point of the output, plus
    ``position``, less the anchor's point of the box; whole pixels (rounded down)."""
    ax, ay = item.anchor
    x = ax * output[0] + item.position[0] - ax * box[0]
    y = ay * output[1] + item.position[1] - ay * box[1]
    return int(np.floor(x + 1e-6)), int(np.floor(y + 1e-6))


def _encoded(color: tuple[float, ...]) -> list[float]:
    rgb = linear_to_srgb(np.array(color[:3]))  # the output holds encoded values
    return [float(rgb[0]), float(rgb[1]), float(rgb[2]), float(color[3])]


def layout(atlas: FontAtlas, items: list[ScreenItem], output: tuple[int, int]) -> np.ndarray:
    """Quads of ``items`` in drawing order: float32 rows of (x, y, w, h screen pixels from the
    top-left, atlas x, y, w, h texels, r, g, b sRGB-encoded, a; a picture panel's: its
    picture's index, 0, -1, 0 and its colour linear).  Spaces and empty lines make no quad; a
    text's background is a quad just before its glyphs."""
    rows: list[list[float]] = []
    cw, ch = atlas.cell
    sx, sy = atlas.cell_of(SOLID)
    for item in items:
        colour = _encoded(item.color)
        if item.text is None:
            w, h = int(round(item.size[0])), int(round(item.size[1]))
            if w > 0 and h > 0 and item.color[3] > 0.0:
                x, y = box_corner(item, (w, h), output)
                if item.picture:   # (its picture's index, marked by a width of -1; its colour linear)
                    rows.append([x, y, w, h, item.picture - 1, 0.0, -1.0, 0.0, *item.color])
                else:
                    rows.append([x, y, w, h, sx, sy, 0.0, 0.0, *colour])
            continue
        if not item.text:
            continue
        s = item.scale
        box = text_size(atlas, item.text, s)
        x0, y = box_corner(item, box, output)
        if item.background is not None and item.background[3] > 0.0:
            pad = int(round(item.padding))
            rows.append([x0 - pad, y - pad, box[0] + 2 * pad, box[1] + 2 * pad, sx, sy, 0.0, 0.0,
                         *_encoded(item.background)])
        if item.color[3] <= 0.0:
            continue
        for line in item.text.split("\n"):
            x = x0
            for c in line:
                code = ord(c) if FIRST_CHAR <= ord(c) <= LAST_CHAR else ord(FALLBACK)
                if c != " ":
                    tx, ty = atlas.cell_of(code)
                    rows.append([x - atlas.origin_x * s, y, cw * s, ch * s, tx, ty, cw, ch, *colour])
                x += atlas.advances[code] * s
            y += atlas.line_height * s
    return np.array(rows, np.float32).reshape(-1, QUAD_FLOATS)


class TextPass:
    """The atlas texture and the instanced quad draw (see the module's docstring)."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self.atlas = make_atlas()
        h, w = self.atlas.pixels.shape
        self.texture = ctx.texture((w, h), 1, self.atlas.pixels.tobytes(), alignment=1)
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.shaders = shaders
        self.program = shaders.program("screen_text.vert", "screen_text.frag")
        self.program["atlas"].value = TEXT_UNIT
        self.corners = ctx.buffer(np.array([0, 0, 1, 0, 0, 1, 1, 1], np.float32).tobytes())
        self.quads = ctx.buffer(reserve=MAX_QUADS * QUAD_FLOATS * 4, dynamic=True)
        self.vao = self._vertex_array(self.program)
        # The picture panels' builds, by (tone curve, automatic exposure, grade, table): program, vertex array.
        self._pictures: dict[tuple[str, bool, bool, bool], tuple[moderngl.Program, moderngl.VertexArray]] = {}
        self._written: dict[int, dict[str, object]] = {}   # the picture builds' uniforms as last written, by program
        self.drawn = 0  # quads drawn in the last draw
        self.cut = 0    # quads left out (past MAX_QUADS) in the last draw

    def _vertex_array(self, program: moderngl.Program, atlas: bool = True) -> moderngl.VertexArray:
        """The quad and the rows read by ``program`` (a picture's build reads no atlas rect)."""
        rows = (self.quads, "4f 4f 4f/i", "screen_rect", "atlas_rect", "color") if atlas else \
            (self.quads, "4f 16x 4f/i", "screen_rect", "color")
        return self.ctx.vertex_array(program, [(self.corners, "2f", "corner"), rows])

    def _picture_build(self, look: PictureLook) -> tuple[moderngl.Program, moderngl.VertexArray]:
        """The picture panels' build for ``look``'s curve, automatic exposure, grade and grade's
        table, made once."""
        key = (look.curve, look.exposure_state is not None, grades(look.grading), look.lut is not None)
        build = self._pictures.get(key)
        if build is None:
            defines = {"PICTURE": "1", "TONEMAP_CURVE": str(TONEMAP_CURVES.index(look.curve))}
            defines.update((name, "1") for name, on in zip(("AUTO_EXPOSURE", "GRADE", "LUT"), key[1:], strict=True)
                           if on)
            program = self.shaders.program("screen_text.vert", "screen_text.frag", defines=defines)
            program["picture"].value = PICTURE_UNIT
            if key[1]:
                program["exposure_state"].value = EXPOSURE_UNIT
            if key[3]:
                program["lut_map"].value = LUT_UNIT
            build = self._pictures[key] = (program, self._vertex_array(program, atlas=False))
        return build

    def _set_look(self, program: moderngl.Program, look: PictureLook) -> None:
        """``look``'s exposure, grade and table on the picture build ``program`` (the present's
        own values: the panel's colours go through what the frame's went through), each uniform
        written only when its value changed (a write is a GL call)."""
        values: dict[str, object] = {"exposure": look.scale}
        if look.exposure_state is not None:
            bind_texture(self.ctx, look.exposure_state, EXPOSURE_UNIT)
        if grades(look.grading):
            values.update(grade_uniforms(look.grading))
        if look.lut is not None:
            bind_texture(self.ctx, look.lut, LUT_UNIT)
            values["lut_scale"], values["lut_bias"] = lut_lookup(look.grading.lut)
            values["lut_strength"] = look.grading.lut_strength
        written = self._written.setdefault(id(program), {})
        for name, value in values.items():
            if written.get(name) != value:
                if isinstance(value, bytes):
                    program[name].write(value)
                else:
                    program[name].value = value
                written[name] = value

    def draw(self, quads: np.ndarray, framebuffer: moderngl.Framebuffer, size: tuple[int, int],
             pictures: tuple[moderngl.Texture, ...] = (), look: PictureLook = PLAIN_LOOK) -> None:
        """Blend ``quads`` (``layout``'s rows) over ``framebuffer`` (``size`` pixels); a picture
        panel's row samples ``pictures[its index]``, exposed and tone-mapped by ``look`` (the
        present's, of the frame under it)."""
        self.cut = max(0, len(quads) - MAX_QUADS)
        if self.cut:
            warnings.warn(f"screen text: {len(quads)} quads this frame, {self.cut} left out (at most {MAX_QUADS} "
                          "glyphs and panels a frame)", stacklevel=2)
            quads = quads[:MAX_QUADS]
        self.drawn = len(quads)
        if not self.drawn or size[0] <= 0 or size[1] <= 0:
            return
        quads = np.ascontiguousarray(quads, np.float32)
        framebuffer.use()
        apply_pass_state(self.ctx, _TEXT, (0, 0, *size))
        bind_texture(self.ctx, self.texture, TEXT_UNIT)
        output_size = (float(size[0]), float(size[1]))
        self.program["output_size"].value = output_size
        marked = np.flatnonzero(quads[:, 6] < 0.0)   # the picture panels' rows
        if not len(marked):
            self._run(quads, self.vao)
            return
        program, vao = self._picture_build(look)
        program["output_size"].value = output_size
        self._set_look(program, look)
        start = 0
        for row in marked:   # the runs of quads before each picture, then the picture alone
            if row > start:
                self._run(quads[start:row], self.vao)
            index = int(quads[row, 4])
            if 0 <= index < len(pictures):
                bind_texture(self.ctx, pictures[index], PICTURE_UNIT)
                self._run(quads[row:row + 1], vao)
            start = row + 1
        if start < len(quads):
            self._run(quads[start:], self.vao)

    def _run(self, quads: np.ndarray, vao: moderngl.VertexArray) -> None:
        """One instanced draw of ``quads`` (written at the buffer's start) by ``vao``'s build
        (the atlas's, or a picture's)."""
        self.quads.write(quads.tobytes())
        vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=len(quads))

    def release(self) -> None:
        for _, vao in self._pictures.values():
            vao.release()
        for obj in (self.vao, self.quads, self.corners, self.texture):
            obj.release()
