"""What a click on a monitor's screen picks: the thing its picture shows there, as a click on a
mirror picks the thing seen in it.  The main view's ray through the clicked pixel is cast
(``raycast_seen``: on through mirrors and portals) to the screen; the point's texture
coordinates on the screen's mesh give the picture's pixel, and the monitor camera's ray
through that pixel is cast on in turn, into a picture in the picture too, up to
``MAX_PICTURES_FOLLOWED`` deep.  Cast on the CPU (``engine/rules/raycast.py``): the picture
keeps no id image of what it shows.  The lens's cast meets only what its views draw (the
visibility rule: its layers, what is hidden in direct views, and past a mirror or portal
what that view draws: ``raycast_seen``'s ``view_mask``)."""
from __future__ import annotations

from collections.abc import Callable, Collection

import numpy as np
from pyglm import glm

from components import Camera, MeshRef, Monitor, Transform
from components.visibility import visibility_code
from engine.core.transforms import current_world_matrix
from engine.core.world import World
from engine.render.views import camera_view
from engine.rules.raycast import RayHit, raycast_seen, shared_caster
from shell.handles import view_ray

MAX_PICTURES_FOLLOWED = 4   # pictures in pictures a click follows (a camera seeing its own screen stops there)


def into_pictures(world: World, pictures: Collection[int], origin: glm.vec3, direction: glm.vec3,
                  view_mask: int | None = None) -> Callable[[int], int | None]:
    """For the entity a click picked (the id image's, at the pixel whose ray from the main
    view, of ``view_mask`` (None: any), is ``origin``, ``direction``), what it picks: a
    monitor's screen that has a picture (``pictures``: ``MonitorPictures.entities``) gives
    what its picture shows at the point the ray meets (None: the sky there); anything else is
    itself."""
    def follow(picked: int) -> int | None:
        return seen_in_pictures(world, pictures, picked, origin, direction, view_mask)
    return follow


def seen_in_pictures(world: World, pictures: Collection[int], picked: int, origin: glm.vec3,
                     direction: glm.vec3, view_mask: int | None = None) -> int | None:
    """``picked``, or where it is a screen with a picture, what the picture shows along the
    ray (``into_pictures``), followed into pictures in pictures."""
    entity: int | None = picked
    for _ in range(MAX_PICTURES_FOLLOWED):
        if entity is None or entity not in pictures or not world.exists(entity):
            return entity
        monitor = world.try_get(entity, Monitor)
        seen = raycast_seen(world, origin, direction, view_mask=view_mask)
        if monitor is None or seen is None or seen.hit.entity != entity:
            return entity   # (the CPU's cast and the picture disagree at an edge: the screen)
        uv = _uv_at(world, seen.hit)
        lens = monitor.camera
        camera = world.try_get(lens, Camera) if lens is not None and world.exists(lens) else None
        if uv is None or camera is None or not world.has(lens, Transform):
            return entity
        width, height = monitor.size
        pose = current_world_matrix(world, world.get(lens, Transform))
        view = camera_view(pose, camera.fov_y, camera.near, camera.far, (width, height),
                           ortho_height=camera.ortho_height if camera.projection == "orthographic" else None)
        # The picture's texel at the point (its rows from the bottom, as the screen samples it).
        origin, direction = view_ray(view.view_proj, (width, height), (uv[0] * width, (1.0 - uv[1]) * height))
        view_mask = visibility_code(view.kinds, camera.layer_mask)
        seen = raycast_seen(world, origin, direction, view_mask=view_mask)
        entity = None if seen is None else seen.hit.entity
    return entity


def _uv_at(world: World, hit: RayHit) -> tuple[float, float] | None:
    """The texture coordinates of the mesh of ``hit.entity`` at ``hit.point`` (its triangle's,
    by the point's barycentric weights in the triangle as the cast met it: posed by its Skin
    and Morph, ``RayCaster.triangles``); None where it has none."""
    mesh_ref = world.try_get(hit.entity, MeshRef)
    if mesh_ref is None or mesh_ref.mesh.uvs is None or not len(mesh_ref.mesh.uvs):
        return None
    mesh = mesh_ref.mesh
    a, b, c = shared_caster(world).triangles(hit.entity)[hit.triangle]
    corners = mesh.indices.reshape(-1, 3)[hit.triangle]
    point = np.array(hit.point, np.float64)
    ab, ac, ap = b - a, c - a, point - a
    d00, d01, d11 = ab @ ab, ab @ ac, ac @ ac
    d20, d21 = ap @ ab, ap @ ac
    denominator = d00 * d11 - d01 * d01
    if abs(denominator) < 1e-20:
        return None
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    uv = (1.0 - v - w) * np.asarray(mesh.uvs[corners[0]]) + v * np.asarray(mesh.uvs[corners[1]]) \
        + w * np.asarray(mesh.uvs[corners[2]])
    return float(uv[0]), float(uv[1])
