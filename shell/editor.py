"""Editing a level in the window: pick an entity from the frame's id images or the entity
list, set its fields through the components' own checks, add and remove components, make,
duplicate and delete entities, undo and redo, save.

GL-free: the editor works on a World and on id images already read back (numpy arrays), so
the overlay (``shell.overlay``) calls it and tests drive it headless. An edit is a field
write as code makes it (``setattr`` on the component: its ``_validate`` and the world's
invariants refuse a bad value before anything changes), so an edit in the window, in code
and in a level file are held to one set of rules. Undo and redo are the command pattern:
each edit is kept as what it changed (the component, the field, the value before and after;
or the component added or removed) and undone by writing the old value back through the
same checks. A drag is many writes of one field: ``merge=True`` folds them into one edit.
Saving writes the level file back into its own text (``save_level(keep=...)``), so the
file's diff is the edit.
"""
from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import tomllib
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    ComponentWarning,
    Decal,
    FromDecal,
    FromModel,
    Material,
    MeshRef,
    Model,
    Transform,
    look_rotation,
)
from components.rendering import MATERIAL_IMAGES, automatic_mix
from engine.assets.level_assets import MESH_MAKERS, LevelAssets, level_model, level_texture, user_asset_roots
from engine.assets.level_read import DERIVED_COMPONENTS, ENGINE_COMPONENTS, REFERENCE_FIELDS, REFERENCE_KINDS
from engine.assets.level_save import save_level
from engine.assets.mesh import load_model_file
from engine.core.errors import SpeculumError
from engine.core.transforms import current_world_matrix
from engine.core.world import World, check_components
from engine.rules.frame_rules import active_camera
from engine.rules.light_rules import followed_sun

MAX_UNDO = 1000  # edits kept for undo; the oldest go first
MAX_LISTED = 200  # entities the entity list shows at once (a filter finds the rest)
NEW_DISTANCE = 3.0  # metres in front of the active camera a new entity is made
NEW_MESH = "box"    # the shape a MeshRef added in the editor starts as
MIN_SCALE_FACTOR = 0.01  # a scale drag shrinks an axis to this share of its scale at the drag's start at most
SAME_ANGLES_DEGREES = 0.01  # a rotation within this of the angles last shown shows them as they were
                            # (at yaw 90 pitch and roll turn about one axis: the triple is not unique)
TEXTURE_FIELDS = MATERIAL_IMAGES  # Material's images
# Every image field, (component, field): typed as a level file's texture table names it.
IMAGE_FIELDS = frozenset({("Material", name) for name in TEXTURE_FIELDS} | {("PointLight", "cookie"),
                                                                    ("ParticleEmitter", "texture"),
                                                                    ("Decal", "texture"), ("Decal", "normal_map")})

# Fields whose None means "the engine decides" (what it decides: ``Editor.automatic``).  The
# inspector shows such a field as automatic with a button that pins the value in use now, and
# a pinned one with a button that hands it back to the engine.
AUTOMATIC_FIELDS: dict[tuple[str, str], str] = {
    ("Skybox", "sun_direction"): "follows the brightest directional light",
    ("Reflective", "mix"): "1.0 untextured, 0.5 textured",
    ("ParticleEmitter", "end_color"): "its colour, faded to alpha 0",
}

# Fields whose None means "off": the inspector shows such a field as off with a button that
# switches it on at the value given here, and a set one with a button that switches it off.
OFF_FIELDS: dict[tuple[str, str], tuple[Any, str]] = {
    ("Material", "alpha_cutoff"): (0.5, "a cutout: nothing is drawn where the alpha is below it"),
    ("Decal", "alpha_cutoff"): (0.5, "a hard edge: solid where the image's alpha reaches it, nothing below"),
    ("Decal", "layers"): ((0,), "only surfaces on these reflection layers take it (off: every surface)"),
}


Needs = Callable[[World, int, "str | None"], "str | None"]  # LevelGame.needs


def euler_degrees(rotation: glm.quat, near: glm.vec3 | None = None) -> glm.vec3:
    """Euler angles in degrees (glm's x, y, z: pitch, yaw, roll) that make ``rotation``, the
    triple nearest ``near``.  Every rotation has two, (x, y, z) and (x + 180, 180 - y,
    z + 180), each angle free by whole turns; glm's own keeps yaw in [-90, 90].  Shown that
    way, a yaw dragged past 90 came back as the other triple, so the drag turned back at 90
    (as Unity, the inspector keeps the angles last shown and shows the triple nearest them)."""
    first = glm.vec3(glm.degrees(glm.eulerAngles(glm.normalize(glm.dquat(rotation)))))
    if near is None:
        return first
    best, best_distance = first, float("inf")
    for triple in (first, glm.vec3(first.x + 180.0, 180.0 - first.y, first.z + 180.0)):
        moved = glm.vec3(*(angle + 360.0 * round((hint - angle) / 360.0)
                           for angle, hint in zip(triple, near, strict=True)))
        distance = sum(abs(angle - hint) for angle, hint in zip(moved, near, strict=True))
        if distance < best_distance:
            best, best_distance = moved, distance
    return best


def turn_degrees(angles: glm.vec3, rotation: glm.quat) -> float:
    """The angle in degrees between the rotation Euler ``angles`` make and ``rotation``, in
    double precision, the stored one made unit there (a float quaternion's dot, or its length off
    1 by a float's rounding, resolves no turn under about 0.05 degrees)."""
    made = glm.dquat(glm.radians(glm.dvec3(angles)))
    return math.degrees(2.0 * math.acos(min(abs(glm.dot(made, glm.normalize(glm.dquat(rotation)))), 1.0)))


class EditError(SpeculumError, ValueError):
    """An edit that cannot be made (no such entity, component or field): says which."""


@dataclasses.dataclass
class Edit:
    """One undoable edit: ``action`` is "set" (``field`` from ``before`` to ``after``), "add"
    or "remove" (``component``, the object itself, so undo puts back the very same one),
    "create" or "delete" (a whole entity: its components, the very same objects, made again
    under a new id; the edits that name the old id are moved to it: ``Editor._restore``)."""

    action: str
    entity: int
    kind: type | None  # None: a whole entity ("create", "delete")
    component: Any     # "create", "delete": the entity's components; ``field`` its name
    field: str | None = None
    before: Any = None  # "delete": the portals whose partner it was (cleared with it)
    after: Any = None
    open: bool = True  # a drag still going on: a merging write of the same field joins it


def _copy(value: Any) -> Any:
    """A value kept for undo, apart from the one the component holds (glm vectors are
    edited in place by games; lists by hand)."""
    if isinstance(value, (glm.vec2, glm.vec3, glm.vec4, glm.quat, glm.dvec3, glm.dquat)):
        return type(value)(value)
    if isinstance(value, list):
        return list(value)
    return value


def pick(ids: np.ndarray, surface_ids: np.ndarray | None, x: int, y: int, surface: bool = False) -> int | None:
    """The entity at pixel (``x``, ``y`` from the top left) of a frame's id images: the one
    finally seen there (``RenderTargets.read_ids``: a box seen in a mirror is the box), or
    with ``surface`` the one drawn there in the main view (``read_surface_ids``: the mirror
    or portal the pixel was seen through, or the thing itself where nothing reflects).
    None for the sky, or a pixel outside the image."""
    image = surface_ids if surface else ids
    if image is None:
        raise EditError("picking the surface needs the frame's surface id image (read_surface_ids)")
    height, width = image.shape[:2]
    if not (0 <= x < width and 0 <= y < height):
        return None
    entity = int(image[y, x])
    return entity or None


_PASSED_ON: dict = {}  # the warnings _says_warnings has passed on to the console (warnings' own registry)


def _says_warnings(edit: Callable[..., Any]) -> Callable[..., Any]:
    """An edit whose write a rule answers with a ``ComponentWarning`` (a portal's mesh that is
    not its size, a water with no waves: allowed, but likely not meant) shows the warning as the
    editor's message, as a refusal's is shown: the overlay's user sees it, not only the console,
    where it is passed on too."""
    @functools.wraps(edit)
    def heard(self: Editor, *args: Any, **kwargs: Any) -> Any:
        caught: list[warnings.WarningMessage] = []
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                result = edit(self, *args, **kwargs)
        finally:  # (a refused edit's warnings reach the console too)
            for w in caught:  # (the console's filter as for any warning: a drag's hundred writes say it once)
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, registry=_PASSED_ON,
                                       source=w.source)
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]
        if said:
            self.message = said[-1]
        return result
    return heard


class Editor:
    """Edits of one world, with undo and redo, and the selected entity.

    ``components``: the components that may be added, by name (the engine's
    ``ENGINE_COMPONENTS`` and the game's own, ``LevelGame.components``). ``names``: entity
    ids by name (``LevelGame.names``), kept in the saved file. ``level_path``: the level file
    the world was loaded from, whose text a save keeps. ``message``: why the last edit was
    refused (the component's own words), None after one that was made."""

    def __init__(self, world: World, components: Mapping[str, type] | None = None,
                 names: Mapping[str, int] | None = None, level_path: str | Path | None = None,
                 asset_roots: Sequence[str | Path] = (), needs: Needs | None = None) -> None:
        self.world = world
        self.needs = needs  # the game's reason it cannot do without an entity or a component of it
        self.asset_roots = [Path(root) for root in asset_roots]  # the game's, besides the level's folder
        self.components: dict[str, type] = {**ENGINE_COMPONENTS, **(components or {})}
        self.game_components = {k: v for k, v in (components or {}).items() if k not in ENGINE_COMPONENTS}
        self.names: dict[str, int] = dict(names or {})
        self.level_path = Path(level_path) if level_path is not None else None
        self.selected: int | None = None
        self.message: str | None = None
        self._done: list[Edit] = []
        self._undone: list[Edit] = []
        self._everything: list[Edit] = []  # every edit made, undone or not: what a save may write
        self._applied = 0  # undos and redos made (``edit_count``)
        self._angles: dict[tuple[int, str, str], glm.vec3] = {}  # rotations' angles last shown (``angles``)
        self._files: dict[tuple[str, int], Any] = {}  # model files as loaded (``model_variants``, ``model_clips``)

    # --- selection -------------------------------------------------------------------------
    def pick(self, ids: np.ndarray, surface_ids: np.ndarray | None, x: int, y: int,
             surface: bool = False, follow: Callable[[int], int | None] | None = None) -> int | None:
        """Select the entity at a pixel (``pick``); the sky selects nothing. ``follow``: what a
        picked entity picks in turn (``shell/picture_pick.py``: a monitor's screen, what its
        picture shows there), but for the ``surface`` itself. A new selection clears the
        message of the last refused edit."""
        picked = pick(ids, surface_ids, x, y, surface)
        if follow is not None and picked is not None and not surface:
            picked = follow(picked)
        part = self.world.try_get(picked, FromModel) if picked is not None and self.world.exists(picked) else None
        # A model's part is the file's: the click selects the model (its root), what a level
        # file holds and a designer moves, as Unity's and Godot's editors pick a placed scene.
        self.selected = part.model if part is not None and self.world.exists(part.model) else picked
        cut = self.world.try_get(picked, FromDecal) if picked is not None and self.world.exists(picked) else None
        if cut is not None and self.world.exists(cut.decal):  # a decal's cut mesh: the decal
            self.selected = cut.decal
        self.message = None
        return self.selected

    def select(self, entity: int | None) -> None:
        """Select ``entity`` (from the entity list: a light, the sky or a camera has no pixel
        to click), or nothing; an EditError for an entity that does not exist."""
        if entity is not None and not self.world.exists(entity):
            raise EditError(f"entity {entity} does not exist")
        self.selected = entity
        self.message = None

    def name_of(self, entity: int) -> str:
        """The entity's name in the level file, or ``entity <id>``."""
        return next((n for n, e in self.names.items() if e == entity), f"entity {entity}")

    def label(self, entity: int, name: str | None = None) -> str:
        """How the entity list shows an entity: its name and the kinds of its components
        (Transform left out: nearly everything has one), as ``sun: DirectionalLight``."""
        kinds = sorted(n for n, _ in self.components_of(entity) if n != "Transform")
        return f"{name or self.name_of(entity)}: {', '.join(kinds) or 'Transform'}"

    def listed(self, text: str = "", limit: int = MAX_LISTED) -> tuple[list[tuple[int, str]], bool]:
        """The entity list: (entity, ``label``) in the order they were made, those whose label
        holds ``text`` (any case), at most ``limit``; and whether more matched.  Without a
        filter it stops at the limit, so a world of 100,000 entities lists its first ones at
        once; with one, every entity's label is looked at."""
        needle = text.strip().lower()
        by_id = {e: n for n, e in self.names.items()}
        found: list[tuple[int, str]] = []
        for entity in self.world.entities():
            if self.world.has(entity, FromDecal):  # a decal's cut mesh: the engine's, made again with each cut
                continue
            label = self.label(entity, by_id.get(entity))
            if needle and needle not in label.lower():
                continue
            if len(found) == limit:
                return found, True
            found.append((entity, label))
        return found, False

    def reference_choices(self, entity: int, component: str | type, field: str,
                          limit: int = MAX_LISTED) -> tuple[list[tuple[int | None, str]], bool]:
        """What a field naming another entity (``REFERENCE_FIELDS``: a Transform's parent, a
        Portal's partner, a ParticleEmitter's sub-emitter, a Monitor's camera) may name, for the
        inspector's choice: none, then the other entities holding what it names (a Transform;
        ``REFERENCE_KINDS``: a Portal, a ParticleEmitter, a Camera) by ``label``, at most ``limit``; and
        whether there were more.  The component's own checks still judge the choice (a
        parent that descends from the entity is a cycle, refused)."""
        name = component if isinstance(component, str) else component.__name__
        if (name, field) not in REFERENCE_FIELDS:
            raise EditError(f"{name}.{field} does not name an entity")
        by_id = {e: n for n, e in self.names.items()}
        kind = ENGINE_COMPONENTS[REFERENCE_KINDS.get((name, field), "Transform")]
        others = sorted(e for e, _ in self.world.query_one(kind) if e != entity)
        choices = [(None, "none"), *((e, self.label(e, by_id.get(e))) for e in others[:limit])]
        return choices, len(others) > limit

    def switched_on(self, entity: int, component: str | type, field: str) -> Any:
        """The value a field whose None has a meaning takes when given one: the value in use
        for a field the engine decides (``automatic``), the ``OFF_FIELDS`` value for one that
        is off.  An EditError for another field."""
        name = type(self.component(entity, component)).__name__
        off = OFF_FIELDS.get((name, field))
        return off[0] if off is not None else self.automatic(entity, component, field)

    def automatic(self, entity: int, component: str | type, field: str) -> Any:
        """The value the engine uses for a field left to it (``AUTOMATIC_FIELDS``), as a value
        the field takes: pinning it changes nothing on screen.  An EditError for another field."""
        target = self.component(entity, component)
        name = type(target).__name__
        if (name, field) not in AUTOMATIC_FIELDS:
            raise EditError(f"{name}.{field} is not a field the engine decides")
        if name == "Skybox":
            return glm.vec3(*followed_sun(self.world).direction)
        if name == "ParticleEmitter":
            return target.final_color
        return automatic_mix(self.world.try_get(entity, Material))

    # --- what an entity holds --------------------------------------------------------------
    def component(self, entity: int, component: str | type) -> Any:
        """The entity's component of that class (or class name); an EditError if it has none."""
        if not self.world.exists(entity):
            raise EditError(f"entity {entity} does not exist")
        name = component if isinstance(component, str) else component.__name__
        found = next((c for c in self.world.components_of(entity) if type(c).__name__ == name), None)
        if found is None:
            raise EditError(f"{self.name_of(entity)} has no {name}")
        return found

    def components_of(self, entity: int) -> list[tuple[str, Any]]:
        """(class name, component) of the entity's editable components, in a stable order:
        its Transform first (where it is, what a designer moves most, as Unity's inspector has
        it), the rest by name (derived state, PortalClone and Slice, is the engine's and not
        shown)."""
        if not self.world.exists(entity):
            return []
        found = [(type(c).__name__, c) for c in self.world.components_of(entity)
                 if type(c).__name__ not in DERIVED_COMPONENTS]
        return sorted(found, key=lambda item: (item[0] != "Transform", item[0]))

    @staticmethod
    def fields(component: Any) -> list[tuple[str, Any]]:
        """(field, value) of a component's public fields, in declaration order."""
        if not dataclasses.is_dataclass(component):
            return []
        return [(f.name, getattr(component, f.name)) for f in dataclasses.fields(component)
                if f.init and not f.name.startswith("_")]

    def addable(self, entity: int) -> list[str]:
        """Names of the components the entity could be given (those it has not got)."""
        held = {type(c).__name__ for c in self.world.components_of(entity)} if self.world.exists(entity) else set()
        return sorted(n for n in self.components if n not in held)

    # --- edits -----------------------------------------------------------------------------
    @_says_warnings
    def set_field(self, entity: int, component: str | type, field: str, value: Any, merge: bool = False) -> None:
        """Write ``value`` into a field as code would (``setattr``): the component's checks
        and the world's invariants refuse a bad value with their own ComponentValueError,
        and nothing changes. ``merge``: part of a drag (one undo step for the whole drag)."""
        self._refuse_made_again(entity)
        target = self.component(entity, component)
        if type(target).__name__ == "Model" and field == "variant" and value and isinstance(value, str) \
                and target.file and value not in self.model_variants(entity):
            variants = ", ".join(repr(v) for v in self.model_variants(entity)) or "none"
            self.message = f"Model.variant: the model file has no material variant {value!r} (its variants: {variants})"
            raise EditError(self.message)
        kind = type(target).__name__
        if kind in ("Animation", "AnimationLayer") and field == "clip" and value and isinstance(value, str) \
                and self.world.has(entity, Model) and value not in self.model_clips(entity):
            clips = ", ".join(repr(c) for c in self.model_clips(entity)) or "none"
            self.message = f"{kind}.clip: the model file has no clip {value!r} (its clips: {clips})"
            raise EditError(self.message)
        if dataclasses.is_dataclass(target) and field not in {f.name for f in dataclasses.fields(target)}:
            raise EditError(f"{type(target).__name__} has no field {field!r} "
                            f"(fields: {', '.join(n for n, _ in self.fields(target))})")
        wanted = REFERENCE_KINDS.get((kind, field))
        if wanted is not None and isinstance(value, int) and not (
                self.world.exists(value) and self.world.has(value, ENGINE_COMPONENTS[wanted])):
            self.message = f"{kind}.{field}: {self.name_of(value)} has no {wanted} (it names one, or none)"
            raise EditError(self.message)
        before = _copy(getattr(target, field))
        try:
            setattr(target, field, value)
        except ComponentValueError as exc:
            self.message = str(exc)
            raise
        self.message = None
        after = _copy(getattr(target, field))
        last = self._done[-1] if self._done else None
        if merge and last is not None and last.open and last.action == "set" and last.component is target \
                and last.field == field and last.entity == entity:
            last.after = after
        else:
            self._push(Edit("set", entity, type(target), target, field, before, after))
        self._done[-1].open = merge

    @_says_warnings
    def set_fields(self, entity: int, component: str | type, values: Mapping[str, Any]) -> None:
        """Write several fields of one component as one undo step (``set_field`` for each; a
        refused value leaves every field as it was)."""
        self._refuse_made_again(entity)
        target = self.component(entity, component)
        names = tuple(values)
        before = tuple(_copy(getattr(target, name)) for name in names)
        try:
            for name in names:
                setattr(target, name, values[name])
        except ComponentValueError as exc:
            for name, value in zip(names, before, strict=True):
                setattr(target, name, _copy(value))
            self.message = str(exc)
            raise
        self.message = None
        self._push(Edit("set", entity, type(target), target, names, before,
                        tuple(_copy(getattr(target, name)) for name in names), open=False))

    def place(self, entity: int, point: glm.vec3, normal: glm.vec3) -> None:
        """Put ``entity`` on the surface at world ``point`` whose unit ``normal`` faces the side
        it is put on, in one undo step: a ``Decal`` centred there and turned to throw its image
        into the surface (its -z along -normal; its image's top up a wall, or towards -z on a
        floor or ceiling), anything else moved, not turned, until the box of its mesh rests on
        the surface there (its lowest corner along the normal on the surface's plane; without a
        mesh, its origin at the point).  The overlay's Shift+click places the selection where
        the picture shows a surface, through mirrors and portals (``raycast_seen``)."""
        transform = self.component(entity, Transform)
        point, normal = glm.vec3(point), glm.normalize(glm.vec3(normal))
        world = current_world_matrix(self.world, transform)
        parent = transform.parent
        to_parent = glm.mat4(1.0)
        if parent is not None and self.world.exists(parent) and self.world.has(parent, Transform):
            to_parent = glm.inverse(current_world_matrix(self.world, self.world.get(parent, Transform)))
        values: dict[str, Any] = {}
        if self.world.has(entity, Decal):
            up = glm.vec3(0.0, 0.0, -1.0) if abs(normal.y) > 0.9 else glm.vec3(0.0, 1.0, 0.0)
            linear = glm.mat3(to_parent)
            frame = glm.quat_cast(glm.mat3(*(glm.normalize(column) for column in (linear[0], linear[1], linear[2]))))
            values["rotation"] = glm.normalize(frame * look_rotation(-normal, up))
            origin = point
        else:
            mesh_ref = self.world.try_get(entity, MeshRef)
            origin = point
            if mesh_ref is not None:
                lo, hi = mesh_ref.mesh.bounds
                corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
                linear = np.array(glm.mat3(world).to_list(), np.float64)   # (columns as rows)
                lowest = float(np.min(corners @ linear @ np.array(normal, np.float64)))
                origin = point - normal * lowest
        values["position"] = glm.vec3(to_parent * glm.vec4(origin, 1.0))
        self.set_fields(entity, Transform, values)

    def move(self, entity: int, start: glm.vec3, world_offset: glm.vec3) -> None:
        """Put ``entity`` at ``world_offset`` (world units) from where it stood at the drag's
        start (``start``: its Transform.position then), the offset carried into its parent's
        space; one undo step for the whole drag (``end_drag`` ends it)."""
        transform = self.component(entity, Transform)
        offset = glm.vec3(world_offset)
        parent = transform.parent
        if parent is not None and self.world.exists(parent) and self.world.has(parent, Transform):
            offset = glm.inverse(glm.mat3(current_world_matrix(self.world, self.world.get(parent, Transform)))) * offset
        self.set_field(entity, Transform, "position", glm.vec3(start) + offset, merge=True)

    def mesh_shape(self, entity: int) -> str:
        """The shape of the entity's mesh: a ``MESH_MAKERS`` name, or "file" or "model" for a
        mesh loaded from one, or the mesh's name (made in code)."""
        source = getattr(self.component(entity, "MeshRef").mesh, "source", None) or {}
        return next((key for key in (*MESH_MAKERS, "file") if key in source),
                    "model" if "inside" in source or "model" in source else self.component(entity, "MeshRef").mesh.name)

    def set_mesh_shape(self, entity: int, shape: str) -> None:
        """Give the entity's MeshRef a new mesh of ``shape`` (``MESH_MAKERS``: box, quad,
        plane, sphere) at its default size (the Transform's scale sizes it); one undo step."""
        if shape not in MESH_MAKERS:
            raise EditError(f"no mesh shape {shape!r} (shapes: {', '.join(MESH_MAKERS)})")
        self.set_field(entity, "MeshRef", "mesh", MESH_MAKERS[shape]())

    def texture_text(self, entity: int, field: str, component: str = "Material") -> str:
        """An image field (``IMAGE_FIELDS``: a Material texture, a PointLight's cookie) as a
        level file writes it, inside its braces (``checker = [128, 4]``, ``file = "wood.png"``);
        "" for none, and the image's name for one made in code (no level file can name it)."""
        texture = getattr(self.component(entity, component), field)
        if texture is None:
            return ""
        source = dict(getattr(texture, "source", None) or {})
        if not source:
            return f"(made in code: {texture.name})"
        if "file" in source and self.level_path is not None:
            try:
                source["file"] = os.path.relpath(source["file"], self.level_path.parent)
            except ValueError:  # another drive
                pass
        return ", ".join(f"{key} = {json.dumps(value)}" for key, value in source.items())

    def set_texture(self, entity: int, field: str, text: str, component: str = "Material") -> None:
        """Give an image field (``IMAGE_FIELDS``) the texture ``text`` names as a level file's
        table would, inside its braces: ``checker = [128, 4]`` (with ``a``, ``b``),
        ``ripples = [256, 6]``, ``file = "wood.png"`` (beside the level, or in an asset root);
        "" for none.  Made and checked by the level file's own reader (``level_texture``), so
        what is refused there is refused here, with its words (an EditError)."""
        if (component, field) not in IMAGE_FIELDS:
            raise EditError(f"{component}.{field} is not an image (images: "
                            f"{', '.join(sorted(f'{c}.{f}' for c, f in IMAGE_FIELDS))})")
        value = None
        if text.strip():
            try:
                spec = tomllib.loads(f"texture = {{ {text} }}")["texture"]
                folder = self.level_path.parent if self.level_path is not None else Path.cwd()
                value = level_texture(spec, LevelAssets(folder, [*self.asset_roots, *user_asset_roots()]),
                                      normal_map=field == "normal_map")
            except (tomllib.TOMLDecodeError, ValueError, OSError) as exc:
                self.message = f"{component}.{field}: {exc}"
                raise EditError(self.message) from exc
        self.set_field(entity, component, field, value)

    def model_file_text(self, entity: int) -> str:
        """A Model's file as a level file writes it: relative to the level's folder."""
        file = self.component(entity, "Model").file
        if not file:
            return ""
        folder = self.level_path.parent if self.level_path is not None else Path.cwd()
        return Path(os.path.relpath(os.path.abspath(file), folder)).as_posix()

    def set_model_file(self, entity: int, text: str) -> None:
        """Place the model file ``text`` names (beside the level, or in an asset root; "" for
        none) with the entity's Model: loaded and checked now by the level file's own reader
        (``level_model``), so a file that cannot be placed is refused here, in its words (an
        EditError); the models stage makes its parts in the next frame."""
        value = ""
        if text.strip():
            if not self.world.has(entity, Transform):
                self.message = f"Model.file: {self.name_of(entity)} has no Transform (where the model would stand)"
                raise EditError(self.message)
            try:
                folder = self.level_path.parent if self.level_path is not None else Path.cwd()
                value = level_model(text.strip(), LevelAssets(folder, [*self.asset_roots, *user_asset_roots()]),
                                    self.component(entity, "Model").variant)
            except (ValueError, OSError, SpeculumError) as exc:
                self.message = f"Model.file: {exc}"
                raise EditError(self.message) from exc
        self.set_field(entity, "Model", "file", value)

    def model_variants(self, entity: int) -> list[str]:
        """The material variants of the entity's Model's file (``KHR_materials_variants``; []
        without a file or any)."""
        loaded = self._model_file(entity)
        return loaded.variants if loaded is not None else []

    def model_clips(self, entity: int) -> list[str]:
        """The animation clips of the entity's Model's file ([] without a Model, a file or any)."""
        loaded = self._model_file(entity) if self.world.has(entity, Model) else None
        return [clip.name for clip in loaded.animations] if loaded is not None else []

    def _model_file(self, entity: int):
        """The entity's Model's file as loaded (its meshes only), once a file and modification
        time (the inspector asks every frame it shows its variants or clips); None without one
        or where it cannot be loaded."""
        file = self.component(entity, "Model").file
        if not file:
            return None
        try:
            stamp = os.stat(file).st_mtime_ns
        except OSError:
            return None
        key = (file, stamp)
        if key not in self._files:
            try:
                self._files[key] = load_model_file(file, roots=[Path(file).parent, *self.asset_roots,
                                                                *user_asset_roots()], materials=False)
            except (SpeculumError, OSError, ValueError):
                self._files[key] = None
        return self._files[key]

    def turn(self, entity: int, start: glm.quat, world_axis: glm.vec3, angle: float) -> None:
        """Turn ``entity`` by ``angle`` (radians) about ``world_axis`` through its origin from
        the rotation it had at the drag's start (``start``: its Transform.rotation then), the
        turn carried into its parent's space; one undo step for the whole drag."""
        transform = self.component(entity, Transform)
        turn = glm.angleAxis(angle, glm.normalize(glm.vec3(world_axis)))
        parent = transform.parent
        if parent is not None and self.world.exists(parent) and self.world.has(parent, Transform):
            linear = glm.mat3(current_world_matrix(self.world, self.world.get(parent, Transform)))
            frame = glm.quat_cast(glm.mat3(*(glm.normalize(column) for column in (linear[0], linear[1], linear[2]))))
            turn = glm.inverse(frame) * turn * frame
        self.set_field(entity, Transform, "rotation", glm.normalize(turn * glm.quat(start)), merge=True)

    def rescale(self, entity: int, start: glm.vec3, axis: int, factor: float) -> None:
        """Scale ``entity`` along its own ``axis`` (0-2) by ``factor`` from the scale it had at
        the drag's start (``start``), at least ``MIN_SCALE_FACTOR`` of it; one undo step."""
        scale = glm.vec3(start)
        scale[axis] *= max(factor, MIN_SCALE_FACTOR)
        self.set_field(entity, Transform, "scale", scale, merge=True)

    def angles(self, entity: int, component: str | type, field: str) -> glm.vec3:
        """A rotation field's Euler angles in degrees, to show: those last shown or set where
        they still make the rotation (to ``SAME_ANGLES_DEGREES``), else the triple that makes
        it nearest them (``euler_degrees``), so the numbers move on smoothly under a drag past
        90 degrees, a turn handle, an undo or the game's own writes."""
        name = component if isinstance(component, str) else component.__name__
        key = (entity, name, field)
        rotation = glm.quat(getattr(self.component(entity, component), field))
        shown = self._angles.get(key)
        if shown is None or turn_degrees(shown, rotation) > SAME_ANGLES_DEGREES:
            shown = euler_degrees(rotation, shown)
        self._angles[key] = glm.vec3(shown)
        return glm.vec3(shown)

    def set_angles(self, entity: int, component: str | type, field: str, degrees: Sequence[float],
                   merge: bool = False) -> str | None:
        """Set a rotation field from Euler angles in degrees (glm's x, y, z), kept as the
        angles it shows (``angles``); why it was refused, or None (``try_set_field``)."""
        angles = glm.vec3(*(float(value) for value in degrees))
        refused = self.try_set_field(entity, component, field, glm.quat(glm.radians(angles)), merge)
        if refused is None:
            name = component if isinstance(component, str) else component.__name__
            self._angles[(entity, name, field)] = angles
        return refused

    def try_set_field(self, entity: int, component: str | type, field: str, value: Any,
                      merge: bool = False) -> str | None:
        """``set_field``, answering why it was refused (the component's message) or None."""
        try:
            self.set_field(entity, component, field, value, merge)
        except (ComponentValueError, EditError, TypeError, ValueError) as exc:
            self.message = str(exc)
            return self.message
        return None

    def end_drag(self) -> None:
        """The drag is over: the next write of the same field is an edit of its own."""
        if self._done:
            self._done[-1].open = False

    @_says_warnings
    def add_component(self, entity: int, name: str, **fields: Any) -> Any:
        """Give the entity a new component of class ``name`` (one of ``components``), made
        from ``fields`` (its defaults otherwise) and checked as a spawn would check it."""
        cls = self.components.get(name)
        if cls is None:
            raise EditError(f"no component {name!r} to add (components: {', '.join(sorted(self.components))})")
        if not self.world.exists(entity):
            raise EditError(f"entity {entity} does not exist")
        self._refuse_made_again(entity)
        if self.world.has(entity, cls):
            raise EditError(f"{self.name_of(entity)} already has a {name}")
        if name == "MeshRef" and "mesh" not in fields:
            fields = {**fields, "mesh": MESH_MAKERS[NEW_MESH]()}  # a shape to start from (``set_mesh_shape``)
        if name == "Portal" and "size" not in fields:  # the opening the mesh shows: its outline, as drawn
            fields = {**fields, **_portal_size_of(self.world.try_get(entity, MeshRef))}
        if name == "LevelOfDetail" and "meshes" not in fields:  # a chain of one to start from: the mesh it has
            mesh_ref = self.world.try_get(entity, MeshRef)
            if mesh_ref is None:
                self.message = (f"{self.name_of(entity)}: a LevelOfDetail swaps the entity's MeshRef.mesh; "
                                "add a MeshRef first")
                raise EditError(self.message)
            fields = {**fields, "meshes": (mesh_ref.mesh,)}
        try:
            component = cls(**fields)
            self._check_whole(entity, [*self.world.components_of(entity), component])
            self.world.add_component(entity, component)
        except (ComponentValueError, TypeError) as exc:
            self.message = f"{name}: {exc}" if isinstance(exc, TypeError) else str(exc)
            raise EditError(self.message) from exc
        self.message = None
        self._push(Edit("add", entity, cls, component, open=False))
        return component

    def remove_component(self, entity: int, name: str) -> Any:
        """Take the entity's component of class ``name`` away (undo gives the same one back)."""
        self._refuse_made_again(entity)
        component = self.component(entity, name)
        self._refuse_if_needed(entity, type(component).__name__)
        kind = type(component).__name__
        for (holder_kind, field), wanted in sorted(REFERENCE_KINDS.items()):
            for holder, held in self.world.query_one(ENGINE_COMPONENTS[holder_kind]) if wanted == kind else ():
                if holder != entity and getattr(held, field) == entity:
                    self.message = (f"{self.name_of(entity)}'s {kind} is what {self.name_of(holder)}'s "
                                    f"{holder_kind}.{field} names: set that to none first")
                    raise EditError(self.message)
        try:
            self._check_whole(entity, [c for c in self.world.components_of(entity) if c is not component])
        except ComponentValueError as exc:
            self.message = str(exc)
            raise EditError(self.message) from exc
        self.world.remove_component(entity, type(component))
        self.message = None
        self._push(Edit("remove", entity, type(component), component, open=False))
        return component

    # --- whole entities ----------------------------------------------------------------------
    def create(self, *components: Any, name: str | None = None) -> int:
        """A new entity of ``components`` (none: a Transform ``NEW_DISTANCE`` in front of the
        active camera, where it shows), named ``name`` or ``new`` (made unique: ``new_2``), selected.
        A save writes it at the end of the level file."""
        if not components:
            components = (Transform(position=self._in_view()),)
        entity = self._spawn(components, self._free_name(name or "new"))
        self._push(Edit("create", entity, None, list(components), self.name_of(entity), open=False))
        self.select(entity)
        return entity

    def duplicate(self, entity: int) -> int:
        """A copy of ``entity`` where it stands (each component made again from its fields;
        a portal's copy has no partner: a pair is two portals), named ``<name>_copy``, selected."""
        self._refuse_made_again(entity)
        made = []
        for cls_name, component in self.components_of(entity):
            fields = {f: _copy(value) for f, value in self.fields(component)}
            if cls_name == "Portal":
                fields["partner"] = None
            made.append(type(component)(**fields))
        return self.create(*made, name=f"{self.name_of(entity)}_copy")

    def delete(self, entity: int) -> None:
        """Delete ``entity`` (undo makes it again, with its components, under a new id).  A
        portal paired with it is left without a partner (closed); an entity that is another's
        parent, or the only active camera, is refused (an EditError saying which)."""
        name = self.name_of(entity)
        if not self.world.exists(entity):
            raise EditError(f"entity {entity} does not exist")
        self._refuse_made_again(entity)
        self._refuse_if_needed(entity, None)
        # (a model's parts go with its root: the models stage deletes them)
        children = [self.name_of(e) for e, t in self.world.query_one(Transform) if t.parent == entity and e != entity
                    and getattr(self.world.try_get(e, FromModel), "model", None) != entity
                    and getattr(self.world.try_get(e, FromDecal), "decal", None) != entity]  # (the decals stage's)
        if children:
            self.message = f"{name} is the parent of {', '.join(children)}: delete them or clear their parent first"
            raise EditError(self.message)
        if self.world.has(entity, Camera) and active_camera(self.world) == entity \
                and sum(camera.active for _, camera in self.world.query_one(Camera)) == 1:
            self.message = f"{name} holds the only active camera: every frame would be black without it"
            raise EditError(self.message)
        edit = Edit("delete", entity, None, [c for _, c in self.components_of(entity)], name, open=False)
        self._remove(edit)
        self._push(edit)

    def _refuse_made_again(self, entity: int) -> None:
        """An EditError for an edit of a model's part (it is made from the model's file each
        time the level loads, so a level file could keep no edit of it: edit the file, or the
        model's own entity, its place, its Model) or of a decal's cut mesh (its decal's)."""
        part = self.world.try_get(entity, FromModel) if self.world.exists(entity) else None
        if part is not None:
            self.message = (f"{self.name_of(entity)} is a part of the model {self.name_of(part.model)}, made from its "
                            "file each time the level loads: edit the model's entity (its Transform, its Model) or "
                            "the file")
            raise EditError(self.message)
        cut = self.world.try_get(entity, FromDecal) if self.world.exists(entity) else None
        if cut is not None:
            self.message = (f"{self.name_of(entity)} is the cut mesh of the decal {self.name_of(cut.decal)}, made "
                            "again each time the decal or what it lies on changes: edit the decal")
            raise EditError(self.message)

    def _refuse_if_needed(self, entity: int, component: str | None) -> None:
        """An EditError, in the game's words, where the game cannot do without ``entity`` or
        that component of it (``needs``)."""
        reason = self.needs(self.world, entity, component) if self.needs is not None else None
        if reason:
            self.message = f"{self.name_of(entity)}: {reason}"
            raise EditError(self.message)

    def _in_view(self) -> glm.vec3:
        camera = active_camera(self.world)
        if camera is None:
            return glm.vec3(0.0)
        matrix = current_world_matrix(self.world, self.world.get(camera, Transform))
        return glm.vec3(matrix * glm.vec4(0.0, 0.0, -NEW_DISTANCE, 1.0))

    def _free_name(self, wanted: str) -> str:
        """``wanted``, or ``wanted_2``, ``_3``...: a name no entity has, nor had in this editor
        (a save removes a deleted entity by its name)."""
        taken = set(self.names) | {e.field for e in self._everything if e.kind is None}
        name, n = wanted, 1
        while name in taken:
            n += 1
            name = f"{wanted}_{n}"
        return name

    def _spawn(self, components: Any, name: str) -> int:
        try:
            entity = self.world.spawn(*components)
        except ComponentValueError as exc:
            self.message = f"{name}: {exc}"
            raise EditError(self.message) from exc
        self.names[name] = entity
        self.message = None
        return entity

    def _remove(self, edit: Edit) -> None:
        """Delete ``edit``'s entity, clearing each field that names it and may name none (a
        portal's partner, a monitor's camera, a sub-emitter: ``REFERENCE_KINDS``; each kept
        in ``edit.before`` as (component, field) to be given back): the world behaves as it
        did (a field naming an entity gone names none), and the level file saved names no
        entity it lacks."""
        edit.before = [(component, field) for cls_name, field in sorted(REFERENCE_KINDS)
                       for e, component in self.world.query_one(ENGINE_COMPONENTS[cls_name])
                       if e != edit.entity and getattr(component, field) == edit.entity]
        for component, field in edit.before:
            setattr(component, field, None)
        self.world.delete_entity(edit.entity)
        self.names.pop(edit.field, None)
        if self.selected == edit.entity:
            self.selected = None

    def _restore(self, edit: Edit) -> None:
        """Make ``edit``'s entity again from its components, under a new id: every edit, and
        every field its deletion cleared (a portal's partner, a monitor's camera, a
        sub-emitter), that named the old id names the new one."""
        old, entity = edit.entity, self._spawn(edit.component, edit.field)
        for component, field in edit.before or ():
            setattr(component, field, entity)
        for moved in (*self._done, *self._undone, *self._everything):
            if moved.entity == old:
                moved.entity = entity

    def _check_whole(self, entity: int, components: list[Any]) -> None:
        """Refuse an entity the frame would refuse: the registered invariants over its
        components together (a Water needs a Mirror), and a Mirror needs a MeshRef and a
        Transform (the surfaces stage draws it from them; a level file is held to the same)."""
        held = {type(c).__name__ for c in components}
        if "Mirror" in held and not {"MeshRef", "Transform"} <= held:
            missing = " and no ".join(k for k in ("MeshRef", "Transform") if k not in held)
            raise ComponentValueError(f"{self.name_of(entity)}: a Mirror needs a MeshRef and a Transform "
                                      f"(it would have no {missing})")
        check_components(components, entity)

    def _push(self, edit: Edit) -> None:
        self._everything.append(edit)
        self._done.append(edit)
        del self._done[:-MAX_UNDO]
        self._undone.clear()

    # --- undo and redo ---------------------------------------------------------------------
    @property
    def edit_count(self) -> int:
        """Edits made, undone and redone so far: changes whenever an edit changes the world."""
        return len(self._everything) + self._applied

    @property
    def can_undo(self) -> bool:
        return bool(self._done)

    @property
    def can_redo(self) -> bool:
        return bool(self._undone)

    def undo(self) -> bool:
        """Take back the last edit; False when there is none."""
        if not self._done:
            return False
        edit = self._done.pop()
        edit.open = False
        self._apply(edit, backwards=True)
        self._undone.append(edit)
        return True

    def redo(self) -> bool:
        """Make the last undone edit again; False when there is none."""
        if not self._undone:
            return False
        edit = self._undone.pop()
        self._apply(edit, backwards=False)
        self._done.append(edit)
        return True

    def _apply(self, edit: Edit, backwards: bool) -> None:
        self._applied += 1
        if edit.kind is None:  # a whole entity
            if (edit.action == "create") == backwards:
                self._remove(edit)
            else:
                self._restore(edit)
            return
        if not self.world.exists(edit.entity):
            raise EditError(f"entity {edit.entity} (edited) no longer exists")
        if edit.action == "set" and isinstance(edit.field, tuple):  # (set_fields: one step)
            for name, value in zip(edit.field, edit.before if backwards else edit.after, strict=True):
                setattr(edit.component, name, _copy(value))
        elif edit.action == "set":
            setattr(edit.component, edit.field, _copy(edit.before if backwards else edit.after))
        elif (edit.action == "add") == backwards:
            self.world.remove_component(edit.entity, edit.kind)
        else:
            self.world.add_component(edit.entity, edit.component)

    # --- saving ----------------------------------------------------------------------------
    def save(self, path: str | Path | None = None) -> Path:
        """Write the level file (``path``, else the one loaded) keeping the loaded file's text,
        with the edited components written in (``save_level(keep=..., only=...)``): the diff
        is the edits. A world not loaded from a file is written afresh."""
        target = Path(path) if path is not None else self.level_path
        if target is None:
            raise EditError("no level file to save to: give a path")
        keep = self.level_path if self.level_path is not None and self.level_path.exists() else None
        # Only what was edited: the running game moves things too (a spinning crate, the
        # camera flown about), and that is play, not an edit of the level.
        if keep is None:
            return save_level(self.world, target, self.names, extra_components=self.game_components)
        edited = {(self.name_of(e.entity), e.kind.__name__) for e in self._everything if e.kind is not None}
        unpaired = {id(c) for e in self._everything if e.action == "delete" for c, _ in e.before or ()}
        edited |= {(self.name_of(e), cls_name) for cls_name, _ in REFERENCE_KINDS
                   for e, c in self.world.query_one(ENGINE_COMPONENTS[cls_name]) if id(c) in unpaired}
        whole = {e.field for e in self._everything if e.kind is None}  # entities made or deleted
        added = {name for name in whole if name in self.names and self.world.exists(self.names[name])}
        return save_level(self.world, target, self.names, extra_components=self.game_components, keep=keep,
                          only=edited, added=added, removed=whole - added)


def _portal_size_of(mesh_ref: MeshRef | None) -> dict[str, tuple[float, float]]:
    """``size`` for a Portal added to an entity whose mesh is a flat rectangle centred on it
    (a quad): its width and height, so the rectangle things go through is the one the view
    shows on (``mirror_rules.warn_portal_not_flat`` says a mismatch); nothing otherwise (the
    Portal's default, and the rule says why where the mesh is not a quad)."""
    if mesh_ref is None:
        return {}
    lo, hi = mesh_ref.mesh.bounds
    w, h, depth = (float(hi[i] - lo[i]) for i in range(3))
    centred = max(abs(float(lo[0] + hi[0])), abs(float(lo[1] + hi[1]))) <= 1e-6 * max(w, h, 1e-9)
    if not (w > 0.0 and h > 0.0 and depth <= 1e-6 * max(w, h) and centred):
        return {}
    return {"size": (float(f"{w:.6e}"), float(f"{h:.6e}"))}  # (float32 bounds: 1.6, not 1.600000023841858)
