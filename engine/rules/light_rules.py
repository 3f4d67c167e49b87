"""Which lights light the scene when there are more than the Lights block has slots for,
and which slot each one takes, defined once for the prepare stage (the Lights block) and
the shadows stage (which lights' maps are drawn, into which slot): a light's shadow is
always the shadow of a light that is lit, read at that light's slot.

The rule is the per-object light importance of the engines users know (Unity's "important"
pixel lights, Godot's and Unreal's light culling) made for the camera and what its mirrors
and portals show: a level with forty torches lights the sixteen that matter where the camera
is and in the rooms its portals open on, not the first sixteen made.

- **Point lights** by their importance to the active camera (``point_importance``): those
  whose range sphere holds the camera first, each by the light it brings to the camera's
  point (luminance of colour x intensity times the scene shader's own falloff at that
  distance, ``falloff``: the windowed inverse square of ``shaders/scene.frag``); then the
  rest, each by its luminance over 1 + the squared distance from the camera to its range
  sphere (the same inverse square, measured to the nearest point it lights).  Without an
  active camera, by luminance alone.  A light counts by the same measure at the eye of each
  mirror and portal view of last frame's tree (``ViewEyes``, published by the reflect
  stage), times the share of the screen the view showed (its rectangle's, from
  ``MIN_VIEW_SHARE`` of it up), where that is more than it brings to the camera: a torch in
  the room a portal opens on, far from the camera, matters as much as the portal is large.
  Each monitor's camera counts the same way, at the share of the frame its picture shows
  (``PictureEyes``, published by the monitors stage): a torch a security camera watches
  matters as much as its screen is large.
  (A frame has one Lights block for all its views, so a view's lights compete with the
  camera's.)
  A spot light (``PointLight.spot_angle``) counts as the point light it is, its cone left
  out: what it brings near the camera is at most that (its cone may light the floor at the
  camera's feet while aimed away from the camera itself).
- **Directional lights** by luminance.
- **Ties** by creation order (entity id): the same answer every run.
- **The sky's sun** (``sky_sun``): a generated sky whose ``Skybox.sun_direction`` is not
  pinned draws its disc against the brightest directional light, by the same luminance.
- **Shadow cubes** (``MAX_POINT_SHADOWS`` of them): among the kept point lights that cast
  shadows, by the same importance.

**Stable slots.**  A light kept from one choice to the next keeps its slot (its row of the
Lights block and its shadow slot), so a still scene's block and cached shadow maps stay as
they are and nothing flickers; a light coming in takes a freed slot, the lowest first, and
lights coming in together take them in creation order (with room for every light, the
slots are the lights in the order they were made, as before this rule).  A freed slot no
light takes stays in the block as a black light until one does (the count ends at the
highest slot in use).

**Hysteresis.**  A light left out replaces a kept one only when it is clearly more
important: its range sphere holds the camera and the kept one's does not, or, of the same
kind, its importance is more than ``HYSTERESIS`` times the kept one's.  Two lights of about
equal importance do not swap every frame as the camera sways between them: the one kept
stays kept until the other matters a quarter more.  (Ranking only past a camera-distance
threshold was the other way; it would still swap at the threshold's edge every frame the
camera crosses it, and does not hold for lights that move.)

**When.**  The prepare stage asks for a choice only when a light came, went, changed or
moved, or, while the answer depends on the camera (``KeptLights.by_eye``: more point lights
than slots, or more casting ones kept than cubes), when the active camera moved or another
became active, or the views' eyes moved (``choice_stands``: the test ``lights_this_frame``,
the extract stage's choice made ahead, makes too, so the two agree every frame); a still
scene ranks nothing.  It publishes the answer as
``world.resources[KeptLights]``; ``kept_lights(world)`` reads it.

GL-free: numpy only (the limits are the render side's, given by the callers).
"""
from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from pyglm import glm

from components import ComponentValueError, DirectionalLight, PointLight, Skybox, Transform
from components.limits import MIN_LIGHT_SIDE
from components.rendering import DEFAULT_SUN_DIRECTION
from components.tracking import raw_field
from engine.core.budget import spending_order
from engine.core.color import LUMINANCE
from engine.core.world import World, world_invariant
from engine.rules.frame_rules import frame_rules, world_corners
from engine.rules.screen_rects import largest_share

# A light left out replaces a kept one only at more than this times its importance.
HYSTERESIS = 1.25
# A mirror or portal view counts for the lights from this share of the screen up.
MIN_VIEW_SHARE = 0.01


@dataclass(frozen=True)
class LightLimits:
    """How many lights of each kind the render side has slots for
    (``engine/render/views.py``: ``MAX_DIRECTIONAL_LIGHTS``, ``MAX_POINT_LIGHTS``,
    ``MAX_POINT_SHADOWS``)."""

    directional: int
    point: int
    point_shadows: int


@dataclass(frozen=True)
class KeptLights:
    """One choice of the lights that light the scene (``choose_lights``).

    ``directional`` and ``point``: slot -> the light's entity (None: a freed slot, black),
    as long as the highest slot in use; ``point_shadows``: shadow cube -> the kept point
    light's entity (None: a free cube); ``cut``: (directional, point) lights left out;
    ``shadows_cut``: point lights casting shadows with no cube (left out, or kept past the
    cubes); ``by_eye``: whether the choice depends on the camera (``camera``, whose position
    it was made from: ``eye``) and the views' eyes (``views``: ``ViewEyes.points``)."""

    directional: tuple[int | None, ...] = ()
    point: tuple[int | None, ...] = ()
    point_shadows: tuple[int | None, ...] = ()
    cut: tuple[int, int] = (0, 0)
    shadows_cut: int = 0
    by_eye: bool = False
    camera: int | None = None
    eye: tuple[float, float, float] | None = None
    views: tuple[tuple[float, float, float, float], ...] = ()

    def point_slot(self, entity: int) -> int:
        """The Lights block slot of kept point light ``entity`` (-1: not kept)."""
        return self.point.index(entity) if entity in self.point else -1


@dataclass(frozen=True, eq=False)
class ViewEyes:
    """The mirror and portal views the reflect stage drew last (objects with ``.level``,
    ``.view.eye`` and ``.rect``, screen pixels: ``engine.render.tree_walk.ReflectionView``;
    level 0, the camera's own, is left out) and the
    screen's ``size``: published as ``world.resources[ViewEyes]`` each frame, read by the
    light rule the next.  ``points`` is worked out only when a choice depends on them."""

    views: Sequence[Any]
    size: tuple[int, int]

    @functools.cached_property
    def projections(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The mirror and portal views' (level 0 left out): each one's view-projection as a
        (4, 4) float64 array a row of world points is multiplied by, its rectangle on the
        screen (x, y, width, height) and its size: (n, 4, 4), (n, 4), (n, 2); worked out once
        (the monitors stage's screens' shares of the frame)."""
        nodes = [node for node in self.views if node.level > 0]
        return (np.array([node.view.view_proj.to_list() for node in nodes], np.float64).reshape(-1, 4, 4),
                np.array([node.rect for node in nodes], np.float64).reshape(-1, 4),
                np.array([node.view.size for node in nodes], np.float64).reshape(-1, 2))

    @functools.cached_property
    def points(self) -> tuple[tuple[float, float, float, float], ...]:
        """(x, y, z, share) of each view's eye that shows at least ``MIN_VIEW_SHARE`` of the
        screen: its rectangle's area over the screen's."""
        screen = max(1, self.size[0] * self.size[1])
        found = []
        for node in self.views:
            share = min(1.0, node.rect[2] * node.rect[3] / screen)
            if node.level > 0 and share >= MIN_VIEW_SHARE:
                eye = node.view.eye
                found.append((float(eye.x), float(eye.y), float(eye.z), share))
        return tuple(found)


@dataclass(frozen=True, eq=False)
class PictureEyes:
    """The monitors' cameras as eyes (published by the monitors stage each frame, read with
    ``ViewEyes`` the next: ``view_eyes``): a torch in the room a security camera watches
    matters as much as its screen is large, as a portal's would.  Each screen: its camera's
    eye, its mesh, world matrix and pose's box (``world_corners``' ``bounds``: None, the
    mesh's own; the whole None: no mesh) and its ``ScreenPanel``'s pixels; the
    output's ``size``, the main view's ``matrix`` (``screen_rects.view_matrix``; None: no
    camera) and last frame's mirror and portal views (``eyes``).  ``points`` is worked out
    only when a choice depends on them."""

    screens: tuple[tuple[tuple[float, float, float], Any, float], ...] = ()
    size: tuple[int, int] = (0, 0)
    matrix: np.ndarray | None = None
    eyes: ViewEyes | None = None

    @functools.cached_property
    def points(self) -> tuple[tuple[float, float, float, float], ...]:
        """(x, y, z, share) of each camera whose picture shows at least ``MIN_VIEW_SHARE`` of
        the frame: the largest of its screen's rectangles in the main view and in the mirror
        and portal views (``screen_rects.largest_share``) and its panel's."""
        if not self.screens:
            return ()
        matrices, rects, sizes = self.eyes.projections if self.eyes is not None else \
            (np.zeros((0, 4, 4)), np.zeros((0, 4)), np.zeros((0, 2)))
        if self.matrix is not None:
            matrices = np.concatenate([self.matrix[None], matrices])
            rects = np.concatenate([[(0.0, 0.0, *self.size)], rects])
            sizes = np.concatenate([[self.size], sizes])
        found = []
        for eye, placed, panel in self.screens:
            share = panel / (self.size[0] * self.size[1])
            if placed is not None:
                share = max(share, largest_share(world_corners(*placed), matrices, rects, sizes, self.size))
            if share >= MIN_VIEW_SHARE:
                found.append((*eye, min(1.0, share)))
        return tuple(found)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of linear colours (..., 3)."""
    return np.asarray(rgb, np.float64) @ LUMINANCE


def falloff(distance: np.ndarray, light_range: np.ndarray) -> np.ndarray:
    """The scene shader's point-light falloff (``shaders/scene.frag`` ``direct_lighting``):
    (1 - (d / range)^4)^2 clamped, over d^2 + 1."""
    d = np.asarray(distance, np.float64)
    fade = np.clip(1.0 - np.power(d / np.asarray(light_range, np.float64), 4), 0.0, 1.0)
    return fade * fade / (d * d + 1.0)


# A spot light's cone as the shaders read it (``spot_cone``): all round, a point light's.
ALL_ROUND = (0.0, 0.0, 0.0, 1.0)
# The narrowest fade at a cone's edge, in the cosine of the angle from its axis: a hard edge
# (``PointLight.spot_blend`` 0) fades over this, a few hundredths of a degree, not a step.
SPOT_EDGE = 1e-4


def spot_cone(axis: Sequence[float], angle_degrees: float, blend: float) -> tuple[float, float, float, float]:
    """A spot light's cone (``PointLight.spot_angle`` and ``spot_blend`` about ``axis``, the
    way it shines) as the Lights and VirtualLights blocks hold it: (axis x k, -cos(outer) x k)
    with k = 1 / (cos(inner) - cos(outer)), outer the angle, inner ``angle x (1 - blend)``.
    Then for ``l`` the unit vector from a lit point to the light, dot(-l, xyz) + w is 0 on
    the cone's edge and 1 on the inner cone's, and ``spot_factor`` smoothsteps it: one dot
    product a pixel, no trigonometry, a vector a light.  All round (180 degrees):
    ``ALL_ROUND``, whose factor is 1 everywhere."""
    if angle_degrees >= 180.0:
        return ALL_ROUND
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    outer = np.cos(np.radians(angle_degrees))
    inner = np.cos(np.radians(angle_degrees * (1.0 - blend)))
    k = 1.0 / max(inner - outer, SPOT_EDGE)
    return (float(a[0] * k), float(a[1] * k), float(a[2] * k), float(-outer * k))


def lamp_cone(light: PointLight, world: Any) -> tuple[float, float, float, float]:
    """``spot_cone`` of point light ``light`` whose entity's world matrix is ``world`` (glm):
    about its -Z (the way a camera there would look), ``ALL_ROUND`` at 180 degrees."""
    if light.spot_angle >= 180.0:
        return ALL_ROUND
    forward = world[2].xyz
    return spot_cone((-forward.x, -forward.y, -forward.z), light.spot_angle, light.spot_blend)


# A light without a cookie, as the Lights and VirtualLights blocks' cookie rows hold it
# (``lamp_cookie``): its layer -1.
NO_COOKIE = ((0.0, 0.0, 0.0, -1.0), (0.0, 0.0, 0.0, 0.0))
# An all-round light's cookie (wrapped about it) has -2 - layer in its first row's w, and half
# more where the rows' frame is mirrored (``carried_cookie``): its forward is then
# -cross(top, right), not cross(top, right).
WRAPPED_COOKIE = -2.0
MIRRORED_FRAME = 0.5


def lamp_cookie(light: PointLight, world: Any, layer: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The cookie rows of spot ``light`` (``PointLight.cookie``) whose entity's world matrix
    is ``world`` (glm), its image in layer ``layer`` of the cookie array: (X / t, layer) and
    (Y / t, 0), X and Y the entity's unit +X and +Y (the image's right and top), t the tangent
    of its ``spot_angle``.  For ``d`` the unit vector from the light to a point and F the
    cone's axis, the point's place in the image is 0.5 + 0.5 (d.X/t, d.Y/t) / d.F
    (``shaders/include/spot_cookie.glsl``): the image fills the square about the cone's circle,
    a slide projector's.  ``NO_COOKIE`` without a cookie.

    An all-round light's (``spot_angle`` 180) is wrapped about it instead, an equirectangular
    image (longitude, latitude): rows (X, -2 - layer) and (Y, 0), X and Y unit, its forward
    F = Y x X (the entity's -Z); a direction d lands at u = 0.5 + atan2(d.X, d.F) / 2 pi,
    v = 0.5 + asin(d.Y) / pi, the image's middle ahead of the light.

    A rectangle light's image is on its face, not projected (``lamp_rectangle``): ``NO_COOKIE``."""
    if light.cookie is None or is_panel(light):
        return NO_COOKIE
    if light.spot_angle >= 180.0:
        right, up = glm.normalize(world[0].xyz), glm.normalize(world[1].xyz)
        return (float(right.x), float(right.y), float(right.z), WRAPPED_COOKIE - layer), \
            (float(up.x), float(up.y), float(up.z), 0.0)
    t = math.tan(math.radians(light.spot_angle))
    right, up = glm.normalize(world[0].xyz) / t, glm.normalize(world[1].xyz) / t
    return (float(right.x), float(right.y), float(right.z), float(layer)), (float(up.x), float(up.y), float(up.z), 0.0)


def cone_reaches(cone: Sequence[float], apex: Sequence[float], centre: Sequence[float], radius: float) -> bool:
    """Whether a spot light at ``apex`` with ``cone`` (``spot_cone``) can light any point of
    the ball of ``radius`` about ``centre``: the angle from its axis to the ball's centre,
    less the ball's angular radius, within the cone's angle.  Conservative (a surface's
    outline is tested by the ball holding it): it only rules out."""
    opened = opened_cone(cone)
    if opened is None:
        return True
    axis, outer = opened
    to = np.asarray(centre, np.float64) - np.asarray(apex, np.float64)
    d = float(np.linalg.norm(to))
    if d <= radius:
        return True
    return _angle(axis, to / d) - math.degrees(math.asin(radius / d)) < outer


# The widest angle from a cube face's axis to a direction that face holds (to its corners:
# atan(sqrt(2))), and a margin for the shadow filter's reach across a face's edge.
_FACE_REACH_DEGREES = math.degrees(math.atan(math.sqrt(2.0)))
_FACE_MARGIN_DEGREES = 2.0


def cube_faces_lit(cone: Sequence[float], axes: Sequence[Sequence[float]]) -> tuple[bool, ...]:
    """Which faces of a point light's shadow cube (``axes``: each face's forward,
    ``CUBE_FACES`` order) a spot's ``cone`` can light through: those whose pyramid of
    directions comes within the cone's angle of its axis (with a margin for the filter).  A
    face left out holds no point the light reaches, so its shadow is never read: a spot
    aimed straight down 30 degrees wide draws one face, not six.  All True all round."""
    opened = opened_cone(cone)
    if opened is None:
        return (True,) * len(axes)
    axis, outer = opened
    reach = outer + _FACE_REACH_DEGREES + _FACE_MARGIN_DEGREES
    return tuple(_angle(axis, np.asarray(face, np.float64)) < reach for face in axes)


# A spot no wider than this (``PointLight.spot_angle``, from its axis) casts from one
# perspective depth map fitted to its cone, as Unity, Godot and three.js draw a spot's shadow.
# The map's ``shadow_resolution`` texels span 2 tan(angle) where a cube face's span 2 (tan 45
# degrees): up to 45 degrees it is at least as sharp as the cube, a narrow cone several times
# sharper (15 degrees: 3.7x, 6 degrees: 9.5x), and it is one pass where the cube takes one to
# five faces.  A wider spot, and a lamp all round, keep the cube (its lit faces drawn).
SPOT_MAP_MAX_ANGLE = 45.0
# Texels the map reaches past the cone's edge, each side: the filter's taps and the normal
# offset of a point just inside the cone stay on the map.
SPOT_MAP_MARGIN_TEXELS = 4


def spot_map_half_width(light: PointLight) -> float | None:
    """The half-width (the tangent of its half-angle) of the perspective shadow map fitted to
    point light ``light``'s cone with ``SPOT_MAP_MARGIN_TEXELS`` to spare, or None where the
    light casts from a cube (all round, wider than ``SPOT_MAP_MAX_ANGLE``, or with a size: a
    sphere's, a tube's or a rectangle's shadow is soft, which only its cube's lookup makes,
    ``shaders/include/shadows.glsl`` ``soft_cube_shadow``; its cone's faces of it alone drawn)."""
    if light.spot_angle > SPOT_MAP_MAX_ANGLE or light.radius > 0.0 or light.rectangle[0] > 0.0 or light.length > 0.0:
        return None
    return cone_half_width(light.spot_angle, light.shadow_resolution)


def cone_half_width(angle_degrees: float, resolution: int) -> float:
    """The half-width (tangent of the half-angle) of a perspective map of ``resolution`` texels
    a side holding a cone ``angle_degrees`` from its axis with ``SPOT_MAP_MARGIN_TEXELS`` to spare
    (a spot's own map, or its image's through a mirror: ``shadow_rules.virtual_shadow_camera``)."""
    return math.tan(math.radians(angle_degrees)) / (1.0 - 2.0 * SPOT_MAP_MARGIN_TEXELS / resolution)


def shadow_texel_tangent(light: PointLight) -> float:
    """A texel of point light ``light``'s shadow map across, over its distance from the light,
    at its widest (on a face's or a map's axis: off it a flat map's texels subtend less):
    ``2 / resolution`` on a cube's face, ``2 x half-width / resolution`` on a spot's map."""
    half_width = spot_map_half_width(light)
    return 2.0 * (1.0 if half_width is None else half_width) / light.shadow_resolution


def opened_cone(cone: Sequence[float]) -> tuple[np.ndarray, float] | None:
    """A packed cone (``spot_cone``) opened back into its unit axis and its angle (degrees);
    None all round."""
    c = np.asarray(cone, np.float64)
    k = float(np.linalg.norm(c[:3]))
    if k == 0.0:
        return None
    return c[:3] / k, math.degrees(math.acos(max(-1.0, min(1.0, -c[3] / k))))


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (degrees) between unit vectors ``a`` and ``b``."""
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b)))))


def spot_factor(cone: Sequence[float], to_light: np.ndarray) -> np.ndarray:
    """How much of a spot light's light (``spot_cone``'s ``cone``) goes along the unit
    vectors ``to_light`` reversed (rows: from lit points to the light): 0 outside the cone,
    1 inside the inner cone, smoothstep between (``shaders/include/spot_cone.glsl``'s
    ``spot_factor``: the same answers)."""
    c = np.asarray(cone, np.float64)
    t = np.clip(-(np.asarray(to_light, np.float64) @ c[:3]) + c[3], 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def carried_cone(cone: Sequence[float], carry: Any) -> tuple[float, float, float, float]:
    """``cone`` as a light's image through a mirror or portal sees it: its axis turned by
    ``carry``'s linear part (a glm 4x4 matrix), kept at its length (the same cone about the
    carried axis: a mirror or a portal keeps angles)."""
    c = np.asarray(cone, np.float64)
    length = float(np.linalg.norm(c[:3]))
    if length == 0.0:
        return ALL_ROUND
    m = np.array(carry.to_list(), np.float64).T   # glm's lists are its columns
    turned = m[:3, :3] @ c[:3]
    turned *= length / np.linalg.norm(turned)
    return (float(turned[0]), float(turned[1]), float(turned[2]), float(c[3]))


def carried_cookie(rows: tuple[Sequence[float], Sequence[float]], carry: Any) -> tuple[tuple[float, ...], ...]:
    """A light's cookie rows (``lamp_cookie``) as its image through a mirror or portal sees
    them: the image's right and top turned by ``carry``'s linear part (a glm 4x4 matrix), each
    kept at its length, the layer kept.  Turned, not worked out again from the carried axis: a
    mirror turns the frame's handedness, so its image of the light projects the picture the
    other way round, as a real mirror shows it.  A wrapped cookie's forward (their cross
    product) is turned too: where ``carry`` mirrors (a negative determinant), its w's
    ``MIRRORED_FRAME`` half flips, so the forward stays the light's own, carried."""
    if rows[0][3] == NO_COOKIE[0][3]:
        return NO_COOKIE
    m = np.array(carry.to_list(), np.float64).T[:3, :3]   # glm's lists are its columns
    carried = []
    for row in rows:
        v = np.asarray(row[:3], np.float64)
        turned = m @ v
        turned *= np.linalg.norm(v) / np.linalg.norm(turned)
        carried.append([float(turned[0]), float(turned[1]), float(turned[2]), float(row[3])])
    if rows[0][3] <= WRAPPED_COOKIE and np.linalg.det(m) < 0.0:
        code = WRAPPED_COOKIE - rows[0][3]   # layer, and a half where mirrored
        layer = math.floor(code + 0.25)
        carried[0][3] = WRAPPED_COOKIE - (layer + (0.0 if code - layer > 0.25 else MIRRORED_FRAME))
    return tuple(tuple(row) for row in carried)


# A light that is no rectangle, as the Lights and VirtualLights blocks' rectangle rows hold
# it (``lamp_rectangle``): its half sides zero.
NO_RECTANGLE = ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))


def is_panel(light: PointLight) -> bool:
    """Whether point light ``light`` is a rectangle (``PointLight.rectangle``; not a tube)."""
    return light.rectangle[0] > 0.0 and light.length == 0.0


def lamp_rectangle(light: PointLight, world: Any, face: int = -1) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The rectangle rows of point light ``light`` (``PointLight.rectangle``) whose entity's
    world matrix is ``world`` (glm): (U, s / A) and (V, 0), U and V the half sides (the
    entity's unit +X times half the width, its unit +Y times half the height: the entity's
    scale leaves them as they are, as it leaves a radius), A the area, s the side the light
    shines from as a sign: its front is s cross(U, V) (-1 here: the entity's -Z).  The
    shader takes the rectangle's radiance as the light's colour x intensity x |s / A|
    (``shaders/include/rect_lights.glsl``).  A tube (``PointLight.length``): (U, 1 / A) and
    (0, 0, 0, R), U its half length along the entity's unit +X, R its radius (at least half
    ``MIN_LIGHT_SIDE``: a line is a tube that thin), A = 2 R x length, the rectangle through
    its axis the shader turns to face each point (``tube_radius``).  ``NO_RECTANGLE`` for a
    point or a sphere.

    ``face``: the layer of the rectangle's ``cookie`` in the cookie array
    (``engine/render/spot_cookies.py``; -1: none), the image on its face: V's w is then
    -1 - ``face`` (``rect_face`` in ``shaders/include/rect_lights.glsl``; a tube's w, its
    radius, is above 0, a plain rectangle's 0)."""
    width, height = light.rectangle
    if light.length > 0.0:
        radius = tube_radius(light)
        axis = glm.normalize(world[0].xyz) * (0.5 * light.length)
        return (float(axis.x), float(axis.y), float(axis.z), 1.0 / (light.length * 2.0 * radius)), \
            (0.0, 0.0, 0.0, radius)
    if width == 0.0:
        return NO_RECTANGLE
    right, up = glm.normalize(world[0].xyz) * (0.5 * width), glm.normalize(world[1].xyz) * (0.5 * height)
    return (float(right.x), float(right.y), float(right.z), -1.0 / (width * height)), \
        (float(up.x), float(up.y), float(up.z), -1.0 - face if face >= 0 else 0.0)


def tube_radius(light: PointLight) -> float:
    """A tube light's radius as drawn: its ``radius``, at least half ``MIN_LIGHT_SIDE``."""
    return max(float(light.radius), 0.5 * MIN_LIGHT_SIDE)


def sphere_radius(light: PointLight) -> float:
    """The radius point light ``light``'s highlight is a sphere's of (``sphere_highlight``):
    its ``radius``, 0 for a tube (whose radius is the tube's: ``lamp_rectangle``)."""
    return 0.0 if light.length > 0.0 else float(light.radius)


def light_size(light: PointLight, world: Any) -> tuple[float, float, float, float]:
    """A point light's size for its soft shadows (``shaders/include/shadows.glsl``
    ``soft_cube_shadow``), whose entity's world matrix is ``world`` (glm): the radius of a
    disc as big, its sphere's radius or a disc of its rectangle's area or its tube's outline's
    (length x diameter) (metres; 0: a point, whose shadow is as hard as its map allows), then a
    rectangle's front (the entity's unit -Z: nothing behind its plane blocks its light; 0 for a
    sphere or a tube, which shine all round)."""
    width, height = light.rectangle
    if light.length > 0.0:
        return (math.sqrt(light.length * 2.0 * tube_radius(light) / math.pi), 0.0, 0.0, 0.0)
    if width == 0.0:
        return (float(light.radius), 0.0, 0.0, 0.0)
    front = -glm.normalize(world[2].xyz)
    return (math.sqrt(width * height / math.pi), float(front.x), float(front.y), float(front.z))


def carried_rectangle(rows: tuple[Sequence[float], Sequence[float]], carry: Any) -> tuple[tuple[float, ...], ...]:
    """A light's rectangle rows (``lamp_rectangle``) as its image through a mirror or portal
    sees them: the half sides moved by ``carry``'s linear part (a glm 4x4 matrix; a portal
    that scales scales them, and a tube's radius), the radiance kept (light keeps its radiance
    along a ray), and where ``carry`` mirrors (a negative determinant) the front's sign turned,
    so the image shines from the side the mirror shows lit (a tube shines all round).  A face's
    image (V's w below 0) is kept: read through the carried corners, a mirror shows it the
    other way round, as a real one does."""
    if rows[0][3] == 0.0:
        return NO_RECTANGLE
    m = np.array(carry.to_list(), np.float64).T[:3, :3]   # glm's lists are its columns
    u, v = m @ np.asarray(rows[0][:3], np.float64), m @ np.asarray(rows[1][:3], np.float64)
    tube = rows[1][3] > 0.0
    sign = -1.0 if np.linalg.det(m) < 0.0 and not tube else 1.0
    fourth = float(rows[1][3]) * abs(np.linalg.det(m)) ** (1.0 / 3.0) if tube else float(rows[1][3])
    return (float(u[0]), float(u[1]), float(u[2]), float(rows[0][3]) * sign), \
        (float(v[0]), float(v[1]), float(v[2]), fourth)


def point_importance(positions: np.ndarray, ranges: np.ndarray, rgb: np.ndarray,
                     eye: Sequence[float] | None) -> tuple[np.ndarray, np.ndarray]:
    """(holds, importance) of point lights to a camera at ``eye``: whether each one's range
    sphere holds the camera, and the light it brings there (inside: luminance x ``falloff``
    at the camera; outside: luminance / (1 + gap^2), gap the distance from the camera to the
    sphere).  Without ``eye``: no sphere holds it, importance is luminance."""
    lum = luminance(np.asarray(rgb, np.float64).reshape(-1, 3))
    if eye is None:
        return np.zeros(len(lum), bool), lum
    holds, importance = _importance_at(positions, ranges, lum, np.asarray(eye, np.float64).reshape(1, 3))
    return holds[:, 0], importance[:, 0]


def view_importance(positions: np.ndarray, ranges: np.ndarray, rgb: np.ndarray,
                    points: Sequence[tuple[float, float, float, float]]) -> np.ndarray:
    """The most each point light brings to any of the views' eyes (``ViewEyes.points``:
    x, y, z, share): ``point_importance``'s measure times the view's share of the screen;
    zeros without views."""
    lum = luminance(np.asarray(rgb, np.float64).reshape(-1, 3))
    if not points:
        return np.zeros(len(lum))
    at = np.asarray(points, np.float64).reshape(-1, 4)
    return (_importance_at(positions, ranges, lum, at[:, :3])[1] * at[:, 3]).max(axis=1)


def _importance_at(positions: np.ndarray, ranges: np.ndarray, lum: np.ndarray,
                   eyes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(holds, importance), each (lights, eyes): ``point_importance``'s rule at each eye."""
    ranges = np.asarray(ranges, np.float64).reshape(-1, 1)
    offsets = np.asarray(positions, np.float64).reshape(-1, 1, 3) - eyes.reshape(1, -1, 3)
    distance = np.linalg.norm(offsets, axis=2)
    holds = distance < ranges
    gap = np.maximum(distance - ranges, 0.0)
    lum = lum.reshape(-1, 1)
    return holds, np.where(holds, lum * falloff(distance, ranges), lum / (1.0 + gap * gap))


def _keep(ids: list[int], holds: np.ndarray, importance: np.ndarray, slots: tuple[int | None, ...],
          limit: int) -> tuple[int | None, ...]:
    """The slots of the ``limit`` lights kept of ``ids`` (importance and holds by row), from
    the last choice's ``slots``: the most important, with hysteresis, each in its old slot."""
    if len(ids) <= limit:
        kept = set(ids)
    else:
        order = [ids[i] for i in spending_order(holds.astype(np.float64), importance, ids).tolist()]
        rank = {entity: place for place, entity in enumerate(order)}
        row = {entity: i for i, entity in enumerate(ids)}
        kept = {entity for entity in slots if entity is not None and entity in rank}
        outside = [entity for entity in order if entity not in kept]
        while len(kept) < limit:
            kept.add(outside.pop(0))

        def beats(a: int, b: int) -> bool:
            i, j = row[a], row[b]
            if holds[i] != holds[j]:
                return bool(holds[i])
            return bool(importance[i] > HYSTERESIS * importance[j])

        while outside:
            worst = max(kept, key=rank.__getitem__)
            if not beats(outside[0], worst):
                break
            kept.remove(worst)
            kept.add(outside.pop(0))
            outside.append(worst)
            outside.sort(key=rank.__getitem__)
    placed = [entity if entity in kept else None for entity in slots[:limit]]
    placed += [None] * (limit - len(placed))
    free = iter([i for i, entity in enumerate(placed) if entity is None])
    for entity in sorted(kept - set(placed)):
        placed[next(free)] = entity
    while placed and placed[-1] is None:
        placed.pop()
    return tuple(placed)


def choose_lights(world: World, previous: KeptLights | None, limits: LightLimits) -> KeptLights:
    """The lights that light the scene now and their slots (the module's rule), from the last
    choice ``previous`` (None: the first)."""
    previous = previous or KeptLights()
    camera = frame_rules(world).active_camera
    eye = None
    if camera is not None:
        position = world.get(camera, Transform).world[3]
        eye = (float(position.x), float(position.y), float(position.z))
    # Importance is worked out only where there are more lights than places (most scenes:
    # never), the slots alone otherwise.
    suns = sorted(world.query_one(DirectionalLight), key=lambda pair: pair[0])
    sun_ids = [entity for entity, _ in suns]
    brightness = np.zeros(len(suns))
    if len(suns) > limits.directional:
        brightness = luminance(np.array([raw_field(light, "color").xyz * light.intensity for _, light in suns],
                                        np.float64).reshape(-1, 3))
    directional = _keep(sun_ids, np.zeros(len(suns), bool), brightness, previous.directional, limits.directional)
    lamps = sorted(world.query(PointLight, Transform), key=lambda pair: pair[0])
    lamp_ids = [entity for entity, _ in lamps]
    shadowed = sum(1 for _, (light, _) in lamps if light.shadows)
    holds, importance = np.zeros(len(lamps), bool), np.zeros(len(lamps))
    views: tuple[tuple[float, float, float, float], ...] = ()
    if len(lamps) > limits.point or shadowed > limits.point_shadows:
        positions = np.array([t.world[3].xyz for _, (_, t) in lamps], np.float64)
        ranges = np.array([light.range for _, (light, _) in lamps], np.float64)
        rgb = np.array([raw_field(light, "color").xyz * light.intensity for _, (light, _) in lamps], np.float64)
        holds, importance = point_importance(positions, ranges, rgb, eye)
        views = view_eyes(world) if eye is not None else ()
        if views:
            importance = np.maximum(importance, view_importance(positions, ranges, rgb, views))
    point = _keep(lamp_ids, holds, importance, previous.point, limits.point)
    kept = set(point) - {None}
    casting = [i for i, (entity, (light, _)) in enumerate(lamps) if light.shadows and entity in kept]
    cubes = _keep([lamp_ids[i] for i in casting], holds[casting], importance[casting], previous.point_shadows,
                  limits.point_shadows)
    return KeptLights(directional=directional, point=point, point_shadows=cubes,
                      cut=(len(suns) - sum(e is not None for e in directional), len(lamps) - len(kept)),
                      shadows_cut=shadowed - sum(e is not None for e in cubes),
                      by_eye=len(lamps) > limits.point or len(casting) > limits.point_shadows,
                      camera=camera, eye=eye, views=views)


def view_eyes(world: World) -> tuple[tuple[float, float, float, float], ...]:
    """Last frame's mirror and portal views' eyes and shares (``ViewEyes.points``; none
    before the reflect stage has drawn), then the monitors' cameras' (``PictureEyes``)."""
    found, pictures = world.resources.get(ViewEyes), world.resources.get(PictureEyes)
    return (found.points if found is not None else ()) + (pictures.points if pictures is not None else ())


class SkySun(NamedTuple):
    """Where a generated sky's sun stands and what colour its disc takes (``sky_sun``), and
    its moon's (a ``DirectionalLight`` whose ``body`` is "moon"; None: no moon)."""

    direction: tuple[float, float, float]               # unit, towards the sun
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)  # times ``Skybox.sun_color``: the light's colour
    moon: tuple[float, float, float] | None = None      # unit, towards the moon
    moon_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)  # times ``Skybox.moon_color``: its light's colour


def sky_sun(world: World, skybox: Skybox) -> SkySun:
    """A generated sky's sun: at ``skybox.sun_direction`` when pinned; else against the
    brightest ``DirectionalLight`` (luminance of colour x intensity, the directional lights'
    rank above; ties to the first made), its disc tinted by that light's colour (a red
    evening light, a red disc; its intensity lights the scene, the disc keeps
    ``Skybox.sun_color``'s brightness); else at ``DEFAULT_SUN_DIRECTION``.  A black light
    (luminance 0) is no sun.  The brightest moon (``brightest_directional``'s of the
    "moon" bodies) is its moon, pinned sun or not."""
    if skybox.sun_direction is not None:
        return _with_moon(world, SkySun(tuple(float(c) for c in skybox.sun_direction)))
    return followed_sun(world)


def brightest_directional(world: World, body: str = "sun") -> DirectionalLight | None:
    """The brightest ``DirectionalLight`` of ``body`` (luminance of colour x intensity; ties
    to the first made), or None where there is none or every one is black: the scene's sun
    (or, ``body`` "moon", its moon)."""
    best = brightest_directional_entity(world, body)
    return None if best is None else best[1]


def brightest_directional_entity(world: World, body: str = "sun") -> tuple[int, DirectionalLight] | None:
    """``brightest_directional``'s light with its entity."""
    best, brightest = None, 0.0
    for entity, light in sorted(world.query_one(DirectionalLight), key=lambda pair: pair[0]):
        if light.body != body:
            continue
        bright = float(luminance(raw_field(light, "color").xyz * light.intensity))
        if bright > brightest:
            best, brightest = (entity, light), bright
    return best


def followed_sun(world: World) -> SkySun:
    """The sun of a sky that follows the lights (``sky_sun`` of an unpinned Skybox)."""
    best = brightest_directional(world)
    if best is None:
        return _with_moon(world, SkySun(DEFAULT_SUN_DIRECTION))
    return _with_moon(world, SkySun(tuple(-float(c) for c in best.direction),
                                    tuple(float(c) for c in raw_field(best, "color").xyz)))


def _with_moon(world: World, sun: SkySun) -> SkySun:
    """``sun`` with the world's brightest moon, if it has one."""
    moon = brightest_directional(world, "moon")
    if moon is None:
        return sun
    return sun._replace(moon=tuple(-float(c) for c in moon.direction),
                        moon_tint=tuple(float(c) for c in raw_field(moon, "color").xyz))


def air_tinted(light: DirectionalLight, sun: DirectionalLight | None) -> bool:
    """Whether an atmosphere dims and reddens ``light``'s light on its way down: the sky's
    sun (``sun``, ``brightest_directional``) and every moon; a fill light is as it is given."""
    return light is sun or light.body == "moon"


# How far what is made from a turning sun may lag it: the sky's cube map and light, the
# probes' captures (the sky pass and the direct light follow every frame).  The cube's
# texels are 0.7 degrees at 128 a face, the disc's edge 1.8-2.6 degrees from its centre.
SKY_CUBE_LAG_DEGREES = 1.0
SKY_CUBE_TINT_LAG = 0.02  # ... and its colour, each channel, as a share of the brightest
# Closer than this, two suns are the same sun (a direction normalised again moves a bit).
SAME_SUN_DEGREES = 1e-4
SAME_SUN_TINT = 1e-6


def cube_serves(made: SkySun | None, now: SkySun, degrees: float = SKY_CUBE_LAG_DEGREES,
                tint: float = SKY_CUBE_TINT_LAG) -> bool:
    """Whether a sky cube map made with the sun ``made`` still serves a sky whose sun is
    ``now`` while it turns (within ``degrees``, and ``tint`` of the brightest channel: by default
    ``SKY_CUBE_LAG_DEGREES`` and ``SKY_CUBE_TINT_LAG``): the sky pass draws the sun where it
    is every frame, and reflections and the sky's light, read from the cube, follow a moment
    later, not every frame of a day's turn.  With ``SAME_SUN_DEGREES`` and ``SAME_SUN_TINT``:
    whether it is the same sun, rounding apart."""
    if made is None or (made.moon is None) != (now.moon is None):
        return False
    if made.moon is not None and not (turned_within(made.moon, now.moon, degrees)
                                      and colour_within(made.moon_tint, now.moon_tint, tint)):
        return False
    return turned_within(made.direction, now.direction, degrees) and colour_within(made.tint, now.tint, tint)


def colour_within(made: Sequence[float], now: Sequence[float], share: float) -> bool:
    """Whether colour ``now`` is within ``share`` of ``made``'s brightest channel (or
    ``now``'s, if brighter), in each channel."""
    scale = max(max(made), max(now), 1e-6)
    return float(np.abs(np.subtract(made, now)).max()) <= share * scale


def turned_within(made: Sequence[float], now: Sequence[float], degrees: float) -> bool:
    """Whether direction ``now`` is within ``degrees`` of ``made`` (neither need be unit)."""
    a, b = np.array(made, np.float64), np.array(now, np.float64)
    cosine = float(a @ b) / float(np.linalg.norm(a) * np.linalg.norm(b))
    return cosine >= np.cos(np.radians(degrees))


def sun_relights(made: Sequence[tuple], now: Sequence[tuple], degrees: float = SKY_CUBE_LAG_DEGREES,
                 share: float = SKY_CUBE_TINT_LAG) -> bool:
    """Whether the directional lights ``now`` light things otherwise than ``made``, past
    what a probe's capture may lag them (``degrees`` of turn, ``share`` of colour: by default
    ``SKY_CUBE_LAG_DEGREES`` and ``SKY_CUBE_TINT_LAG``; with ``SAME_SUN_DEGREES`` and
    ``SAME_SUN_TINT``, past a rounding): each a ``sun_states`` row, in creation order.  A light
    that came or went, or changed in anything but its direction, colour and intensity (its
    shadows, their map, its bounces), relights at once."""
    if len(made) != len(now):
        return True
    for (entity_a, towards_a, rgb_a, rest_a), (entity_b, towards_b, rgb_b, rest_b) in zip(made, now, strict=True):
        if entity_a != entity_b or rest_a != rest_b or not turned_within(towards_a, towards_b, degrees) \
                or not colour_within(rgb_a, rgb_b, share):
            return True
    return False


def sun_states(world: World) -> tuple[tuple, ...]:
    """Each directional light as ``sun_relights`` compares them, in creation order: (entity,
    direction, colour x intensity, its other fields)."""
    rows = []
    for entity, light in sorted(world.query_one(DirectionalLight), key=lambda pair: pair[0]):
        rgb = raw_field(light, "color").xyz * light.intensity
        rest = tuple(raw_field(light, name) for name in _SUN_REST)
        rows.append((entity, tuple(light.direction), (float(rgb.x), float(rgb.y), float(rgb.z)), rest))
    return tuple(rows)


# A directional light's fields besides those a turning sun changes (its shadows, their map,
# its bounces): a change to one relights at once.
_SUN_REST = tuple(field.name for field in dataclasses.fields(DirectionalLight)
                  if field.name not in ("direction", "color", "intensity"))


def kept_sun_ways(world: World, limits: LightLimits,
                  kept: KeptLights | None = None) -> tuple[tuple[float, float, float], ...]:
    """The ways the kept directional lights' light travels (the suns of ``kept``, by default
    ``kept_lights``', that shine), unit vectors: what a water's thrown-up caustics lean out
    along (``caustics.reach_box``)."""
    ways = []
    for entity in (kept or kept_lights(world, limits)).directional:
        light = None if entity is None else world.try_get(entity, DirectionalLight)
        if light is not None and light.intensity > 0.0:
            way = glm.normalize(glm.vec3(raw_field(light, "direction")))
            ways.append((float(way.x), float(way.y), float(way.z)))
    return tuple(ways)


def kept_lamp_places(world: World, limits: LightLimits,
                     kept: KeptLights | None = None) -> tuple[tuple[float, float, float], ...]:
    """Where the kept point lights that shine stand (the lamps of ``kept``, by default
    ``kept_lights``'), world: what a water's thrown-up caustics reach out from
    (``caustics.reach_box``)."""
    places = []
    for entity in (kept or kept_lights(world, limits)).point:
        light = None if entity is None else world.try_get(entity, PointLight)
        transform = None if light is None or light.intensity <= 0.0 else world.try_get(entity, Transform)
        if transform is not None:
            m = transform.world
            places.append((float(m[3].x), float(m[3].y), float(m[3].z)))
    return tuple(places)


def kept_lights(world: World, limits: LightLimits) -> KeptLights:
    """The choice the prepare stage published this frame, or, where it has not run (a stage
    run alone), a first choice made now (not stored)."""
    kept = world.resources.get(KeptLights)
    return kept if kept is not None else choose_lights(world, None, limits)


def choice_stands(world: World, kept: KeptLights) -> bool:
    """Whether ``kept`` is this frame's choice as it is (the module's "When"): no light came,
    went or changed, no point light moved, got or lost its Transform (its own or a parent's:
    the transform stage lists both in ``frame.moved``), and, where the choice depends on the
    eyes (``kept.by_eye``), the active camera did not move (nor another become active) and its
    views' eyes are where they were (``view_eyes``).  The prepare stage's test and
    ``lights_this_frame``'s, one rule."""
    if world.changed(DirectionalLight) or world.changed(PointLight):
        return False
    frame = world.frame
    moved, added, removed = frame.moved, frame.added, frame.removed
    if (moved or added or removed) and any(entity in moved or entity in added or entity in removed
                                           for entity, _ in world.query_one(PointLight)):
        return False
    if not kept.by_eye:
        return True
    camera = frame_rules(world).active_camera
    return camera == kept.camera and (camera is None or camera not in moved) and view_eyes(world) == kept.views


def lights_this_frame(world: World, limits: LightLimits) -> KeptLights:
    """The choice the prepare stage will make this frame, made ahead of it (not stored): the
    last one published where it stands (``choice_stands``, the prepare stage's own test),
    else from it by the same rule, so a stage before the prepare stage (the extract stage's
    keying of rows under waters) sees a light new this frame."""
    kept = world.resources.get(KeptLights)
    if kept is not None and choice_stands(world, kept):
        return kept
    return choose_lights(world, kept, limits)


@world_invariant(Skybox)
def check_one_sky(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """Refuse a second Skybox in a world: the sky drawn, its light from all round and its sun
    are the world's one sky's (a Skybox's fields change it; another would leave which one
    shows to chance)."""
    if not isinstance(joining, Skybox):
        return
    others = [other for other, _ in world.query_one(Skybox) if other != entity]
    if others:
        raise ComponentValueError(f"Skybox on entity {entity}: entity {min(others)} holds the world's Skybox "
                                  "already, and a world has one sky; change that one's fields, or remove it first")
