"""The debug overlay: frame rate and a frame-time graph, what the last frame cost (passes, draw
calls, views per reflection level, probe captures), the reflection and probe capture paths
in use, toggles for them, the post-processing (tone curve, exposure, bloom; toggles for
bloom, fog, the grade, ambient occlusion (and a view of it alone), screen reflections, the
materials' reflections of the sky and the curve), and shader errors from hot reload;
and the level editor's panels (``shell/editor_panels.py``: the entity list, the inspector,
the selection's handles, the editor's keys), whose selection it outlines wherever it shows
(``engine/render/outline.py``).

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
import time
from collections import deque
from typing import TYPE_CHECKING

import moderngl
import numpy as np
from imgui_bundle import imgui
from moderngl_window.integrations.imgui_bundle import ModernGLRenderer

from components.post import TONEMAP_CURVES
from engine.render.bindings import bind_texture, invalidate
from engine.render.present import ANTIALIAS_MODES
from engine.render.resample import RENDER_SCALE_RANGE
from shell.editor_panels import POSITION, EditorPanels
from shell.overlay_text import overlay_lines

if TYPE_CHECKING:  # the app's window makes the overlay
    from shell.app import Engine

FRAME_HISTORY = 120             # frames in the frame-time graph and the frame rate's average
REFLECTION_PATHS = ("per_mirror", "batched", "auto")
PROBE_PATHS = ("auto", "six_pass", "layered")
MAX_DEPTH_CAP = 16
CURVE_CHOICES = (None, *TONEMAP_CURVES)   # None: each camera's own Tonemap curve
CURVE_WIDTH = 100                          # pixels of the curve's drop-down
SLIDER_WIDTH = 90                          # pixels of the render scale's and sharpening's sliders
# moderngl-window's key names -> ImGui's keys: what typing in a field and editing its text need.
IMGUI_KEYS = {"BACKSPACE": imgui.Key.backspace, "DELETE": imgui.Key.delete, "ENTER": imgui.Key.enter,
              "ESCAPE": imgui.Key.escape, "TAB": imgui.Key.tab, "LEFT": imgui.Key.left_arrow,
              "RIGHT": imgui.Key.right_arrow, "UP": imgui.Key.up_arrow, "DOWN": imgui.Key.down_arrow,
              "HOME": imgui.Key.home, "END": imgui.Key.end, "A": imgui.Key.a, "C": imgui.Key.c,
              "V": imgui.Key.v, "X": imgui.Key.x, "Y": imgui.Key.y, "Z": imgui.Key.z}


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


class DebugOverlay(EditorPanels):
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
        self.windows: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {}  # a panel's corners (pixels)
        self._last = None
        self._previous = imgui.get_current_context()
        self.context = imgui.create_context()
        _LIVE.append(self.context)
        io = imgui.get_io()
        io.set_ini_filename("")  # no imgui.ini written next to the game
        self.renderer = OverlayRenderer(ctx, (1, 1))
        self.io = io
        self.scale = 1.0                      # pixels an ImGui unit (set_scale, taken at a draw)
        self._wanted_scale = 1.0
        self._outline = None                  # the selection's outline pass (made when first drawn)
        self._init_panels()

    def set_scale(self, scale: float) -> None:
        """Draw at ``scale`` pixels an ImGui unit (a window's pixel ratio: on a high-DPI
        screen 2, so the text and the widgets are the size they are elsewhere)."""
        self._wanted_scale = float(scale) if scale and scale > 0 else 1.0  # taken at the next draw

    def _apply_scale(self) -> None:
        """The wanted scale made ImGui's (its context current: the draw's)."""
        if self._wanted_scale != self.scale:
            style = imgui.get_style()
            style.scale_all_sizes(self._wanted_scale / self.scale)
            style.font_scale_dpi = self._wanted_scale
            self.scale = self._wanted_scale

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
        self._apply_scale()
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
        imgui.set_next_window_pos(imgui.ImVec2(POSITION[0] * self.scale, POSITION[1] * self.scale))
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
                         scale_min=0.0, graph_size=imgui.ImVec2(220 * self.scale, 40 * self.scale))
        imgui.separator()
        reflect, probes, renderer = engine.reflection_system, engine.stages["probes"], engine.renderer
        chosen = self._radios("reflections", REFLECTION_PATHS, reflect.path, "reflection")
        if chosen != reflect.path:  # set only when chosen: a new path is new settings
            reflect.path = chosen
        changed, cap = imgui.slider_int("depth cap", reflect.max_depth_cap, 0, MAX_DEPTH_CAP)
        if changed:
            reflect.max_depth_cap = cap
        self._widget("depth cap")
        chosen = self._radios("probes", PROBE_PATHS, probes.path, "probe")
        if chosen != probes.path:
            probes.path = chosen
        imgui.same_line(spacing=24)
        _, self.show_entities = imgui.checkbox("entities", self.show_entities)
        self._widget("entities")
        chosen = self._radios("AA", ANTIALIAS_MODES, renderer.antialias, "aa")
        if chosen != renderer.antialias:
            renderer.antialias = chosen
        present = engine.stages["present"]
        for label, stage, switch in (("shadows", engine.stages["shadows"], "enabled"), ("bloom", present, "bloom"),
                                     ("fog", engine.stages["prepare"], "fog"), ("grade", present, "grade"),
                                     ("AO", engine.stages["main"], "occlusion"),
                                     ("AO only", present, "show_occlusion"),
                                     ("caustics", engine.stages["prepare"], "caustics")):
            if label != "grade":  # (the grade, AO and the curve on a row of their own: the window stays narrow)
                imgui.same_line()
            self._switch(label, stage, switch)
        imgui.same_line()
        imgui.set_next_item_width(CURVE_WIDTH * self.scale)
        if imgui.begin_combo("curve", present.curve or "camera's"):
            self._widget("curve")
            for curve in CURVE_CHOICES:
                if imgui.selectable(f"{curve or 'camera'}##curve", present.curve == curve)[0]:
                    present.curve = curve
                self._widget(f"curve {curve or 'camera'}")
            imgui.end_combo()
        else:
            self._widget("curve")
        self._switch("SSR", engine.stages["main"], "reflections")  # (the screen reflections on a row of their own)
        imgui.same_line()
        self._switch("SSR only", engine.renderer.screen_reflections, "show_found")
        imgui.same_line()
        self._switch("sky refl", engine.stages["prepare"], "environment_reflections")
        imgui.same_line()
        self._switch("DoF", present, "depth_of_field")
        imgui.same_line()
        self._switch("motion blur", present, "motion_blur")
        lo, hi = RENDER_SCALE_RANGE   # (the picture's size and sharpening on a row of their own)
        imgui.set_next_item_width(SLIDER_WIDTH * self.scale)
        changed, scale = imgui.slider_float("render scale", renderer.render_scale, lo, hi, "%.2f")
        if changed:
            renderer.render_scale = min(max(scale, lo), hi)
        self._widget("render scale", SLIDER_WIDTH * self.scale)
        imgui.same_line()
        imgui.set_next_item_width(SLIDER_WIDTH * self.scale)
        changed, sharpness = imgui.slider_float("sharpen", renderer.sharpness, 0.0, 1.0, "%.2f")
        if changed:
            renderer.sharpness = min(max(sharpness, 0.0), 1.0)
        self._widget("sharpen", SLIDER_WIDTH * self.scale)
        x, y = imgui.get_window_pos()
        w, h = imgui.get_window_size()
        width, height = self.io.display_size
        self.region = (int(x), int(y), int(min(np.ceil(w), width - x)), int(min(np.ceil(h), height - y)))
        imgui.end()
        self._inspector(engine, self._entity_list(engine))
        self._transform_handles(engine)

    def _switch(self, label: str, owner: object, switch: str) -> None:
        """A checkbox for ``owner``'s boolean ``switch`` (a stage's own: set only when clicked)."""
        changed, on = imgui.checkbox(label, getattr(owner, switch))
        if changed:
            setattr(owner, switch, on)
        self._widget(label)

    def _widget(self, name: str, frame: float | None = None) -> None:
        """Note where the last item is (its middle; a slider's, ``frame`` wide, its frame's
        middle, not its label's): what a click at it acts on (the tests click there)."""
        low, high = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        x = low.x + frame / 2.0 if frame is not None else (low.x + high.x) / 2.0
        self.widgets[name] = (x, (low.y + high.y) / 2.0)

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
