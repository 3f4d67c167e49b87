"""The particle rule: an emitter whose ``shape`` is "mesh" is born on its entity's mesh, so it
needs a ``MeshRef`` on the same entity.  Checked when the value is given (a spawn, an
``add_component``, a write of ``ParticleEmitter.shape``), as the world's invariants are, so the
mistake is refused at the line that makes it, not frames later in the particles stage."""
from __future__ import annotations

from typing import Any

from components import MeshRef, ParticleEmitter
from components.tracking import ComponentValueError
from engine.core.world import World, world_invariant


@world_invariant(ParticleEmitter, whole=True)
def check_mesh_emitter_has_mesh(world: World, entity: int, joining: Any = None, shape: str | None = None,
                                **_other: Any) -> None:
    """A "mesh" shaped emitter needs a MeshRef on its entity (``shape``: one about to be set)."""
    emitter = joining if isinstance(joining, ParticleEmitter) else (
        world.try_get(entity, ParticleEmitter) if world.exists(entity) else None)
    wanted = shape if shape is not None else getattr(emitter, "shape", None)
    if wanted == "mesh" and world.exists(entity) and world.try_get(entity, MeshRef) is None:
        raise ComponentValueError(f"ParticleEmitter on entity {entity}: shape \"mesh\" is born on the entity's mesh; "
                                  "give the entity a MeshRef too")


@world_invariant(ParticleEmitter)
def check_mesh_shape_written(world: World, entity: int, joining: Any = None, shape: str | None = None,
                             **_other: Any) -> None:
    """``ParticleEmitter.shape`` written "mesh" on an entity with no MeshRef (the spawn's own
    check is the whole one above: the MeshRef may come later in the spawn's list)."""
    if shape == "mesh" and world.exists(entity) and world.try_get(entity, MeshRef) is None:
        raise ComponentValueError(f"ParticleEmitter.shape on entity {entity}: \"mesh\" is born on the entity's mesh, "
                                  "and it has no MeshRef; give it one first")
