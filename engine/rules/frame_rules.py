"""Rules several systems must agree on, worked out once a frame: which portal pairs are
open, which camera is active, where a mesh's bounds are in the world.

These used to be decided separately by travel, slicing, the surfaces and export, and the
copies disagreed (a portal whose partner was disabled drew a view through it while travel
refused it; a partner without a Transform crashed slicing).  Now there is one definition
of each, as pure functions over a World (no GL), and the ``rules`` stage
(``systems/frame_rules_system.py``) publishes their answers as ``world.resources[FrameRules]``
right after the game's update.  A system reads them with ``frame_rules(world)``, which
gives this frame's published rules, or works them out by the same functions when they are
absent or stale (a system run alone in a test, or export between frames).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
from pyglm import glm

from components import Camera, Portal, Transform
from engine.core.transforms import current_world_matrix
from engine.core.world import World

if TYPE_CHECKING:
    from engine.assets.mesh import Mesh


def open_portal_pairs(world: World) -> dict[int, int]:
    """Every open portal, mapped to the partner it looks out of.

    A portal is open when it is enabled and has a Transform, and its partner is set, is not
    the portal itself, exists (not deleted), has a Portal and a Transform, and is enabled,
    and neither is mirrored by its parents (``mirrored_by_parents``).
    Anything else is closed: the portal shows its ``closed_color``, nothing travels through
    it and nothing is sliced at it.

    The partner need not name the portal back: A -> B with B -> C (or B with no partner)
    is a one-way window, A opening onto B's front, as travel has always allowed.  Requiring
    both directions would close such a portal without gaining anything, since every use
    (view, travel, slice) only needs the entry portal and the one it looks out of.
    """
    pairs: dict[int, int] = {}
    for entity, (portal, transform) in world.query(Portal, Transform):
        partner = portal.partner
        if not portal.enabled or partner is None or partner == entity or not world.exists(partner):
            continue
        out = world.try_get(partner, Portal)
        out_transform = world.try_get(partner, Transform)
        if out is None or not out.enabled or out_transform is None:
            continue
        if mirrored_by_parents(world, transform) or mirrored_by_parents(world, out_transform):
            continue
        pairs[entity] = partner
    return pairs


def mirrored_by_parents(world: World, transform: Transform) -> bool:
    """Whether a portal's parents mirror it (their scales' negative parts, with its own, odd
    in number): closed, as a pair carries a turn and a move, not a mirror image.  Its own
    Transform cannot mirror it (``mirror_rules.check_portal_not_mirrored`` refuses that when
    given); a root portal asks nothing more."""
    if transform.parent is None:
        return False
    return glm.determinant(glm.mat3(current_world_matrix(world, transform))) < 0.0


def mirrored_portals(world: World) -> list[int]:
    """The enabled portals their parents mirror (``mirrored_by_parents``): closed, each said by
    the rules stage."""
    return [entity for entity, (portal, transform) in world.query(Portal, Transform)
            if portal.enabled and mirrored_by_parents(world, transform)]


def active_camera(world: World) -> int | None:
    """The camera the main view looks through: of the Cameras with ``active`` set and a
    Transform, the one with the lowest entity id (deterministic when a game leaves two
    active); None when there is none."""
    cameras = [entity for entity, (camera, _) in world.query(Camera, Transform) if camera.active]
    return min(cameras) if cameras else None


def active_camera_parts(world: World) -> tuple[int, Camera, Transform] | None:
    """This frame's active camera (``frame_rules(world).active_camera``, the rule above) with
    its Camera and Transform, or None: what the main view looks through and what the shell
    places and exports."""
    entity = frame_rules(world).active_camera
    return None if entity is None else (entity, world.get(entity, Camera), world.get(entity, Transform))


def world_corners(mesh: Mesh, model: glm.mat4, bounds: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The 8 corners of ``mesh.bounds`` (or ``bounds``: a skinned mesh's pose's box) carried
    by ``model``: an (8, 4) float64 array of homogeneous world-space rows.

    Order: x outer loop, then y, then z (corner ``i`` takes the high bound on x when bit 2
    is set, y bit 1, z bit 0).  The mirror outline relies on it: it picks the four corners
    on one side of the flat axis by that bit."""
    lo, hi = mesh.bounds if bounds is None else bounds
    corners = np.array([(x, y, z, 1.0) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])],
                       np.float64)
    # glm's to_list() is column by column, so rows @ it is model * each corner.
    return corners @ np.array(model.to_list(), np.float64)


@dataclass(frozen=True)
class FrameRules:
    """The rules' answers for one frame (``frame`` is the ``world.frame_index`` they were
    worked out in; a read in a later frame works them out again)."""

    open_portals: Mapping[int, int] = field(default_factory=lambda: MappingProxyType({}))
    active_camera: int | None = None
    frame: int = -1


def compute_frame_rules(world: World) -> FrameRules:
    """Work every rule out now, from the world as it is."""
    return FrameRules(MappingProxyType(open_portal_pairs(world)), active_camera(world), world.frame_index)


def frame_rules(world: World) -> FrameRules:
    """This frame's rules: the published resource when the rules stage ran this frame,
    otherwise worked out now (not stored: only the rules stage publishes)."""
    rules = world.resources.get(FrameRules)
    if rules is not None and rules.frame == world.frame_index:
        return rules
    return compute_frame_rules(world)
