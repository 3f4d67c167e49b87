"""What a crossing test needs of each open portal this frame (``PortalGate``): its plane, its
rectangle, and the pair transform that carries what goes in to its partner.  One rule for
everything that goes through portals: travellers and the camera (``systems/portal_travel_system.py``)
and particles (``systems/particle_system.py``).  A crossing is a path from the portal's front
(local +Z) to its back that meets the plane inside the rectangle (``size``, local units, so a
scaled portal's rectangle scales with it), in the portal's own space: from where the thing was
against the portal as it stood at the end of the last frame (``PortalGate.was_to_local``,
``was_plane``: a portal that slid since, ``slid``) to where it is against it now, so a portal
that slides (a door moving, a platform carrying it) swallows what it passes over, moving or
not; only open pairs count (``frame_rules.open_portal_pairs``)."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from pyglm import glm

from components import Portal, Transform
from engine.core.portal_math import pair_rotation, pair_transform, portal_plane
from engine.core.transforms import current_world_matrix
from engine.core.world import World


@dataclass
class PortalGate:
    """One usable portal this frame, with everything a crossing test needs."""

    entity: int
    partner: int
    to_local: glm.mat4        # world -> the portal's local space
    plane: glm.vec4           # its world plane, its front positive
    half: tuple[float, float]  # half its rectangle (local x, y)
    carry: glm.mat4           # the pair transform (world -> world, in at this portal, out at its partner)
    turn: glm.quat            # carry's rotation
    exit_plane: glm.vec4      # the partner's plane
    # Where it stood at the end of the last frame, if it slid since (``slid``); else its pose now.
    was_to_local: glm.mat4 | None = None
    was_plane: glm.vec4 | None = None

    def inside(self, point: glm.vec3, margin: float = 0.0) -> bool:
        """Whether ``point`` (on or near the plane) is within the rectangle, grown by ``margin``."""
        local = self.to_local * glm.vec4(point, 1.0)
        return abs(local.x) <= self.half[0] + margin and abs(local.y) <= self.half[1] + margin

    def path_in(self, before: glm.vec3, now: glm.vec3) -> float | None:
        """Where along the path from ``before`` (at the end of the last frame) to ``now`` it
        went into this portal (0 to 1), in the portal's own space (the crossing rule above);
        None where it did not."""
        was_plane = self.plane if self.was_plane is None else self.was_plane
        d0 = glm.dot(glm.vec3(was_plane), before) + was_plane.w
        d1 = glm.dot(glm.vec3(self.plane), now) + self.plane.w
        if d0 < 0.0 or d1 >= 0.0:
            return None  # came from behind, or is still in front
        t = d0 / (d0 - d1)
        was_to_local = self.to_local if self.was_to_local is None else self.was_to_local
        local = glm.mix(glm.vec3(was_to_local * glm.vec4(before, 1.0)), glm.vec3(self.to_local * glm.vec4(now, 1.0)), t)
        return t if abs(local.x) <= self.half[0] and abs(local.y) <= self.half[1] else None


# A portal that moved at most this share of its rectangle's larger side and turned at most
# SLIDE_TURN degrees since the last frame slid there (what it passed over went in); further,
# it was placed anew (a portal shot to another wall), and what stood in front of where it was
# does not go in (``slid``).
SLIDE = 0.5
SLIDE_TURN = 30.0


def slid(was: PortalGate, gate: PortalGate) -> bool:
    """Whether the portal of ``gate`` moved since the last frame (``was``) by a slide."""
    if was.to_local == gate.to_local:
        return False
    was_world, now_world = glm.inverse(was.to_local), glm.inverse(gate.to_local)
    step = glm.length(glm.vec3(now_world[3]) - glm.vec3(was_world[3]))
    facing = glm.dot(glm.vec3(was.plane), glm.vec3(gate.plane))
    return step <= SLIDE * 2.0 * max(gate.half) and facing >= math.cos(math.radians(SLIDE_TURN))


def portal_gates(world: World, open_portals: Mapping[int, int],
                 last: Mapping[int, PortalGate] | None = None) -> list[PortalGate]:
    """A gate for each open pair (entry portal -> the partner it looks out of), from the
    portals' poses now (``current_world_matrix``: before or after the transform stage alike);
    with ``last`` (the gates the caller made last frame, by portal), each portal that slid
    since also holds where it stood then."""
    gates = []
    for entity, partner in open_portals.items():
        portal = world.get(entity, Portal)
        look_in = current_world_matrix(world, world.get(entity, Transform))
        look_out = current_world_matrix(world, world.get(partner, Transform))
        carry = pair_transform(look_in, look_out)
        gate = PortalGate(entity, partner, glm.inverse(look_in), portal_plane(look_in),
                          (portal.size[0] / 2, portal.size[1] / 2), carry, pair_rotation(carry), portal_plane(look_out))
        was = last.get(entity) if last else None
        if was is not None and slid(was, gate):
            gate.was_to_local, gate.was_plane = was.to_local, was.plane
        gates.append(gate)
    return gates
