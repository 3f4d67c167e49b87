"""The frame's public data: what one stage publishes for the later ones, and what games and
tools read (``world.resources[Type]``).  Plain data: no GL objects, no packed bytes, and no
import of ``engine/render`` (importing this module imports no GL library).

- ``Surfaces`` (the surfaces stage): every mirror and portal as a ``SurfaceState``: its
  plane, outline, where its view goes (``carry``), its look; a game traces rays with them
  (mirror beam) as the view tree draws with them.
- ``PortalCrossings`` (the travel stage): who went through which portal, with the pair's
  ``carry`` and ``turn``, so a game turns what it keeps itself (a body's velocity) by the
  rotation the engine turned the camera with.
- ``RenderStats`` (``engine/frame_stats.py``, made fresh by ``shell.app.Engine.frame``): what
  the frame cost, and, as a ``BudgetLedger``, what its ``ViewBudget`` allowed and was spent on.
- ``ViewBudget`` (``engine/core/budget.py``): the frame's budget a game or level file sets.

Other resources live with their owners: ``Input`` and ``Output`` (``engine/core/frame_io.py``,
the shell's), ``FrameRules`` (the rules stage: ``engine/rules/frame_rules.py``),
``ShadowCasters`` (the shadows stage: ``engine/rules/shadow_rules.py``), ``ProbeSchedule`` and
``ProbeStates`` (the probes' scheduler: ``engine/rules/probe_schedule.py``).  What the render
stages hand each other is theirs, beside the passes: the main view and the targets it was
drawn into (``engine.render.frame_views.FrameViews``), the planner's table of these surfaces
(``PlannerSurfaces``) and the probes each surface falls back to (``SurfaceBlends``, the
extract stage's), both in ``engine.render.surface_table``.  Games import engine data from
here and from ``components``; one that picks through the last frame's main view reads
``FrameViews`` (mirror beam).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pyglm import glm

from components.limits import ALL_LAYERS
from components.visibility import DRAWN_EVERYWHERE
from engine.assets.texture_data import TextureData
from engine.core.budget import ViewBudget, ViewBudgetError
from engine.frame_stats import BudgetLedger, RenderStats

__all__ = ["BudgetLedger", "MirrorBumps", "PicturesDrawn", "PortalCrossing", "PortalCrossings", "RenderStats",
           "SurfaceMotion", "SurfaceState", "Surfaces", "ViewBudget", "ViewBudgetError", "WaterFlow", "WaterLook"]



@dataclass(frozen=True, eq=False)
class MirrorBumps:
    """A mirror's normal map (``Material.normal_map``) as its composite reads it: the map,
    its scale, and the mirror's UVs as a function of world position on its plane (rows: u
    and v as ``dot(row.xyz, p) + row.w``; SurfaceSystem fits them to the mesh)."""

    normal_map: TextureData
    scale: float
    uv_rows: np.ndarray          # (2, 4) float64
    plane_offset: float          # d of the mirror's world plane n.p + d = 0


@dataclass(eq=False)
class WaterFlow:
    """Where a water surface's waves are this frame (``components.Water.offset``: the first
    normal-map layer's shift in map tiles, u and v, each in [0, 1)), as its composite reads
    it.  The surfaces stage copies it in place every frame: one object per water entity for
    its life, shared by each SurfaceState made for it, so the state is not made again only
    because the waves moved."""

    offset: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True, eq=False)
class WaterLook:
    """A mirror's water (``components.Water``) as its composite reads it: the reflectance
    looking straight down (Schlick's F0 from the index), the second layer's share, the
    normal map's repeats across the mirror's UVs, and the waves' offset (``WaterFlow``)."""

    f0: float
    cross: float
    tiling: float
    flow: WaterFlow
    underside: bool = False  # seen from below (Surfaces.undersides): its reflectance from the water's side


@dataclass(eq=False)
class SurfaceState:
    """A mirror or a portal as the passes see it: where it is and where its view goes.  One
    object per surface while it is unchanged (the surfaces stage makes a new one when it
    changes), so what is derived from it can be kept by identity (the renderer's packed
    composite parameters)."""

    entity: int
    kind: str                    # "mirror" or "portal"
    plane: glm.vec4              # world; its normal points to the side it is seen from
    corners: np.ndarray          # world corners, homogeneous rows
    outline: np.ndarray | None   # for a flat surface: its 4 world corners as a 2 x 2 grid (a quad), else None
    carry: glm.mat4              # takes the parent camera to this surface's view (a reflection, or the pair)
    exit_plane: glm.vec4         # what the view keeps: the mirror's front, or the look-out portal's front
    exit_entity: int             # the surface the view looks out of: the mirror itself, or the partner
    max_depth: int
    enabled: bool = True
    tint: glm.vec4 = field(default_factory=lambda: glm.vec4(1.0))
    reflect_rate: float = 1.0
    roughness: float = 0.0
    resolution_scale: float = 1.0
    bumps: MirrorBumps | None = None  # a mirror's normal map, as its composite reads it
    water: WaterLook | None = None    # a mirror that is water: Fresnel weight and moving waves
    layers: int = ALL_LAYERS     # the reflection layers its view shows (components/limits.py)
    drawn: int = DRAWN_EVERYWHERE  # where the surface itself is drawn: the kinds of view it is hidden in
                                   # and its own layers (none: not drawn), packed as an instance's code
                                   # (engine/rules/visibility_rules.py entity_code); layer 0 unless told
    priority: int = 0            # the view budget keeps higher priorities first (Mirror.priority, Portal.priority)
    end_image: bool | str = "auto"  # past the depth limit, last frame's image: True, False, or "auto" (facing pairs)
    fade: tuple[float, float, float, float] | None = None  # a mirror's fades: distance start, end (m), angle
                                                           # start, end (degrees); None: no fade
    carries_light: bool = False  # Mirror.reflects_light, Portal.carries_light: lights shine through it


@dataclass
class Surfaces:
    """This frame's mirrors and portals by entity (a world resource, from the surfaces stage).

    A water's state faces up, its top; ``undersides`` holds each water's state seen from
    below (its plane turned to face down, ``WaterLook.underside``).  The view trees' planner
    holds both (``engine/render/surface_table.py``): each view, at any level, sees the side
    facing its eye.  Lights, probes' fallbacks and the other stages read the tops."""

    mirrors: dict[int, SurfaceState]
    portals: dict[int, SurfaceState]
    undersides: dict[int, SurfaceState] = field(default_factory=dict)

    def mirror_planes(self) -> dict[int, tuple[list[float], list[float]]]:
        """Each mirror's world plane as (point on it, unit normal towards its front)."""
        planes = {}
        for entity, state in self.mirrors.items():
            n = glm.vec3(state.plane)
            planes[entity] = (list(-state.plane.w * n), list(n))
        return planes


@dataclass
class SurfaceMotion:
    """The mirrors and portals whose view moved since the last frame (a world resource, from
    the surfaces stage, every frame): each one's ``SurfaceState.carry`` as it was then, by
    entity (a mirror that moved or turned; a portal that moved, or whose partner did).  Temporal
    AA and motion blur follow what such a view shows by it (``MirrorPasses.surface_motion``):
    a reflection moves on the picture as its mirror turns, not only as the camera does."""

    before: dict[int, glm.mat4] = field(default_factory=dict)


@dataclass(frozen=True)
class ContactLamps:
    """The point and spot lights whose light the active camera's ``ContactShadows`` takes too
    (``PointLight.contact_shadows``; a world resource, from the prepare stage): each one's
    world position, by channel (the channel + 1 is in its Lights block row: scene.frag), at
    most ``MAX_CONTACT_LAMPS``; ``cut``: those flagged that reach the scene past them."""

    positions: tuple[tuple[float, float, float], ...] = ()
    cut: int = 0


@dataclass(frozen=True)
class VolumetricLamps:
    """The point and spot lights whose light the active camera's ``VolumetricFog`` scatters
    (``PointLight.volumetric`` above 0; a world resource, from the prepare stage): each one's
    slot in the Lights block and its ``volumetric``, at most ``MAX_VOLUMETRIC_LAMPS``, the
    first by slot; ``cut``: those past them."""

    slots: tuple[int, ...] = ()
    scatter: tuple[float, ...] = ()
    cut: int = 0


@dataclass(frozen=True)
class CloudChanges:
    """How many times the world's clouds have changed past what a reflection probe's capture
    may lag them (came, went, changed, or drifted past ``clouds.shadows_served``; a world
    resource, from the prepare stage): the probe scheduler relights every probe when it moves on."""

    count: int = 0


@dataclass(frozen=True)
class PicturesDrawn:
    """The screens whose ``Monitor`` pictures were drawn (a world resource, from the monitor
    stage): ``count`` moves on each frame it draws any, ``screens`` are that frame's.  A picture
    drawn again changes what its screen looks like, as a new material would: the probe
    scheduler, which runs before the monitor stage, counts those screens as changed looks at
    its next update (an ``on_change`` probe recaptures the faces that see them).  ``first``:
    those of ``screens`` drawn for the first time (their screens were black till then: a
    ``once`` or ``scripted`` probe captured before recaptures the faces that see them)."""

    count: int = 0
    screens: frozenset[int] = frozenset()
    first: frozenset[int] = frozenset()


@dataclass(frozen=True)
class FiredEvent:
    """An ``AnimationEvents`` event the playback of ``clip`` passed on ``entity`` (a model's
    root): its ``name`` and ``time`` in the clip; ``layer`` True where the root's
    ``AnimationLayer`` played it, not its ``Animation``."""

    entity: int
    clip: str
    name: str
    time: float
    layer: bool = False


class FiredEvents(list):
    """The animation events of the latest frame's models stage, in the order each root's
    playback met them (list of FiredEvent); ``dropped`` counts those a frame left out
    (``engine.core.clip_events.MAX_EVENTS_A_FRAME`` a clip)."""

    dropped: int = 0


@dataclass(frozen=True)
class PortalCrossing:
    """``entity`` went into ``from_portal`` and came out of ``to_portal``; ``carry`` took it
    there (world to world: the pair's transform) and ``turn`` is carry's rotation, what a
    game turns a facing it keeps itself by.  A velocity it keeps goes by
    ``engine.core.portal_math.carried_velocity(carry, turn, velocity)``: turned, and scaled
    where the pair's portals differ in scale, as a Traveller's is (by the pair's one factor:
    through ``glm.mat3(carry)``'s float32 a speed drifts a little each time there and back)."""

    entity: int
    from_portal: int
    to_portal: int
    carry: glm.mat4 = field(default_factory=glm.mat4, compare=False)
    turn: glm.quat = field(default_factory=glm.quat, compare=False)


class PortalCrossings(list):
    """The crossings of the latest frame, in the order they happened (list of PortalCrossing)."""
