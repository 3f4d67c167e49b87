"""The level editor's handles and framing, as geometry (GL-free): where an entity's move,
turn and scale handles stand on the main view's screen (``transform_handles``), which of them
the mouse is on, what a drag along or round one asks for (``Handles.distance``,
``Handles.sweep``), what a selected light, probe, emitter or decal reaches (``reach_outline``),
the markers of the lights, probes, emitters and decals that have no mesh to click (``markers``,
``marker_at``), and where
a camera stands to frame an entity (``framing_eye``).  The overlay (``shell/overlay.py``)
draws them and drags them; the edits they make are the editor's (``Editor.move``,
``Editor.turn``, ``Editor.rescale``: ``shell/editor.py``).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from pyglm import glm

from components import (
    Decal,
    DirectionalLight,
    FogVolume,
    IrradianceVolume,
    MeshRef,
    ParticleEmitter,
    PointLight,
    ReflectionProbe,
    Transform,
)
from engine.core.transforms import current_world_matrix
from engine.core.world import World
from engine.rules.probe_rules import world_bounds

GIZMO_SHARE = 0.15  # a handle's world length (a ring's radius): this share of its distance from the eye
HANDLE_MODES = ("move", "turn", "scale")
AXES = (glm.vec3(1.0, 0.0, 0.0), glm.vec3(0.0, 1.0, 0.0), glm.vec3(0.0, 0.0, 1.0))
RING_POINTS = 48    # points on a turn handle's ring

Pixel = tuple[float, float]


@dataclasses.dataclass(frozen=True)
class Handles:
    """An entity's transform handles as the main view shows them, in output pixels from the
    top left: one a world axis (``move``, ``turn``), or one an axis of its own (``scale``: the
    scale is the entity's own), each a line from its origin (``move``, ``scale``) or a ring
    about it (``turn``), ``GIZMO_SHARE`` of its distance from the eye long (a constant size
    on screen)."""

    mode: str
    origin: Pixel
    axes: tuple[glm.vec3, ...]             # the world direction each handle stands for
    lines: tuple[tuple[Pixel, ...], ...]   # each handle on screen: [origin, end], or its ring's points
    length: float                          # a handle's world length (a ring's radius)
    toward_eye: tuple[bool, ...]           # each axis points to the eye's side of the origin

    def nearest(self, point: Pixel, reach: float) -> int | None:
        """The handle passing within ``reach`` pixels of ``point``, the nearest; None for none."""
        best, found = reach, None
        p = glm.vec2(point)
        for index, line in enumerate(self.lines):
            ring = line + line[:1] if self.mode == "turn" else line
            for a, b in zip(ring, ring[1:], strict=False):
                a, b = glm.vec2(a), glm.vec2(b)
                segment = b - a
                along = glm.clamp(glm.dot(p - a, segment) / max(glm.dot(segment, segment), 1e-9), 0.0, 1.0)
                gap = glm.length(p - (a + segment * along))
                if gap <= best:
                    best, found = gap, index
        return found

    def distance(self, axis: int, moved: Pixel) -> float:
        """(``move``, ``scale``) The world distance along ``axis`` a mouse moved by ``moved``
        pixels asks for: its part along the handle on screen, at the handle's scale."""
        origin, end = self.lines[axis]
        segment = glm.vec2(end) - glm.vec2(origin)
        pixels = glm.length(segment)
        if pixels < 1e-6:  # the axis points at the eye: it cannot be dragged along
            return 0.0
        return glm.dot(glm.vec2(moved), segment / pixels) * self.length / pixels

    def sweep(self, axis: int, before: Pixel, now: Pixel) -> float:
        """(``turn``) The angle about ``axis`` (radians, right-handed) that the mouse moving
        from ``before`` to ``now`` sweeps about the origin on screen: counter-clockwise on
        screen is positive about an axis pointing to the eye."""
        o = glm.vec2(self.origin)
        a, b = glm.vec2(before) - o, glm.vec2(now) - o
        if glm.length(a) < 1e-6 or glm.length(b) < 1e-6:
            return 0.0
        clockwise = math.atan2(a.x * b.y - a.y * b.x, glm.dot(a, b))  # rows run down the screen
        return -clockwise if self.toward_eye[axis] else clockwise


def screen_point(view_proj: glm.mat4, size: tuple[int, int], point: glm.vec3) -> Pixel | None:
    """Where world ``point`` lands on an output of ``size`` seen through ``view_proj``, in
    pixels from the top left; None behind the eye."""
    clip = view_proj * glm.vec4(point, 1.0)
    if clip.w <= 1e-6:
        return None
    return ((clip.x / clip.w * 0.5 + 0.5) * size[0], (0.5 - clip.y / clip.w * 0.5) * size[1])


def view_ray(view_proj: glm.mat4, size: tuple[float, float], pixel: Pixel) -> tuple[glm.vec3, glm.vec3]:
    """The ray through ``pixel`` (output pixels from the top left) of a view of ``size``: its
    start on the near plane and its unit direction (``screen_point`` the other way; an
    orthographic view's rays are parallel)."""
    inverse = glm.inverse(view_proj)
    x = pixel[0] / size[0] * 2.0 - 1.0
    y = 1.0 - pixel[1] / size[1] * 2.0
    near = inverse * glm.vec4(x, y, -1.0, 1.0)
    far = inverse * glm.vec4(x, y, 1.0, 1.0)
    start = glm.vec3(near) / near.w
    return start, glm.normalize(glm.vec3(far) / far.w - start)


def descendants(world: World, entity: int) -> set[int]:
    """Every entity whose Transform's parent chain leads to ``entity`` (its children, theirs...)."""
    children: dict[int, list[int]] = {}
    for child, transform in world.query_one(Transform):
        if transform.parent is not None:
            children.setdefault(transform.parent, []).append(child)
    found: set[int] = set()
    todo = [entity]
    while todo:
        for child in children.get(todo.pop(), ()):
            if child not in found and child != entity:
                found.add(child)
                todo.append(child)
    return found


def transform_handles(world: World, entity: int, view_proj: glm.mat4, eye: glm.vec3, size: tuple[int, int],
                      mode: str = "move") -> Handles | None:
    """``entity``'s handles of ``mode`` (``HANDLE_MODES``) in the view ``view_proj`` (from
    ``eye``) on an output of ``size`` pixels; None when it has no Transform or a handle is
    behind the eye."""
    if mode not in HANDLE_MODES:
        raise ValueError(f"no handles {mode!r} (modes: {', '.join(HANDLE_MODES)})")
    transform = world.try_get(entity, Transform)
    if transform is None:
        return None
    matrix = current_world_matrix(world, transform)
    origin = glm.vec3(matrix[3])
    length = GIZMO_SHARE * max(glm.length(origin - glm.vec3(eye)), 1e-3)
    if view_proj[0][3] == 0.0 and view_proj[1][3] == 0.0 and view_proj[2][3] == 0.0:
        # An orthographic view (its rays parallel): as long on screen as from a 60-degree
        # camera, whatever the distance; its clip y grows by |row 1| a world unit.
        across = glm.length(glm.vec3(view_proj[0][1], view_proj[1][1], view_proj[2][1]))
        length = GIZMO_SHARE / (max(across, 1e-9) * math.tan(math.radians(30.0)))
    axes = AXES
    if mode == "scale":
        axes = tuple(glm.normalize(glm.vec3(matrix[i])) if glm.length(glm.vec3(matrix[i])) > 1e-9 else AXES[i]
                     for i in range(3))

    if mode == "turn":
        worlds = []
        for i in range(3):
            u, v = AXES[(i + 1) % 3], AXES[(i + 2) % 3]
            worlds.append([origin + length * (math.cos(t) * u + math.sin(t) * v)
                           for t in (2.0 * math.pi * k / RING_POINTS for k in range(RING_POINTS))])
    else:
        worlds = [[origin, origin + axis * length] for axis in axes]
    centre = screen_point(view_proj, size, origin)
    lines = [[screen_point(view_proj, size, point) for point in line] for line in worlds]
    if centre is None or any(p is None for line in lines for p in line):
        return None
    toward = tuple(glm.dot(axis, glm.vec3(eye) - origin) > 0.0 for axis in axes)
    return Handles(mode, centre, axes, tuple(tuple(line) for line in lines), length, toward)


OUTLINE_POINTS = 48   # points on a light outline's circle
CONE_EDGES = 4        # lines from a spot's apex to its cone's far circle


@dataclasses.dataclass(frozen=True)
class ReachOutline:
    """What a selected light or probe reaches, as the main view shows it (as Unity and Godot
    draw them): a spot light's cone (its apex, ``CONE_EDGES`` lines along its edge and the
    circle where they end, ``range`` metres from the apex), a light all round's range sphere
    (a circle about each world axis), a sun's direction (an arrow from where it stands, or,
    with no Transform, from ``SUN_ARROW_AHEAD`` metres ahead of the eye), or a reflection
    probe's influence box (its twelve edges, and the box inside where its weight is whole
    when it has a ``blend_distance``).
    ``world``: each polyline's points (closed circles repeat their first point); ``lines``:
    the same on screen, output pixels from the top left."""

    world: tuple[tuple[glm.vec3, ...], ...]
    lines: tuple[tuple[Pixel, ...], ...]


def reach_outline(world: World, entity: int, view_proj: glm.mat4, size: tuple[int, int]) -> ReachOutline | None:
    """``entity``'s ``ReachOutline`` in the view ``view_proj`` on an output of ``size``: its
    sun's arrow, its point light's reach, its particle emitter's launch cone, its decal's box
    (and the way it throws), its irradiance volume's box (and where its blend starts), its fog
    volume's ellipsoid (where its axes' planes cut it), else
    its probe's influence box; None when it has
    none of them (or no Transform, but for a sun; or a probe serving only its own entity).
    A polyline with a point behind the eye is left out (the rest still show)."""
    transform = world.try_get(entity, Transform)
    sun = world.try_get(entity, DirectionalLight)
    if sun is not None:
        anchor = glm.vec3(current_world_matrix(world, transform)[3]) if transform is not None \
            else _ahead(view_proj, SUN_ARROW_AHEAD)
        worlds = _sun_arrow(anchor, glm.vec3(sun.direction))
    elif transform is None:
        return None
    elif (light := world.try_get(entity, PointLight)) is not None:
        worlds = _light_reach(light, current_world_matrix(world, transform))
    elif (emitter := world.try_get(entity, ParticleEmitter)) is not None:
        worlds = _emitter_reach(emitter, current_world_matrix(world, transform))
    elif world.has(entity, Decal):
        worlds = _decal_box(current_world_matrix(world, transform))
    elif (volume := world.try_get(entity, IrradianceVolume)) is not None:
        centre = glm.vec3(current_world_matrix(world, transform)[3])
        worlds = _influence_box(centre, glm.vec3(volume.size), volume.blend_distance)
    elif (fog := world.try_get(entity, FogVolume)) is not None:
        worlds = _ellipsoid(current_world_matrix(world, transform), glm.vec3(fog.size))
    else:
        probe = world.try_get(entity, ReflectionProbe)
        if probe is None or probe.influence is None:
            return None
        centre = glm.vec3(current_world_matrix(world, transform)[3])
        worlds = _influence_box(centre, glm.vec3(probe.influence), probe.blend_distance)
    kept_world, kept_lines = [], []
    for line in worlds:
        pixels = [screen_point(view_proj, size, point) for point in line]
        if all(p is not None for p in pixels):
            kept_world.append(tuple(line))
            kept_lines.append(tuple(pixels))
    return ReachOutline(tuple(kept_world), tuple(kept_lines))


SUN_ARROW_AHEAD = 5.0   # metres ahead of the eye a sun's arrow starts (a sun has no place)
SUN_ARROW_LENGTH = 1.5  # metres


def _ahead(view_proj: glm.mat4, distance: float) -> glm.vec3:
    """The point ``distance`` metres ahead of the eye along the middle of the view.  The eye
    is what a perspective view-projection sends to clip w = 0 on its axis (clip (0, 0, 1, 0)
    brought back); the middle of the far plane gives the way."""
    inverse = glm.inverse(glm.dmat4(view_proj))
    at_eye, far = inverse * glm.dvec4(0.0, 0.0, 1.0, 0.0), inverse * glm.dvec4(0.0, 0.0, 1.0, 1.0)
    eye, toward = glm.dvec3(at_eye) / at_eye.w, glm.dvec3(far) / far.w
    return glm.vec3(eye + glm.normalize(toward - eye) * distance)


def _sun_arrow(anchor: glm.vec3, direction: glm.vec3) -> list[tuple[glm.vec3, ...]]:
    """An arrow from ``anchor`` the way a sun's light travels (``SUN_ARROW_LENGTH`` long,
    four barbs at its head)."""
    d = glm.normalize(direction)
    tip = anchor + d * SUN_ARROW_LENGTH
    helper = glm.vec3(0.0, 1.0, 0.0) if abs(d.y) < 0.9 else glm.vec3(1.0, 0.0, 0.0)
    u = glm.normalize(glm.cross(d, helper))
    v = glm.cross(d, u)
    barb = 0.2 * SUN_ARROW_LENGTH
    return [(anchor, tip), *((tip, tip - d * barb + side * (0.5 * barb)) for side in (u, -u, v, -v))]


def _influence_box(centre: glm.vec3, influence: glm.vec3, blend: float) -> list[tuple[glm.vec3, ...]]:
    """A probe's influence box about ``centre`` (world axes, ``influence`` wide: the box
    ``probe_rules.probe_weight`` weighs), and the box ``blend`` inside it, as edges."""
    boxes = [influence * 0.5]
    if blend > 0.0:
        boxes.append(influence * 0.5 - glm.vec3(blend))
    edges = []
    for half in boxes:
        corners = [centre + glm.vec3(x * half.x, y * half.y, z * half.z)
                   for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
        for a in range(8):
            for bit in (1, 2, 4):
                if not a & bit:
                    edges.append((corners[a], corners[a | bit]))
    return edges


def _decal_box(matrix: glm.mat4) -> list[tuple[glm.vec3, ...]]:
    """A decal's box (its Transform's unit cube: the twelve edges) and an arrow from the middle
    of its image's face the way it is thrown (-z), as polylines."""
    corners = [glm.vec3(matrix * glm.vec4(x, y, z, 1.0)) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    edges = [(corners[a], corners[a | bit]) for a in range(8) for bit in (1, 2, 4) if not a & bit]
    start, tip = glm.vec3(matrix * glm.vec4(0.0, 0.0, 0.5, 1.0)), glm.vec3(matrix * glm.vec4(0.0, 0.0, -0.5, 1.0))
    return [*edges, (start, tip)]


def _light_reach(light: PointLight, matrix: glm.mat4) -> list[tuple[glm.vec3, ...]]:
    """A point light's cone (a spot) or range sphere, as polylines."""
    forward = -glm.vec3(matrix[2])
    axis = glm.normalize(forward) if glm.length(forward) > 1e-9 else glm.vec3(0.0, 0.0, -1.0)
    return _cone(glm.vec3(matrix[3]), axis, float(light.spot_angle), float(light.range))


def _emitter_reach(emitter: ParticleEmitter, matrix: glm.mat4) -> list[tuple[glm.vec3, ...]]:
    """A particle emitter's launch cone (its ``direction`` and ``spread``, the emitter's frame)
    as long as its fastest particle flies in its longest life (its drag slowing it; gravity
    left out: the cone is where they set off), as polylines."""
    axis = glm.vec3(glm.mat3(matrix) * glm.vec3(emitter.direction))
    axis = glm.normalize(axis) if glm.length(axis) > 1e-9 else glm.vec3(0.0, 1.0, 0.0)
    speed, life = emitter.speed[1], emitter.lifetime[1]
    flight = speed * life if emitter.drag <= 0.0 else speed / emitter.drag * (1.0 - math.exp(-emitter.drag * life))
    return _cone(glm.vec3(matrix[3]), axis, float(emitter.spread), min(max(flight, MIN_EMITTER_REACH),
                                                                       MAX_EMITTER_REACH))


MIN_EMITTER_REACH, MAX_EMITTER_REACH = 0.25, 100.0  # metres an emitter's outline is long, at least and at most


def _ellipsoid(matrix: glm.mat4, size: glm.vec3) -> list[tuple[glm.vec3, ...]]:
    """A fog volume's ellipsoid (``size`` across along the unit axes of ``matrix``, its
    scale left out, about its position): the three ellipses where its axes' planes cut it,
    as closed polylines."""
    centre = glm.vec3(matrix[3])
    axes = [glm.normalize(glm.vec3(matrix[i])) * (0.5 * size[i]) if glm.length(glm.vec3(matrix[i])) > 1e-9
            else AXES[i] * (0.5 * size[i]) for i in range(3)]
    steps = [2.0 * math.pi * k / OUTLINE_POINTS for k in range(OUTLINE_POINTS + 1)]
    return [tuple(centre + math.cos(t) * axes[i] + math.sin(t) * axes[(i + 1) % 3] for t in steps) for i in range(3)]


def _cone(apex: glm.vec3, axis: glm.vec3, half_angle: float, reach: float) -> list[tuple[glm.vec3, ...]]:
    """The cone of ``half_angle`` degrees about the unit ``axis`` from ``apex``, ``reach`` long
    (its rim circle and ``CONE_EDGES`` edges), or at 180 degrees the sphere of that radius
    (three great circles), as polylines."""
    steps = [2.0 * math.pi * k / OUTLINE_POINTS for k in range(OUTLINE_POINTS + 1)]
    if half_angle < 180.0:
        helper = glm.vec3(0.0, 1.0, 0.0) if abs(axis.y) < 0.9 else glm.vec3(1.0, 0.0, 0.0)
        u = glm.normalize(glm.cross(axis, helper))
        v = glm.cross(axis, u)
        theta = math.radians(half_angle)
        centre, radius = apex + axis * (reach * math.cos(theta)), reach * math.sin(theta)
        circle = tuple(centre + radius * (math.cos(t) * u + math.sin(t) * v) for t in steps)
        edges = [(apex, circle[k * OUTLINE_POINTS // CONE_EDGES]) for k in range(CONE_EDGES)]
        return [circle, *edges]
    return [tuple(apex + reach * (math.cos(t) * AXES[(i + 1) % 3] + math.sin(t) * AXES[(i + 2) % 3])
                  for t in steps) for i in range(3)]


MARKER_REACH = 10.0   # pixels (at scale 1) from a marker that a click selects it


@dataclasses.dataclass(frozen=True)
class Marker:
    """An entity with no mesh to click (a lamp, a spot, a probe) drawn as a marker where it
    stands: ``kind`` "light", "probe", "emitter", "decal", "volume" or "fog", ``at`` its place on
    screen (output pixels from the top left)."""

    entity: int
    kind: str
    at: Pixel


def markers(world: World, view_proj: glm.mat4, size: tuple[int, int]) -> list[Marker]:
    """The markers in view (in front of the eye, inside the output): each entity with a
    Transform and a point light, a reflection probe, a particle emitter, a decal or an
    irradiance volume or a fog volume but no visible mesh, which the id images cannot pick (an entity with a
    mesh is picked where it shows; particles write no id; a decal's cut mesh is picked as the
    decal, but it may cut nothing)."""
    found = []
    for kind, component in (("light", PointLight), ("probe", ReflectionProbe), ("emitter", ParticleEmitter),
                            ("decal", Decal), ("volume", IrradianceVolume), ("fog", FogVolume)):
        for entity, _ in world.query_one(component):
            transform, mesh_ref = world.try_get(entity, Transform), world.try_get(entity, MeshRef)
            if transform is None or (mesh_ref is not None and mesh_ref.visible):
                continue
            at = screen_point(view_proj, size, glm.vec3(current_world_matrix(world, transform)[3]))
            if at is not None and 0.0 <= at[0] < size[0] and 0.0 <= at[1] < size[1]:
                found.append(Marker(entity, kind, at))
    return found


def marker_at(found: list[Marker], point: Pixel, reach: float) -> int | None:
    """The entity of the marker nearest ``point`` within ``reach`` pixels; None for none."""
    best, entity = reach, None
    for marker in found:
        gap = math.hypot(marker.at[0] - point[0], marker.at[1] - point[1])
        if gap <= best:
            best, entity = gap, marker.entity
    return entity


FRAME_MARGIN = 1.3  # framing a selection: its bounding sphere fills this much less than the view's height


def framing_eye(world: World, entity: int, forward: glm.vec3, fov_y_degrees: float) -> glm.vec3 | None:
    """Where an eye looking along ``forward`` stands to frame ``entity``: its bounding sphere
    (``framing_sphere``) centred in view and filling the view's height less
    ``FRAME_MARGIN``; None when it has no Transform.  The view keeps its direction, as an
    editor's "frame selected" does."""
    found = framing_sphere(world, entity)
    if found is None:
        return None
    centre, radius = found
    distance = radius * FRAME_MARGIN / math.tan(math.radians(fov_y_degrees) / 2.0)
    return centre - glm.normalize(glm.vec3(forward)) * distance


def framing_sphere(world: World, entity: int) -> tuple[glm.vec3, float] | None:
    """``entity``'s bounding sphere as framing sees it: its mesh's world box's, or a metre
    across about its origin (None: no Transform).  An orthographic camera frames it by
    standing back along its axis and spanning ``2 x radius x FRAME_MARGIN``."""
    transform = world.try_get(entity, Transform)
    if transform is None:
        return None
    matrix = current_world_matrix(world, transform)
    centre, radius = glm.vec3(matrix[3]), 0.5
    mesh = world.try_get(entity, MeshRef)
    if mesh is not None:
        lo, hi = world_bounds(mesh.mesh, matrix)
        centre = glm.vec3(*((lo + hi) / 2.0))
        radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-3)
    return centre, radius
