"""One game's ECS world: an esper world of its own plus the change sets systems read.

esper 3 keeps worlds as module-level state selected by name; every method here switches to
this world first, so two games (or two tests) never see each other's entities.  All
structural changes go through this wrapper so it can record them: systems then work on
what changed this frame instead of scanning every entity.
"""
from __future__ import annotations

import itertools
import sys
import warnings
from collections import defaultdict
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

import esper

from components.tracking import ComponentValueError, ComponentWarning, TrackedComponent

C = TypeVar("C")
# Invariants over an entity's components together, by the component kinds that trigger them:
# ``check(world, entity, joining, **pending)`` raises ComponentValueError.  Rules modules
# register them (``world_invariant``; the mirror-mesh rule: engine/rules/mirror_rules.py), so
# the world runs them when a component of those kinds joins an entity, and components ask
# for them when a field changes (``World.check_invariants``), without either knowing the rule.
Invariant = Callable[..., None]
_INVARIANTS: dict[type, list[Invariant]] = defaultdict(list)
# Invariants that need the entity's components together (a Water needs a Mirror): at spawn
# they run once every component is attached (the order components are listed in is free);
# ``add_component`` on an existing entity runs them with the joining component.
_WHOLE_INVARIANTS: dict[type, list[Invariant]] = defaultdict(list)


def check_components(components: Iterable[Any], entity: int = 0) -> None:
    """Run the registered invariants over ``components`` that are to make one entity, before
    any world holds them (a level file checks each entity when it loads, so a refusal names
    the file and line; the editor an entity's components as an edit would leave them): the
    checks see them as one entity's components, and a refusal names ``entity`` (0: one not
    made yet).  What a rule only says (a ComponentWarning) is said when a world takes them,
    not here as well."""
    held = {type(component): component for component in components}
    detached = _Detached(held, entity)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ComponentWarning)
        for kind, component in held.items():   # (each as the one joining, as a spawn adds them)
            for check in (*_INVARIANTS.get(kind, ()), *_WHOLE_INVARIANTS.get(kind, ())):
                check(detached, entity, component)


class _Detached:
    """One entity's components as an invariant reads a world (``try_get``, ``exists``,
    ``query_one``: a world that holds that entity alone)."""

    def __init__(self, held: dict[type, Any], entity: int) -> None:
        self._held, self._entity = held, entity

    def exists(self, entity: int) -> bool:
        return True

    def try_get(self, entity: int, kind: type[C]) -> C | None:
        return self._held.get(kind)

    def query_one(self, kind: type[C]) -> list[tuple[int, C]]:
        return [(self._entity, self._held[kind])] if kind in self._held else []


def world_invariant(*kinds: type, whole: bool = False) -> Callable[[Invariant], Invariant]:
    """Register the decorated check for every world, run when one of ``kinds`` joins an
    entity or asks (see ``_INVARIANTS``); ``whole``: a check that needs the entity's other
    components (``_WHOLE_INVARIANTS``), run at the end of a spawn and on a later join."""
    table = _WHOLE_INVARIANTS if whole else _INVARIANTS

    def register(check: Invariant) -> Invariant:
        for kind in kinds:
            if check not in table[kind]:
                table[kind].append(check)
        return check
    return register

_world_ids = itertools.count(1)
_HELD_BY_WATCH_ONLY = 4  # sys.getrefcount of a watched value nobody else holds, in settle_in_place_edits


@dataclass
class FrameEvents:
    """What the TransformSystem saw this frame, for later systems (probes, renderer)."""

    moved: set[int] = field(default_factory=set)
    added: set[int] = field(default_factory=set)
    removed: set[int] = field(default_factory=set)
    # The world matrix the TransformSystem wrote this frame, by entity (``Transform.world``,
    # handed on so the extract stage does not look a thousand movers' components up again);
    # an entity missing here is read from its Transform.
    worlds: dict[int, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TransformTree:
    """Each parent's children as the TransformSystem last linked them (its own index, kept by
    it: read it, never write it), published as a world resource.  A stage that runs before
    the transform stage (portal slicing) adds the links made this frame (``more``)."""

    children: Mapping[int, set[int]]

    def descendants(self, entity: int, more: Mapping[int, set[int]] | None = None) -> list[int]:
        """Every entity below ``entity``, nearest first (none for an entity with no children);
        ``more``: links the index does not hold yet (this frame's, before the transform stage)."""
        children = self.children
        found = list(children.get(entity, ()))
        if more:
            found += [child for child in more.get(entity, ()) if child not in found]
        for below in found:  # (grows as it goes: a breadth-first walk)
            found.extend(children.get(below, ()))
            if more:
                found += [child for child in more.get(below, ()) if child not in found]
        return found


class World:
    """A named esper world with change tracking and a resource table.

    ``resources`` holds per-world singletons that are not components (the renderer, the
    input state, the frame's pass statistics), keyed by type.
    """

    def __init__(self, name: str | None = None) -> None:
        self.name = f"{name or 'world'}#{next(_world_ids)}"
        self.resources: dict[type, Any] = {}
        self.frame = FrameEvents()
        self.frame_index = 0
        self._changed: dict[type, set[int]] = defaultdict(set)
        self._deleted: set[int] = set()
        self._made = 0  # the highest entity id spawned (ids only grow)
        self._systems: list[esper.Processor] = []
        # The in-place watch (components.tracking's docstring): (id, field) -> (component,
        # field, the value read, a copy of it), filled by reads, settled by the transform stage.
        self._handed: dict[tuple[int, str], tuple[TrackedComponent, str, Any, Any]] = {}
        # Components a hot write path reported this step, by kind and entity (``written``).
        self._written: dict[type, dict[int, Any]] = defaultdict(dict)
        self._closed = False
        # ``change_count()`` when the last step ended, before its change sets were forgotten.
        self.last_step_changes = 0
        self._use()

    # --- context -------------------------------------------------------------------------
    def _use(self) -> None:
        if self._closed:
            raise RuntimeError(f"world {self.name} was closed")
        if esper.current_world != self.name:
            esper.switch_world(self.name)

    def close(self) -> None:
        """Delete every entity (systems release their GPU resources) and drop the world."""
        if self._closed:
            return
        self._use()
        for entity in list(esper.get_entities()):
            self.delete_entity(entity)
        esper.clear_dead_entities()
        for system in reversed(self._systems):
            close = getattr(system, "close", None)
            if close is not None:
                close()
        esper.switch_world("default")
        esper.delete_world(self.name)
        self._closed = True

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- entities and components ----------------------------------------------------------
    def spawn(self, *components: Any) -> int:
        """Create an entity with these components and return its id.

        All or nothing: if any component is refused, the entity and the components already
        attached are taken out again, so no half-built entity stays in the world.
        """
        self._use()
        entity = esper.create_entity()
        self._made = max(self._made, entity)
        try:
            for component in components:
                self._add(entity, component, whole=False)
            # Each whole-entity check once (one registered for several kinds the entity holds too).
            for check in dict.fromkeys(check for component in components
                                       for check in _WHOLE_INVARIANTS.get(type(component), ())):
                check(self, entity, None)
            self._check_whole(entity, components)
        except BaseException:
            for component in esper.components_for_entity(entity):
                self._detach(component, entity)
                self._changed[type(component)].discard(entity)
            esper.delete_entity(entity, immediate=True)
            raise
        return entity

    def add_component(self, entity: int, component: Any) -> None:
        """Attach ``component`` (replacing one of its type); see components.tracking on sharing."""
        self._add(entity, component, whole=True)

    def _add(self, entity: int, component: Any, whole: bool) -> None:
        self._use()
        kind = type(component)
        if isinstance(component, TrackedComponent):
            self._check_sharing(entity, component)
        check = getattr(component, "check_attach", None)
        if check is not None:
            check(entity)
        parent = getattr(component, "parent", None) if kind.__name__ == "Transform" else None
        if parent is not None:
            if parent == entity:
                raise ComponentValueError(f"Transform.parent of entity {entity} is the entity itself, got {parent!r}")
            if not self.exists(parent):
                raise ComponentValueError(f"Transform.parent of entity {entity} names no entity in this world, "
                                          f"got {parent!r}")
            walk, seen = parent, set()
            while walk is not None and walk not in seen:
                seen.add(walk)
                above = esper.try_component(walk, kind) if esper.entity_exists(walk) else None
                walk = above.parent if above is not None else None
                if walk == entity:
                    raise ComponentValueError(f"Transform.parent {parent!r} of entity {entity} would make a "
                                              f"cycle (entity {parent} descends from entity {entity})")
        for check in (*_INVARIANTS.get(kind, ()), *(_WHOLE_INVARIANTS.get(kind, ()) if whole else ())):
            check(self, entity, component)
        if esper.has_component(entity, kind):
            old = esper.component_for_entity(entity, kind)
            if old is not component:
                self._detach(old, entity)
        esper.add_component(entity, component)
        if isinstance(component, TrackedComponent):
            object.__setattr__(component, "_entity", entity)
            object.__setattr__(component, "_entities", component._entities | {entity})
            object.__setattr__(component, "_sink", self._changed[kind])
            object.__setattr__(component, "_world_ref", self)
            object.__setattr__(component, "_handed", self._handed)
            object.__setattr__(component, "_written", self._written[kind])
        self._changed[kind].add(entity)

    def _check_whole(self, entity: int, components: tuple[Any, ...]) -> None:
        """Checks that need the entity's components together, so they fail at spawn, not frame 1."""
        names = {type(c).__name__: c for c in components}
        mesh_ref = names.get("MeshRef")
        if mesh_ref is not None and "Material" in names and "Transform" not in names \
                and esper.has_component(entity, type(mesh_ref)) is not False:
            if not any(type(c).__name__ == "Transform" for c in esper.components_for_entity(entity)):
                warnings.warn(f"entity {entity} has MeshRef and Material but no Transform: it is not drawn "
                              f"until one is added", stacklevel=3)

    def settle_in_place_edits(self) -> int:
        """Report the glm vectors and quaternions edited in place since they were read (the
        in-place watch, ``components.tracking``'s docstring): each value read from a
        component in this world since the last settle is compared with the copy taken when
        it was read; one that differs is checked by the component's own rules (a NaN put in
        ``t.position.x`` is refused here, naming the field) and reported as a write of its
        field.  A value the component no longer holds (the field was assigned since: that
        write was reported) is dropped, and so is one of a component this world no longer holds
        (replaced, or its entity deleted: a bad edit refused at one frame is not refused again
        at every frame after the game replaced what held it); one still held elsewhere (a game keeps ``p =
        t.position``) stays watched with a fresh copy.  Returns how many edits were found.
        Called by the transform stage, before it reads the change sets."""
        handed = self._handed
        if not handed:
            return 0
        found = 0
        kept = {}
        for key, (component, name, value, copy) in handed.items():
            if component.__dict__.get(name) is not value:
                continue  # assigned since: reported by that write; the old value is not the field's
            if component.__dict__.get("_world_ref") is not self:
                continue  # replaced or its entity deleted since: no longer this world's to check or report
            if value != copy:
                found += 1
                try:
                    component._validate(name, type(value)(value))
                except ComponentValueError as exc:
                    raise ComponentValueError(f"{exc} (an in-place edit of {type(component).__name__}.{name}, "
                                              f"e.g. {name}.x = ..., seen at frame {self.frame_index + 1})") from None
                component.touch()
                copy = type(value)(value)
            # Held by the component's dict, this entry, the loop's two names and the call's
            # argument: more means someone else keeps it and may edit it again unread.
            if sys.getrefcount(value) > _HELD_BY_WATCH_ONLY:
                kept[key] = (component, name, value, copy)
        handed.clear()
        handed.update(kept)
        return found

    def check_invariants(self, entity: int, kind: type, **pending: Any) -> None:
        """Run the invariants registered for ``kind`` on ``entity`` as if the fields in
        ``pending`` already held their new values (a component's field setter asks before it
        takes a value, so the refusal comes then, not frames later in a system)."""
        for check in _INVARIANTS.get(kind, ()):
            check(self, entity, None, **pending)

    def _check_sharing(self, entity: int, component: TrackedComponent) -> None:
        """Refuse a component of another world, or a per-entity one already held elsewhere."""
        holders = component._entities - {entity}
        if component._sink is None or not holders:
            return
        name = type(component).__name__
        if component._sink is not self._changed[type(component)]:
            raise ComponentValueError(f"{name} given to entity {entity} already belongs to entity "
                                      f"{min(holders)} of another world; give each its own {name}")
        if not component.SHAREABLE:
            raise ComponentValueError(
                f"{name} given to entity {entity} already belongs to entity {min(holders)}; a {name} "
                f"is one entity's own state, give each entity its own (dataclasses.replace copies one)")

    def remove_component(self, entity: int, kind: type[C]) -> C | None:
        self._use()
        if not esper.has_component(entity, kind):
            return None
        component = esper.remove_component(entity, kind)
        self._detach(component, entity)
        self._changed[kind].add(entity)
        return component

    def delete_entity(self, entity: int) -> None:
        """Delete at the start of the next step; systems see it in ``deleted()`` then."""
        self._use()
        if not esper.entity_exists(entity) or entity in self._deleted:
            return
        for component in esper.components_for_entity(entity):
            self._detach(component, entity)
            self._changed[type(component)].add(entity)
        self._deleted.add(entity)
        esper.delete_entity(entity)

    @staticmethod
    def _detach(component: Any, entity: int) -> None:
        """``entity`` lets go of ``component``; others sharing it keep reporting their writes."""
        if isinstance(component, TrackedComponent):
            rest = component._entities - {entity}
            object.__setattr__(component, "_entities", rest)
            if rest:
                if component._entity == entity:
                    object.__setattr__(component, "_entity", min(rest))
            else:
                object.__setattr__(component, "_sink", None)
                object.__setattr__(component, "_world_ref", None)

    def ever_made(self, entity: int) -> bool:
        """Whether ``entity`` is an id this world has made (it may be deleted since): an id
        past them names nothing, now or before (a typo, another world's id)."""
        return 0 < entity <= self._made

    def exists(self, entity: int) -> bool:
        self._use()
        return esper.entity_exists(entity) and entity not in self._deleted

    def has(self, entity: int, kind: type) -> bool:
        self._use()
        return esper.has_component(entity, kind)

    def get(self, entity: int, kind: type[C]) -> C:
        self._use()
        return esper.component_for_entity(entity, kind)

    def try_get(self, entity: int, kind: type[C]) -> C | None:
        self._use()
        return esper.try_component(entity, kind)

    def query(self, *kinds: type) -> list[tuple[int, tuple[Any, ...]]]:
        """Entities with all of ``kinds`` (not those deleted and awaiting the next step)."""
        self._use()
        found = esper.get_components(*kinds)
        return [item for item in found if item[0] not in self._deleted] if self._deleted else found

    def query_one(self, kind: type[C]) -> list[tuple[int, C]]:
        self._use()
        found = esper.get_component(kind)
        return [item for item in found if item[0] not in self._deleted] if self._deleted else found

    def components_of(self, entity: int) -> tuple[Any, ...]:
        self._use()
        return esper.components_for_entity(entity)

    def entities(self) -> list[int]:
        self._use()
        return [e for e in esper.get_entities() if e not in self._deleted]

    # --- change sets -----------------------------------------------------------------------
    def changed(self, kind: type) -> set[int]:
        """Entities whose ``kind`` component was added, removed or written since last step."""
        if self._closed:  # _check_open, inlined: dozens of calls a frame
            self._check_open()
        found = self._changed.get(kind)
        return set() if found is None else found

    def changed_any(self, kinds: Iterable[type]) -> set[int]:
        """Entities with a component of any of ``kinds`` added, removed or written since the
        last step: the union of ``changed`` over them, a new set (one call, not one a kind)."""
        if self._closed:
            self._check_open()
        sets = self._changed
        found: set[int] = set()
        for kind in kinds:
            entities = sets.get(kind)
            if entities:
                found |= entities
        return found

    def change_count(self) -> int:
        """How many changes this step recorded so far: entries of the change sets (an entity
        whose component of a kind was added, removed or written) and deletions.  Only grows
        within a step, so two counts that agree say nothing changed between them (the reflect
        stage's still frames: ``last_step_changes`` is the count a step ended with)."""
        if self._closed:
            self._check_open()
        return sum(map(len, self._changed.values())) + len(self._deleted)

    def written(self, kind: type) -> dict[int, Any]:
        """Components of ``kind`` whose writes came through a hot path this step (Transform's
        glm position and rotation writes), by entity: the object each write was made on, so
        that the transform stage finds a thousand movers' components without a look-up each
        in esper's table of every entity (which a frame of 100,000 leaves out of the caches).
        A hint, not a change set: an entry whose component has since left its entity or this
        world (``_sink`` not this world's set for ``kind``, ``_entity`` another) is stale;
        ``changed`` stays the record of what changed."""
        if self._closed:
            self._check_open()
        found = self._written.get(kind)
        return {} if found is None else found

    def deleted(self) -> set[int]:
        """Entities deleted since the last step (their components are gone now)."""
        self._check_open()
        return self._deleted

    def _check_open(self) -> None:
        # A closed world's sets are stale: answering them would hide a use after close.
        if self._closed:
            raise RuntimeError(f"world {self.name} was closed")

    # --- systems ---------------------------------------------------------------------------
    def add_system(self, system: esper.Processor, priority: int) -> None:
        """Systems run from high to low priority; see ARCHITECTURE.md for the order."""
        self._use()
        esper.add_processor(system, priority=priority)
        self._systems.append(system)

    def get_system(self, kind: type[C]) -> C | None:
        self._use()
        return esper.get_processor(kind)

    def step(self, dt: float) -> None:
        """Run every system once, then forget this frame's changes."""
        self._use()
        esper.process(dt)
        esper.clear_dead_entities()  # what systems deleted this frame is gone before the next
        self.frame_index += 1
        self.last_step_changes = self.change_count()
        for entities in self._changed.values():
            entities.clear()
        for components in self._written.values():
            components.clear()
        self._deleted = set()
