"""Particles: an emitter of camera-facing sprites (sparks, smoke, dust, fire).

The emitter is plain data here; the particles stage (``systems/particle_system.py``) spawns
and moves its particles (``engine/core/particle_cloud.py``), and every view (the main
camera's, each mirror's and portal's) draws them in among its glass
(``engine/render/particle_draw.py``)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.limits import MAX_PARTICLE_LIFETIME, MAX_PARTICLES, MAX_SHEET_CELLS
from components.tracking import (
    ComponentValueError,
    TrackedComponent,
    boolean,
    choice,
    color,
    direction,
    finite,
    integer,
    vec3,
)
from components.transform import POSITION_MAX

# Assets are the engine's types (engine.assets.texture_data.TextureData); components import none
# of it: the field is checked by the class's ASSET_KIND.
TextureData = Any

PARTICLE_BLENDS = ("additive", "alpha")
PARTICLE_SHAPES = ("point", "sphere", "box", "mesh")
PARTICLE_SPACES = ("world", "local")
MAX_PARTICLE_RATE = 1.0e6      # particles a second (max_particles caps what lives anyway)
MAX_PARTICLE_SPEED = 1.0e4     # metres a second
MAX_PARTICLE_SIZE = 1.0e4      # metres across
MAX_PARTICLE_SPIN = 1.0e5      # degrees a second
MAX_PARTICLE_DRAG = 1.0e3      # per second
MAX_PARTICLE_GRAVITY = 1.0e4   # metres a second squared, a component
MAX_PARTICLE_STRETCH = 100.0   # seconds of flight a streak is long
MAX_PREWARM_SECONDS = 10.0     # the most time a prewarm runs (ParticleEmitter.prewarm)
MAX_PARTICLE_KEYS = 16         # keys of a colour or size curve over a particle's life
MAX_PARTICLE_SOFTNESS = 1e3    # metres over which a soft particle fades into what is behind it


@dataclass(eq=False)
class ParticleEmitter(TrackedComponent):
    """Spawns particles at its entity's Transform, as Unity's particle system, Godot's
    CPUParticles3D and three.js's point sprites do: each particle a square that faces the
    view it is drawn in, born at the emitter, flying and fading, then gone.

    - **Emission.**  ``rate`` particles a second while ``playing``, spread evenly through
      each frame (a fast emitter leaves a trail, not clumps), and ``burst`` at once each time
      it starts playing (when it is added playing, or ``playing`` turns True): an explosion
      is ``rate=0, burst=200``.  Stopping leaves the living ones to die out.  ``burst_on``
      names an animation event (``AnimationEvents``): each time one of that name fires on
      the model the emitter hangs under (its entity or a parent is the model's root), while
      playing, ``burst`` are born (a footstep's dust, a sword's sparks), instead of as it
      starts.
    - **Where and which way.**  Born at a point (``shape`` "point"), anywhere in a ball of
      radius ``extent.x`` ("sphere") or a box of half-sizes ``extent`` ("box"), in the
      emitter's frame; flying along ``direction`` (its frame) within a cone of ``spread``
      degrees about it (180: every way) at a speed between ``speed``'s two.  ``shape``
      "mesh": born anywhere on the surface of the entity's ``MeshRef`` mesh (evenly by area)
      and flying out along the face's normal there (within ``spread``; ``direction`` unused):
      sparkles off a mirror's frame, embers off a log.  It needs a MeshRef on the entity.
    - **Flight.**  ``gravity`` (world, m/s^2) pulls, ``drag`` slows (the velocity keeps
      exp(-drag dt)); a "world" space particle that flies into an open portal comes out of
      its partner, carried as a traveller is; ``ground`` (a world height; None: none) is a
      floor they bounce off, keeping ``bounce`` of their speed into it (0: they stop on it
      and slide).  ``space`` "world": a particle stays where it was born when the emitter
      moves (smoke from a torch); "local": the whole cloud moves with it (a jet's glow).
    - **Life.**  Each lives between ``lifetime``'s two seconds; its size goes from
      ``size[0]`` to ``size[1]`` metres across and its colour from ``color`` to
      ``end_color`` (None: ``color`` at alpha 0, so it fades out) over its life; or, given,
      along ``size_keys`` ((life share, metres), ...) and ``color_keys`` ((life share, r, g,
      b, a), ...): a curve through the keys, straight between them, held before the first and
      after the last (fire: yellow, orange, red, then smoke grey).  It starts turned
      between ``angle``'s two degrees about the view's axis (a sprite that must stay upright:
      ``(0, 0)``) and spins at between ``spin``'s two degrees a second.
    - **Look.**  ``texture`` its sprite (its alpha its shape; None: a round soft spot),
      ``sheet`` (columns, rows) a flipbook on it played once over a particle's life, left to
      right, top row first.  ``blend`` "additive": its light adds to what is behind (sparks,
      fire, glow; colour past 1 blooms), in any order; "alpha": it covers what is behind by its
      alpha (smoke, dust), the farthest drawn first in each view.  ``lit`` False: its colour
      is its light (unlit); True: its colour is an albedo lit by the sun, lamps, their light
      through mirrors and portals and the light from all round where it is, with their
      shadows, as a thin sheet facing
      the viewer that lets ``translucency`` of the light through from behind (smoke lit by a
      lamp behind it glows at its edge of the lamp).  ``stretch`` (seconds) above 0 draws
      each as a streak along its flight as the view sees it, its size across and ahead, its
      speed x ``stretch`` long behind (sparks, rain: Unity's stretched billboards); its angle
      is then the flight's.  ``softness`` (metres) above 0 fades a particle where what is
      behind it is nearer than that (soft particles: smoke meets a floor or wall without a
      hard line), at the cost of a copy of the view's depth a pass that draws one.
    - ``max_particles`` living at once (spawning stops there, counted in
      ``RenderStats.particles_capped``); ``seed`` makes the same cloud again; ``prewarm``
      starts the cloud as it would be after its longest lifetime of playing (Unity's
      prewarm: a torch already smoking on the first frame), stepped at 30 Hz up to
      ``MAX_PREWARM_SECONDS``.
    - ``ribbon``: the particles joined in the order they were born into one band facing
      the view (a trail: Unity's trail and ribbon renderers, Godot's trails): a sword's
      swing, a comet's tail, a light painted through the air behind a moving emitter, each
      particle a point of it, its size the band's width there and its colour the colour
      there (so a trail fades and narrows to its end as its particles age), bent smoothly
      through each point; the texture stretched along it from the newest to the oldest and
      across it (None: soft across its width).  Drawn as a whole, in no order of its own;
      ``angle``, ``spin``, ``stretch`` and ``sheet`` do not apply.  A point carried through a
      portal starts a new band beyond it.
    - ``on_death``: another emitter's entity (a sub-emitter), whose ``burst`` is born where
      each of these particles dies, flying by its own settings (fireworks: a rocket's spark
      climbs, and bursts where it ends), whether it plays or not (give it ``playing`` False
      for no births of its own).  An entity with no ParticleEmitter is said once and left
      alone.

    A particle is not an entity: it casts no shadow, is not picked, is not sliced where it
    straddles a portal's plane, and a reflection probe's capture leaves particles out (a
    probe is redrawn on its own schedule, so its faces would hold a still frame of them).
    """

    rate: float = 20.0
    burst: int = 0
    playing: bool = True
    lifetime: Any = (1.0, 1.0)
    speed: Any = (1.0, 1.0)
    direction: Any = field(default_factory=lambda: glm.vec3(0.0, 1.0, 0.0))
    spread: float = 15.0
    shape: str = "point"
    extent: Any = field(default_factory=lambda: glm.vec3(0.0))
    gravity: Any = field(default_factory=lambda: glm.vec3(0.0))
    drag: float = 0.0
    size: Any = (0.1, 0.1)
    color: Any = field(default_factory=lambda: glm.vec4(1.0))
    end_color: Any = None
    blend: str = "additive"
    texture: TextureData | None = None
    sheet: Any = (1, 1)
    spin: Any = (0.0, 0.0)
    angle: Any = (0.0, 360.0)
    space: str = "world"
    max_particles: int = 1000
    seed: int = 0
    lit: bool = False
    translucency: float = 0.5
    stretch: float = 0.0
    ground: float | None = None
    bounce: float = 0.3
    softness: float = 0.0
    burst_on: str = ""
    color_keys: Any = ()
    size_keys: Any = ()
    prewarm: bool = False
    on_death: int | None = None
    ribbon: bool = False

    def _validate(self, name: str, value: Any) -> Any:
        if name == "rate":
            return finite(self, name, value, low=0.0, high=MAX_PARTICLE_RATE)
        if name == "burst":
            return integer(self, name, value, low=0, high=MAX_PARTICLES)
        if name == "on_death":
            return None if value is None else integer(self, name, value, low=1, high=2**31 - 1)
        if name in ("playing", "lit", "prewarm", "ribbon"):
            return boolean(self, name, value)
        if name == "lifetime":
            return self._range(name, value, low=0.0, high=MAX_PARTICLE_LIFETIME, positive=True)
        if name == "speed":
            return self._range(name, value, low=0.0, high=MAX_PARTICLE_SPEED)
        if name == "size":
            return self._pair(name, value, low=0.0, high=MAX_PARTICLE_SIZE)
        if name == "spin":
            return self._range(name, value, low=-MAX_PARTICLE_SPIN, high=MAX_PARTICLE_SPIN)
        if name == "angle":
            return self._range(name, value, low=-360.0, high=360.0)
        if name == "direction":
            return direction(self, name, value)
        if name == "spread":
            return finite(self, name, value, low=0.0, high=180.0)
        if name == "shape":
            value = choice(self, name, value, PARTICLE_SHAPES)
            world = getattr(self, "_world_ref", None)
            if world is not None:
                for entity in self._entities:  # a mesh to be born on, as at spawn
                    world.check_invariants(entity, ParticleEmitter, shape=value)
            return value
        if name == "extent":
            # (Further out than a Transform may stand, a particle is born nowhere it could be drawn.)
            return vec3(self, name, value, low=0.0, high=POSITION_MAX, why=" metres (Transform's POSITION_MAX)")
        if name == "gravity":
            g = vec3(self, name, value)
            if max(abs(c) for c in g) > MAX_PARTICLE_GRAVITY:
                raise ComponentValueError(f"ParticleEmitter.gravity must have components within "
                                          f"+-{MAX_PARTICLE_GRAVITY:g} m/s^2, got {value!r}")
            return g
        if name == "drag":
            return finite(self, name, value, low=0.0, high=MAX_PARTICLE_DRAG)
        if name == "color":
            return color(self, name, value)
        if name == "end_color":
            return None if value is None else color(self, name, value)
        if name == "blend":
            return choice(self, name, value, PARTICLE_BLENDS)
        if name == "space":
            value = choice(self, name, value, PARTICLE_SPACES)
            if value == "local" and self.__dict__.get("ground") is not None:
                raise ComponentValueError('ParticleEmitter.space cannot be "local" with a ground (a world height): '
                                          "set ground to None first")
            return value
        if name == "texture" and value is not None:
            if getattr(type(value), "ASSET_KIND", None) != "texture":
                raise ComponentValueError("ParticleEmitter.texture must be an engine.assets.texture_data.TextureData, "
                                          f"got {type(value).__name__}")
            return value
        if name == "sheet":
            try:
                columns, rows = value
            except (TypeError, ValueError):
                raise ComponentValueError(f"ParticleEmitter.sheet must be two ints (columns, rows), "
                                          f"got {value!r}") from None
            whole = [int(v) if isinstance(v, float) and v.is_integer() else v for v in (columns, rows)]  # (dragged)
            return (integer(self, "sheet", whole[0], low=1, high=MAX_SHEET_CELLS),
                    integer(self, "sheet", whole[1], low=1, high=MAX_SHEET_CELLS))
        if name == "max_particles":
            return integer(self, name, value, low=1, high=MAX_PARTICLES)
        if name == "seed":
            return integer(self, name, value, low=0, high=2**63 - 1)
        if name == "translucency":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "stretch":
            return finite(self, name, value, low=0.0, high=MAX_PARTICLE_STRETCH)
        if name == "ground":
            if value is None:
                return None
            if self.__dict__.get("space") == "local":
                raise ComponentValueError('ParticleEmitter.ground is a world height: give it to a "world" space '
                                          f'emitter, not a "local" one, got {value!r}')
            height = finite(self, name, value)
            if abs(height) > POSITION_MAX:
                raise ComponentValueError(f"ParticleEmitter.ground must be within {POSITION_MAX:g} m of y = 0 (a "
                                          f"world height: no Transform stands further out), got {value!r}")
            return height
        if name == "bounce":
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "color_keys":
            return self._keys(name, value, 5, lambda key: (key[0], *color(self, name, key[1:])))
        if name == "size_keys":
            return self._keys(name, value, 2, lambda key: (key[0], finite(self, name, key[1], low=0.0,
                                                                             high=MAX_PARTICLE_SIZE)))
        if name == "burst_on":
            if not isinstance(value, str):
                raise ComponentValueError(f"ParticleEmitter.burst_on must be an animation event's name (a str; \"\": "
                                          f"none), got {value!r}")
            return value
        if name == "softness":
            return finite(self, name, value, low=0.0, high=MAX_PARTICLE_SOFTNESS)
        return value

    def _keys(self, name: str, value: Any, width: int, check) -> tuple[tuple[float, ...], ...]:
        """A curve over a particle's life: keys (share of its life 0 to 1, value...), the
        shares increasing; each key's value checked by ``check``."""
        try:
            keys = [tuple(key) for key in value]
        except TypeError:
            raise ComponentValueError(f"ParticleEmitter.{name} must be keys (life share, ...), got {value!r}") from None
        if len(keys) > MAX_PARTICLE_KEYS:
            raise ComponentValueError(f"ParticleEmitter.{name} holds at most {MAX_PARTICLE_KEYS} keys, got {len(keys)}")
        checked = []
        for key in keys:
            if len(key) != width and not (width == 5 and len(key) == 4):
                raise ComponentValueError(f"ParticleEmitter.{name}: a key is (life share, "
                                          f"{'r, g, b[, a]' if width == 5 else 'size'}), got {key!r}")
            share = finite(self, name, key[0], low=0.0, high=1.0)
            checked.append(check((share, *key[1:])))
        if any(b[0] <= a[0] for a, b in zip(checked, checked[1:], strict=False)):
            raise ComponentValueError(f"ParticleEmitter.{name}: the keys' life shares must increase, got {value!r}")
        return tuple(tuple(float(v) for v in key) for key in checked)

    def _pair(self, name: str, value: Any, low: float, high: float, positive: bool = False) -> tuple[float, float]:
        """Two numbers (one is both), each finite in [low, high] (> 0 when ``positive``)."""
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = (value, value)
        try:
            first, second = value
        except (TypeError, ValueError):
            raise ComponentValueError(f"ParticleEmitter.{name} must be a number or two numbers, "
                                      f"got {value!r}") from None
        return (finite(self, name, first, low=low, high=high, positive=positive),
                finite(self, name, second, low=low, high=high, positive=positive))

    def _range(self, name: str, value: Any, low: float, high: float, positive: bool = False) -> tuple[float, float]:
        """A (least, most) pair: ``_pair``'s, the first not above the second."""
        least, most = self._pair(name, value, low, high, positive)
        if least > most:
            raise ComponentValueError(f"ParticleEmitter.{name} must be (least, most) with least <= most, "
                                      f"got {value!r}")
        return (least, most)

    @property
    def final_color(self) -> glm.vec4:
        """The colour at death: ``end_color``, or ``color`` at alpha 0."""
        end = self.end_color
        return glm.vec4(glm.vec3(self.color), 0.0) if end is None else glm.vec4(end)

    @property
    def frames(self) -> int:
        """The flipbook's frames (``sheet``'s columns x rows)."""
        return self.sheet[0] * self.sheet[1]
