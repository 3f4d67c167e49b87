"""Rules: which portal pairs are open and which camera is active, worked out once a frame.

Runs right after the game's update (which may enable, disable, delete or re-pair portals
and switch cameras) and before input and travel, and publishes
``world.resources[FrameRules]`` (``engine/rules/frame_rules.py``) so travel, slicing, the
surfaces and the main view all act on the same answer this frame.
It also says, once a portal and id, when a portal's ``partner`` names an entity the world
never made (``PortalPartnerWarning``: the portal stays closed): at the frame, not when the
component is made, so a pair spawned one after the other is no mistake.
"""
from __future__ import annotations

import warnings

import esper

from components import Portal
from components.portal import PortalPartnerWarning
from engine.core.world import World
from engine.rules.frame_rules import FrameRules, compute_frame_rules


class FrameRulesSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        self._said: set[tuple[int, int]] = set()  # (portal, partner) already warned about

    def process(self, dt: float) -> None:
        world = self.world
        world.resources[FrameRules] = compute_frame_rules(world)
        for entity in world.changed(Portal):  # a portal added or re-paired: no loop over every portal a frame
            portal = world.try_get(entity, Portal) if world.exists(entity) else None
            partner = portal.partner if portal is not None else None
            if partner is not None and not world.ever_made(partner) and (entity, partner) not in self._said:
                self._said.add((entity, partner))
                warnings.warn(PortalPartnerWarning(
                    f"Portal on entity {entity}: partner {partner} names no entity in this world, so the portal "
                    "stays closed (it shows closed_color) until partner names a portal"), stacklevel=2)
