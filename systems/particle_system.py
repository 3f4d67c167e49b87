"""Particles: every ``ParticleEmitter``'s particles spawned, moved and aged, then handed to the
GPU, once a frame after the extract stage (every game system that moves things has run).

Each emitter entity has a ``ParticleCloud`` (``engine/core/particle_cloud.py``: arrays, a
fixed handful of numpy calls a step whatever the count), stepped by the frame's time at its
entity's world matrix (identity without a Transform); its drawn rows go to the scene pass's
``ParticleDraw`` (``engine/render/particle_draw.py``), which every view then draws in among its
glass.  A cloud is made when its emitter comes (or its ``seed`` changes: the same seed makes
the same cloud; ``prewarm`` steps it a lifetime first) and dropped with its GPU buffer when the
emitter or its entity goes.  A frame: every cloud stepped (a world-space one through the open
portals, ``engine/rules/portal_gates.py``; a burst for each of its ``burst_on`` events this
frame's models stage fired), then each sub-emitter's bursts where another's particles died
(``on_death``), then the rows.  The living particles and those the emitters'
``max_particles`` kept from being born are counted in ``RenderStats``; an emitter that starts
being capped, a "mesh" emitter that lost its MeshRef and an ``on_death`` that names no
emitter are each said once in a ``ParticleLimitWarning``.
"""
from __future__ import annotations

import warnings

import esper
import numpy as np
from pyglm import glm

from components import MeshRef, Transform, Visibility
from components.particles import MAX_PREWARM_SECONDS, ParticleEmitter
from engine.core.errors import ParticleLimitWarning
from engine.core.particle_cloud import Gate, ParticleCloud
from engine.core.transforms import MAX_PARENT_HOPS
from engine.core.world import World
from engine.render.renderer import Renderer
from engine.resources import FiredEvents, RenderStats
from engine.rules.frame_rules import frame_rules
from engine.rules.portal_gates import PortalGate, portal_gates
from engine.rules.visibility_rules import entity_code

_IDENTITY = glm.mat4(1.0)
PREWARM_RATE = 30.0  # steps a second a prewarm runs (ParticleEmitter.prewarm)


class ParticleSystem(esper.Processor):
    """Steps every emitter's cloud and hands its rows to the renderer."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        super().__init__()
        self.world = world
        self.renderer = renderer
        self.clouds: dict[int, tuple[ParticleCloud, int]] = {}   # by entity: its cloud and the seed it grew from
        self._capped: set[int] = set()  # emitters capped last frame (warned once a run of capped frames)
        self._meshless: set[int] = set()  # "mesh" emitters whose MeshRef went (warned once)
        self._targetless: set[tuple[int, int]] = set()  # (emitter, on_death) pairs said to name no emitter
        # The open portals' gates of the last frame, by portal (portal_gates: a portal that slid
        # since swallows the particles it passed over); empty after a frame that made none.
        self._gates_last: dict[int, PortalGate] = {}

    def process(self, dt: float) -> None:
        world = self.world
        draw = self.renderer.scene_pass.particle_draw
        stats: RenderStats = world.resources[RenderStats]
        emitters = world.query_one(ParticleEmitter)
        gates = None  # the open portals, made once a frame when a world-space emitter has particles
        seen = set()
        living = capped = 0
        stepped = []  # (entity, emitter, cloud, matrix): stepped this frame
        gates_last, self._gates_last = self._gates_last, {}
        for entity, emitter in emitters:
            seen.add(entity)
            kept = self.clouds.get(entity)
            fresh = kept is None or kept[1] != emitter.seed
            if fresh:
                kept = self.clouds[entity] = (ParticleCloud(emitter.seed, emitter.max_particles), emitter.seed)
            cloud = kept[0]
            transform = world.try_get(entity, Transform)
            matrix = transform.world if transform is not None else _IDENTITY
            if fresh and emitter.prewarm and emitter.playing:  # as after a lifetime of playing, at 30 Hz
                mesh_ref = world.try_get(entity, MeshRef) if emitter.shape == "mesh" else None
                seconds = min(emitter.lifetime[1], MAX_PREWARM_SECONDS)
                mesh = mesh_ref.mesh if mesh_ref is not None else None
                for _ in range(round(seconds * PREWARM_RATE)):
                    cloud.step(emitter, matrix, 1.0 / PREWARM_RATE, mesh=mesh)
            if gates is None and cloud.count and emitter.space == "world":
                made = portal_gates(world, frame_rules(world).open_portals, gates_last)
                self._gates_last = {gate.entity: gate for gate in made}
                gates = _numpy_gates(made)
            mesh_ref = world.try_get(entity, MeshRef) if emitter.shape == "mesh" else None
            if emitter.shape == "mesh" and mesh_ref is None and entity not in self._meshless:
                self._meshless.add(entity)
                warnings.warn(f"entity {entity}: its ParticleEmitter's shape is \"mesh\" and its MeshRef is gone: "
                              "none are born until it has one again", ParticleLimitWarning, stacklevel=2)
            elif mesh_ref is not None:
                self._meshless.discard(entity)
            cloud.step(emitter, matrix, dt, self._bursts(entity, emitter.burst_on) if emitter.burst_on else 0,
                       gates if emitter.space == "world" and gates else (),
                       mesh_ref.mesh if mesh_ref is not None else None)
            stepped.append((entity, emitter, cloud, matrix))
        by_entity = {entity: (emitter, cloud, matrix) for entity, emitter, cloud, matrix in stepped}
        for entity, emitter, cloud, _ in stepped:  # sub-emitters' bursts where particles died
            if emitter.on_death is not None and len(cloud.died):
                target = by_entity.get(emitter.on_death)
                if target is None:
                    self._warn_no_target(entity, emitter.on_death)
                else:
                    target[1].burst_at(target[0], cloud.died, target[2])
        for entity, emitter, cloud, matrix in stepped:
            living += cloud.count
            capped += cloud.capped
            self._warn_capped(entity, emitter, cloud.capped)
            if cloud.count:
                code = entity_code(world.try_get(entity, Visibility))
                draw.update(entity, emitter, cloud.rows(emitter, matrix), code)
            elif entity in draw.emitters:  # (all gone: nothing to draw, nothing to upload each frame)
                draw.drop(entity)
        for entity in [e for e in self.clouds if e not in seen]:
            del self.clouds[entity]
            self._capped.discard(entity)
            draw.drop(entity)
        stats.particles = living
        stats.particles_capped = capped

    def _warn_no_target(self, entity: int, target: int) -> None:
        if (entity, target) not in self._targetless:
            self._targetless.add((entity, target))
            warnings.warn(f"entity {entity}: its ParticleEmitter.on_death names entity {target}, which has no "
                          "ParticleEmitter: nothing is born where its particles die", ParticleLimitWarning,
                          stacklevel=3)

    def _bursts(self, entity: int, event: str) -> int:
        """How many ``event``s fired this frame (``FiredEvents``) on the model ``entity`` hangs
        under: its own root's, or a parent's up its chain."""
        fired = self.world.resources.get(FiredEvents)
        if not fired:
            return 0
        roots = {e.entity for e in fired if e.name == event}
        count, walk, hops = 0, entity, 0
        while walk is not None and hops <= MAX_PARENT_HOPS and roots:
            if walk in roots:
                count += sum(1 for e in fired if e.name == event and e.entity == walk)
                break
            transform = self.world.try_get(walk, Transform) if self.world.exists(walk) else None
            walk, hops = (transform.parent if transform is not None else None), hops + 1
        return count

    def _warn_capped(self, entity: int, emitter: ParticleEmitter, capped: int) -> None:
        if not capped:
            self._capped.discard(entity)
            return
        if entity not in self._capped:
            self._capped.add(entity)
            warnings.warn(f"entity {entity}: its ParticleEmitter spawns more than its max_particles "
                          f"({emitter.max_particles}) can hold living at once ({capped} not born this frame): "
                          "raise max_particles, or lower rate, burst or lifetime", ParticleLimitWarning, stacklevel=2)


def _numpy_gates(gates: list[PortalGate]) -> list[Gate]:
    """The gates as the particle step reads them (``particle_cloud.Gate``: numpy, row by row)."""
    rows = []
    for gate in gates:
        plane, to_local = np.array(gate.plane, np.float64), np.array(gate.to_local, np.float64)
        rows.append((plane, to_local, gate.half, np.array(gate.carry, np.float64),
                     plane if gate.was_plane is None else np.array(gate.was_plane, np.float64),
                     to_local if gate.was_to_local is None else np.array(gate.was_to_local, np.float64)))
    return rows
