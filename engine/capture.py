"""Frames, id images and scene exports written to disk, for debugging and verification."""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from pyglm import glm

from components import Camera, MeshRef, Portal, Transform
from engine.frame_rules import frame_rules
from engine.portal_math import pair_transform
from engine.world import World

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
                 mirror_planes: dict[int, tuple[list[float], list[float]]] | None = None) -> Path:
    """Write world-space geometry (one GLB node per renderable entity, named by its id) and,
    beside it, a JSON of the camera, each entity's component types and their field values
    (``component_values``: enough to rebuild the scene), each mirror's world
    plane (a point on it and its unit normal, towards the reflecting side), each portal's
    partner, each reflection probe and which probe each entity samples.  The geometry's
    format follows the extension (``SCENE_FORMATS``); any other is refused."""
    import trimesh

    path = Path(path)
    if path.suffix.lower() not in SCENE_FORMATS:
        raise ValueError(f"export_scene: {str(path)!r} must end in {' or '.join(SCENE_FORMATS)}")
    path.parent.mkdir(parents=True, exist_ok=True)
    scene = trimesh.Scene()
    for entity, (mesh_ref, transform) in world.query(MeshRef, Transform):
        mesh = mesh_ref.mesh
        matrix = np.array(transform.world.to_list(), np.float64).T  # glm is column-major
        positions = mesh.positions @ matrix[:3, :3].T + matrix[:3, 3]
        geometry = trimesh.Trimesh(positions, mesh.indices, process=False)
        scene.add_geometry(geometry, node_name=str(entity), geom_name=str(entity))
    if path.suffix.lower() == ".glb":
        scene.export(str(path), file_type="glb")
    else:
        path.write_bytes(trimesh.exchange.gltf.export_gltf(scene, embed_buffers=True)["model.gltf"])

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
    }
    path.with_suffix(".json").write_text(json.dumps(info, indent=1))
    return path


def _probes(world: World) -> dict[str, dict]:
    """Each reflection probe (by the entity owning it: a ReflectionProbe's, or an object's own
    automatic one) with where and how it captures, and which probe each entity samples."""
    from engine.probe_rules import probe_for
    from engine.render.probes import ProbeStates

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
    partner; both None when the pair is closed (``engine.frame_rules.open_portal_pairs``)."""
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


# How component field values are written to scene.json (``component_values``).  Every kind
# is plain JSON; ``VALUE_KINDS`` goes into the file so a tool reading it needs nothing else.
VALUE_KINDS = {
    "null": "no value (None)",
    "bool": "true / false",
    "int": "an integer (Transform.parent, Portal.partner, PortalClone.source/.portal: an entity id)",
    "float": "a number; inf, -inf and nan are written as those strings",
    "str": "a string",
    "vec2": "[x, y]", "vec3": "[x, y, z]", "vec4": "[x, y, z, w] (colours: [r, g, b, a])",
    "quat": "[w, x, y, z]: a unit quaternion, w first (glm.quat(w, x, y, z))",
    "mat4": "16 numbers, column by column (glm's order)",
    "list": "a list of values, each written by these rules",
    "array": "{'shape': [...], 'dtype': ..., 'values': nested lists} (a numpy array of up to 64 values)",
    "array_summary": "{'shape': [...], 'dtype': ...} (a larger numpy array, e.g. generated sky faces)",
    "mesh": "{'name', 'id', 'vertices', 'triangles', 'bounds': [min xyz, max xyz] local}: entities with "
            "the same id share one mesh; the entity's geometry is node <entity id> of the .glb/.gltf beside "
            "this file, in world space (its Transform's world matrix undoes it)",
    "texture": "{'name', 'size': [width, height]}: pixels by name, not embedded",
    "object": "an object's public fields, each written by these rules",
}
_GLM_KIND = {glm.vec2: "vec2", glm.vec3: "vec3", glm.vec4: "vec4", glm.quat: "quat", glm.mat4: "mat4"}
_ARRAY_VALUES_MAX = 64


def json_value(value: Any) -> tuple[Any, str]:
    """``value`` as plain JSON and the kind it was written as (a key of ``VALUE_KINDS``)."""
    from engine.mesh import Mesh
    from engine.texture_data import TextureData

    if value is None:
        return None, "null"
    if isinstance(value, bool | np.bool_):
        return bool(value), "bool"
    if isinstance(value, int | np.integer):
        return int(value), "int"
    if isinstance(value, float | np.floating):
        return _number(value), "float"
    if isinstance(value, str):
        return value, "str"
    kind = _GLM_KIND.get(type(value))
    if kind == "quat":
        return [_number(v) for v in (value.w, value.x, value.y, value.z)], kind
    if kind == "mat4":
        return [_number(v) for column in value.to_list() for v in column], kind
    if kind is not None:
        return [_number(v) for v in value], kind
    if isinstance(value, Mesh):
        low, high = value.positions.min(axis=0), value.positions.max(axis=0)
        return {"name": value.name, "id": value.id, "vertices": len(value.positions),
                "triangles": len(value.indices), "bounds": [[_number(v) for v in low], [_number(v) for v in high]]}, \
            "mesh"
    if isinstance(value, TextureData):
        height, width = np.asarray(value.pixels).shape[:2]
        return {"name": value.name, "size": [int(width), int(height)]}, "texture"
    if isinstance(value, np.ndarray):
        summary = {"shape": list(value.shape), "dtype": str(value.dtype)}
        if value.size > _ARRAY_VALUES_MAX:
            return summary, "array_summary"
        return {**summary, "values": json.loads(json.dumps(value.tolist(), default=str))}, "array"
    if isinstance(value, list | tuple):
        return [json_value(v)[0] for v in value], "list"
    return {name: json_value(v)[0] for name, v in _public_fields(value).items()}, "object"


def _number(value: Any) -> float | str:
    value = float(value)
    return value if math.isfinite(value) else str(value)


def _public_fields(component: Any) -> dict[str, Any]:
    """The fields a component is made from: a dataclass's init fields, else its public attributes."""
    if dataclasses.is_dataclass(component):
        return {f.name: getattr(component, f.name) for f in dataclasses.fields(component)
                if f.init and not f.name.startswith("_")}
    return {name: v for name, v in vars(component).items() if not name.startswith("_")}


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
            for name, value in _public_fields(component).items():
                fields[name], kind = json_value(value)
                if kind != "null" or name not in info["fields"]:
                    info["fields"][name] = kind
    return {"components": values, "component_types": dict(sorted(types.items())), "value_kinds": VALUE_KINDS}
