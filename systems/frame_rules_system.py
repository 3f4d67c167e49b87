"""Rules: which portal pairs are open and which camera is active, worked out once a frame.

Runs right after the game's update (which may enable, disable, delete or re-pair portals
and switch cameras) and before input and travel, and publishes
``world.resources[FrameRules]`` (``engine/rules/frame_rules.py``) so travel, slicing, the
surfaces and the main view all act on the same answer this frame.
"""
from __future__ import annotations

import esper

from engine.core.world import World
from engine.rules.frame_rules import FrameRules, compute_frame_rules


class FrameRulesSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world

    def process(self, dt: float) -> None:
        self.world.resources[FrameRules] = compute_frame_rules(self.world)
