"""What a crossing test needs of each open portal this frame (``PortalGate``): its plane, its
rectangle, and the pair transform that carries what goes in to its partner.  One rule for
everything that goes through portals: travellers and the camera (``systems/portal_travel_system.py``)
and particles (``systems/particle_system.py``).  A crossing is a path from the portal's front
(local +Z) to its back that meets the plane inside the rectangle (``size``, local units, so a
scaled portal's rectangle scales with it); only open pairs count
(``frame_rules.open_portal_pairs``)."""
from __future__ import annotations

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

    def inside(self, point: glm.vec3, margin: float = 0.0) -> bool:
        """Whether ``point`` (on or near the plane) is within the rectangle, grown by ``margin``."""
        local = self.to_local * glm.vec4(point, 1.0)
        return abs(local.x) <= self.half[0] + margin and abs(local.y) <= self.half[1] + margin


def portal_gates(world: World, open_portals: Mapping[int, int]) -> list[PortalGate]:
    """A gate for each open pair (entry portal -> the partner it looks out of), from the
    portals' poses now (``current_world_matrix``: before or after the transform stage alike)."""
    gates = []
    for entity, partner in open_portals.items():
        portal = world.get(entity, Portal)
        look_in = current_world_matrix(world, world.get(entity, Transform))
        look_out = current_world_matrix(world, world.get(partner, Transform))
        carry = pair_transform(look_in, look_out)
        gates.append(PortalGate(entity, partner, glm.inverse(look_in), portal_plane(look_in),
                                (portal.size[0] / 2, portal.size[1] / 2), carry, pair_rotation(carry),
                                portal_plane(look_out)))
    return gates
