"""The debug overlay: frame rate and a frame-time graph, what the last frame cost (passes,
draw calls, views per reflection level, probe captures), the reflection and probe capture
paths in use, toggles for them, the post-processing (tone curve, exposure, bloom; toggles
for bloom and the curve), and shader errors from hot reload; and the level editor's inspector (``shell/editor.py``): a
click in the world selects the entity seen there (Ctrl+click: the mirror or portal it was
seen through), or the entity list (every entity by name and kinds, filtered) one that shows
nowhere, outlined wherever it shows (``engine/render/outline.py``), with handles to move it
along a world axis, turn it about one or scale it along its own (``shell/handles.py``); its components'
fields are drag inputs, checkboxes and colour pickers that edit it through the components'
own checks, with undo, redo, add, remove and save; a field the engine decides while unset
(``editor.AUTOMATIC_FIELDS``) is pinned at the value in use, or handed back.

It is an immediate-mode GUI (Dear ImGui, through imgui-bundle) drawn by moderngl-window's
moderngl renderer for it, after the present stage, over the finished frame in the output
framebuffer (a window's, or the headless capture target for ``--overlay`` PNGs).  Nothing is
drawn by hand: the overlay only reads the engine's own numbers (``RenderStats``, the
reflect stage's settings and view tree, the probes stage's path) and writes the settings
its toggles change.

No window is needed: the overlay owns its ImGui context and sets the display size and time
step itself each frame; input comes only when a shell forwards it (``shell/window.py``).
moderngl-window 3.1's renderer still uploads the font the way ImGui did before 1.92; ImGui
1.92 (imgui-bundle 1.93) hands the backend its textures to create, update and destroy
(``RendererHasTextures``), which ``OverlayRenderer`` does with moderngl textures.

The overlay changes GL state (blending, scissor, texture unit 0, the bound framebuffer);
every engine pass applies its whole state when it starts (``bindings.PassState``), so the
next frame is drawn as if no overlay had been (``tests/test_overlay.py`` checks it).
"""
from __future__ import annotations

import ctypes
import math
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import moderngl
import numpy as np
from imgui_bundle import imgui
from moderngl_window.integrations.imgui_bundle import ModernGLRenderer
from pyglm import glm

from components import ComponentValueError, Transform
from components.post import TONEMAP_CURVES
from engine.assets.level_assets import MESH_MAKERS
from engine.assets.level_file import LevelGame
from engine.assets.level_read import REFERENCE_FIELDS
from engine.assets.values import json_value
from engine.render.bindings import bind_texture, invalidate
from shell.editor import AUTOMATIC_FIELDS, TEXTURE_FIELDS, EditError, Editor
from shell.handles import HANDLE_MODES, Handles, framing_eye, transform_handles
from shell.overlay_text import overlay_lines

if TYPE_CHECKING:  # the app's window makes the overlay
    from shell.app import Engine

FRAME_HISTORY = 120             # frames in the frame-time graph and the frame rate's average
POSITION = (8, 8)               # the overlay window's top-left corner, in pixels from the top-left
REFLECTION_PATHS = ("per_mirror", "batched", "auto")
PROBE_PATHS = ("auto", "six_pass", "layered")
MAX_DEPTH_CAP = 16
CURVE_CHOICES = (None, *TONEMAP_CURVES)   # None: each camera's own Tonemap curve
CURVE_WIDTH = 100                          # pixels of the curve's drop-down
INSPECTOR_WIDTH = 320                      # pixels of the inspector, at the right edge
DRAG_SPEED = 0.01                          # a number field's change per pixel dragged
# moderngl-window's key names -> ImGui's keys: what typing in a field and editing its text need.
IMGUI_KEYS = {"BACKSPACE": imgui.Key.backspace, "DELETE": imgui.Key.delete, "ENTER": imgui.Key.enter,
              "ESCAPE": imgui.Key.escape, "TAB": imgui.Key.tab, "LEFT": imgui.Key.left_arrow,
              "RIGHT": imgui.Key.right_arrow, "UP": imgui.Key.up_arrow, "DOWN": imgui.Key.down_arrow,
              "HOME": imgui.Key.home, "END": imgui.Key.end, "A": imgui.Key.a, "C": imgui.Key.c,
              "V": imgui.Key.v, "X": imgui.Key.x, "Y": imgui.Key.y, "Z": imgui.Key.z}
HDR_COLOUR = imgui.ColorEditFlags_.float | imgui.ColorEditFlags_.hdr  # colour fields: floats, not clamped to 0-1
SNAP = {"move": 0.25, "turn": math.radians(15.0), "scale": 0.1}  # a handle's steps with Ctrl held
GIZMO_REACH = 6.0                          # pixels from a move handle that still take it
LIST_REFRESH_S = 0.5                       # the entity list is made again at most this often (else on an edit)
ENTITY_LIST_WIDTH, ENTITY_LIST_HEIGHT = INSPECTOR_WIDTH - 16, 160  # pixels of the entity list's scrolled part


@dataclass
class _Drag:
    """A transform handle being dragged: what, which handle, the Transform field's value and
    the mouse when it was pressed, the handles then (their scale holds for the drag), and a
    turn's angle so far and the mouse's last place."""

    entity: int
    axis: int
    start: object
    pressed: tuple[float, float]
    handles: Handles
    last: tuple[float, float]
    angle: float = 0.0


class OverlayRenderer(ModernGLRenderer):
    """moderngl-window's ImGui renderer with ImGui 1.92's texture protocol: each texture ImGui
    asks for (the font atlas, grown as glyphs are needed) is created, updated and destroyed
    as a moderngl texture registered under its GL name."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        super().__init__(ctx=ctx, display_size=size)
        self.io.backend_flags |= imgui.BackendFlags_.renderer_has_textures
        platform = imgui.get_platform_io()
        platform.renderer_texture_max_width = platform.renderer_texture_max_height = ctx.info["GL_MAX_TEXTURE_SIZE"]

    def refresh_font_texture(self) -> None:
        """Nothing to do: the font atlas arrives as an ImGui texture request (``render``)."""

    def _update_texture(self, tex: imgui.ImTextureData) -> None:
        status = tex.status
        if status == imgui.ImTextureStatus.want_create:
            texture = self.ctx.texture((tex.width, tex.height), 4, tex.get_pixels_array().tobytes())
            texture.repeat_x = texture.repeat_y = False
            self.register_texture(texture)
            tex.set_tex_id(texture.glo)
            tex.status = imgui.ImTextureStatus.ok
        elif status == imgui.ImTextureStatus.want_updates:
            texture = self._textures[tex.tex_id]
            pixels = tex.get_pixels_array().reshape(tex.height, tex.width, 4)
            for r in tex.updates:
                block = np.ascontiguousarray(pixels[r.y:r.y + r.h, r.x:r.x + r.w])
                texture.write(block.tobytes(), viewport=(r.x, r.y, r.w, r.h))
            tex.status = imgui.ImTextureStatus.ok
        elif status == imgui.ImTextureStatus.want_destroy:
            texture = self._textures.pop(tex.tex_id, None)
            if texture is not None:
                texture.release()
            tex.set_tex_id(0)
            tex.status = imgui.ImTextureStatus.destroyed

    def render(self, draw_data: imgui.ImDrawData) -> None:
        """Draw ``draw_data`` into the bound framebuffer (its viewport set by the caller)."""
        for tex in imgui.get_platform_io().textures:
            if tex.status != imgui.ImTextureStatus.ok:
                self._update_texture(tex)
        io = self.io
        width, height = io.display_size
        fb_height = int(height * io.display_framebuffer_scale[1])
        if width <= 0 or height <= 0:
            return
        self.projMat.value = (2.0 / width, 0.0, 0.0, 0.0, 0.0, -2.0 / height, 0.0, 0.0,
                              0.0, 0.0, -1.0, 0.0, -1.0, 1.0, 0.0, 1.0)
        draw_data.scale_clip_rects(imgui.ImVec2(*io.display_framebuffer_scale))
        self.ctx.enable_only(moderngl.BLEND)
        self.ctx.blend_equation = moderngl.FUNC_ADD
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        for commands in draw_data.cmd_lists:
            vertices = commands.vtx_buffer.size() * imgui.VERTEX_SIZE
            indices = commands.idx_buffer.size() * imgui.INDEX_SIZE
            for buffer, size in ((self._vertex_buffer, vertices), (self._index_buffer, indices)):
                if buffer.size < size:
                    buffer.orphan(size)
            self._vertex_buffer.write((ctypes.c_byte * vertices).from_address(commands.vtx_buffer.data_address()))
            self._index_buffer.write((ctypes.c_byte * indices).from_address(commands.idx_buffer.data_address()))
            for command in commands.cmd_buffer:
                texture = self._textures.get(command.get_tex_id())
                if texture is None:
                    raise ValueError(f"overlay: ImGui drew with texture {command.get_tex_id()}, which it never "
                                     f"asked to create (known: {list(self._textures)})")
                # Through the record: it takes off a sampler object the engine left on unit 0
                # (the reflections' mipmapped albedo filter), which would leave the font
                # atlas, with no mip levels, incomplete (black on a GPU).
                bind_texture(self.ctx, texture, 0)
                x, y, z, w = command.clip_rect
                self.ctx.scissor = int(x), int(fb_height - w), int(z - x), int(w - y)
                self._vao.render(moderngl.TRIANGLES, vertices=command.elem_count, first=command.idx_offset)
        self.ctx.scissor = None
        # Blending, the scissor and unit 0 were set past the engine's pass-state cache: its
        # next frame sets every pass state and binding afresh (Engine.frame keeps them otherwise).
        invalidate(self.ctx)

    def shutdown(self) -> None:
        for tex in imgui.get_platform_io().textures:
            if tex.status != imgui.ImTextureStatus.destroyed:
                tex.status = imgui.ImTextureStatus.want_destroy
                self._update_texture(tex)
        for texture in self._textures.values():
            texture.release()
        self._textures.clear()
        self.io.backend_flags &= ~imgui.BackendFlags_.renderer_has_textures
        for obj in (self._vao, self._vertex_buffer, self._index_buffer, self._prog):
            obj.release()


_LIVE: list = []  # the ImGui contexts of overlays not yet released, oldest first


def _alive(context) -> bool:
    return context is not None and any(context == live for live in _LIVE)


class DebugOverlay:
    """One overlay on one GL context: ``record`` each frame's time, ``draw`` after the frame.

    ``release`` gives back its GL objects and destroys its ImGui context, once (a second call
    does nothing: destroying an ImGui context twice aborts the process with "double free or
    corruption"), and makes current again the context that was current before, unless that
    one has been destroyed since (overlays released in any order)."""

    def __init__(self, ctx: moderngl.Context, visible: bool = True) -> None:
        self.ctx = ctx
        self.visible = visible
        self.frame_times: deque[float] = deque(maxlen=FRAME_HISTORY)
        self.lines: list[str] = []           # the text of the last overlay drawn
        self.shown_errors: list[str] = []    # the shader errors it showed (hot reload)
        self.region: tuple[int, int, int, int] | None = None  # x, y (from the top-left), w, h last drawn
        self.widgets: dict[str, tuple[float, float]] = {}  # each toggle's centre, last drawn (pixels)
        self._last = None
        self._previous = imgui.get_current_context()
        self.context = imgui.create_context()
        _LIVE.append(self.context)
        io = imgui.get_io()
        io.set_ini_filename("")  # no imgui.ini written next to the game
        self.renderer = OverlayRenderer(ctx, (1, 1))
        self.io = io
        self.editor: Editor | None = None     # the level editor of the engine's world (made when first drawn)
        self.inspector_lines: list[str] = []  # the inspector's text last drawn (entity, components, message)
        self._outline = None
        self._removing: tuple[int, str] | None = None
        self._names_taken: dict[str, int] | None = None  # the game's names the editor last took (a rebuild's are new)
        self.show_entities = False            # the entity list is shown ("entities" ticked)
        self.handle_mode = "move"             # the selection's handles: HANDLE_MODES, chosen in the inspector
        self.handles: Handles | None = None   # the selection's handles, last drawn
        self._hovered: int | None = None      # the handle under the mouse
        self._dragging: _Drag | None = None   # a handle being dragged
        self.entity_filter = ""               # the entity list's filter, as typed
        self.listed_entities: list[str] = []  # the entity list's labels last drawn (while it is open)
        self._listed: tuple | None = None     # (what it was made for, when, entities, more): _listing

    def record(self, seconds: float | None = None) -> None:
        """Add one frame's time (``None``: the time since the last call, wall clock)."""
        now = time.perf_counter()
        if seconds is None:
            seconds = now - self._last if self._last is not None else 0.0
        self._last = now
        if seconds > 0:
            self.frame_times.append(seconds)

    def toggle(self) -> None:
        self.visible = not self.visible

    # --- input a shell forwards (moderngl-window's mouse buttons: 1 left, 2 right, 3 middle) ---
    def mouse_moved(self, x: float, y: float) -> None:
        self.io.add_mouse_pos_event(float(x), float(y))

    def mouse_button(self, button: int, down: bool) -> None:
        index = {1: 0, 2: 1, 3: 2}.get(button)
        if index is not None:
            self.io.add_mouse_button_event(index, down)

    def editing(self, engine: Engine) -> Editor:
        """The editor of ``engine``'s world (a new one when the world was rebuilt): the game's
        own components, entity names and level file, where it is a ``LevelGame``."""
        game = engine.game if isinstance(engine.game, LevelGame) else None
        rebuilt = game is not None and game.names is not self._names_taken  # the world built again from its
        if self.editor is None or self.editor.world is not engine.world or rebuilt:  # file (a new dict of names):
            self.editor = Editor(engine.world, *((game.components, game.names, game.level_path, game.asset_roots)
                                                 if game else ()))
            self._names_taken = game.names if game else None                  # its edits named entities gone
        return self.editor

    def click(self, engine: Engine, x: float, y: float, surface: bool = False) -> bool:
        """A click in the world at output pixel (``x``, ``y``) while the overlay is shown:
        select what the last frame's id images hold there (``surface``: the mirror or portal
        seen through). True when it was the editor's click (the overlay is shown)."""
        targets = engine.renderer.targets
        if not self.visible or self.context is None or targets is None:
            return False
        self.editing(engine).pick(targets.read_ids(), targets.read_surface_ids(), int(x), int(y), surface)
        return True

    def key(self, name: str, down: bool, ctrl: bool = False, shift: bool = False) -> None:
        """A key (moderngl-window's name for it: "BACKSPACE", "A") pressed or let go, with the
        modifiers held: to the field being typed in (``IMGUI_KEYS``)."""
        self.io.add_key_event(imgui.Key.mod_ctrl, ctrl)
        self.io.add_key_event(imgui.Key.mod_shift, shift)
        key = IMGUI_KEYS.get(name)
        if key is not None:
            self.io.add_key_event(key, down)

    def scroll(self, x: float, y: float) -> None:
        """The mouse wheel turned (the window's steps): scrolls the list or window under it."""
        self.io.add_mouse_wheel_event(float(x), float(y))

    def text(self, characters: str) -> None:
        """Characters typed (the window's text events): into the field being typed in."""
        for character in characters:
            self.io.add_input_character(ord(character))

    @property
    def wants_keyboard(self) -> bool:
        """A field is being typed in: the keys are its, not the game's or the editor's."""
        return self.visible and self.io.want_capture_keyboard

    def shortcut(self, engine: Engine, name: str, ctrl: bool = False, shift: bool = False) -> bool:
        """The editor's keys while the overlay is shown and no field is typed in: Ctrl+Z undo,
        Ctrl+Y or Ctrl+Shift+Z redo, Ctrl+D duplicate and Delete delete the selection, Ctrl+S
        save, F frame the selection (the camera moved to see it whole).  True when ``name``
        was one (the game does not get it)."""
        if not self.visible or self.context is None:
            return False
        editor = self.editing(engine)
        entity = editor.selected if editor.selected is not None and engine.world.exists(editor.selected) else None
        if ctrl and (name == "Y" or (name == "Z" and shift)):
            self._try(editor, editor.redo)
        elif ctrl and name == "Z":
            self._try(editor, editor.undo)
        elif ctrl and name == "D" and entity is not None:
            self._try(editor, editor.duplicate, entity)
        elif name == "DELETE" and entity is not None:
            self._try(editor, editor.delete, entity)
        elif ctrl and name == "S" and editor.level_path is not None:
            self._save(engine, editor)
        elif name == "F" and not ctrl and entity is not None:
            self._frame_selection(engine, entity)
        else:
            return False
        return True

    @property
    def wants_mouse(self) -> bool:
        """The pointer is over the overlay (its clicks and drags are the overlay's)."""
        return self.visible and (self.io.want_capture_mouse or self._hovered is not None or self._dragging is not None)

    def draw(self, engine: Engine, framebuffer: moderngl.Framebuffer, size: tuple[int, int]) -> None:
        """Lay out the overlay for ``engine``'s last frame, apply its toggles, and draw it
        over ``framebuffer`` (``size`` pixels)."""
        if not self.visible or self.context is None or size[0] <= 0 or size[1] <= 0:
            return
        imgui.set_current_context(self.context)
        io = self.io
        io.display_size = imgui.ImVec2(*size)
        io.display_framebuffer_scale = imgui.ImVec2(1.0, 1.0)
        io.delta_time = self.frame_times[-1] if self.frame_times else 1.0 / 60.0
        if imgui.get_frame_count() == 0:
            # ImGui measures an auto-sized window in its first frame and shows it from the
            # second: lay the first one out unseen, so a single headless frame has the overlay.
            imgui.new_frame()
            self._layout(engine)
            imgui.end_frame()
        imgui.new_frame()
        self._layout(engine)
        imgui.render()
        self._draw_outline(engine, framebuffer, size)
        framebuffer.use()
        self.ctx.viewport = (0, 0, *size)
        self.renderer.render(imgui.get_draw_data())

    def _draw_outline(self, engine: Engine, framebuffer: moderngl.Framebuffer, size: tuple[int, int]) -> None:
        editor, targets = self.editor, engine.renderer.targets
        if editor is None or editor.selected is None or targets is None or not engine.world.exists(editor.selected):
            return
        from engine.render.outline import SelectionOutline, outline_ids

        if self._outline is None:
            self._outline = SelectionOutline(self.ctx, engine.renderer.shaders)
        self._outline.draw(outline_ids(targets, engine.world, editor.selected), framebuffer, size, editor.selected)

    def _layout(self, engine) -> None:
        self.lines = overlay_lines(engine, self.frame_times)
        imgui.set_next_window_pos(imgui.ImVec2(*POSITION))
        imgui.set_next_window_bg_alpha(0.85)
        flags = (imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
                 | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_move)
        imgui.begin("Speculum (F1)", None, flags)
        # A shader that failed to build comes first, at the top: the reason the picture is
        # wrong.  One error in full (the variants of one file fail alike), the rest counted.
        self.shown_errors = list(engine.renderer.shaders.errors.values())
        level_reload = getattr(engine, "level_reload", None)
        if level_reload is not None and level_reload.error:  # a saved level file that failed to load
            self.shown_errors.insert(0, level_reload.error)
        if self.shown_errors:
            imgui.text_colored(imgui.ImVec4(1.0, 0.35, 0.3, 1.0), self.shown_errors[0])
            if len(self.shown_errors) > 1:
                imgui.text_colored(imgui.ImVec4(1.0, 0.35, 0.3, 1.0),
                                   f"(and {len(self.shown_errors) - 1} more: shaders that failed to build)")
            imgui.separator()
        for line in self.lines:
            imgui.text(line)
        times = np.array(self.frame_times or [0.0], np.float32) * 1000.0
        imgui.plot_lines("##frame times", times, overlay_text=f"frame ms, max {times.max():.1f}",
                         scale_min=0.0, graph_size=imgui.ImVec2(220, 40))
        imgui.separator()
        reflect, probes, renderer = engine.reflection_system, engine.stages["probes"], engine.renderer
        imgui.text("reflections")
        for path in REFLECTION_PATHS:
            imgui.same_line()
            if imgui.radio_button(f"{path}##reflection", reflect.path == path):
                reflect.path = path
            self._widget(f"reflection {path}")
        changed, cap = imgui.slider_int("depth cap", reflect.max_depth_cap, 0, MAX_DEPTH_CAP)
        if changed:
            reflect.max_depth_cap = cap
        self._widget("depth cap")
        imgui.text("probes")
        for path in PROBE_PATHS:
            imgui.same_line()
            if imgui.radio_button(f"{path}##probe", probes.path == path):
                probes.path = path
            self._widget(f"probe {path}")
        imgui.same_line(spacing=24)
        _, self.show_entities = imgui.checkbox("entities", self.show_entities)
        self._widget("entities")
        changed, fxaa = imgui.checkbox("FXAA", renderer.antialias == "fxaa")
        if changed:
            renderer.antialias = "fxaa" if fxaa else "off"
        self._widget("fxaa")
        shadows = engine.stages["shadows"]
        imgui.same_line()
        changed, on = imgui.checkbox("shadows", shadows.enabled)
        if changed:
            shadows.enabled = on
        self._widget("shadows")
        present = engine.stages["present"]
        imgui.same_line()
        changed, bloom = imgui.checkbox("bloom", present.bloom)
        if changed:
            present.bloom = bloom
        self._widget("bloom")
        imgui.same_line()
        imgui.set_next_item_width(CURVE_WIDTH)
        if imgui.begin_combo("curve", present.curve or "camera's"):
            self._widget("curve")
            for curve in CURVE_CHOICES:
                if imgui.selectable(f"{curve or 'camera'}##curve", present.curve == curve)[0]:
                    present.curve = curve
                self._widget(f"curve {curve or 'camera'}")
            imgui.end_combo()
        else:
            self._widget("curve")
        x, y = imgui.get_window_pos()
        w, h = imgui.get_window_size()
        width, height = self.io.display_size
        self.region = (int(x), int(y), int(min(np.ceil(w), width - x)), int(min(np.ceil(h), height - y)))
        imgui.end()
        self._inspector(engine, self._entity_list(engine))
        self._transform_handles(engine)

    # --- the level editor's entity list and inspector -----------------------------------------
    def _entity_list(self, engine: Engine) -> float:
        """Every entity by name and kinds, to select one a click cannot reach (a light, the
        sky, a camera, post settings) or find one by name: a filter (any part of the label)
        over a scrolled list, in a window at the top of the right edge (the inspector below
        it).  Shown while the overlay's "entities" box is ticked, so a big world costs nothing
        here otherwise.  Returns the window's bottom (pixels from the top; the inspector goes
        below it)."""
        if not self.show_entities:
            self.listed_entities = []
            return POSITION[1] - 4
        width, _height = self.io.display_size
        imgui.set_next_window_pos(imgui.ImVec2(max(width - INSPECTOR_WIDTH - POSITION[0], 0), POSITION[1]))
        imgui.set_next_window_size(imgui.ImVec2(INSPECTOR_WIDTH, 0))
        imgui.set_next_window_bg_alpha(0.85)
        flags = (imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
                 | imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_move)
        imgui.begin("Entities", None, flags)
        imgui.text("entities")
        try:
            self._entities(engine)
        finally:
            bottom = imgui.get_window_pos().y + imgui.get_window_size().y
            imgui.end()
        return bottom

    def _entities(self, engine: Engine) -> None:
        editor = self.editing(engine)
        imgui.same_line()
        if imgui.small_button("new entity"):  # a Transform in front of the camera, selected: add to it
            self._try(editor, editor.create)
        self._widget("new entity")
        _, self.entity_filter = imgui.input_text("filter##entities", self.entity_filter)
        self._widget("entity filter")
        listed, more = self._listing(editor)
        self.listed_entities = [label for _, label in listed]
        imgui.begin_child("##entity list", imgui.ImVec2(ENTITY_LIST_WIDTH, ENTITY_LIST_HEIGHT))
        for entity, label in listed:
            if imgui.selectable(f"{label}##entity {entity}", editor.selected == entity)[0]:
                editor.select(entity)
            self._widget(f"entity {entity}")
        if more:
            imgui.text_disabled(f"(more than {len(listed)}: filter to find the rest)")
        imgui.end_child()

    def _listing(self, editor: Editor) -> tuple[list[tuple[int, str]], bool]:
        """``Editor.listed`` for the filter, made again when the filter or the editor's edits
        changed and otherwise at most every ``LIST_REFRESH_S`` (a filter looks at every
        entity's label: 0.23 s for 100,000 entities, which each frame would make the window
        crawl; what the game spawns shows a moment later)."""
        key = (id(editor), self.entity_filter, editor.edit_count)
        now = time.perf_counter()
        cached = self._listed
        if cached is None or cached[0] != key or now - cached[1] > LIST_REFRESH_S:
            cached = self._listed = (key, now, *editor.listed(self.entity_filter))
        return cached[2], cached[3]

    def _inspector(self, engine: Engine, top: float) -> None:
        editor = self.editing(engine)
        entity = editor.selected
        lines: list[str] = []
        chosen = entity is not None and engine.world.exists(entity)
        if not chosen and not (editor.can_undo or editor.can_redo):  # shown once something is clicked
            self.inspector_lines = lines
            return
        width, _height = self.io.display_size
        imgui.set_next_window_pos(imgui.ImVec2(max(width - INSPECTOR_WIDTH - POSITION[0], 0), top + 4))
        imgui.set_next_window_size_constraints(imgui.ImVec2(INSPECTOR_WIDTH, 0), imgui.ImVec2(INSPECTOR_WIDTH, 10000))
        imgui.set_next_window_bg_alpha(0.85)
        flags = (imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
                 | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_move)
        imgui.begin("Inspector", None, flags)
        for action, can, do in (("undo", editor.can_undo, editor.undo), ("redo", editor.can_redo, editor.redo)):
            if imgui.button(action) and can:
                try:
                    do()
                except Exception as exc:  # an edit of an entity gone since (a level reloaded): said, not raised
                    editor.message = str(exc)
            self._widget(action)
            imgui.same_line()
        for action, do in (("duplicate", editor.duplicate), ("delete", editor.delete)) if chosen else ():
            if imgui.button(action):
                self._try(editor, do, entity)
            self._widget(action)
            imgui.same_line()
        if editor.level_path is not None:
            if imgui.button("save"):
                self._save(engine, editor)
            self._widget("save")
        else:
            imgui.new_line()
        if editor.message:  # why the last edit was refused (the component's words), or "saved ..."
            lines.append(editor.message)
            imgui.push_text_wrap_pos(imgui.get_cursor_pos_x() + INSPECTOR_WIDTH - 16)
            imgui.text_colored(imgui.ImVec4(1.0, 0.35, 0.3, 1.0), editor.message)
            imgui.pop_text_wrap_pos()
        entity = editor.selected  # a duplicate or a deletion above chose another, or none
        if entity is None or not engine.world.exists(entity):  # undo and redo alone (after a deletion)
            self.inspector_lines = lines
            imgui.end()
            return
        imgui.text("handles")
        for mode in HANDLE_MODES:
            imgui.same_line()
            if imgui.radio_button(f"{mode}##handles", self.handle_mode == mode):
                self.handle_mode = mode
            self._widget(f"handles {mode}")
        imgui.push_item_width(INSPECTOR_WIDTH * 0.6)
        name = editor.name_of(entity)
        lines.append(name if name == f"entity {entity}" else f"{name} (entity {entity})")
        imgui.text(lines[-1])
        for cls_name, component in editor.components_of(entity):
            lines.append(cls_name)
            opened = imgui.collapsing_header(f"{cls_name}##{entity}", imgui.TreeNodeFlags_.default_open)
            self._widget(cls_name)
            if not opened:
                continue
            for field, value in editor.fields(component):
                self._field(editor, entity, cls_name, field, value, lines)
            if imgui.small_button(f"remove {cls_name}"):
                self._removing = (entity, cls_name)
            self._widget(f"remove {cls_name}")
        addable = editor.addable(entity)
        if addable and imgui.begin_combo("add component", ""):
            for name in addable:
                if imgui.selectable(name, False)[0]:
                    try:
                        editor.add_component(entity, name)
                    except Exception as exc:  # the message is the editor's
                        editor.message = str(exc)
            imgui.end_combo()
        self._widget("add component")
        imgui.pop_item_width()
        removing, self._removing = self._removing, None
        if removing is not None:  # after the loop over the components it changes
            try:
                editor.remove_component(*removing)
            except Exception as exc:
                editor.message = str(exc)
        self.inspector_lines = lines
        imgui.end()

    def _field(self, editor: Editor, entity: int, cls_name: str, field: str, value, lines: list[str]) -> None:
        """One field's input: numbers drag, booleans tick, colours pick, the rest is shown."""
        label = f"{field}##{cls_name}.{field}"
        try:
            data, kind = json_value(value)
        except Exception:
            data, kind = None, "object"
        changed, new = False, None
        automatic = AUTOMATIC_FIELDS.get((cls_name, field))
        if automatic is not None and value is None:  # the engine decides: shown as such, pinned at what it uses
            imgui.text(f"{field}: automatic")
            imgui.set_item_tooltip(automatic)
            self._widget(f"{cls_name}.{field}")
            imgui.same_line()
            if imgui.small_button(f"pin##{cls_name}.{field}"):
                try:
                    editor.try_set_field(entity, cls_name, field, editor.automatic(entity, cls_name, field))
                except EditError as exc:
                    editor.message = str(exc)
            self._widget(f"{cls_name}.{field} pin")
            lines.append(f"  {field} = automatic")
            return
        if (cls_name, field) in REFERENCE_FIELDS:  # another entity, chosen from those it may name
            changed, new = self._reference(editor, entity, cls_name, field, value, label)
        elif cls_name == "Material" and field in TEXTURE_FIELDS:  # written as in a level file, taken on Enter
            entered, text = imgui.input_text(label, editor.texture_text(entity, field),
                                             imgui.InputTextFlags_.enter_returns_true)
            if entered:
                self._try(editor, editor.set_texture, entity, field, text)
        elif (cls_name, field) == ("MeshRef", "mesh"):  # a shape to choose (its size: the Transform's scale)
            shape = editor.mesh_shape(entity)
            if imgui.begin_combo(label, shape):
                for choice in MESH_MAKERS:
                    if imgui.selectable(f"{choice}##mesh", choice == shape)[0] and choice != shape:
                        self._try(editor, editor.set_mesh_shape, entity, choice)
                    self._widget(f"MeshRef.mesh {choice}")
                imgui.end_combo()
        elif kind == "bool":
            changed, new = imgui.checkbox(label, bool(data))
        elif kind == "float":
            changed, new = imgui.drag_float(label, float(data), DRAG_SPEED)
        elif kind == "int":
            changed, new = imgui.drag_int(label, int(data))
        elif kind in ("vec2", "vec3", "vec4"):
            if "color" in field and kind == "vec4":  # in floats, unclamped: a light's or the sun's colour passes 1
                changed, new = imgui.color_edit4(label, list(data), HDR_COLOUR)
            elif "color" in field and kind == "vec3":
                changed, new = imgui.color_edit3(label, list(data), HDR_COLOUR)
            else:
                drag = {"vec2": imgui.drag_float2, "vec3": imgui.drag_float3, "vec4": imgui.drag_float4}[kind]
                changed, new = drag(label, list(data), DRAG_SPEED)
        elif kind == "quat":  # as Euler angles in degrees (pitch, yaw, roll: glm's x, y, z)
            angles = glm.degrees(glm.eulerAngles(value))
            changed, new = imgui.drag_float3(f"{field} (deg)##{cls_name}.{field}", list(angles), DRAG_SPEED * 50)
            if changed:
                new = glm.quat(glm.radians(glm.vec3(*new)))
        elif kind == "str":  # a choice ("aces", "cube", ...): written, taken on Enter, refused with the choices
            changed, new = imgui.input_text(label, data, imgui.InputTextFlags_.enter_returns_true)
        elif field.endswith("layers") and (kind == "list" or data is None):  # reflection layers: "1, 3", taken on Enter
            changed, text = imgui.input_text(label, ", ".join(str(v) for v in data or []),
                                             imgui.InputTextFlags_.enter_returns_true)
            if changed:
                new = parse_layers(text)
                if new is None:
                    editor.message = f"{cls_name}.{field}: layers are whole numbers, as 1, 3; got {text!r}"
                    changed = False
        else:
            shown = value if kind in ("null", "int") else (getattr(value, "name", None) or kind)
            imgui.text(f"{field}: {shown}")
        self._widget(f"{cls_name}.{field}")
        if kind in ("vec2", "vec3", "vec4", "quat"):  # where its first number is (a drag on one component)
            self.widgets[f"{cls_name}.{field}.left"] = (imgui.get_item_rect_min().x + 8.0,
                                                        self.widgets[f"{cls_name}.{field}"][1])
        lines.append(f"  {field} = {data if kind not in ('mesh', 'texture', 'object', 'array') else kind}")
        if changed:
            if isinstance(new, list | tuple) and not field.endswith("layers"):
                new = tuple(float(v) for v in new)
            editor.try_set_field(entity, cls_name, field, new, merge=True)
        if imgui.is_item_deactivated():
            editor.end_drag()
        if automatic is not None:  # pinned: a button hands it back to the engine
            if imgui.small_button(f"automatic##{cls_name}.{field}"):
                editor.try_set_field(entity, cls_name, field, None)
            imgui.set_item_tooltip(automatic)
            self._widget(f"{cls_name}.{field} automatic")

    def _transform_handles(self, engine: Engine) -> None:
        """The selection's handles over the world (x red, y green, z blue; ``transform_handles``),
        of the inspector's mode: ``move`` along a world axis, ``turn`` about one (its ring),
        ``scale`` along one of its own.  A handle pressed and dragged edits the Transform from
        where it stood when pressed: the mouse's motion along the handle on screen at the
        handle's scale, or the angle it sweeps about the origin; one undo step a drag."""
        editor, view = self.editor, engine.main_view
        entity = editor.selected if editor is not None else None
        handles = None
        if entity is not None and view is not None and engine.world.exists(entity):
            size = self.io.display_size
            handles = transform_handles(engine.world, entity, view.view_proj, view.eye, (size.x, size.y),
                                        self.handle_mode)
        self.handles = handles
        if handles is None:
            self._end_drag(editor)
            self._hovered = None
            return
        point = (self.io.mouse_pos.x, self.io.mouse_pos.y)
        drag = self._dragging
        if drag is not None:
            if drag.entity == entity and drag.handles.mode == handles.mode and imgui.is_mouse_down(0):
                self._drag_to(editor, drag, point)
            else:
                self._end_drag(editor)
        else:
            over_window = imgui.is_window_hovered(imgui.HoveredFlags_.any_window)
            self._hovered = None if over_window else handles.nearest(point, GIZMO_REACH)
            if self._hovered is not None and imgui.is_mouse_clicked(0):
                transform = engine.world.get(entity, Transform)
                start = {"move": transform.position, "turn": transform.rotation, "scale": transform.scale}[handles.mode]
                self._dragging = _Drag(entity, self._hovered, type(start)(start), point, handles, point)
        active = self._dragging.axis if self._dragging is not None else self._hovered
        draw = imgui.get_background_draw_list()
        for axis, line in enumerate(handles.lines):
            rgb = [0.25, 0.25, 0.25]
            rgb[axis] = 1.0
            colour = imgui.get_color_u32(imgui.ImVec4(*rgb, 1.0 if axis == active else 0.8))
            width = 4.0 if axis == active else 2.5
            points = [imgui.ImVec2(*p) for p in line]
            if handles.mode == "turn":
                draw.add_polyline(points, colour, width, imgui.ImDrawFlags_.closed)
                continue
            draw.add_line(points[0], points[1], colour, width)
            end, r = points[1], width + 2.0
            if handles.mode == "scale":
                draw.add_rect_filled(imgui.ImVec2(end.x - r, end.y - r), imgui.ImVec2(end.x + r, end.y + r), colour)
            else:
                draw.add_circle_filled(end, r, colour)

    def _drag_to(self, editor: Editor, drag: _Drag, point: tuple[float, float]) -> None:
        """A handle's drag with the mouse at ``point``: the Transform from the drag's start;
        with Ctrl held, in steps (``SNAP``: a quarter metre, 15 degrees, a tenth of the scale)."""
        handles, axis = drag.handles, drag.axis
        moved = (point[0] - drag.pressed[0], point[1] - drag.pressed[1])
        step = SNAP[handles.mode] if self.io.key_ctrl else 0.0

        def snapped(value: float) -> float:
            return round(value / step) * step if step else value

        try:
            if handles.mode == "move":
                editor.move(drag.entity, drag.start, handles.axes[axis] * snapped(handles.distance(axis, moved)))
            elif handles.mode == "scale":
                factor = snapped(1.0 + handles.distance(axis, moved) / handles.length)
                editor.rescale(drag.entity, drag.start, axis, factor)
            else:  # the angle swept, added up frame by frame (a drag may go round more than half a turn)
                drag.angle += handles.sweep(axis, drag.last, point)
                drag.last = point
                editor.turn(drag.entity, drag.start, handles.axes[axis], snapped(drag.angle))
        except (ComponentValueError, EditError) as exc:
            editor.message = str(exc)

    def _end_drag(self, editor: Editor | None) -> None:
        if self._dragging is not None and editor is not None:
            editor.end_drag()
        self._dragging = None

    @staticmethod
    def _frame_selection(engine: Engine, entity: int) -> None:
        """The camera moved to frame ``entity``, looking the way it looked (``framing_eye``):
        play, like flying there, not an edit of the level."""
        active = engine.active_camera()
        if active is None or active[0] == entity:
            return
        _, camera, transform = active
        forward = transform.rotation * glm.vec3(0.0, 0.0, -1.0)
        eye = framing_eye(engine.world, entity, forward, camera.fov_y)
        if eye is not None:
            transform.position = eye

    @staticmethod
    def _save(engine: Engine, editor: Editor) -> None:
        try:
            saved = editor.save()
            watch = engine.level_reload
            if watch is not None and Path(watch.path).resolve() == saved.resolve():
                # The world is what was written: not rebuilt from it (the undo list stays).
                watch.follow(saved)
            editor.message = f"saved {saved}"
        except Exception as exc:  # shown in the overlay, the window keeps running
            editor.message = str(exc)

    @staticmethod
    def _try(editor: Editor, do, *args) -> None:
        """An editor action from a button: a refusal is shown (the editor's message), not raised."""
        try:
            do(*args)
        except (EditError, ComponentValueError) as exc:
            editor.message = str(exc)

    def _reference(self, editor: Editor, entity: int, cls_name: str, field: str, value, label: str):
        """A combo of what a reference field may name (``Editor.reference_choices``), listed
        only while it is open."""
        shown = "none" if value is None or not editor.world.exists(value) else editor.label(value)
        changed, new = False, value
        if imgui.begin_combo(label, shown):
            choices, more = editor.reference_choices(entity, cls_name, field)
            for choice, text in choices:
                if imgui.selectable(f"{text}##{cls_name}.{field}.{choice}", choice == value)[0]:
                    changed, new = choice != value, choice
                self._widget(f"{cls_name}.{field} {choice}")
            if more:
                imgui.text_disabled(f"(the first {len(choices) - 1} listed)")
            imgui.end_combo()
        return changed, new

    def _widget(self, name: str) -> None:
        low, high = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        self.widgets[name] = ((low.x + high.x) / 2.0, (low.y + high.y) / 2.0)

    def release(self) -> None:
        if self.context is None:
            return  # released already
        if self._outline is not None:
            self._outline.release()
            self._outline = None
        context, self.context = self.context, None
        current = imgui.get_current_context()
        imgui.set_current_context(context)
        try:
            self.renderer.shutdown()
        finally:
            imgui.destroy_context(context)  # leaves no context current
            _LIVE[:] = [live for live in _LIVE if not live == context]
            for candidate in (current, self._previous):
                if _alive(candidate):
                    imgui.set_current_context(candidate)
                    break


def parse_layers(text: str) -> list[int] | None:
    """Reflection layers typed in the inspector ("1, 3" or "1 3"; empty: none), or None when a
    part is not a whole number (the component's own check then judges the numbers)."""
    parts = text.replace(",", " ").split()
    try:
        return [int(part) for part in parts]
    except ValueError:
        return None
