"""Travel through portals: move travellers, detect front-to-back crossings, carry them across.

Runs after input (the fly camera has moved) and before the TransformSystem (which then
publishes the teleported poses), so every rendered frame shows a traveller on one side only.

Who travels: every entity with a ``Traveller`` and the active camera (``Camera.active``,
lowest id, with a Transform: ``engine.rules.frame_rules.active_camera``; it needs no Traveller).
Travellers are expected to be roots: one whose Transform has a parent is moved by its
velocity but never teleported (its pose is relative to something that does not travel
with it).

A crossing is the segment from where the traveller was at the end of the last frame to where
it is now going from a portal's front (local +Z) to its back inside its rectangle, in the
portal's own space, so a portal that slides over a thing standing still swallows it
(``engine.rules.portal_gates``, the rule particles cross by too).  Only
open pairs count (``engine.rules.frame_rules.open_portal_pairs``, the rule the views and slicing
use too): a portal that is disabled, or whose partner is deleted, disabled or has no
Portal or Transform, is just a quad.  The new pose is ``pair_transform(in, out)``
applied to the old one (``portal_math.carried_pose``: the pose the partner's view showed, which
the slice's clone had; a pair whose portals differ in scale scales it, a pair of one scale keeps
it bit for bit); the Traveller's velocity goes with it (turned, and scaled by such a pair), the
camera's frustum tip is measured as its scaled view has it (a crossing that would take a scale
past ``Transform``'s ``SCALE_RANGE`` or a speed past ``MAX_SPEED``, a pair of two scales gone
through again and again, is not made: said once, it goes on behind the portal), and a FlyController's yaw / pitch
are recomputed from the new orientation (a
pair not related by a turn about the vertical leaves a roll in the Transform, which the fly
camera drops at the next mouse move, as it keeps no roll).

Near plane: the camera sees nothing closer than its near plane, so a portal quad that cut the
frustum between the eye and the near rectangle would be clipped and show what lies behind
it.  The camera therefore goes through as soon as the tip of its frustum (the pyramid from
the eye to the near-plane rectangle) touches the portal plane inside the rectangle, while
the eye is still in front and not backing away from it; then it is carried and pushed along
the exit portal's normal just far enough that the whole pyramid is in front of the exit
portal (``CLEAR`` x near), so it comes out just in front of it, facing away.  The push is the
only difference between the image seen through the portal and the image after the teleport:
the eye's distance to the look-in plane when flying straight in (about near, 0.05-0.07 m in
the tests), at most twice the eye-to-near-corner reach when looking along the portal.
The near-rectangle aspect comes from the frame's ``Output`` resource (its size) when there is
one, else ``aspect`` (16:9 by default).

Ping-pong: an entity that just came out of a portal cannot cross that exit portal again in
the very next frame.  Each frame's crossings are published as ``world.resources[PortalCrossings]``
(a fresh list every frame).
"""
from __future__ import annotations

import esper
from pyglm import glm

from components import Camera, FlyController, Transform, Traveller, yaw_pitch_of
from components.portal import MAX_SPEED
from components.tracking import warn_component
from components.transform import SCALE_RANGE
from engine.core.frame_io import Output
from engine.core.portal_math import carried_pose, carried_velocity, carries_scale, near_plane_corners
from engine.core.reflection_math import signed_distance
from engine.core.world import World
from engine.resources import PortalCrossing, PortalCrossings
from engine.rules.frame_rules import frame_rules
from engine.rules.portal_gates import PortalGate, portal_gates

DEFAULT_ASPECT = 16.0 / 9.0
TOUCH = 0.02  # the frustum tip "touches" a portal within TOUCH x near of its plane
CLEAR = 0.1  # after a teleport the whole tip is at least CLEAR x near in front of the exit
# Edges of the frustum tip: points are [eye, corner 0..3] (corners go round the rectangle).
_TIP_EDGES = ((0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1))


class PortalTravelSystem(esper.Processor):
    """Moves travellers by their velocity and carries them (and the camera) through portals.

    The frame's ``Output`` resource supplies the camera's near-plane aspect (``aspect`` when
    there is none).
    """

    def __init__(self, world: World, aspect: float = DEFAULT_ASPECT) -> None:
        self.world = world
        self.aspect = aspect
        self._last: dict[int, glm.vec3] = {}  # world position at the end of the last frame
        self._exited: dict[int, int] = {}  # entity -> portal it came out of last frame
        self._gates_last: dict[int, PortalGate] = {}  # each open portal's gate as the last frame used it
        self._too_far_said: set[tuple[int, int]] = set()  # (entity, portal) a crossing refused for its scale
        world.resources[PortalCrossings] = PortalCrossings()

    # --- frame -----------------------------------------------------------------------------
    def process(self, dt: float) -> None:
        world = self.world
        crossings = PortalCrossings()
        world.resources[PortalCrossings] = crossings
        movers: dict[int, tuple[Transform, Camera | None]] = {}
        start: dict[int, glm.vec3] = {}
        for entity, (traveller, transform) in world.query(Traveller, Transform):
            if not world.exists(entity):
                continue
            movers[entity] = (transform, None)
            start[entity] = glm.vec3(transform.position)
            v = traveller.velocity
            if v.x or v.y or v.z:
                transform.position = transform.position + v * dt
        rules = frame_rules(world)
        if rules.active_camera is not None:
            entity = rules.active_camera
            transform = world.get(entity, Transform)
            movers[entity] = (transform, world.get(entity, Camera))
            start.setdefault(entity, glm.vec3(transform.position))

        gates = portal_gates(self.world, rules.open_portals, self._gates_last)
        self._gates_last = {gate.entity: gate for gate in gates}
        moving = any(gate.was_plane is not None for gate in gates)
        last, exited = self._last, self._exited
        self._last, self._exited = {}, {}
        for entity, (transform, cam) in movers.items():
            before = last.get(entity, start[entity])
            if transform.parent is None and gates and (cam is not None or moving or before != transform.position):
                gate = self._crossed(gates, before, transform, cam, exited.get(entity))
                if gate is not None and self._carry(entity, transform, cam, gate):
                    crossings.append(PortalCrossing(entity, gate.entity, gate.partner, gate.carry, gate.turn))
                    self._exited[entity] = gate.partner
            self._last[entity] = glm.vec3(transform.position)

    def _tip(self, position: glm.vec3, rotation: glm.quat, scale: glm.vec3, cam: Camera) -> list[glm.vec3]:
        """The camera's frustum tip in the world: its eye and near rectangle, as its view
        has them (a scaled camera, one a scaled portal pair carried, reaches that much further)."""
        corners = near_plane_corners(glm.vec3(0.0), glm.quat(), cam.fov_y, cam.near, self.near_aspect(),
                                     _ortho_height(cam))
        return [glm.vec3(position), *(position + rotation * (scale * c) for c in corners)]

    def near_aspect(self) -> float:
        """Aspect of the camera's near rectangle: the frame being rendered, else ``aspect``."""
        output = self.world.resources.get(Output)
        if output is not None and output.size[0] > 0 and output.size[1] > 0:
            return output.size[0] / output.size[1]
        return self.aspect

    # --- crossing tests ------------------------------------------------------------------------
    def _crossed(self, gates: list[PortalGate], before: glm.vec3, transform: Transform, cam: Camera | None,
                 skip: int | None) -> PortalGate | None:
        """The portal this traveller went into this frame (the earliest along its path)."""
        now = glm.vec3(transform.position)
        tip = None
        best: tuple[float, float, PortalGate] | None = None
        for gate in gates:
            if gate.entity == skip:
                continue
            d0 = signed_distance(gate.plane if gate.was_plane is None else gate.was_plane, before)
            d1 = signed_distance(gate.plane, now)
            if d0 < 0.0:
                continue  # came from behind (or walks behind it): no travel
            if d1 < 0.0:
                t = gate.path_in(before, now)
                if t is None:
                    continue  # passed beside the rectangle
                key = (t, 0.0)
            elif cam is not None and d1 <= d0 + 1e-9:  # not while backing away from its front
                if tip is None:
                    tip = self._tip(now, transform.rotation, transform.scale, cam)
                if not self._tip_touches(gate, tip, TOUCH * cam.near * _size(transform.scale)):
                    continue
                key = (1.0, d1)
            else:
                continue
            if best is None or key < best[:2]:
                best = (*key, gate)
        return best[2] if best is not None else None

    def _tip_touches(self, gate: PortalGate, tip: list[glm.vec3], touch: float) -> bool:
        """Whether the frustum tip reaches within ``touch`` of the portal plane inside its
        rectangle: its cross-section with that (offset) plane overlaps the rectangle."""
        s = [signed_distance(gate.plane, p) - touch for p in tip]
        if min(s) >= 0.0:
            return False
        if s[0] <= 0.0:
            section = tip  # the eye itself is within ``touch``: the whole tip is at the plane
        else:
            section = [glm.mix(tip[a], tip[b], s[a] / (s[a] - s[b]))
                       for a, b in _TIP_EDGES if (s[a] < 0.0) != (s[b] < 0.0)]
        local = [gate.to_local * glm.vec4(p, 1.0) for p in section]
        xs = [p.x for p in local]
        ys = [p.y for p in local]
        hw, hh = gate.half[0] + touch, gate.half[1] + touch
        return min(xs) <= hw and max(xs) >= -hw and min(ys) <= hh and max(ys) >= -hh

    # --- teleport ------------------------------------------------------------------------------
    def _carry(self, entity: int, transform: Transform, cam: Camera | None, gate: PortalGate) -> bool:
        """Carry it through ``gate``: True, or False (nothing changed, said once) where a pair of
        two scales would take its scale or speed past what a Transform or Traveller holds."""
        world = self.world
        position, rotation, scale = carried_pose(gate.carry, gate.turn, transform.position, transform.rotation,
                                                 transform.scale)
        scaled = carries_scale(gate.carry)
        traveller = world.try_get(entity, Traveller)
        if scaled and self._too_far(entity, gate, scale, traveller):
            return False
        if cam is not None:
            tip = self._tip(position, rotation, scale, cam)
            lowest = min(signed_distance(gate.exit_plane, p) for p in tip)
            clear = CLEAR * cam.near * _size(scale)
            if lowest < clear:
                position += glm.vec3(gate.exit_plane) * (clear - lowest)
        transform.position = position
        transform.rotation = rotation
        if scaled:
            transform.scale = scale
        if traveller is not None:  # (a pair of one size: turned, as the rotation is, bit for bit)
            velocity = traveller.velocity
            traveller.velocity = carried_velocity(gate.carry, gate.turn, velocity) if scaled else gate.turn * velocity
        fly = world.try_get(entity, FlyController)
        if fly is not None:
            forward = rotation * glm.vec3(0.0, 0.0, -1.0)
            yaw, pitch = yaw_pitch_of(forward)
            if abs(forward.y) < 0.9999:  # straight up or down keeps the old yaw
                fly.yaw = fly.yaw + (yaw - fly.yaw + 180.0) % 360.0 - 180.0  # nearest turn: no jump
            fly.pitch = max(-89.0, min(89.0, pitch))
        return True

    def _too_far(self, entity: int, gate: PortalGate, scale: glm.vec3, traveller: Traveller | None) -> bool:
        """Whether going through ``gate`` (a pair of two scales, again and again) would take a
        scale past ``SCALE_RANGE`` or a speed past ``MAX_SPEED``: then it is not carried and
        goes on behind the portal as through a closed one, said once for it and that portal."""
        low, high = SCALE_RANGE
        speed = glm.length(glm.mat3(gate.carry) * traveller.velocity) if traveller is not None else 0.0
        if all(low <= abs(c) <= high for c in scale) and speed <= MAX_SPEED:
            return False
        if (entity, gate.entity) not in self._too_far_said:
            self._too_far_said.add((entity, gate.entity))
            warn_component(f"entity {entity}: going through portal {gate.entity} (its pair scales by its portals' "
                           f"Transforms) would make its Transform.scale {tuple(round(float(c), 9) for c in scale)} "
                           f"and its speed {float(speed):.6g} m/s, past what they hold ({low:g} to {high:g}, at most "
                           f"{MAX_SPEED:g} m/s): it is not carried, and goes on behind the portal")
        return True


def _size(scale: glm.vec3) -> float:
    """How much a (camera's) scale stretches its near plane's reach: its largest part."""
    return max(abs(scale.x), abs(scale.y), abs(scale.z))


def _ortho_height(cam: Camera) -> float | None:
    """An orthographic camera's near rectangle's height (None: a perspective camera's comes from its field of view)."""
    return cam.ortho_height if cam.projection == "orthographic" else None
