"""The render system: extract what changed from the ECS, prepare GPU data, render views.

Phases of a frame (see ARCHITECTURE.md):
  extract  - instance records of entities whose mesh, material or transform changed
  prepare  - upload changed instance rows, lights, the sky when the Skybox changed
  render   - the main camera's view into level-0 targets (reflections and present follow
             in their own systems)
Nothing here writes game state.
"""
from __future__ import annotations

from dataclasses import dataclass

import esper
import moderngl
import numpy as np
from pyglm import glm

from components import (
    Camera,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Portal,
    PortalClone,
    Reflective,
    Refractive,
    Skybox,
    Slice,
    Transform,
)
from engine.render.instances import InstanceBatch
from engine.render.renderer import Renderer, RenderStats
from engine.render.sky import build_faces
from engine.render.views import View, camera_view, lights_block
from engine.world import World
from systems.material_dispatch import choose_material

MATERIAL_KINDS = (MeshRef, Material, Emissive, Reflective, Refractive, Mirror, Portal, Slice, PortalClone)
NO_SLICE = (0.0, 0.0, 0.0, 1.0)
AMBIENT = (0.03, 0.03, 0.035)


@dataclass
class Output:
    """Where the frame goes: a window's framebuffer or a capture target, and its size."""

    framebuffer: moderngl.Framebuffer
    size: tuple[int, int]


class RenderSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.output: Output | None = None
        self.main_view: View | None = None
        self._batch_of: dict[int, InstanceBatch] = {}
        self._lights = b""
        world.resources[Renderer] = renderer

    # --- extract ---------------------------------------------------------------------------
    def _extract(self) -> None:
        world = self.world
        touched: set[int] = set()
        for kind in MATERIAL_KINDS:
            touched |= world.changed(kind)
        for entity in touched:
            self._refresh_instance(entity)
        # Every moved entity, touched or not: a refresh writes the transform only when the
        # entity joins a batch (a Slice removed in the frame it moved left it stale).
        for entity in world.frame.moved | world.frame.added:
            batch = self._batch_of.get(entity)
            if batch is not None:
                _write_transform(batch.row(entity), world.get(entity, Transform))

    def _refresh_instance(self, entity: int) -> None:
        world = self.world
        mesh_ref = world.try_get(entity, MeshRef) if world.exists(entity) else None
        transform = world.try_get(entity, Transform) if mesh_ref is not None else None
        old = self._batch_of.get(entity)
        if mesh_ref is None or transform is None or not mesh_ref.visible:
            if old is not None:
                self._remove_instance(entity, old)
            return
        material = world.try_get(entity, Material)
        batch = self.renderer.batch_for(mesh_ref.mesh, material.texture if material else None)
        if old is not batch:
            if old is not None:
                self._remove_instance(entity, old)
            row = batch.add(entity)
            self._batch_of[entity] = batch
            _write_transform(row, transform)
        else:
            row = batch.row(entity)
        choice = choose_material(material, world.try_get(entity, Emissive), world.try_get(entity, Reflective),
                                 world.try_get(entity, Refractive), world.try_get(entity, Mirror),
                                 world.try_get(entity, Portal))
        row["color"] = choice.color
        row["surface"] = choice.surface
        row["reflect"] = choice.reflect_params
        row["tint"] = choice.tint
        slice_ = world.try_get(entity, Slice)
        row["slice"] = slice_.plane if slice_ is not None else NO_SLICE
        clone = world.try_get(entity, PortalClone)
        row["slots"] = (choice.emissive, choice.refract, choice.reflect, clone.source if clone else entity)
        batch.variants_changed()

    def _remove_instance(self, entity: int, batch: InstanceBatch) -> None:
        batch.remove(entity)
        del self._batch_of[entity]
        self.renderer.drop_batch_if_empty(batch)

    # --- prepare ---------------------------------------------------------------------------
    def _prepare(self) -> None:
        world = self.world
        renderer = self.renderer
        if world.changed(Skybox):
            skies = world.query_one(Skybox)
            renderer.set_sky_faces(build_faces(skies[0][1]) if skies else None)
        renderer.upload_instances()
        directional = [(light.direction, light.color.xyz * light.intensity)
                       for _, light in world.query_one(DirectionalLight)]
        point = [(t.world[3].xyz, light.range, light.color.xyz * light.intensity)
                 for _, (light, t) in world.query(PointLight, Transform)]
        block = lights_block(AMBIENT, directional, point)
        if block != self._lights:
            renderer.set_lights(block)
            self._lights = block

    def active_camera(self) -> tuple[int, Camera, Transform] | None:
        cameras = [(e, c, t) for e, (c, t) in self.world.query(Camera, Transform) if c.active]
        return min(cameras, key=lambda item: item[0]) if cameras else None

    # --- render ----------------------------------------------------------------------------
    def process(self, dt: float) -> None:
        renderer = self.renderer
        renderer.stats = RenderStats()
        self.world.resources[RenderStats] = renderer.stats
        self._extract()
        self._prepare()
        output = self.output
        camera = self.active_camera()
        if output is None or camera is None or output.size[0] <= 0 or output.size[1] <= 0:
            self.main_view = None  # minimised window or nothing to look through
            return
        _, cam, cam_t = camera
        targets = renderer.levels.get(0, output.size)
        self.main_view = camera_view(cam_t.world, cam.fov_y, cam.near, cam.far, output.size)
        renderer.scene_pass.draw([self.main_view], targets)

    def close(self) -> None:
        for entity, batch in list(self._batch_of.items()):
            self._remove_instance(entity, batch)


def _write_transform(row: np.void, transform: Transform) -> None:
    model = transform.world
    row["model"] = np.frombuffer(model.to_bytes(), np.float32)
    row["normal_matrix"] = np.frombuffer(glm.transpose(glm.inverse(glm.mat3(model))).to_bytes(), np.float32)
