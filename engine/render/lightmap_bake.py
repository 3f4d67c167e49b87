"""Baking a lightmap (``Material.lightmap``) with the engine's own probe captures.

``bake_lightmap(engine, entity)`` finds, for each texel of a ``size`` x ``size`` image laid
over the entity's mesh by the UV set its Material reads a lightmap on (the second where its
``second_uv_maps`` names "lightmap", else the first: it must lay the mesh out once, without
overlaps, within 0..1), the point of the surface under its centre and that
point's normal (the triangles rasterised in UV space with numpy); captures the world's light
from just above the point as a reflection probe does (six 90-degree views of ``resolution``
texels, the entity itself left out: ``engine/render/probes.py``), reads the cube back,
projects it on nine spherical harmonics and evaluates the irradiance for the normal
(``engine/render/irradiance.py``, as the irradiance volumes' points); a texel is that
irradiance over pi, the colour a white matte surface shows there.  Texels no triangle covers
take their nearest covered neighbour's colour (a few rounds of dilation, so the filter's
reach past a chart's edge finds light, not black).

What it captures is what a probe sees: the sky, the lit surfaces round the point (the lights'
own light on them and their shadows, their light from all round as the captures have it),
emissive things: the light from all round, bounced once, and the sun through the surfaces
it lights.  The lights' own light on the surface is not in it: the engine adds it (and its
shadows) at run time, as Unity's "baked indirect" mode.

``bake_lightmaps(engine, entities, bounces=n)`` bakes several surfaces that light each other
(a room's walls, floor and ceiling), each round with the last round's lightmaps on, so the
light goes round n times (Unity's and Blender's bounces): a round's captures see each
neighbour lit by its last lightmap as well as by the lights, which the next lightmap then
holds.  In a closed room of albedo a glowing L all over, round n gives L (1 + a + ... +
a^(n-1)) (the furnace test's series, ``tests/test_lightmaps.py``).

The image is 8-bit sRGB: its largest value is returned as the intensity the material takes
(``Material.lightmap_intensity``), the image divided by it.  A bake is six views a covered
texel and a read back of each cube (a 32 x 32 map on llvmpipe takes some seconds): a tool for
a level's build, run between frames, not in one.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from pyglm import glm

from components import Material, MeshRef, Morph, Skin, Transform
from engine.assets.texture_data import TextureData
from engine.core.color import linear_to_srgb
from engine.core.errors import AssetError
from engine.render.bindings import SCRATCH_UNIT
from engine.render.irradiance import evaluate_sh, project_faces
from engine.render.probes import face_view
from engine.render.raw_gl import read_cube_level

if TYPE_CHECKING:
    from engine.core.world import World
    from shell.app import Engine

BAKE_KEY = -(1 << 30)   # the scratch cube's key among the probes' (no entity's, no volume's)
MAX_BOUNCES = 8         # bake_lightmaps' rounds (light halved by each bounce off a grey wall: 8 leave 1/256)
LIFT = 0.02             # metres above the surface a texel's light is captured from
DILATE_ROUNDS = 4       # texels past a chart's edge given its neighbours' light


def texel_points(positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, triangles: np.ndarray,
                 size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The point and normal (mesh space) under each texel centre of a ``size`` x ``size``
    image over the UVs (row 0 the image's top, v = 1), and which texels a triangle covers:
    (size, size, 3), (size, size, 3), (size, size) bool.  A texel two triangles share takes
    the last one's."""
    points = np.zeros((size, size, 3))
    ways = np.zeros((size, size, 3))
    covered = np.zeros((size, size), bool)
    for a, b, c in np.asarray(triangles, np.int64):
        uv = np.asarray(uvs, np.float64)[[a, b, c]] * size   # texel units, v up
        low = np.floor(uv.min(axis=0) - 0.5).astype(int)
        high = np.ceil(uv.max(axis=0) + 0.5).astype(int)
        xs = np.arange(max(low[0], 0), min(high[0], size))
        ys = np.arange(max(low[1], 0), min(high[1], size))
        if not len(xs) or not len(ys):
            continue
        cx, cy = np.meshgrid(xs + 0.5, ys + 0.5)
        d = np.stack([cx, cy], -1) - uv[0]
        e1, e2 = uv[1] - uv[0], uv[2] - uv[0]
        det = e1[0] * e2[1] - e1[1] * e2[0]
        if abs(det) < 1e-12:
            continue
        w1 = (d[..., 0] * e2[1] - d[..., 1] * e2[0]) / det
        w2 = (e1[0] * d[..., 1] - e1[1] * d[..., 0]) / det
        w0 = 1.0 - w1 - w2
        inside = (w0 >= -1e-9) & (w1 >= -1e-9) & (w2 >= -1e-9)
        if not inside.any():
            continue
        weights = np.stack([w0, w1, w2], -1)[inside]
        rows = size - 1 - np.broadcast_to(ys[:, None], inside.shape)[inside]
        cols = np.broadcast_to(xs[None, :], inside.shape)[inside]
        points[rows, cols] = weights @ np.asarray(positions, np.float64)[[a, b, c]]
        ways[rows, cols] = weights @ np.asarray(normals, np.float64)[[a, b, c]]
        covered[rows, cols] = True
    lengths = np.linalg.norm(ways, axis=-1, keepdims=True)
    ways = np.where(lengths > 1e-12, ways / np.maximum(lengths, 1e-12), 0.0)
    return points, ways, covered


def dilate(light: np.ndarray, covered: np.ndarray, rounds: int = DILATE_ROUNDS) -> np.ndarray:
    """``light`` (size, size, 3) with each uncovered texel next to covered ones given their
    mean, ``rounds`` times outwards."""
    light, covered = light.copy(), covered.copy()
    for _ in range(rounds):
        total = np.zeros_like(light)
        count = np.zeros(covered.shape)
        for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)):
            shifted = np.roll(np.roll(covered, dy, axis=0), dx, axis=1)
            if dy:
                shifted[0 if dy > 0 else -1, :] = False
            if dx:
                shifted[:, 0 if dx > 0 else -1] = False
            total += np.roll(np.roll(light, dy, axis=0), dx, axis=1) * shifted[..., None]
            count += shifted
        grow = ~covered & (count > 0)
        light[grow] = total[grow] / count[grow][:, None]
        covered = covered | grow
    return light


def _check_settings(size: int, resolution: int, near: float, far: float) -> None:
    if isinstance(size, bool) or not isinstance(size, int) or not 4 <= size <= 512:
        raise AssetError(f"bake_lightmap: size must be a whole number of texels from 4 to 512, got {size!r}")
    if isinstance(resolution, bool) or not isinstance(resolution, int) or not 4 <= resolution <= 128:
        raise AssetError(f"bake_lightmap: resolution must be a whole number from 4 to 128, got {resolution!r}")
    if not (0.0 < near < far and math.isfinite(far)):
        raise AssetError(f"bake_lightmap: near and far must be 0 < near < far, finite, got {near!r}, {far!r}")


def _surface(world: World, entity: int, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The world point and normal under each texel of ``entity``'s ``size`` x ``size``
    lightmap and which texels its mesh covers; an AssetError naming what cannot be baked."""
    mesh_ref, transform = world.try_get(entity, MeshRef), world.try_get(entity, Transform)
    if mesh_ref is None or transform is None:
        raise AssetError(f"bake_lightmap: entity {entity} has no MeshRef and Transform to lay a lightmap over")
    if world.has(entity, Skin) or world.has(entity, Morph):
        raise AssetError(f"bake_lightmap: entity {entity} is posed (a Skin or a Morph bends its mesh): a lightmap "
                         "is baked over a mesh that stays as it is")
    mesh = mesh_ref.mesh
    material = world.try_get(entity, Material)
    second = material is not None and "lightmap" in material.second_uv_maps
    uvs = mesh.second_uvs if second and mesh.second_uvs is not None else mesh.uvs
    points, ways, covered = texel_points(mesh.positions, mesh.normals, uvs, mesh.indices.reshape(-1, 3), size)
    if not covered.any():
        raise AssetError(f"bake_lightmap: entity {entity}'s mesh {mesh.name!r} covers no texel of a {size} x "
                         f"{size} lightmap (its UVs lie outside 0..1, or its triangles have no area in them)")
    matrix = np.array(transform.world.to_list(), np.float64).T   # (glm's lists are its columns)
    normal_matrix = np.linalg.inv(matrix[:3, :3]).T
    world_points = points @ matrix[:3, :3].T + matrix[:3, 3]
    world_ways = ways @ normal_matrix.T
    world_ways /= np.maximum(np.linalg.norm(world_ways, axis=-1, keepdims=True), 1e-12)
    return world_points, world_ways, covered


def bake_lightmap(engine: Engine, entity: int, size: int = 32, resolution: int = 16, near: float = 0.01,
                  far: float = 100.0) -> tuple[TextureData, float]:
    """The lightmap of ``entity`` (a MeshRef with a Transform) as its world stands after its
    last frame: an sRGB image of ``size`` x ``size`` texels (4 to 512) and the intensity it is
    read at (``Material(lightmap=image, lightmap_intensity=intensity)``); each texel's light
    captured at ``resolution`` texels a face (4 to 128) between ``near`` and ``far``."""
    _check_settings(size, resolution, near, far)
    world_points, world_ways, covered = _surface(engine.world, entity, size)
    renderer = engine.renderer
    light = np.zeros((size, size, 3))
    probes, ctx = renderer.probes, renderer.ctx
    try:
        for row, column in zip(*np.nonzero(covered), strict=True):
            at = glm.vec3(*(world_points[row, column] + world_ways[row, column] * max(LIFT, 2.0 * near)))
            views = {face: face_view(face, at, near, far, resolution, skip=entity) for face in range(6)}
            probes.capture(BAKE_KEY, views, None, 0)
            texture = probes.cubes[BAKE_KEY].texture
            faces = np.stack([read_cube_level(ctx, texture, face, 0, SCRATCH_UNIT)[..., :3] for face in range(6)])
            irradiance = evaluate_sh(project_faces(faces.astype(np.float64)), world_ways[row, column])
            light[row, column] = np.maximum(irradiance, 0.0) / math.pi
    finally:
        probes.drop(BAKE_KEY)
    light = dilate(light, covered)
    intensity = float(light.max())
    if intensity <= 0.0:
        return TextureData(np.full((size, size, 4), (0, 0, 0, 255), np.uint8), name=f"lightmap {entity}"), 1.0
    encoded = linear_to_srgb(light / intensity)
    pixels = np.concatenate([np.clip(np.round(encoded * 255.0), 0, 255), np.full((size, size, 1), 255.0)], -1)
    return TextureData(pixels.astype(np.uint8), name=f"lightmap {entity}"), intensity


def bake_lightmaps(engine: Engine, entities: Sequence[int], bounces: int = 1, size: int = 32, resolution: int = 16,
                   near: float = 0.01, far: float = 100.0) -> dict[int, tuple[TextureData, float]]:
    """Lightmaps for ``entities`` that light each other, ``bounces`` rounds (1 to
    ``MAX_BOUNCES``): their lightmaps taken off first, then each round every one baked
    (``bake_lightmap``: ``size``, ``resolution``, ``near``, ``far``) with the last round's on,
    and put on (``Material.lightmap``, ``lightmap_intensity``; a frame of no time between
    rounds, so the captures see them).  Returns each entity's image and intensity, as they are
    on its material after the last round.  Each round costs what a ``bake_lightmap`` of each
    does."""
    if isinstance(bounces, bool) or not isinstance(bounces, int) or not 1 <= bounces <= MAX_BOUNCES:
        raise AssetError(f"bake_lightmaps: bounces must be a whole number from 1 to {MAX_BOUNCES}, got {bounces!r}")
    entities = list(entities)
    if len(set(entities)) != len(entities):
        raise AssetError(f"bake_lightmaps: an entity is named twice in {entities}")
    world = engine.world
    _check_settings(size, resolution, near, far)
    for entity in entities:   # (every one checked before any lightmap is taken off: nothing half-baked)
        if world.try_get(entity, Material) is None:
            raise AssetError(f"bake_lightmaps: entity {entity} has no Material to put its lightmap on")
        _surface(world, entity, size)
    for entity in entities:   # (the first round sees no bake of theirs)
        world.get(entity, Material).lightmap = None
    engine.frame(0.0, None)
    baked: dict[int, tuple[TextureData, float]] = {}
    for round_ in range(bounces):
        baked = {entity: bake_lightmap(engine, entity, size, resolution, near, far) for entity in entities}
        for entity, (image, intensity) in baked.items():
            material = world.get(entity, Material)
            material.lightmap = image
            material.lightmap_intensity = intensity
        if round_ + 1 < bounces:
            engine.frame(0.0, None)
    return baked
