"""World matrices, recomputed only for transforms that changed (or whose parent did)."""
from __future__ import annotations

import esper
from pyglm import glm

from components import Transform
from engine.core.world import FrameEvents, TransformTree, World

_NEW = object()  # not yet seen by the system (its parent_of has no entry)


class TransformSystem(esper.Processor):
    """Updates ``Transform.world`` for changed entities and their descendants.

    Publishes ``world.frame`` (moved / added / removed entity sets) for later systems: the
    renderer re-uploads only moved instances and probes re-render only when something near
    them moved; and its index of each parent's children (``TransformTree``: a traveller's
    parts, for portal slicing).  Code that runs before this stage works the same matrix out from the
    components with ``engine.core.transforms.current_world_matrix`` (a parent that does not
    exist or has no Transform is no parent, here and there).
    """

    def __init__(self, world: World) -> None:
        self.world = world
        self._parent_of: dict[int, int | None] = {}
        self._children: dict[int, set[int]] = {}
        world.resources[TransformTree] = TransformTree(self._children)  # (the same dict: kept as it changes)

    def process(self, dt: float) -> None:
        world = self.world
        # Vectors and quaternions edited in place since they were read (``t.position.y +=
        # 1``) are reported as writes first, so this stage and every later one see them.
        world.settle_in_place_edits()
        events = FrameEvents()
        changed = world.changed(Transform)
        if not changed:
            world.frame = events
            return
        parent_of, children = self._parent_of, self._children
        moved, added = events.moved, events.added
        component, deleted = _lookups(world)
        worlds = events.worlds
        dirty: set[int] = set()  # entities in a hierarchy: their subtrees are worked out below
        written = world.written(Transform)  # the movers' components, as their writes left them
        for entity in changed:
            transform = written.get(entity)
            if transform is None or transform._sink is not changed or transform._entity != entity:
                try:  # not a hot-path write, or the component has left the entity since
                    transform = None if deleted and entity in deleted else component(entity, Transform)
                except KeyError:  # gone from the world (deleted, and cleared, since it changed)
                    transform = None
            if transform is None:
                if entity in parent_of:
                    events.removed.add(entity)
                    self._unlink(entity)
                    dirty.update(children.pop(entity, ()))  # orphans become roots
                continue
            parent = parent_of.get(entity, _NEW)
            (added if parent is _NEW else moved).add(entity)
            if (parent is not None and parent is not _NEW) or transform.parent is not None \
                    or (children and children.get(entity)):
                self._link(entity, transform.parent)
                dirty.add(entity)
                continue
            # The common case, a root without children: its world matrix is its local one,
            # written here without the subtree walk.
            parent_of[entity] = None
            worlds[entity] = transform.__dict__["_world"] = transform.local_matrix()
        if dirty:
            self._expand(dirty)
            for entity in dirty:
                parent = parent_of.get(entity)
                if parent is None or parent not in dirty:
                    self._update_subtree(entity, worlds)
            moved |= dirty - added
        world.frame = events

    def _link(self, entity: int, parent: int | None) -> None:
        old = self._parent_of.get(entity)
        if old is not None and old != parent:
            self._children.get(old, set()).discard(entity)
        if parent is not None:
            ancestor = parent
            while ancestor is not None:
                if ancestor == entity:
                    raise ValueError(f"Transform.parent of entity {entity} makes a cycle through {parent}")
                ancestor = self._parent_of.get(ancestor)
            self._children.setdefault(parent, set()).add(entity)
        self._parent_of[entity] = parent

    def _unlink(self, entity: int) -> None:
        parent = self._parent_of.pop(entity, None)
        if parent is not None:
            self._children.get(parent, set()).discard(entity)

    def _expand(self, dirty: set[int]) -> None:
        stack = list(dirty)
        while stack:
            for child in self._children.get(stack.pop(), ()):
                if child not in dirty:
                    dirty.add(child)
                    stack.append(child)

    def _update_subtree(self, root: int, worlds: dict[int, glm.mat4]) -> None:
        world = self.world
        stack = [root]
        while stack:
            entity = stack.pop()
            transform = world.try_get(entity, Transform)
            if transform is None:
                continue
            parent = self._parent_of.get(entity)
            parent_t = world.try_get(parent, Transform) if parent is not None else None
            local = transform.local_matrix()
            matrix = worlds[entity] = parent_t.world * local if parent_t is not None else local
            object.__setattr__(transform, "_world", matrix)
            stack.extend(self._children.get(entity, ()))



def _lookups(world: World):
    """(component(entity, kind), the entities deleted this frame): esper's own call when the
    world is esper's current one (as in a step: a dict lookup, not the world's checks per
    call), else the world's; either raises KeyError for an entity that is gone."""
    return esper.try_component if esper.current_world == world.name else world.try_get, world.deleted()
