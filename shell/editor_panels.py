"""The level editor's panels in the debug overlay (``shell/overlay.py``, which draws them
after its own window).  A click in the world selects the entity seen there (Ctrl+click: the
mirror or portal it was seen through), the entity list (every entity by name and kinds,
filtered) one that shows nowhere; the inspector shows its components' fields as drag
inputs, checkboxes, colour pickers (in floats, unclamped), choices and typed text, with
undo, redo, duplicate, delete, add, remove and save; a field the engine decides while unset
(``editor.AUTOMATIC_FIELDS``) is pinned at the value in use, or handed back, and one that
is off while unset (``editor.OFF_FIELDS``: a cutout's alpha cutoff) switched on or off.  The
selection's handles (their geometry: ``shell/handles.py``) move, turn and scale it; the
editor's keys (``shortcut``) undo, redo, duplicate, delete, save and frame it.

A mixin of ``DebugOverlay``: it reads the overlay's ImGui state (``io``, ``widgets``) and
keeps its own on it; every edit goes through the GL-free editor (``shell/editor.py``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from imgui_bundle import imgui
from pyglm import glm

from components import ComponentValueError, FromDecal, Transform
from components.rendering import MATERIAL_IMAGES
from engine.assets.level_assets import MESH_MAKERS
from engine.assets.level_file import LevelGame
from engine.assets.level_read import REFERENCE_FIELDS
from engine.assets.values import json_value
from engine.core.frame_io import Output
from engine.rules.raycast import raycast_seen
from shell.editor import AUTOMATIC_FIELDS, IMAGE_FIELDS, OFF_FIELDS, EditError, Editor
from shell.handles import (
    FRAME_MARGIN,
    HANDLE_MODES,
    MARKER_REACH,
    Handles,
    Marker,
    ReachOutline,
    descendants,
    framing_eye,
    framing_sphere,
    marker_at,
    markers,
    reach_outline,
    transform_handles,
    view_ray,
)
from shell.picture_pick import into_pictures

if TYPE_CHECKING:
    from shell.app import Engine

POSITION = (8, 8)               # the overlay's windows' inset from the output's corners, in pixels
INSPECTOR_WIDTH = 320                      # pixels of the inspector, at the right edge
MIN_INSPECTOR_HEIGHT = 120.0               # pixels: the inspector's height however little room is left
DRAG_SPEED = 0.01                          # a number field's change per pixel dragged
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


class EditorPanels:
    """The editor's part of ``DebugOverlay`` (see the module's docstring)."""

    def _init_panels(self) -> None:
        self.editor: Editor | None = None     # the level editor of the engine's world (made when first drawn)
        self.inspector_lines: list[str] = []  # the inspector's text last drawn (entity, components, message)
        self._removing: tuple[int, str] | None = None
        self._names_taken: dict[str, int] | None = None  # the game's names the editor last took (a rebuild's are new)
        self.show_entities = False            # the entity list is shown ("entities" ticked)
        self.handle_mode = "move"             # the selection's handles: HANDLE_MODES, chosen in the inspector
        self.handles: Handles | None = None   # the selection's handles, last drawn
        self.reach_outline: ReachOutline | None = None   # the selected light's or probe's reach, last drawn
        self.markers: list[Marker] = []   # the lights' and probes' markers, last drawn
        self._hovered: int | None = None      # the handle under the mouse
        self._dragging: _Drag | None = None   # a handle being dragged
        self.entity_filter = ""               # the entity list's filter, as typed
        self.listed_entities: list[str] = []  # the entity list's labels last drawn (while it is open)
        self._listed: tuple | None = None     # (what it was made for, when, entities, more): _listing

    def editing(self, engine: Engine) -> Editor:
        """The editor of ``engine``'s world (a new one when the world was rebuilt): the game's
        own components, entity names and level file, where it is a ``LevelGame``."""
        game = engine.game if isinstance(engine.game, LevelGame) else None
        rebuilt = game is not None and game.names is not self._names_taken  # the world built again from its
        if self.editor is None or self.editor.world is not engine.world or rebuilt:  # file (a new dict of names):
            self.editor = Editor(engine.world, *((game.components, game.names, game.level_path, game.asset_roots,
                                                  game.needs) if game else ()))
            self._names_taken = game.names if game else None                  # its edits named entities gone
        return self.editor

    def click(self, engine: Engine, x: float, y: float, surface: bool = False, place: bool = False) -> bool:
        """A click in the world at output pixel (``x``, ``y``) while the overlay is shown:
        select what the last frame's id images hold there (``surface``: the mirror or portal
        seen through), or (``place``: Shift+click) put the selection on the surface the
        picture shows there, followed through mirrors and portals (``Editor.place``). True
        when it was the editor's click (the overlay is shown)."""
        targets = engine.renderer.targets
        if not self.visible or self.context is None or targets is None:
            return False
        editor = self.editing(engine)
        view = engine.main_view
        if place:
            self._place_at(engine, editor, x, y)
            return True
        if view is not None and not surface:   # a light's or probe's marker first: it has no pixel of its own
            size = self.io.display_size
            entity = marker_at(markers(engine.world, view.view_proj, (size.x, size.y)), (x, y),
                               MARKER_REACH * self.scale)
            if entity is not None:
                editor.select(entity)
                return True
        # The id images are the drawn picture's size (smaller at a render scale below 1).
        output = engine.world.resources.get(Output)
        across, down = (targets.size[0] / output.size[0], targets.size[1] / output.size[1]) if output else (1, 1)
        follow = None
        if view is not None:   # (a monitor's screen picks what its picture shows there)
            size = self.io.display_size
            follow = into_pictures(engine.world, engine.renderer.monitors.entities,
                                   *view_ray(view.view_proj, (size.x, size.y), (x, y)), view.view_mask)
        editor.pick(targets.read_ids(), targets.read_surface_ids(), int(x * across), int(y * down), surface, follow)
        return True

    def _place_at(self, engine: Engine, editor: Editor, x: float, y: float) -> None:
        """Shift+click: the selection put where the main view's ray through output pixel
        (``x``, ``y``) meets a surface, followed through mirrors and portals; the selection,
        its descendants and decals' cuts are left out of the cast, and in each stretch what that
        view does not draw (``raycast_seen``'s ``view_mask``)."""
        entity = editor.selected
        view = engine.main_view
        if entity is None or not engine.world.exists(entity) or view is None:
            editor.message = "select something first: Shift+click puts the selection where you click"
            return
        size = self.io.display_size
        origin, direction = view_ray(view.view_proj, (size.x, size.y), (x, y))
        world = engine.world
        own = descendants(world, entity) | {entity}
        seen = raycast_seen(world, origin, direction, ignore=own, where=lambda e: not world.has(e, FromDecal),
                            view_mask=view.view_mask)
        if seen is None:
            editor.message = "nothing there to put it on"
            return
        self._try(editor, editor.place, entity, seen.hit.point, seen.hit.normal)

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

    def _entity_list(self, engine: Engine) -> float:
        """Every entity by name and kinds, to select one a click cannot reach (a light, the
        sky, a camera, post settings) or find one by name: a filter (any part of the label)
        over a scrolled list, in a window at the top of the right edge (the inspector below
        it).  Shown while the overlay's "entities" box is ticked, so a big world costs nothing
        here otherwise.  Returns the window's bottom (pixels from the top; the inspector goes
        below it)."""
        if not self.show_entities:
            self.listed_entities = []
            return POSITION[1] * self.scale - 4
        width, _height = self.io.display_size
        inspector, inset = INSPECTOR_WIDTH * self.scale, POSITION[0] * self.scale
        imgui.set_next_window_pos(imgui.ImVec2(max(width - inspector - inset, 0), POSITION[1] * self.scale))
        imgui.set_next_window_size(imgui.ImVec2(inspector, 0))
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
        scale = self.scale
        imgui.begin_child("##entity list", imgui.ImVec2(ENTITY_LIST_WIDTH * scale, ENTITY_LIST_HEIGHT * scale))
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
        width, height = self.io.display_size
        inspector, inset = INSPECTOR_WIDTH * self.scale, POSITION[0] * self.scale
        imgui.set_next_window_pos(imgui.ImVec2(max(width - inspector - inset, 0), top + 4))
        # As tall as its fields, down to the window's bottom at most: past that it scrolls (the
        # wheel over it), so a small window still reaches every field.
        tallest = max(height - top - 4 - inset, MIN_INSPECTOR_HEIGHT * self.scale)
        imgui.set_next_window_size_constraints(imgui.ImVec2(inspector, 0), imgui.ImVec2(inspector, tallest))
        imgui.set_next_window_bg_alpha(0.85)
        flags = (imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
                 | imgui.WindowFlags_.no_collapse | imgui.WindowFlags_.no_move)
        imgui.begin("Inspector", None, flags)
        corner, extent = imgui.get_window_pos(), imgui.get_window_size()
        self.windows["Inspector"] = ((corner.x, corner.y), (corner.x + extent.x, corner.y + extent.y))
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
            imgui.push_text_wrap_pos(imgui.get_cursor_pos_x() + (INSPECTOR_WIDTH - 16) * self.scale)
            imgui.text_colored(imgui.ImVec4(1.0, 0.35, 0.3, 1.0), editor.message)
            imgui.pop_text_wrap_pos()
        entity = editor.selected  # a duplicate or a deletion above chose another, or none
        if entity is None or not engine.world.exists(entity):  # undo and redo alone (after a deletion)
            self.inspector_lines = lines
            imgui.end()
            return
        self.handle_mode = self._radios("handles", HANDLE_MODES, self.handle_mode)
        imgui.push_item_width(INSPECTOR_WIDTH * 0.6 * self.scale)
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
        if kind == "list" and 2 <= len(data) <= 4 and not field.endswith("layers") \
                and all(isinstance(v, int | float) and not isinstance(v, bool) for v in data) \
                and any(isinstance(v, float) for v in data):
            kind = f"vec{len(data)}"   # a pair of numbers (a rectangle's sides, a range): dragged as a vector
        elif kind == "list" and 2 <= len(data) <= 4 and not field.endswith("layers") \
                and all(isinstance(v, int) and not isinstance(v, bool) for v in data):
            kind = f"ivec{len(data)}"  # whole numbers (a volume's points along x, y, z): dragged in steps of 1
        unset = _unset_words(cls_name, field)
        if unset is not None and value is None:  # automatic or off: shown as such, a button gives it a value
            word, give, _, hint = unset
            imgui.text(f"{field}: {word}")
            imgui.set_item_tooltip(hint)
            self._widget(f"{cls_name}.{field}")
            imgui.same_line()
            if imgui.small_button(f"{give}##{cls_name}.{field}"):
                try:
                    editor.try_set_field(entity, cls_name, field, editor.switched_on(entity, cls_name, field))
                except EditError as exc:
                    editor.message = str(exc)
            self._widget(f"{cls_name}.{field} {give}")
            lines.append(f"  {field} = {word}")
            return
        if (cls_name, field) in REFERENCE_FIELDS:  # another entity, chosen from those it may name
            changed, new = self._reference(editor, entity, cls_name, field, value, label)
        elif (cls_name, field) in IMAGE_FIELDS:  # written as in a level file, taken on Enter
            entered, text = imgui.input_text(label, editor.texture_text(entity, field, cls_name),
                                             imgui.InputTextFlags_.enter_returns_true)
            if entered:
                self._try(editor, editor.set_texture, entity, field, text, cls_name)
        elif (cls_name, field) == ("Model", "file"):  # a path beside the level, taken on Enter
            entered, text = imgui.input_text(label, editor.model_file_text(entity),
                                             imgui.InputTextFlags_.enter_returns_true)
            if entered:
                self._try(editor, editor.set_model_file, entity, text)
        elif (cls_name, field) == ("Model", "variant"):  # one of the file's material variants, or its own look
            chosen = value or "(the file's own)"
            if imgui.begin_combo(label, chosen):
                for choice in ("", *editor.model_variants(entity)):
                    shown = choice or "(the file's own)"
                    if imgui.selectable(f"{shown}##variant", choice == value)[0] and choice != value:
                        self._try(editor, editor.set_field, entity, "Model", "variant", choice)
                    self._widget(f"Model.variant {choice}")
                imgui.end_combo()
        elif field == "clip" and cls_name in ("Animation", "AnimationLayer") and editor.model_clips(entity):
            # one of its model's clips
            if imgui.begin_combo(label, value or "(none: at rest)"):
                for choice in ("", *editor.model_clips(entity)):
                    if imgui.selectable(f"{choice or '(none: at rest)'}##{cls_name}.clip", choice == value)[0] \
                            and choice != value:
                        self._try(editor, editor.set_field, entity, cls_name, "clip", choice)
                    self._widget(f"{cls_name}.clip {choice}")
                imgui.end_combo()
        elif (cls_name, field) == ("Material", "second_uv_maps"):  # a tick a map: read at the mesh's second UVs
            imgui.text(f"{field}: the maps read at the mesh's second UV set")
            for name in MATERIAL_IMAGES:
                ticked, on = imgui.checkbox(f"{name}##{cls_name}.{field}", name in value)
                self._widget(f"{cls_name}.{field} {name}")
                if ticked:
                    chosen = tuple(n for n in MATERIAL_IMAGES if (n == name and on) or (n != name and n in value))
                    editor.try_set_field(entity, cls_name, field, chosen)  # (refused: no second set, said why)
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
        elif kind in ("ivec2", "ivec3", "ivec4"):
            drag = {"ivec2": imgui.drag_int2, "ivec3": imgui.drag_int3, "ivec4": imgui.drag_int4}[kind]
            changed, new = drag(label, list(data))
        elif kind == "quat":  # as Euler angles in degrees (pitch, yaw, roll: glm's x, y, z), kept by the editor
            angles = editor.angles(entity, cls_name, field)
            dragged, new_angles = imgui.drag_float3(f"{field} (deg)##{cls_name}.{field}", list(angles),
                                                    DRAG_SPEED * 50)
            if dragged:
                editor.set_angles(entity, cls_name, field, new_angles, merge=True)
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
        if kind in ("vec2", "vec3", "vec4", "ivec2", "ivec3", "ivec4", "quat"):  # where its first number is
            self.widgets[f"{cls_name}.{field}.left"] = (imgui.get_item_rect_min().x + 8.0,
                                                        self.widgets[f"{cls_name}.{field}"][1])
            if kind in ("vec3", "ivec3", "quat"):  # and its second (the middle third of the numbers' width)
                self.widgets[f"{cls_name}.{field}.middle"] = (imgui.get_item_rect_min().x + imgui.calc_item_width() / 2,
                                                              self.widgets[f"{cls_name}.{field}"][1])
        lines.append(f"  {field} = {data if kind not in ('mesh', 'texture', 'object', 'array') else kind}")
        if changed:
            if isinstance(new, list | tuple) and not field.endswith("layers"):
                new = tuple((int if kind.startswith("ivec") else float)(v) for v in new)
            editor.try_set_field(entity, cls_name, field, new, merge=True)
        if imgui.is_item_deactivated():
            editor.end_drag()
        if unset is not None:  # pinned or on: a button hands it back to the engine or switches it off
            _, _, back, hint = unset
            if imgui.small_button(f"{back}##{cls_name}.{field}"):
                editor.try_set_field(entity, cls_name, field, None)
            imgui.set_item_tooltip(hint)
            self._widget(f"{cls_name}.{field} {back}")

    def _transform_handles(self, engine: Engine) -> None:
        """A selected light's or probe's reach (a spot's cone, a light all round's range
        sphere, a probe's influence box: ``reach_outline``) and the selection's handles over
        the world (x red, y green, z blue; ``transform_handles``), of the inspector's mode:
        ``move`` along a world axis, ``turn`` about one (its ring), ``scale`` along one of its
        own.  A handle pressed and dragged edits the Transform from where it stood when
        pressed: the mouse's motion along the handle on screen at the handle's scale, or the
        angle it sweeps about the origin; one undo step a drag."""
        editor, view = self.editor, engine.main_view
        entity = editor.selected if editor is not None else None
        handles = outline = None
        if entity is not None and view is not None and engine.world.exists(entity):
            size = self.io.display_size
            handles = transform_handles(engine.world, entity, view.view_proj, view.eye, (size.x, size.y),
                                        self.handle_mode)
            outline = reach_outline(engine.world, entity, view.view_proj, (size.x, size.y))
        self.handles, self.reach_outline = handles, outline
        self._markers(engine, entity)
        if outline is not None:   # under the handles: where the light or probe reaches, in its own colour
            draw = imgui.get_background_draw_list()
            colour = imgui.get_color_u32(imgui.ImVec4(1.0, 0.85, 0.3, 0.7))
            for line in outline.lines:
                draw.add_polyline([imgui.ImVec2(*p) for p in line], colour, 1.5 * self.scale, 0)
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
            self._hovered = None if over_window else handles.nearest(point, GIZMO_REACH * self.scale)
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
            width = (4.0 if axis == active else 2.5) * self.scale
            points = [imgui.ImVec2(*p) for p in line]
            if handles.mode == "turn":
                draw.add_polyline(points, colour, width, imgui.ImDrawFlags_.closed)
                continue
            draw.add_line(points[0], points[1], colour, width)
            end, r = points[1], width + 2.0 * self.scale
            if handles.mode == "scale":
                draw.add_rect_filled(imgui.ImVec2(end.x - r, end.y - r), imgui.ImVec2(end.x + r, end.y + r), colour)
            else:
                draw.add_circle_filled(end, r, colour)

    def _markers(self, engine: Engine, selected: int | None) -> None:
        """A marker where each light, probe, emitter and decal with no mesh stands (``markers``:
        a light a yellow dot, a probe a cyan ring, an emitter an orange diamond, a decal a violet
        square, the selected one ringed in white): what a click there selects (``click``)."""
        view = engine.main_view
        size = self.io.display_size
        self.markers = markers(engine.world, view.view_proj, (size.x, size.y)) if view is not None else []
        draw = imgui.get_background_draw_list()
        r = 5.0 * self.scale
        light = imgui.get_color_u32(imgui.ImVec4(1.0, 0.85, 0.3, 0.9))
        probe = imgui.get_color_u32(imgui.ImVec4(0.3, 0.9, 1.0, 0.9))
        emitter = imgui.get_color_u32(imgui.ImVec4(1.0, 0.45, 0.1, 0.9))
        decal = imgui.get_color_u32(imgui.ImVec4(0.85, 0.4, 1.0, 0.9))
        fog = imgui.get_color_u32(imgui.ImVec4(0.75, 0.78, 0.82, 0.8))
        white = imgui.get_color_u32(imgui.ImVec4(1.0, 1.0, 1.0, 1.0))
        for marker in self.markers:
            at = imgui.ImVec2(*marker.at)
            if marker.kind == "light":
                draw.add_circle_filled(at, r, light)
            elif marker.kind == "emitter":  # an orange diamond
                draw.add_quad_filled(imgui.ImVec2(at.x, at.y - r), imgui.ImVec2(at.x + r, at.y),
                                     imgui.ImVec2(at.x, at.y + r), imgui.ImVec2(at.x - r, at.y), emitter)
            elif marker.kind == "decal":  # a violet square
                draw.add_rect_filled(imgui.ImVec2(at.x - r, at.y - r), imgui.ImVec2(at.x + r, at.y + r), decal)
            elif marker.kind == "volume":  # a cyan square's outline (a probe's colour: a grid of them)
                draw.add_rect(imgui.ImVec2(at.x - r, at.y - r), imgui.ImVec2(at.x + r, at.y + r), probe, 0.0,
                              2.0 * self.scale)
            elif marker.kind == "fog":  # a grey disc (a puff of mist)
                draw.add_circle_filled(at, r, fog)
            else:
                draw.add_circle(at, r, probe, 0, 2.0 * self.scale)
            if marker.entity == selected:
                draw.add_circle(at, r + 3.0 * self.scale, white, 0, 1.5 * self.scale)

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
        if camera.projection == "orthographic":  # spans the selection, from far enough back to see all of it
            found = framing_sphere(engine.world, entity)
            if found is not None:
                centre, radius = found
                transform.position = centre - glm.normalize(forward) * (radius * FRAME_MARGIN + camera.near + radius)
                camera.ortho_height = 2.0 * radius * FRAME_MARGIN
            return
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

    def _radios(self, label: str, choices, current, key: str | None = None):
        """A row of radio buttons after ``label``: the choice made (``current`` if none);
        each button's widget is "``key`` choice" (``key``: the label)."""
        imgui.text(label)
        key = key or label
        for choice in choices:
            imgui.same_line()
            if imgui.radio_button(f"{choice}##{key}", current == choice):
                current = choice
            self._widget(f"{key} {choice}")
        return current

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


def parse_layers(text: str) -> list[int] | None:
    """Reflection layers typed in the inspector ("1, 3" or "1 3"; empty: none), or None when a
    part is not a whole number (the component's own check then judges the numbers)."""
    parts = text.replace(",", " ").split()
    try:
        return [int(part) for part in parts]
    except ValueError:
        return None


def _unset_words(cls_name: str, field: str) -> tuple[str, str, str, str] | None:
    """How the inspector shows a field whose None has a meaning: (what None is shown as, the
    button that gives it a value, the button that takes it back, the tooltip); None for
    any other field."""
    automatic = AUTOMATIC_FIELDS.get((cls_name, field))
    if automatic is not None:
        return "automatic", "pin", "automatic", automatic
    off = OFF_FIELDS.get((cls_name, field))
    if off is not None:
        return "off", "on", "off", off[1]
    return None
