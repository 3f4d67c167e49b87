"""Frames, id images and scene exports written to disk, for debugging and verification."""
from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    PointLight,
    Portal,
    Refractive,
    Transform,
    Water,
    look_rotation,
)
from engine.assets.gltf_export import ExportCamera, ExportLight, ExportPart, write_gltf
from engine.assets.model_lights import LAMP_FIELDS, SUN_FIELDS
from engine.assets.texture_data import TextureData
from engine.assets.values import VALUE_KINDS, json_value, public_fields
from engine.core.budget import ViewBudget
from engine.core.color import linear_to_srgb
from engine.core.errors import SpeculumError
from engine.core.portal_math import pair_transform
from engine.core.world import World
from engine.rules.frame_rules import frame_rules

if TYPE_CHECKING:
    from shell.app import Engine

# What --export-scene writes, by the file's extension: binary glTF, or JSON glTF with its
# buffer embedded (one file either way).
SCENE_FORMATS = (".glb", ".gltf")


def save_png(rgb: np.ndarray, path: str | Path) -> None:
    from PIL import Image

    Image.fromarray(rgb).save(path)


def save_ids(ids: np.ndarray, path: str | Path) -> None:
    """The entity seen at each pixel (uint32, 0 = sky), row 0 at the top like the PNG."""
    np.save(path, ids.astype(np.uint32))


def export_scene(world: World, path: str | Path, camera_entity: int, size: tuple[int, int],
                 mirror_planes: dict[int, tuple[list[float], list[float]]] | None = None,
                 pictures: Mapping[int, np.ndarray] | None = None) -> Path:
    """Write world-space geometry with its materials (one glTF node per renderable entity,
    named by its id: ``engine/assets/gltf_export.py``, which the engine's loader reads back) and,
    beside it, a JSON of the camera, each entity's component types and their field values
    (``component_values``: enough to rebuild the scene), each mirror's world
    plane (a point on it and its unit normal, towards the reflecting side), each portal's
    partner, each reflection probe and which probe each entity samples, and the frame's
    ``ViewBudget`` (its fields; None: none), which decides which views are drawn.  The geometry's
    format follows the extension (``SCENE_FORMATS``); any other is refused.  ``pictures``: the
    monitors' pictures by entity (linear RGB(A), rows from the top:
    ``MonitorPictures.read``), each written as its screen's emissive map at its brightness
    (clamped at white, sRGB: the screen as it stands at the export)."""
    path = Path(path)
    if path.suffix.lower() not in SCENE_FORMATS:
        raise ValueError(f"export_scene: {str(path)!r} must end in {' or '.join(SCENE_FORMATS)}")
    path.parent.mkdir(parents=True, exist_ok=True)
    pictures = pictures or {}
    write_gltf(path, [_export_part(world, entity, mesh_ref, transform, pictures.get(entity))
                      for entity, (mesh_ref, transform) in sorted(world.query(MeshRef, Transform))],
               _export_lights(world), _export_cameras(world, size[0] / size[1]))

    camera = world.get(camera_entity, Camera)
    cam_world = world.get(camera_entity, Transform).world
    forward = glm.normalize(glm.vec3(cam_world * glm.vec4(0, 0, -1, 0)))
    up = glm.normalize(glm.vec3(cam_world * glm.vec4(0, 1, 0, 0)))
    info = {
        "camera": {
            "entity": camera_entity,
            "position": list(glm.vec3(cam_world[3])),
            "forward": list(forward),
            "up": list(up),
            "fov_y_deg": camera.fov_y,
            "aspect": size[0] / size[1],
            "near": camera.near,
            "far": camera.far,
            "image_size": list(size),
        },
        "entities": {
            str(entity): sorted(type(c).__name__ for c in world.components_of(entity))
            for entity in world.entities()
        },
        **component_values(world),
        "portals": _portal_pairs(world),
        "mirrors": {
            str(entity): {"point": [float(v) for v in point], "normal": [float(v) for v in normal]}
            for entity, (point, normal) in sorted((mirror_planes or {}).items())
        },
        **_probes(world),
        "view_budget": None if (budget := ViewBudget.of(world.resources)) is None else dataclasses.asdict(budget),
    }
    path.with_suffix(".json").write_text(json.dumps(info, indent=1))
    return path


def _export_part(world: World, entity: int, mesh_ref: MeshRef, transform: Transform,
                 picture: np.ndarray | None = None) -> ExportPart:
    """An entity's mesh in world space (its normals by the inverse transpose, turned back
    where the transform mirrors: the winding flips too) with what it is drawn with (a
    monitor's screen: its ``picture`` as its emissive map, at its brightness)."""
    mesh = mesh_ref.mesh
    matrix = np.array(transform.world.to_list(), np.float64).T  # glm is column-major
    linear = matrix[:3, :3]
    normals = np.asarray(mesh.normals, np.float64) @ np.linalg.inv(linear)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    indices = np.asarray(mesh.indices).reshape(-1, 3)
    if np.linalg.det(linear) < 0.0:
        indices = indices[:, ::-1]
    glass = world.try_get(entity, Refractive)
    water = world.try_get(entity, Water)
    mirror = world.try_get(entity, Mirror)
    emissive = world.try_get(entity, Emissive)
    emission = emissive.power if emissive is not None else 0.0
    material = world.try_get(entity, Material)
    monitor = world.try_get(entity, Monitor)
    if monitor is not None and picture is not None:
        encoded = np.round(linear_to_srgb(np.clip(np.asarray(picture, np.float64)[..., :3], 0.0, 1.0)) * 255.0)
        material = dataclasses.replace(material or Material(), emissive_map=TextureData(
            encoded.astype(np.uint8), name=f"monitor {entity}'s picture"))
        emission = monitor.brightness
    return ExportPart(
        str(entity), mesh.positions @ linear.T + matrix[:3, 3], normals, mesh.uvs, indices,
        material=material, second_uvs=mesh.second_uvs, colors=mesh.colors,
        emission=emission,
        glass=(glass.ior, glass.solid, glass.dispersion) if glass is not None else None,
        water_ior=water.ior if water is not None and mirror is not None else None,
        mirror=(tuple(mirror.color)[:3], mirror.reflect_rate, mirror.roughness)
        if mirror is not None and water is None else None)


def _placement(matrix: glm.mat4) -> list[float]:
    """A world matrix's place and turn, its scale left out (a light or camera node's; glTF
    column-major)."""
    turn = glm.mat3(matrix)
    rotation = glm.mat4(glm.mat3(*(glm.normalize(turn[i]) for i in range(3))))
    rotation[3] = glm.vec4(glm.vec3(matrix[3]), 1.0)
    return [float(v) for column in rotation.to_list() for v in column]


def _export_lights(world: World) -> list[ExportLight]:
    """The suns, lamps and spots as ``KHR_lights_punctual`` lights (named by entity), a colour
    past 1 folded into the intensity; a spot wider than glTF's 90 degrees at 90."""
    def colour(rgb, intensity: float) -> tuple[tuple[float, float, float], float]:
        rgb = [float(c) for c in tuple(rgb)[:3]]
        most = max(max(rgb), 1.0)
        return (rgb[0] / most, rgb[1] / most, rgb[2] / most), float(intensity) * most

    lights = []
    for entity, sun in sorted(world.query_one(DirectionalLight)):
        rgb, intensity = colour(sun.color, sun.intensity)
        lights.append(ExportLight(str(entity), "directional", rgb, intensity,
                                  _placement(glm.mat4_cast(look_rotation(glm.vec3(sun.direction)))),
                                  fields=_light_fields(sun, SUN_FIELDS)))
    for entity, (lamp, transform) in sorted(world.query(PointLight, Transform)):
        rgb, intensity = colour(lamp.color, lamp.intensity)
        spot = lamp.spot_angle < 180.0
        outer = math.radians(min(lamp.spot_angle, 90.0))
        fields = _light_fields(lamp, LAMP_FIELDS)
        if lamp.spot_angle <= 90.0 or not spot:   # (the extension's cone says these exactly)
            fields.pop("spot_angle", None)
            fields.pop("spot_blend", None)
        lights.append(ExportLight(str(entity), "spot" if spot else "point", rgb, intensity,
                                  _placement(transform.world), float(lamp.range),
                                  outer * (1.0 - lamp.spot_blend), outer, fields))
    return lights


def _light_fields(light: object, names: dict[str, str]) -> dict[str, object]:
    """``light``'s fields of ``names`` (the extras the loader reads back) that differ from their
    defaults, as JSON values."""
    fields = {}
    for field in dataclasses.fields(light):
        if field.name not in names:
            continue
        value = getattr(light, field.name)
        default = field.default if field.default is not dataclasses.MISSING else field.default_factory()
        if value == default or (isinstance(value, tuple) and tuple(value) == tuple(default)):
            continue
        fields[field.name] = [float(v) for v in value] if names[field.name] == "pair" else value
    return fields


def _export_cameras(world: World, aspect: float) -> list[ExportCamera]:
    """The cameras as glTF's, each drawing a picture of ``aspect`` (width / height: the export's)."""
    return [ExportCamera(str(entity), camera.fov_y, camera.near, camera.far, _placement(transform.world),
                         camera.ortho_height if camera.projection == "orthographic" else None, aspect)
            for entity, (camera, transform) in sorted(world.query(Camera, Transform))]


def _probes(world: World) -> dict[str, dict]:
    """Each reflection probe (by the entity owning it: a ReflectionProbe's, or an object's own
    automatic one) with where and how it captures, and which probe each entity samples."""
    from engine.rules.probe_rules import probe_for
    from engine.rules.probe_schedule import ProbeStates

    states = world.resources.get(ProbeStates, {})
    probes = {}
    for owner, state in sorted(states.items()):
        settings = state.settings
        probes[str(owner)] = {
            "position": [float(v) for v in state.position],
            "automatic": state.automatic,
            "influence": None if settings.influence is None else [float(v) for v in settings.influence],
            "box_projection": settings.box_projection,
            "resolution": settings.resolution,
            "refresh": settings.refresh,
            "captures": state.captures,
            "faces_captured": state.faces_captured,
        }
    samples = {str(e): probe_for(world, e) for e in world.entities() if probe_for(world, e)}
    return {"probes": probes, "samples_probe": samples}


def _portal_pairs(world: World) -> dict[str, dict]:
    """Per portal: its partner and the column-major 4x4 that carries points at it to the
    partner; both None when the pair is closed (``engine.rules.frame_rules.open_portal_pairs``)."""
    pairs = {}
    open_portals = frame_rules(world).open_portals
    for entity, (_, transform) in world.query(Portal, Transform):
        partner = open_portals.get(entity)
        partner_t = world.get(partner, Transform) if partner is not None else None
        carry = pair_transform(transform.world, partner_t.world) if partner_t is not None else None
        pairs[str(entity)] = {
            "partner": partner if partner_t is not None else None,
            "to_partner": [float(v) for column in carry.to_list() for v in column] if carry is not None else None,
        }
    return pairs


def component_values(world: World) -> dict[str, Any]:
    """Per entity, each component's field values (``components``), and per component type
    where its class is and the kind each field is written as (``component_types``), so a tool
    can import the class and call it with the decoded fields."""
    values: dict[str, dict[str, dict[str, Any]]] = {}
    types: dict[str, dict[str, Any]] = {}
    for entity in world.entities():
        row = values[str(entity)] = {}
        for component in sorted(world.components_of(entity), key=lambda c: type(c).__name__):
            cls = type(component)
            info = types.setdefault(cls.__name__, {"class": f"{cls.__module__}.{cls.__qualname__}", "fields": {}})
            fields = row[cls.__name__] = {}
            for name, value in public_fields(component).items():
                fields[name], kind = json_value(value)
                if kind != "null" or name not in info["fields"]:
                    info["fields"][name] = kind
    return {"components": values, "component_types": dict(sorted(types.items())), "value_kinds": VALUE_KINDS}


class OutputPathError(SpeculumError):
    """An output folder that is a file, or cannot be made or written."""


def prepare_out(folder: Path, what: str = "--out") -> None:
    """Make ``folder`` and check it can be written before any rendering, so a bad path is one
    clear line up front instead of a traceback after the first frame."""
    if folder.exists() and not folder.is_dir():
        raise OutputPathError(f"{what} {str(folder)!r} is an existing file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(f"{what} {str(folder)!r} cannot be made: {exc.strerror or exc}") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputPathError(f"{what} {str(folder)!r} is not writable")


def write_scene(engine: Engine, path: Path, size: tuple[int, int]) -> list[Path]:
    """``--export-scene``: the world's geometry and its camera (as seen at ``size``) to
    ``path`` and its ``.json``; returns both paths.  A headless run writes it after its last
    frame, a window as it closes."""
    camera = engine.active_camera()
    if camera is None:
        raise SpeculumError(f"--export-scene {str(path)!r}: the world has no active camera "
                            "(spawn one with engine.spawn_camera), so there is no view to export")
    try:
        monitors = engine.renderer.monitors
        geometry = export_scene(engine.world, path, camera[0], size, engine.reflection_system.mirror_planes(),
                                {entity: monitors.read(entity) for entity in monitors.entities})
    except OSError as exc:
        raise OutputPathError(f"--export-scene {str(path)!r} cannot be written: {exc.strerror or exc}") from None
    return [geometry, geometry.with_suffix(".json")]
