"""Frames, id images and scene exports written to disk, for debugging and verification."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from pyglm import glm

from components import Camera, MeshRef, Portal, Transform
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
    beside it, a JSON of the camera, each entity's component types, each mirror's world
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
    """Per portal: its partner and the column-major 4x4 that carries points at it to the partner."""
    pairs = {}
    for entity, (portal, transform) in world.query(Portal, Transform):
        partner = portal.partner
        partner_t = world.try_get(partner, Transform) if partner is not None and world.exists(partner) else None
        carry = pair_transform(transform.world, partner_t.world) if partner_t is not None else None
        pairs[str(entity)] = {
            "partner": partner if partner_t is not None else None,
            "to_partner": [float(v) for column in carry.to_list() for v in column] if carry is not None else None,
        }
    return pairs
