"""Spawning entities from model files: one entity per mesh part (and per light the file
carries), under one root entity that holds the file's ``Model``.

``spawn_model`` loads a file and spawns it now; a ``Model`` component placed otherwise (a
level file, the editor, a game's code) is spawned by the models stage
(``systems/model_system.py``) with the same ``spawn_parts``.  What was spawned under each
root, and from which ``Model`` values, is the world's ``SpawnedModels`` resource, so a
part set is made once per change, whoever made it.
"""
from __future__ import annotations

import math
import os
import warnings
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Morph,
    PointLight,
    Reflective,
    Refractive,
    Skin,
    Transform,
)
from components.limits import MAX_FAR, MAX_MORPH_WEIGHT, MIN_SPOT_ANGLE
from components.model import MAX_MODEL_PROBES, Animation, FromModel, Model
from components.rendering import MAX_NORMAL_SCALE
from components.tracking import HALF_MAX
from engine.assets.gltf_animations import (
    Clip,
    Layer,
    collapsed,
    layer_weights,
    layered_weights,
    moved_nodes,
    pose_all,
    pose_weights,
    sample_property,
    subtree,
)
from engine.assets.gltf_skins import joint_matrices
from engine.assets.mesh import LoadedModel, flat_plane, load_model_file
from engine.assets.model_cameras import ModelCamera
from engine.assets.model_lights import ModelLight, check_light_intensity
from engine.core.errors import AssetError
from engine.core.transforms import current_world_matrix
from engine.core.world import World

__all__ = ["MAX_MODEL_PROBES", "SpawnedModel", "SpawnedModels", "model_components", "model_key", "pose_parts",
           "remove_parts", "respawn_parts", "root_start", "root_travel", "root_turn", "clip_duration",
           "skin_palettes", "spawn_model", "spawn_parts", "turn_suns", "crossfade"]

@dataclass
class SpawnedModel:
    """What the models stage (or ``spawn_model``) made under one root: from which ``Model``
    values (``model_key``) and the entities."""

    key: tuple
    parts: list[int] = field(default_factory=list)
    nodes: list[int | None] = field(default_factory=list)  # each part's glTF node (None: not animated)
    loaded: LoadedModel | None = None                        # its clips, node tree and skins
    skins: list[int | None] = field(default_factory=list)  # each part's skin (None: not skinned)
    masks: dict[str, np.ndarray] = field(default_factory=dict)  # an AnimationLayer's root -> its nodes (subtree)
    starts: dict[tuple, np.ndarray] = field(default_factory=dict)  # (clip, node) -> its place at the clip's start
    # (clip, node, time) -> its travel there (root_travel), the last few: a frame asks for the
    # same times its pose and the frame before did
    travels: dict[tuple, np.ndarray] = field(default_factory=dict)
    # (kind, index) -> the entities made from a file's material, light or camera, and each
    # light's engine intensity over the file's (what an animation pointer writes), made at the
    # first pose of a clip that has property channels
    targets: dict[tuple[str, int], list[int]] | None = None
    light_scales: dict[int, float] = field(default_factory=dict)
    # The file's values a written field is worked out from with others a pointer may animate
    # apart: a part's emission (its emissiveFactor, strength and part: Emissive.power) and a
    # spot light's cones (inner, outer, radians: PointLight.spot_angle and spot_blend).
    emission: dict[int, list] = field(default_factory=dict)
    cones: dict[int, list[float]] = field(default_factory=dict)

    @property
    def suns(self) -> bool:
        """Whether its file carries a directional light (turned with the model: ``turn_suns``)."""
        return self.loaded is None or any(light.kind == "directional" for light in self.loaded.lights)


class SpawnedModels(dict):
    """The world's resource: root entity -> ``SpawnedModel``."""


def model_key(model: Model) -> tuple:
    """The values a model's parts are made from: a change to any of them makes them again."""
    return (os.path.abspath(model.file), model.light_scale, model.max_probes, model.variant, model.skinning)


def spawn_model(world: World, path: str | Path, position: glm.vec3 | Sequence[float] = (0.0, 0.0, 0.0),
                rotation: glm.quat | Sequence[float] | None = None,
                scale: glm.vec3 | Sequence[float] = (1.0, 1.0, 1.0),
                roots: Sequence[str | Path] | None = None, max_probes: int = MAX_MODEL_PROBES,
                light_scale: float = 1.0, variant: str = "", skinning: str = "linear") -> int:
    """Load ``path`` and spawn it; returns the root entity.

    The file's material decides the components: its colour, texture, metallic and
    roughness, normal, emissive and metallic-roughness maps make the Material; an emissive
    colour gives Emissive(emissive / diffuse), or with an emissive map Emissive(its
    strength) (``ModelPart``); reflectivity > 0 (a metallic glTF material, an MTL's
    ``refl`` or ``Pm``) gives a Mirror on a flat mesh and, on any other (or a flat cutout:
    a mirror is drawn whole), ``Reflective("cube")``: the probes stage gives such a part a
    cube-map probe of its own at its bounding box's centre (engine/rules/probe_rules.py's automatic probe, the seed's
    detection: flat is a planar mirror, curved a cube map), so a chrome teapot reflects the
    room around it, not only the sky.  A probe is six views a capture, so a model gets at
    most ``max_probes`` of them (MAX_MODEL_PROBES): its largest curved reflective parts (by
    their box's diagonal once placed); the others reflect the sky (a metal by its own
    material's environment reflection, an MTL's non-metal reflection by
    ``Reflective("skybox")``) and a warning says how many.  Parts of the same geometry share one Mesh (drawn
    instanced).  ``roots``: the folders the files the model names may be in (None: its own
    folder; ``load_model``).  The file is fully loaded and every component built (so
    validated) before anything is spawned, so a bad file leaves the world untouched.

    Glass (glTF's ``KHR_materials_transmission``, with ``KHR_materials_ior`` and
    ``KHR_materials_volume``, as Blender writes a Principled BSDF's transmission): a curved
    part, counted in the probes' budget with the reflective ones, is ``Refractive`` (the
    file's index; ``solid`` where the volume gives it a thickness, else a thin wall, as glTF
    says) with the colour's alpha 1 - the transmission, so its probe's capture shows
    through it, bent and tinted by its colour; a flat pane (or a curved part past the
    budget) is see-through with ``Material.blend`` "transparent", its alpha 1 - the
    transmission, its reflections whole, showing what lies behind it unbent.

    The lights a glTF file's nodes carry (``KHR_lights_punctual``: Blender's lamps, spots
    and suns) come with it, each an entity under the root placed by its node
    (``engine/assets/model_lights.py``): a point light a ``PointLight`` of the file's
    candela, colour and range (without one, as far as its light stays above
    ``RANGE_CUTOFF_LUX``), a spot light one with ``spot_angle`` its outer cone and
    ``spot_blend`` the share of it outside the inner cone, aimed along its node's -Z, and a
    directional light a ``DirectionalLight`` of the file's lux along its node's -Z as the
    model is placed when spawned.  ``light_scale`` multiplies their intensities (a file's
    physical units to the scene's exposure; an intensity past the engine's half floats is
    refused, saying the scale that fits).  Shadows are the engine's defaults (a sun casts, a
    lamp does not): the extension says nothing of them.

    A glTF file's perspective cameras (``engine/assets/model_cameras.py``) come as Camera
    entities under the root, placed by their nodes, not active: a game shows one by making
    it active (``camera.active = True``; the active camera with the lowest id renders).

    ``variant``: the glTF material variant the parts wear (``KHR_materials_variants``,
    engine/assets/gltf_variants.py; "": the file's default look).  ``skinning``: how its
    skinned parts blend their joints (``Skin.skinning``: "linear" or "dual_quaternion").

    The root holds the file's ``Model`` (its path, ``light_scale``, ``max_probes``, ``variant`` and ``skinning``) and
    each part a ``FromModel`` naming the root: a level file saves the root alone and makes
    the parts again when it is loaded; deleting the root deletes them (the models stage).
    """
    if isinstance(max_probes, bool) or not isinstance(max_probes, int) or max_probes < 0:
        raise AssetError(f"spawn_model: max_probes must be an int >= 0, got {max_probes!r}")
    if isinstance(light_scale, bool) or not isinstance(light_scale, (int, float)) or \
            not (math.isfinite(light_scale) and light_scale >= 0.0):
        raise AssetError(f"spawn_model: light_scale must be a finite number >= 0, got {light_scale!r}")
    root_transform = Transform(position=position, rotation=rotation if rotation is not None else glm.quat(),
                               scale=scale)
    loaded = load_model_file(path, roots=roots, variant=variant)  # (a bad path is refused here, naming it)
    try:
        model = Model(file=os.fspath(path), light_scale=light_scale, max_probes=max_probes, variant=variant,
                      skinning=skinning)
    except ComponentValueError as exc:
        raise AssetError(f"spawn_model: {exc}") from None
    part_components = model_components(loaded, path, root_transform, max_probes, light_scale, skinning)
    root = world.spawn(root_transform, model)
    try:
        spawn_parts(world, root, model, part_components, loaded)
    except BaseException:
        world.delete_entity(root)
        raise
    return root


def model_components(loaded: LoadedModel, path: str | Path, root: Transform, max_probes: int,
                     light_scale: float, skinning: str = "linear") -> list[list]:
    """Each part's and light's components (a Transform first, its parent left for
    ``spawn_parts``), every one built, so checked, before anything is spawned: see
    ``spawn_model`` for what a file's materials and lights become.  ``root``: where the model
    stands (a directional light's direction is turned by it)."""
    parts = loaded.parts
    for part in parts:
        if part.transmission > 0.0 and part.alpha_cutoff is not None:
            warnings.warn(f"mesh file {str(path)!r}: part {part.name!r}: KHR_materials_transmission on an alphaMode "
                          "MASK material is left out (a cutout is opaque where it is drawn)", stacklevel=3)
            part.transmission = 0.0
    curved = [i for i, part in enumerate(parts)
              if (part.reflectivity > 0.0 and not _planar_mirror(part)) or (_glass(part) and not _flat(part))]
    probed = set(sorted(curved, key=lambda i: -_placed_size(parts[i]))[:max_probes])
    _name_sources(path, parts)
    part_components = []
    palettes = skin_palettes(loaded, None, 0.0)  # each skin's joints at rest
    try:
        for index, part in enumerate(parts):
            part_components.append(_part_components(part, index in probed))
            if part.skin is not None:
                part_components[-1].append(Skin(palettes[part.skin], skinning=skinning))
            if part.morph_weights is not None:
                part_components[-1].append(Morph(part.morph_weights))
        for light in loaded.lights:
            part_components.append(_light_components(light, root, light_scale))
        for camera in loaded.cameras:
            part_components.append(_camera_components(camera))
    except (ComponentValueError, AssetError) as exc:
        raise AssetError(f"mesh file {str(path)!r}: {exc}") from exc
    if len(curved) > len(probed):
        warnings.warn(f"mesh file {str(path)!r}: {len(curved)} curved reflective or glass parts: {len(probed)} of "
                      f"them (the largest) get a cube-map probe each, the other {len(curved) - len(probed)} reflect "
                      "the sky (glass: see-through, without refraction) "
                      f"(max_probes = {max_probes}, MAX_MODEL_PROBES by default; or give the model "
                      "ReflectionProbe entities with an influence box)", stacklevel=3)
    return part_components


def _part_components(part, probed: bool) -> list:
    """One mesh part's components: ``probed`` whether it is among the curved reflective or
    glass parts given a probe."""
    # Glass (KHR_materials_transmission): a curved part within the probes' budget refracts
    # its own probe's capture (Refractive, its alpha weighing what passes); a flat pane, or a
    # curved part past the budget, shows what lies behind it as it is, its alpha what the
    # glass lets through and its reflections whole (Material.blend "transparent", as a
    # window pane).
    refracts = _glass(part) and probed
    color = (*part.color[:3], 1.0 - part.transmission) if _glass(part) else part.color
    components = [
        # (parent set by spawn_parts; a part scaled to nothing at rest stands at its node's place
        # unscaled, not drawn until a clip grows it: pose_parts)
        Transform(position=glm.vec3(part.local[3])) if part.hidden else _node_transform(part.local, part.mesh.name),
        MeshRef(part.mesh, visible=not part.hidden),
        Material(color=color, texture=part.texture, metallic=part.metallic, roughness=part.roughness,
                 normal_map=part.normal_map, normal_scale=part.normal_scale, emissive_map=part.emissive_map,
                 metallic_roughness_map=part.metallic_roughness_map, occlusion_map=part.occlusion_map,
                 occlusion_strength=part.occlusion_strength, alpha_cutoff=part.alpha_cutoff,
                 double_sided=part.double_sided and not _planar_mirror(part),
                 blend="transparent" if _glass(part) and not refracts else "fade",
                 clearcoat=part.clearcoat, clearcoat_roughness=part.clearcoat_roughness,
                 unlit=part.unlit, reflectance=part.reflectance, specular_color=part.specular_color,
                 diffuse_transmission=part.diffuse_transmission,
                 diffuse_transmission_color=part.diffuse_transmission_color,
                 sheen_color=part.sheen_color,
                 sheen_roughness=part.sheen_roughness, anisotropy=part.anisotropy,
                 anisotropy_direction=part.anisotropy_direction, iridescence=part.iridescence,
                 iridescence_ior=part.iridescence_ior, iridescence_thickness=part.iridescence_thickness,
                 second_uv_maps=part.second_uv_maps),
    ]
    if part.emissive_factor > 0.0:
        components.append(Emissive(part.emissive_factor))
    if refracts:
        components.append(Refractive(ior=part.ior, solid=part.thick, dispersion=part.dispersion))
    elif part.reflectivity > 0.0 and not _glass(part):
        # A flat reflective surface is a planar mirror; anything else samples a cube-map
        # probe (its own, made by the probes stage at its box's centre).
        if _planar_mirror(part):
            components.append(Mirror(reflect_rate=part.reflectivity, roughness=part.roughness))
        elif probed:
            components.append(Reflective(mode="cube", mix=part.reflectivity))
        elif part.metallic == 0.0:  # (an MTL's reflection: no metal to reflect by)
            components.append(Reflective(mode="skybox", mix=part.reflectivity))
        # else a metal past the probes' budget reflects the sky by its material (its
        # environment reflection, tinted by its colour as a metal's is)
    return components


def spawn_parts(world: World, root: int, model: Model | None, part_components: Sequence[list],
                loaded: LoadedModel | None = None) -> list[int]:
    """Spawn ``part_components`` (``model_components`` of ``loaded``) under ``root``, each
    with a ``FromModel``, and record them in the world's ``SpawnedModels`` (with ``model``'s
    key: None for a model spawned without one, and the parts' nodes, which an ``Animation``
    moves); all or nothing."""
    spawned: list[int] = []
    try:
        for components in part_components:
            components[0].parent = root
            spawned.append(world.spawn(*components, FromModel(model=root)))
    except BaseException:
        for entity in reversed(spawned):
            world.delete_entity(entity)
        raise
    record = world.resources.get(SpawnedModels)
    if record is None:
        record = world.resources[SpawnedModels] = SpawnedModels()
    # (a skinned part stays at the root: its joints place it; its lights and cameras follow their nodes)
    nodes = [None if part.skin is not None else part.node for part in loaded.parts] if loaded is not None else []
    if loaded is not None:
        nodes += [light.node for light in loaded.lights] + [camera.node for camera in loaded.cameras]
    nodes += [None] * (len(spawned) - len(nodes))
    skins = [part.skin for part in loaded.parts] if loaded is not None else []
    skins += [None] * (len(spawned) - len(skins))
    record[root] = SpawnedModel(None if model is None else model_key(model), spawned, nodes, loaded, skins)
    return spawned


def remove_parts(world: World, root: int) -> int:
    """Delete what was spawned under ``root`` from its model (the parts still there);
    returns how many."""
    record = world.resources.get(SpawnedModels, {}).pop(root, None)
    if record is None:
        return 0
    gone = [entity for entity in record.parts if world.exists(entity)]
    for entity in gone:
        world.delete_entity(entity)
    return len(gone)


def respawn_parts(world: World, root: int, roots: Sequence[str | Path] | None = None,
                  loaded: LoadedModel | None = None) -> list[int]:
    """Make ``root``'s parts from its ``Model`` (and Transform) again: the old ones deleted,
    the file loaded (``roots``: the folders the files it names may be in; None: its own
    folder), unless ``loaded`` is it already (a level file's reader loaded it), and every
    part built before the old ones go, so a file that cannot be loaded leaves the world as
    it was and raises an AssetError naming the entity."""
    model = world.get(root, Model)
    transform = world.try_get(root, Transform)
    if transform is None:
        raise AssetError(f"entity {root}: a Model needs a Transform on the same entity (where the model stands)")
    try:
        if loaded is None:
            loaded = load_model_file(model.file, roots=roots, variant=model.variant)
        part_components = model_components(loaded, model.file, transform, model.max_probes, model.light_scale,
                                           model.skinning)
    except AssetError as exc:
        raise AssetError(f"entity {root}'s Model: {exc}") from exc
    remove_parts(world, root)
    return spawn_parts(world, root, model, part_components, loaded)


def _light_components(light: ModelLight, root: Transform, scale: float) -> list:
    """A file's light as the engine's: its Transform under the root, and its light."""
    placed = _node_transform(light.local, light.name)
    intensity = check_light_intensity(light, scale)
    colour = glm.vec4(*light.color, 1.0)
    if light.kind == "directional":
        # along the node's -Z as the root places the model now (a DirectionalLight has a
        # direction, not a place)
        model = glm.translate(glm.vec3(root.position)) * glm.mat4_cast(root.rotation) * glm.scale(glm.vec3(root.scale))
        travel = glm.vec3((model * light.local) * glm.vec4(0.0, 0.0, -1.0, 0.0))
        if glm.length(travel) == 0.0:
            raise ComponentValueError(f"light {light.name!r}: its node's transform has no -Z direction")
        try:
            return [placed, DirectionalLight(direction=travel, color=colour, intensity=intensity,
                                             **(light.fields or {}))]
        except ComponentValueError as exc:
            raise ComponentValueError(f"light {light.name!r}: {exc}") from None
    # (the extras' fields over the extension's: a spot's cone past 90 degrees, its blend as given)
    settings = {"spot_angle": light.spot_angle(), "spot_blend": light.spot_blend(), **(light.fields or {})}
    try:
        lamp = PointLight(color=colour, intensity=intensity, range=light.reach(scale), **settings)
    except ComponentValueError as exc:
        raise ComponentValueError(f"light {light.name!r}: {exc}") from None
    return [placed, lamp]


def pose_parts(world: World, root: int, clip_name: str, time: float, every: bool = True,
               fade: tuple[str, float, float] | None = None,
               layer: tuple[str, float, float, str, str] | None = None, hold: str = "",
               turn: bool = False) -> None:
    """Put ``root``'s parts where clip ``clip_name`` of its model puts their nodes at
    ``time`` (seconds); "" puts them at rest.  Its lights and cameras follow their nodes (a
    camera unscaled; a directional light's direction turned, as the root stands now), its
    skinned parts their joints (their ``Skin``).  ``every`` False (the clip only moved on): only
    the parts the clip moves (their node or an ancestor animated) are written, so the others
    stay unchanged for the stages after (no rows uploaded, no shadow drawn again).  ``fade``:
    (the clip faded from, its time, ``clip_name``'s share from 0 to 1), the two poses mixed
    (``gltf_animations.pose_all``; every part written).  ``layer``: an ``AnimationLayer``'s
    (clip, time, weight, blend, root) laid over that pose (every part written).  A clip or
    layer root the model lacks is an AssetError naming the entity and those it has.  ``hold``:
    the node whose travel across the ground ``clip_name`` carries (``Animation.root_motion``),
    taken out of the pose with everything under it (``root_travel``); ``turn``: its turn about
    the vertical too (``root_turn``: the subtree turned back about the vertical through the
    node's first place)."""
    record = world.resources.get(SpawnedModels, {}).get(root)
    if record is None or record.loaded is None:
        if clip_name:
            raise AssetError(f"entity {root}'s Animation: its model has no animations (clip {clip_name!r})")
        return
    clips = record.loaded.animations

    def found(name: str) -> Clip:
        clip = next((c for c in clips if c.name == name), None)
        if clip is None:
            names = ", ".join(repr(c.name) for c in clips)
            raise AssetError(f"entity {root}'s Animation: its model has no clip {name!r} (its clips: {names})")
        return clip

    clip = found(clip_name) if clip_name else None
    fading = (found(fade[0]), fade[1], fade[2]) if fade is not None and fade[0] else None
    laid = None
    if layer is not None and layer[0]:
        laid = Layer(found(layer[0]), layer[1], layer[2], layer[3] == "additive", _layer_mask(root, record, layer[4]))
    placed = None
    if clip is None and fading is None and laid is None:
        matrices = {}
    else:  # (every node: the parts', the joints')
        placed = pose_all(record.loaded.node_tree, clip or _REST, time, fading, laid)
        if hold and clip is not None:  # walked on the spot: the travel moves the root instead
            travel = root_travel(world, root, clip_name, hold, time)
            held = _layer_mask(root, record, hold, "Animation.root_motion")
            placed[held, :3, 3] -= travel
            if turn:  # (and turned back: the turn turns the root instead)
                node = _named_node(root, record, hold, "Animation.root_motion")
                about = record.starts[(clip_name, node)]
                back = _turn_about(-root_turn(world, root, clip_name, hold, time), about)
                placed[held] = back @ placed[held]
        matrices = {node: placed[node] for node in record.nodes if node is not None}
    every = every or fading is not None or laid is not None
    moved = moved_nodes(record.loaded.node_tree, clip) if clip is not None and not every else None
    if any(skin is not None for skin in record.skins):
        _pose_skins(world, record, clip, time, moved, placed)
    _pose_morphs(world, record, clip, time, every, fading, laid)
    if moved is not None:
        matrices = {node: m for node, m in matrices.items() if node in moved}
    loaded = record.loaded
    if clip is not None and (clip.properties or (fading is not None and fading[0].properties)):
        _pose_properties(world, record, clip, time, fading)
    rest = {thing.node: thing.local for thing in (*loaded.parts, *loaded.lights, *loaded.cameras)}
    for entity, node in zip(record.parts, record.nodes, strict=True):
        if node is None or not world.exists(entity) or (not every and node not in matrices):
            continue
        placed = matrices.get(node)
        local = glm.mat4(*placed.astype(np.float32).T.ravel()) if placed is not None else rest[node]
        shown = world.try_get(entity, MeshRef)
        if collapsed(np.array(local, np.float64)):  # scaled to nothing: not drawn (its light, its camera stay)
            if shown is not None and shown.visible:
                shown.visible = False
            continue
        if shown is not None and not shown.visible:  # grown again from nothing
            shown.visible = True
        at = _node_transform(local, f"node {node}")
        if world.has(entity, Camera):
            at.scale = glm.vec3(1.0)  # (a camera's picture is not stretched by its node's scale)
        transform = world.get(entity, Transform)
        transform.position, transform.rotation, transform.scale = at.position, at.rotation, at.scale
        if world.has(entity, DirectionalLight):
            turn_suns(world, root, [entity])


_REST = Clip("", [], 0.0)  # no clip: every node at rest


def _property_targets(world: World, record: SpawnedModel) -> dict[tuple[str, int], list[int]]:
    """(kind, index) -> the entities made from the file's material, light or camera of that
    index (the record's parts are its parts, then its lights, then its cameras, in order)."""
    if record.targets is None:
        loaded = record.loaded
        targets: dict[tuple[str, int], list[int]] = {}
        made = iter(record.parts)
        for part, entity in zip(loaded.parts, made, strict=False):
            if part.material is not None:
                targets.setdefault(("materials", part.material), []).append(entity)
                record.emission[entity] = [list(part.emissive_rgb), part.emissive_strength, part]
        for light, entity in zip(loaded.lights, made, strict=False):
            if light.light is not None:
                targets.setdefault(("lights", light.light), []).append(entity)
                if light.kind == "spot":
                    record.cones[entity] = [light.inner_cone, light.outer_cone]
                engine_light = world.try_get(entity, PointLight) or world.try_get(entity, DirectionalLight)
                if engine_light is not None and light.intensity > 0.0:
                    record.light_scales[entity] = engine_light.intensity / light.intensity
        for camera, entity in zip(loaded.cameras, made, strict=False):
            if camera.camera is not None:
                targets.setdefault(("cameras", camera.camera), []).append(entity)
        record.targets = targets
    return record.targets


def _pose_properties(world: World, record: SpawnedModel, clip: Clip, time: float,
                     fading: tuple[Clip, float, float] | None = None) -> None:
    """``clip``'s property channels (``KHR_animation_pointer``) at ``time`` written into what
    was made from what each names: a material's colour (a see-through part's alpha kept: its
    glass's), metallic, roughness and cutoff into its parts' Materials; a light's colour and
    intensity (times the light scale it was made with) into its light; a camera's field of
    view and clip planes into its Camera; each kept within what its field takes (a cubic
    spline may overshoot between its keys).  ``fading``: (the clip faded from, its time,
    ``clip``'s share): a property both clips animate is mixed by the share, as a node's pose
    is; one only the clip faded from animates follows it until the fade ends (then it holds)."""
    targets = _property_targets(world, record)
    channels = [(channel, sample_property(channel, time)) for channel in clip.properties]
    if fading is not None:
        old, old_time, share = fading
        before = {(channel.path, channel.node): sample_property(channel, old_time) for channel in old.properties}
        mixed = []
        for channel, value in channels:
            was = before.pop((channel.path, channel.node), None)
            mixed.append((channel, value if was is None else was * (1.0 - share) + value * share))
        channels = mixed + [(channel, before[(channel.path, channel.node)]) for channel in old.properties
                            if (channel.path, channel.node) in before]
    for channel, value in channels:
        kind, name = channel.path.split(".")
        for entity in targets.get((kind, channel.node), ()):
            if not world.exists(entity):
                continue
            if name in ("emissiveFactor", "emissiveStrength"):
                _write_emission(world, record, entity, name, value)
                continue
            for written in _property_fields(world, record, entity, kind, name, value):
                if getattr(written[0], written[1]) != written[2]:  # (a held key: no write)
                    setattr(*written)


def _write_emission(world: World, record: SpawnedModel, entity: int, name: str, value: np.ndarray) -> None:
    """A part's emission after an ``emissiveFactor`` or ``emissiveStrength`` key: its
    Emissive's power as the loader works it out (``ModelPart.emissive_factor``: with an emissive
    map, the factor's largest channel x the strength; without, the factor over the diffuse
    colour on the colour's strongest channel), an Emissive given where the part had none.  A
    map's tint is the file's first factor's (the factor's hue is baked into its texels)."""
    state = record.emission.get(entity)
    if state is None:
        return
    if name == "emissiveFactor":
        state[0] = [float(v) for v in value[:3]]
    else:
        state[1] = float(value[0])
    rgb, strength, part = state
    if part.emissive_map is not None:
        power = max(rgb) * strength
    else:
        channel = int(np.argmax(part.color[:3]))
        power = rgb[channel] * strength / max(part.color[channel], 1e-6)
    power = float(np.clip(power, 0.0, min(1e4, HALF_MAX)))
    emissive = world.try_get(entity, Emissive)
    if emissive is None:
        if power > 0.0:
            world.add_component(entity, Emissive(power))
    elif emissive.power != power:
        emissive.power = power


def _property_fields(world: World, record: SpawnedModel, entity: int, kind: str, name: str,
                     value: np.ndarray) -> list[tuple[object, str, object]]:
    """(the component, its field, the value to write) for a property channel's ``value`` on
    ``entity``, each kept within what its field takes; none where the entity has nothing it
    sets."""
    if kind == "materials":
        material = world.try_get(entity, Material)
        if material is None:
            return []
        if name == "baseColorFactor":
            alpha = material.color[3] if material.blend == "transparent" else float(np.clip(value[3], 0.0, 1.0))
            return [(material, "color", glm.vec4(*np.clip(value[:3], 0.0, HALF_MAX), alpha))]
        if name == "alphaCutoff":
            return [] if material.alpha_cutoff is None else [(material, "alpha_cutoff",
                                                              float(np.clip(value[0], 0.0, 1.0)))]
        if name == "normalScale":
            return [(material, "normal_scale", float(np.clip(value[0], 0.0, MAX_NORMAL_SCALE)))]
        if name == "occlusionStrength":
            return [(material, "occlusion_strength", float(np.clip(value[0], 0.0, 1.0)))]
        return [(material, "metallic" if name == "metallicFactor" else "roughness", float(np.clip(value[0], 0.0, 1.0)))]
    if kind == "lights":
        light = world.try_get(entity, PointLight) or world.try_get(entity, DirectionalLight)
        if light is None:
            return []
        if name == "color":
            return [(light, "color", glm.vec4(*np.clip(value[:3], 0.0, HALF_MAX), 1.0))]
        if name == "intensity":
            return [(light, "intensity",
                     float(np.clip(value[0] * record.light_scales.get(entity, 1.0), 0.0, HALF_MAX)))]
        if not isinstance(light, PointLight):
            return []
        if name == "range":
            return [(light, "range", float(np.clip(value[0], 1e-6, MAX_FAR)))]
        cones = record.cones.get(entity)
        if cones is None:   # (not a spot: its cones are not the file's to turn)
            return []
        cones[0 if name == "innerConeAngle" else 1] = float(value[0])
        outer = float(np.clip(cones[1], math.radians(MIN_SPOT_ANGLE), math.pi / 2))
        inner = float(np.clip(cones[0], 0.0, outer))
        return [(light, "spot_angle", math.degrees(outer)), (light, "spot_blend", (outer - inner) / outer)]
    camera = world.try_get(entity, Camera)
    if camera is None or (name == "yfov" and camera.projection != "perspective") \
            or (name == "ymag" and camera.projection != "orthographic"):
        return []
    if name == "yfov":
        return [(camera, "fov_y", float(np.clip(np.degrees(value[0]), 1.0, 179.0)))]
    if name == "ymag":
        return [(camera, "ortho_height", float(np.clip(2.0 * value[0], 1e-3, 1e6)))]
    if name == "znear":
        return [(camera, "near", float(np.clip(value[0], 1e-6, camera.far * 0.999)))]
    return [(camera, "far", float(max(value[0], camera.near * 1.001)))]


def crossfade(animation: Animation, clip: str, seconds: float) -> None:
    """Start ``animation`` fading from the clip it plays (where it is) into ``clip`` (from its
    start) over ``seconds`` (``Animation``'s fade fields; the models stage plays it on); 0
    seconds, or no clip playing: a plain switch."""
    fading = seconds > 0.0 and bool(animation.clip)
    animation.fade_from, animation.fade_from_time = (animation.clip, animation.time) if fading else ("", 0.0)
    animation.fade_seconds, animation.faded = (seconds, 0.0) if fading else (0.0, 0.0)
    animation.clip, animation.time = clip, 0.0


def skin_palettes(loaded: LoadedModel, clip: Clip | None, time: float, skins: Collection[int] | None = None,
                  placed: np.ndarray | None = None) -> dict[int, np.ndarray]:
    """Each skin's joint matrices (skin index -> (J, 4, 4)) with its joints where ``clip``
    puts them at ``time`` (None: at rest); ``skins``: only those; ``placed``: the nodes'
    matrices there already (``pose_all``'s)."""
    chosen = range(len(loaded.skins)) if skins is None else skins
    if not loaded.skins or not chosen:
        return {}
    if placed is None:
        placed = pose_all(loaded.node_tree, clip or _REST, time)
    return {s: joint_matrices(loaded.skins[s], placed) for s in chosen}


def _pose_skins(world: World, record: SpawnedModel, clip: Clip | None, time: float,
                moved: set[int] | None, placed: np.ndarray | None) -> None:
    """Pose the skinned parts of ``record``: their ``Skin`` from ``clip`` at ``time`` (None:
    at rest); with ``moved`` (the nodes the clip moves), only skins with a joint among them."""
    loaded = record.loaded
    used = {skin for skin in record.skins if skin is not None}
    if moved is not None:
        used = {s for s in used if not moved.isdisjoint(loaded.skins[s].joints)}
    palettes = skin_palettes(loaded, clip, time, used, placed)
    for entity, skin in zip(record.parts, record.skins, strict=True):
        if skin in palettes and world.exists(entity):
            world.get(entity, Skin).joint_matrices = palettes[skin]


def _layer_mask(root: int, record: SpawnedModel, name: str, owner: str = "AnimationLayer") -> np.ndarray | None:
    """The nodes an AnimationLayer whose ``root`` is ``name`` acts on (None: all), or those
    under ``Animation.root_motion``'s node (``owner``), found once a model; a name no node of
    the model has is an AssetError naming the entity, ``owner`` and its nodes' names."""
    if not name:
        return None
    mask = record.masks.get(name)
    if mask is None:
        mask = record.masks[name] = subtree(record.loaded.node_tree, _named_node(root, record, name, owner))
    return mask


def _named_node(root: int, record: SpawnedModel, name: str, owner: str) -> int:
    """The index of ``root``'s model's node called ``name`` (an AssetError naming ``owner``
    and the nodes it has where none is)."""
    tree = record.loaded.node_tree
    if name not in tree.names:
        named = [n for n in tree.names if n]
        shown = ", ".join(repr(n) for n in named[:12]) + (f" and {len(named) - 12} more" if len(named) > 12 else "")
        raise AssetError(f"entity {root}'s {owner}: its model has no node {name!r} "
                         f"(its nodes: {shown or 'none named'})")
    return tree.names.index(name)


def root_travel(world: World, root: int, clip_name: str, node_name: str, time: float) -> np.ndarray:
    """How far clip ``clip_name`` of ``root``'s model has carried node ``node_name`` across the
    ground at ``time`` (model space, x and z; y 0) from where it stood at the clip's start:
    what ``Animation.root_motion`` takes out of the pose and moves the root by."""
    record = world.resources[SpawnedModels][root]
    clip = next(c for c in record.loaded.animations if c.name == clip_name)
    node = _named_node(root, record, node_name, "Animation.root_motion")
    found = record.travels.get((clip_name, node, time))
    if found is not None:
        return found
    start = record.starts.get((clip_name, node))
    if start is None:
        start = record.starts[(clip_name, node)] = pose_all(record.loaded.node_tree, clip, 0.0)[node, :3, 3].copy()
    travel = pose_all(record.loaded.node_tree, clip, time)[node, :3, 3] - start
    travel[1] = 0.0
    if len(record.travels) >= 8:
        del record.travels[next(iter(record.travels))]
    record.travels[(clip_name, node, time)] = travel
    travel.flags.writeable = False  # (kept: callers make new arrays of it)
    return travel


def root_start(world: World, root: int, clip_name: str, node_name: str) -> np.ndarray:
    """Where clip ``clip_name`` of ``root``'s model puts node ``node_name`` at its start (model
    space): what ``root_travel`` measures from, and the vertical ``root_turn``'s turn is taken
    out about."""
    root_travel(world, root, clip_name, node_name, 0.0)   # (kept there)
    record = world.resources[SpawnedModels][root]
    return record.starts[(clip_name, _named_node(root, record, node_name, "Animation.root_motion"))]


def root_turn(world: World, root: int, clip_name: str, node_name: str, time: float) -> float:
    """How far clip ``clip_name`` of ``root``'s model has turned node ``node_name`` about the
    vertical at ``time`` (radians, counter-clockwise seen from above, in (-pi, pi]) from its
    turn at the clip's start: the twist about +y of its rotation since (its swing, a lean or a
    bow, stays in the pose): what ``Animation.root_turn`` takes out of the pose and turns the
    root by."""
    record = world.resources[SpawnedModels][root]
    clip = next(c for c in record.loaded.animations if c.name == clip_name)
    node = _named_node(root, record, node_name, "Animation.root_motion")
    key = (clip_name, node, "turn")
    start = record.starts.get(key)
    if start is None:
        start = record.starts[key] = _rotation_of(pose_all(record.loaded.node_tree, clip, 0.0)[node])
    turned = _rotation_of(pose_all(record.loaded.node_tree, clip, time)[node]) * glm.inverse(start)
    angle = 2.0 * math.atan2(turned.y, turned.w)
    return math.remainder(angle, 2.0 * math.pi)


def _rotation_of(matrix: np.ndarray) -> glm.quat:
    """The rotation of a node's matrix (its columns' scale divided out)."""
    axes = np.asarray(matrix, np.float64)[:3, :3]
    axes = axes / np.linalg.norm(axes, axis=0, keepdims=True)
    return glm.quat_cast(glm.mat3(*axes.T.reshape(-1).tolist()))


def _turn_about(angle: float, place: np.ndarray) -> np.ndarray:
    """The matrix (4, 4) turning by ``angle`` about the vertical through ``place`` (x, z)."""
    c, s = math.cos(angle), math.sin(angle)
    turn = np.array([[c, 0.0, s, 0.0], [0.0, 1.0, 0.0, 0.0], [-s, 0.0, c, 0.0], [0.0, 0.0, 0.0, 1.0]])
    there, back = np.eye(4), np.eye(4)
    there[[0, 2], 3], back[[0, 2], 3] = place[[0, 2]], -place[[0, 2]]
    return there @ turn @ back


def clip_duration(world: World, root: int, clip_name: str) -> float:
    """The length in seconds of clip ``clip_name`` of ``root``'s model (0: none such)."""
    record = world.resources.get(SpawnedModels, {}).get(root)
    clip = next((c for c in record.loaded.animations if c.name == clip_name), None) \
        if record is not None and record.loaded is not None else None
    return clip.duration if clip is not None else 0.0


def _pose_morphs(world: World, record: SpawnedModel, clip: Clip | None, time: float, every: bool,
                 fading: tuple[Clip, float, float] | None = None, layer: Layer | None = None) -> None:
    """Set the ``Morph`` of ``record``'s morphed parts: the weights ``clip``'s ``weights``
    channels give their nodes at ``time``, the file's (the node's or its mesh's) where none
    does; ``every`` False: only the parts a channel animates; ``fading``: mixed from the
    clip faded from's by ``clip``'s share; ``layer``: a layer's laid over them."""
    sampled = pose_weights(clip, time) if clip is not None else {}
    before = pose_weights(fading[0], fading[1]) if fading is not None else None
    laid = layer_weights(layer) if layer is not None else None
    for entity, part in zip(record.parts, record.loaded.parts, strict=False):
        if part.morph_weights is None or not world.exists(entity):
            continue
        weights = sampled.get(part.node)
        if before is not None:
            rest = np.array(part.morph_weights)
            old = before.get(part.node, rest)
            weights = old + fading[2] * ((rest if weights is None else weights) - old)
        if layer is not None:
            weights = layered_weights(weights, np.array(part.morph_weights), part.node, layer, laid)
        if weights is not None:
            world.get(entity, Morph).weights = np.clip(weights, -MAX_MORPH_WEIGHT, MAX_MORPH_WEIGHT)
        elif every:
            world.get(entity, Morph).weights = part.morph_weights


def turn_suns(world: World, root: int, entities: Sequence[int] | None = None) -> None:
    """Point the directional lights among ``root``'s parts (``entities``: those; None: all)
    along their nodes' -Z as the model stands now (a DirectionalLight has a direction, not a
    place: its entity's Transform does not turn it), after the root turned or a clip did."""
    record = world.resources.get(SpawnedModels, {}).get(root)
    for entity in record.parts if entities is None and record is not None else entities or ():
        sun = world.try_get(entity, DirectionalLight) if world.exists(entity) else None
        if sun is None:
            continue
        travel = glm.vec3(current_world_matrix(world, world.get(entity, Transform)) * glm.vec4(0.0, 0.0, -1.0, 0.0))
        if glm.length(travel) > 0.0:
            sun.direction = travel


def _camera_components(camera: ModelCamera) -> list:
    """A file's camera as the engine's, not active (the level's own camera keeps the view
    until a game makes one of the model's active): its node's place and turn (a scale in
    the node is left out: a camera's picture is not stretched by it)."""
    placed = _node_transform(camera.local, camera.name)
    placed.scale = glm.vec3(1.0)
    lens = {"fov_y": camera.fov_y, "near": camera.near, **({"far": camera.far} if camera.far is not None else {}),
            **({"projection": "orthographic", "ortho_height": camera.ortho_height}
               if camera.ortho_height is not None else {})}
    return [placed, Camera(active=False, **lens)]


def _node_transform(local: glm.mat4, name: str) -> Transform:
    """A node's transform in the model as the Transform of an entity under the root."""
    scale_v, rotation_q, translation = glm.vec3(), glm.quat(), glm.vec3()
    if not glm.decompose(local, scale_v, rotation_q, translation, glm.vec3(), glm.vec4()):
        raise ComponentValueError(f"node transform of {name!r} cannot be decomposed")
    return Transform(position=translation, rotation=rotation_q, scale=scale_v)


def _planar_mirror(part) -> bool:
    """Whether a reflective part is a planar mirror: flat, not a cutout (a mirror is drawn
    whole; a flat metal grate reflects a probe or the sky as a curved part does) and not
    glass.  A double-sided mirror is made single-sided: a mirror is seen from its front."""
    return part.reflectivity > 0.0 and _flat(part) and part.alpha_cutoff is None and not _glass(part)


def _glass(part) -> bool:
    """Whether a part lets light through (glTF's KHR_materials_transmission)."""
    return part.transmission > 0.0


def _flat(part) -> bool:
    return flat_plane(part.mesh) is not None


def _placed_size(part) -> float:
    """The diagonal of a part's box once its node transform places it (which parts are
    largest, for the probes)."""
    lo, hi = part.mesh.bounds
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    placed = corners @ np.array(part.local, np.float64).T  # numpy(glm.mat4) reads as M: points are columns
    return float(np.linalg.norm(placed[:, :3].max(axis=0) - placed[:, :3].min(axis=0)))


def _name_sources(path: str | Path, parts: list) -> None:
    """Say where each part came from, as a level file names it (``save_level`` writes a
    spawned model back): a mesh as ``{ file, part }``; an image decoded from inside the
    model file (no file of its own) as ``{"inside": file}``, which ``save_level`` refuses
    plainly (a level file names image files only)."""
    file = str(Path(path).resolve())
    for part in parts:
        if part.mesh.source is None:
            name = part.mesh.name.split(":", 1)[-1]
            part.mesh.source = {"file": file, **({"part": name} if len(parts) > 1 else {})}
        for texture in (part.texture, part.normal_map, part.emissive_map, part.metallic_roughness_map,
                        part.occlusion_map):
            if texture is not None and texture.source is None:
                texture.source = {"inside": file}
