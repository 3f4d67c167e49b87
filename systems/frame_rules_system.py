"""Rules: which portal pairs are open and which camera is active, worked out once a frame.

Runs right after the game's update (which may enable, disable, delete or re-pair portals
and switch cameras) and before input and travel, and publishes
``world.resources[FrameRules]`` (``engine/rules/frame_rules.py``) so travel, slicing, the
surfaces and the main view all act on the same answer this frame.
It also says, once, a portal its parents mirror (closed: ``frame_rules.mirrored_by_parents``),
and, once a portal and id, when a portal's ``partner`` names an entity the world
never made (``PortalPartnerWarning``: the portal stays closed), and a portal whose size is
not its partner's (``_say_sizes``): at the frame, not when the component is made, so a pair
spawned one after the other is no mistake.
"""
from __future__ import annotations

import warnings

import esper

from components import Portal, Transform
from components.portal import PortalPartnerWarning
from components.tracking import warn_component
from engine.core.world import World
from engine.rules.frame_rules import FrameRules, compute_frame_rules, mirrored_portals


class FrameRulesSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        self._said: set[tuple[int, int]] = set()  # (portal, partner) already warned about
        self._mirrored_said: set[int] = set()  # portals mirrored by their parents, already said
        self._sizes_said: set[tuple] = set()  # (portal, partner, their sizes) said not to match

    def process(self, dt: float) -> None:
        world = self.world
        world.resources[FrameRules] = compute_frame_rules(world)
        if world.changed(Transform) or world.changed(Portal):  # (a parent's scale, a portal added)
            mirrored = set(mirrored_portals(world))
            for entity in sorted(mirrored - self._mirrored_said):
                warn_component(f"Portal on entity {entity}: its parents' Transform.scale mirror it (an odd number of "
                               "negative parts), and a portal's view and what goes through it cannot be mirror "
                               "images: it stays closed; turn the parent instead of mirroring it")
            self._mirrored_said = mirrored
        for entity in world.changed(Portal):  # a portal added or re-paired: no loop over every portal a frame
            portal = world.try_get(entity, Portal) if world.exists(entity) else None
            partner = portal.partner if portal is not None else None
            if partner is not None and not world.ever_made(partner) and (entity, partner) not in self._said:
                self._said.add((entity, partner))
                warnings.warn(PortalPartnerWarning(
                    f"Portal on entity {entity}: partner {partner} names no entity in this world, so the portal "
                    "stays closed (it shows closed_color) until partner names a portal"), stacklevel=2)
            self._say_sizes(entity, portal)

    def _say_sizes(self, entity: int, portal: Portal | None) -> None:
        """Say (once a portal, partner and sizes) a portal whose ``size`` is not its partner's:
        the pair carries by the portals' transforms alone, so what goes through the larger
        rectangle outside the smaller comes out beside the partner's opening, out of its wall,
        and the view shows it so.  (A pair meant to differ in size scales a Transform: the
        carry scales then, view and travellers alike.)"""
        world = self.world
        partner = portal.partner if portal is not None else None
        out = world.try_get(partner, Portal) if partner is not None and world.exists(partner) else None
        if out is None or tuple(portal.size) == tuple(out.size):
            return
        key = (min(entity, partner), max(entity, partner), *sorted((tuple(portal.size), tuple(out.size))))
        if key not in self._sizes_said:  # (a pair: once, from either side)
            self._sizes_said.add(key)
            warn_component(f"Portal on entity {entity}: its size {tuple(portal.size)} is not its partner's "
                           f"{tuple(out.size)} (entity {partner}): what goes through the one outside the "
                           "other's rectangle comes out beside it, out of its wall; give both one size (a pair "
                           "larger on one side: scale that portal's Transform)")
