"""The app shell's core: a game and the engine that runs it (one world, its systems in
stage order, one renderer).  The shell is the one place systems are wired into a world;
the rest of ``engine`` never imports ``systems``.

A frame is ``FRAME_STAGES`` in order, one system each (ARCHITECTURE.md says what each
does and where its code is), with the game's own systems (``Game.systems``: each a
``GameSystem`` that runs after and before named stages) ordered in among them when the
Engine is made (``engine.core.game.schedule_order``); ``Engine.schedule`` is the result, the
frame as it runs.  A new stage is a new entry here; what a later stage needs from an
earlier one is a world resource (``Output``, ``FrameViews``, ``RenderStats``,
``PortalCrossings``), never a reference to the other system; the engine calls a system
only through its own methods.
"""
from __future__ import annotations

import argparse
import sys
import traceback
from collections.abc import Callable
from dataclasses import replace

import esper
import moderngl

from components import (
    AmbientOcclusion,
    Camera,
    CloudLayer,
    ContactShadows,
    DepthOfField,
    DirectionalLight,
    FlyController,
    Fog,
    Mirror,
    MotionBlur,
    Portal,
    ScreenReflections,
    Skybox,
    TimeOfDay,
    Transform,
    VolumetricFog,
    yaw_pitch_rotation,
)
from engine.core.errors import AssetError, GLPassError, StartOptionError
from engine.core.frame_io import Input, Output
from engine.core.game import Game, GameSystem, schedule_order
from engine.core.world import FrameEvents, World
from engine.render.bindings import invalidate
from engine.render.frame_views import FrameViews
from engine.render.gl_context import prepare_context
from engine.render.raw_gl import make_current
from engine.render.renderer import Renderer
from engine.render.views import View
from engine.resources import RenderStats, ViewBudget
from engine.rules.frame_rules import active_camera_parts
from engine.rules.light_rules import brightest_directional
from shell.level_reload import POLL_INTERVAL as RELOAD_INTERVAL
from shell.level_reload import LevelReload
from systems import (
    ExtractSystem,
    FlyCameraSystem,
    MainViewSystem,
    PortalTravelSystem,
    PrepareSystem,
    PresentSystem,
    ReflectionSystem,
    TransformSystem,
)
from systems.cloud_system import CloudSystem
from systems.decal_system import DecalSystem
from systems.detail_system import DetailSystem
from systems.frame_rules_system import FrameRulesSystem
from systems.irradiance_volume_system import IrradianceVolumeSystem
from systems.model_system import ModelSystem
from systems.monitor_system import MonitorSystem
from systems.particle_system import ParticleSystem
from systems.portal_slice_system import PortalSliceSystem
from systems.probe_system import ProbeAfterPresentSystem, ProbeSystem
from systems.ripple_system import RippleSystem
from systems.shadow_system import ShadowSystem
from systems.surface_system import SurfaceSystem
from systems.text_system import TextSystem
from systems.time_of_day_system import TimeOfDaySystem

# --shafts on a camera without a Fog: thin air (a thing 50 m off keeps 22% of its light).
SHAFTS_FOG_DENSITY = 0.03


class GameGuard:
    """Runs the game's own code in a frame (its ``update``, its systems) and, where ``contain``
    is set (the window shell: a level being edited there must not be lost to the game's
    error), stops it at its first exception instead of ending the program: the traceback is
    printed, ``stopped`` says where and what, and until ``resume`` the game's code is left
    out of the frames while the engine's stages run on (the world is drawn, the editor
    works: undo, save).  Unset (headless runs, tests), an exception ends the frame as ever."""

    def __init__(self) -> None:
        self.contain = False
        self.stopped: str | None = None  # "<stage>: <exception>" where the game stopped

    def call(self, stage: str, run: Callable[[float], None], dt: float) -> None:
        if self.stopped is not None:
            return
        if not self.contain:
            run(dt)
            return
        try:
            run(dt)
        except Exception as exc:  # the game's code: any error it raises stops it, not the window
            self.stopped = f"{stage}: {type(exc).__name__}: {exc}"
            print(f"speculum: the game stopped in {stage} (F5 resumes it):", file=sys.stderr)
            traceback.print_exc()

    def resume(self) -> None:
        """Run the game's code again from the next frame."""
        self.stopped = None


def _guarded(guard: GameGuard, stage: str, process: Callable[[float], None]) -> Callable[[float], None]:
    return lambda dt: guard.call(stage, process, dt)


class GameUpdateSystem(esper.Processor):
    """The game stage: the game's own ``update``."""

    def __init__(self, game: Game, world: World, guard: GameGuard) -> None:
        self.game = game
        self.world = world
        self.guard = guard

    def process(self, dt: float) -> None:
        self.guard.call("game", lambda step: self.game.update(self.world, step), dt)


class GameSystemProcessor(esper.Processor):
    """A game system given as ``function(world, dt)``, run in its place in the schedule."""

    def __init__(self, system: GameSystem, world: World, guard: GameGuard) -> None:
        self.system = system
        self.world = world
        self.guard = guard

    def process(self, dt: float) -> None:
        self.guard.call(self.system.name, lambda step: self.system.system(self.world, step), dt)


class LateTransformSystem(esper.Processor):
    """"transform_late": world matrices again, after game systems that run between the
    transform stage and extract (the schedule puts one after each such run of them), so the
    Transforms they write are drawn this frame.  The transform stage's system works out
    every Transform changed this frame again (its change set lasts the frame) and
    ``world.frame`` becomes what both passes saw."""

    def __init__(self, world: World, transform: esper.Processor) -> None:
        self.world = world
        self.transform = transform

    def process(self, dt: float) -> None:
        earlier = self.world.frame
        self.transform.process(dt)
        later = self.world.frame
        removed = earlier.removed | later.removed
        added = (earlier.added | later.added) - removed
        self.world.frame = FrameEvents(moved=(earlier.moved | later.moved) - added - removed, added=added,
                                       removed=removed)


# (stage, what makes its system from the engine).  Order is execution order.
FRAME_STAGES: tuple[tuple[str, Callable[[Engine], esper.Processor]], ...] = (
    ("game", lambda e: GameUpdateSystem(e.game, e.world, e.game_guard)),
    ("models", lambda e: ModelSystem(e.world)),  # the parts of each Model placed, changed or deleted
    ("rules", lambda e: FrameRulesSystem(e.world)),  # open portal pairs, active camera: FrameRules
    ("input", lambda e: FlyCameraSystem(e.world)),
    ("sun", lambda e: TimeOfDaySystem(e.world)),  # each TimeOfDay's clock moved on, its light turned
    ("clouds", lambda e: CloudSystem(e.world)),  # each CloudLayer's clouds moved on the wind
    ("travel", lambda e: PortalTravelSystem(e.world)),
    ("slice", lambda e: PortalSliceSystem(e.world)),
    ("transform", lambda e: TransformSystem(e.world)),
    ("surfaces", lambda e: SurfaceSystem(e.world)),
    ("detail", lambda e: DetailSystem(e.world)),  # each LevelOfDetail's mesh by its distance from the eyes
    # each Decal's surfaces cut into its mesh (a new part's Transform worked out at once: settle)
    ("decals", lambda e: DecalSystem(e.world, LateTransformSystem(e.world, e.stages["transform"]).process)),
    ("extract", lambda e: ExtractSystem(e.world, e.renderer)),
    ("particles", lambda e: ParticleSystem(e.world, e.renderer)),  # every emitter's particles stepped and uploaded
    ("prepare", lambda e: PrepareSystem(e.world, e.renderer)),
    ("ripples", lambda e: RippleSystem(e.world, e.renderer)),  # each rippling water's height field stepped
    ("shadows", lambda e: ShadowSystem(e.world, e.renderer)),
    ("probes", lambda e: ProbeSystem(e.world, e.renderer)),
    ("volume", lambda e: IrradianceVolumeSystem(e.world, e.renderer)),  # the irradiance volume's points
    ("monitors", lambda e: MonitorSystem(e.world, e.renderer)),  # each Monitor's picture, from its camera
    ("main", lambda e: MainViewSystem(e.world, e.renderer)),
    ("reflect", lambda e: ReflectionSystem(e.world, e.renderer)),
    ("present", lambda e: PresentSystem(e.world, e.renderer)),
    ("text", lambda e: TextSystem(e.world, e.renderer)),  # screen text over the presented frame
    ("probes_after", lambda e: ProbeAfterPresentSystem(e.world, e.renderer)),  # recaptures, for the next frame
)


def start_lens() -> DepthOfField:
    """``--dof``'s lens: a portrait lens wide open, focusing on the picture's middle by itself
    (the camera's own field of view would make a wide, deep-focus lens: nothing to see)."""
    return DepthOfField(f_stop=1.4, focal_length=85.0, max_blur=0.04, autofocus=True)


class Engine:
    """Owns a game's world and renderer on a given GL context."""

    def __init__(self, game: Game, ctx: moderngl.Context) -> None:
        # The game's systems are checked and ordered first: a ScheduleError makes nothing.
        order = schedule_order([name for name, _ in FRAME_STAGES], game.systems(), f"{type(game).__name__}.systems()",
                               reserved=("transform_late",))
        make_current(ctx)  # everything below makes GL objects on it
        caps = prepare_context(ctx)
        invalidate(ctx)  # whatever used the context before this engine: its first passes set everything
        self.game = game
        self.ctx = ctx
        self.world = World(game.title)
        self.world.resources[Input] = Input()  # the shell fills it, systems and the game read it
        self.renderer = Renderer(ctx, caps)
        self.game_guard = GameGuard()  # the game's code: an error ends the frame, or (contain) stops the game
        self.stages: dict[str, esper.Processor] = {}
        for name, make in FRAME_STAGES:
            self.stages[name] = make(self)
        # Light goes no deeper through mirrors and portals than the main view tree's views.
        self.stages["shadows"].depth_cap = lambda: self.stages["reflect"].max_depth_cap
        # The main view draws unlit the mirrors that tree paints over entirely.
        self.stages["main"].depth_cap = lambda: self.stages["reflect"].max_depth_cap
        # The frame as it runs: (name, system), stages and game systems in schedule order.
        self.schedule: list[tuple[str, esper.Processor]] = []
        stage_names = [name for name, _ in FRAME_STAGES]
        transformed = False  # past the transform stage, before extract
        for index, item in enumerate(order):
            if isinstance(item, str):
                self.schedule.append((item, self.stages[item]))
                transformed = stage_names.index(item) >= stage_names.index("transform") and \
                    stage_names.index(item) < stage_names.index("extract")
                continue
            if callable(getattr(item.system, "process", None)):  # a processor: its process guarded
                system = item.system
                # (its own process: one an engine before this one guarded is guarded anew)
                own = system.__dict__.get("_unguarded_process") or system.process
                system._unguarded_process = own
                system.process = _guarded(self.game_guard, item.name, own)
            else:
                system = GameSystemProcessor(item, self.world, self.game_guard)
            self.schedule.append((item.name, system))
            following = order[index + 1] if index + 1 < len(order) else None
            if transformed and isinstance(following, str):
                self.schedule.append(("transform_late", LateTransformSystem(self.world, self.stages["transform"])))
        for index, (_, system) in enumerate(self.schedule):
            self.world.add_system(system, priority=len(self.schedule) - index)
        self.level_reload: LevelReload | None = None  # ``watch_level``: the level file reloads on save
        try:
            game.build(self.world)
        except BaseException:
            self.close()
            raise

    def watch_level(self, interval: float = RELOAD_INTERVAL) -> LevelReload:
        """Reload the game's level file when it is saved (``shell.level_reload``): the shell
        calls ``level_reload.poll()`` before each frame and says what it returns.  A game not
        built from a level file is refused (a SpeculumError)."""
        # A game stopped at an error (``GameGuard``) runs again in the world built afresh.
        self.level_reload = LevelReload(self.game, self.world, interval, on_reload=self.game_guard.resume)
        return self.level_reload

    @property
    def reflection_system(self) -> ReflectionSystem:
        """The reflect stage (its settings are the main view tree's limits and path)."""
        return self.stages["reflect"]

    @property
    def main_view(self) -> View | None:
        """The last frame's main view (None before the first frame, or with no camera)."""
        views = self.world.resources.get(FrameViews)
        return views.main if views is not None else None

    def frame(self, dt: float, output: Output | None) -> None:
        """Run every stage once; the frame is drawn into ``output``.

        The engine's context is made current first (``raw_gl.make_current``): another GL
        context made in the process (a window, a tool's) would otherwise receive this
        engine's draws.  Code that sets GL state on the context between frames other than
        through ``engine.render.bindings`` (its own moderngl draws, raw GL) calls
        ``bindings.invalidate(ctx)`` after it, as the debug overlay does: the state the
        engine's passes set is kept from frame to frame and only what changed is set again."""
        if output is None:
            self.world.resources.pop(Output, None)
        else:
            self.world.resources[Output] = output
        make_current(self.ctx)
        # The pass-state cache (engine/render/bindings.py) carries over from the last frame:
        # what it holds is still bound unless code outside the engine set GL state since, and
        # such code says so with ``bindings.invalidate`` (the debug overlay does after it
        # draws), so a frame binds only what another pass displaced, not everything again.
        pending = self.ctx.error
        if pending != "GL_NO_ERROR":
            # Not this engine's: left by code that used the context since the last frame.
            raise GLPassError(f"OpenGL error {pending} was pending before frame {self.world.frame_index + 1} "
                              "(left by other code on this context, not by the engine)")
        # This frame's counters, fresh: a world resource for whoever reads them after the
        # frame, and where the renderer's passes count while it runs.
        checks = self.renderer.path_checks
        budget = ViewBudget.of(self.world.resources) or ViewBudget()  # checked: a bad one is one error line
        stats = RenderStats(paths_verified=checks.verified(), paths_refused=checks.refused(),
                            view_budget=budget.views, probe_ms_budget=budget.probe_ms, pixel_budget=budget.pixels,
                            min_view_pixels=budget.min_pixels)
        self.world.resources[RenderStats] = self.renderer.stats = stats
        self.world.step(dt)
        self.world.resources[Input].end_frame()
        if self.renderer.needs_preparing:
            # The batches this frame made (the level's, on its first frame) get every
            # program a view may draw them with now, not when a mirror first comes into view.
            surfaces = [s for _, s in self.world.query_one(Mirror)] + [s for _, s in self.world.query_one(Portal)]
            scale = max((getattr(s, "resolution_scale", 1.0) for s in surfaces), default=None)
            self.renderer.prepare_programs(bool(surfaces) and self.reflection_system.path != "per_mirror", scale,
                                           levels=bool(surfaces))
            if surfaces:
                self.reflection_system.prepare()
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error after frame {self.world.frame_index}: {error}")

    def active_camera(self) -> tuple[int, Camera, Transform] | None:
        """(entity, Camera, Transform) of the camera the main view looks through, or None
        (``engine.rules.frame_rules.active_camera_parts``; the rule is ``active_camera`` there)."""
        return active_camera_parts(self.world)

    def place_camera(self, x: float, y: float, z: float, yaw: float, pitch: float) -> None:
        """Move the active camera (``--camera``); yaw 0 looks down -Z, degrees."""
        active = self.active_camera()
        if active is None:
            raise StartOptionError("--camera given but the level has no active Camera")
        entity, _, transform = active
        transform.position = (x, y, z)
        transform.rotation = yaw_pitch_rotation(yaw, pitch)
        fly = self.world.try_get(entity, FlyController)
        if fly is not None:
            fly.yaw, fly.pitch = yaw, pitch

    def start(self, antialias: str = "fxaa", camera: tuple[float, float, float, float, float] | None = None,
              occlusion: bool = False, reflections: bool = False, focus: bool = False,
              motion: bool = False, render_scale: float = 1.0, sharpness: float = 0.0,
              frame_ms: float | None = None, contact: bool = False, shafts: bool = False) -> None:
        """The command line's start options (``shell/runner.py``), after the game is built: the
        anti-aliasing, the render scale and sharpening (``--render-scale``, ``--sharpen``:
        ``engine/render/resample.py``), dynamic resolution's frame time (``--frame-ms``: the
        world's ``ViewBudget.frame_ms``), the camera's pose (``--camera``: ``place_camera``), and screen-space
        ambient occlusion and reflections, depth of field, motion blur and contact shadows
        (``--ao``, ``--ssr``, ``--dof``, ``--motion-blur``, ``--contact-shadows``: an
        ``AmbientOcclusion()``, a ``ScreenReflections()``, a ``DepthOfField`` of an 85 mm lens
        at f/1.4 focusing by itself (``start_lens``), a ``MotionBlur()`` and a
        ``ContactShadows()`` on the active camera, where it has none of its own), and light
        shafts (``--shafts``: a ``VolumetricFog()`` and, where the camera has no ``Fog``, a
        thin one, ``Fog(density=SHAFTS_FOG_DENSITY)``), to see any game or level with them
        without editing it."""
        self.renderer.antialias = antialias
        self.renderer.render_scale = render_scale
        self.renderer.sharpness = sharpness
        if frame_ms is not None:   # (--frame-ms: the level's budget, if any, with it)
            budget = ViewBudget.of(self.world.resources)
            self.world.resources[ViewBudget] = replace(budget or ViewBudget(), frame_ms=frame_ms)
        if camera:
            self.place_camera(*camera)
        for asked, make, flag in ((occlusion, AmbientOcclusion, "--ao"), (reflections, ScreenReflections, "--ssr"),
                                  (focus, start_lens, "--dof"), (motion, MotionBlur, "--motion-blur"),
                                  (contact, ContactShadows, "--contact-shadows")):
            if not asked:
                continue
            active = self.active_camera()
            if active is None:
                raise StartOptionError(f"{flag} given but the level has no active Camera")
            component = make()
            if not self.world.has(active[0], type(component)):
                self.world.add_component(active[0], component)
        if shafts:
            active = self.active_camera()
            if active is None:
                raise StartOptionError("--shafts given but the level has no active Camera")
            if not self.world.has(active[0], Fog):
                self.world.add_component(active[0], Fog(density=SHAFTS_FOG_DENSITY))
            if not self.world.has(active[0], VolumetricFog):
                self.world.add_component(active[0], VolumetricFog())

    def start_from(self, args: argparse.Namespace) -> None:
        """``start`` with the command line's options (``shell/runner.py``'s parser; headless and
        windowed alike)."""
        self.start(args.aa, args.camera, getattr(args, "ao", False), getattr(args, "ssr", False),
                   getattr(args, "dof", False), getattr(args, "motion_blur", False),
                   getattr(args, "render_scale", 1.0), getattr(args, "sharpen", 0.0), getattr(args, "frame_ms", None),
                   getattr(args, "contact_shadows", False), getattr(args, "shafts", False))
        self.start_sky(getattr(args, "sky", None), getattr(args, "time", None), getattr(args, "day_minutes", None),
                       getattr(args, "panorama", None), getattr(args, "panorama_yaw", 0.0), getattr(args, "moon", None),
                       getattr(args, "clouds", None), getattr(args, "panorama_sun", False),
                       getattr(args, "altitude", None))

    def start_sky(self, model: str | None, hour: float | None = None, day_minutes: float | None = None,
                  panorama: str | None = None, panorama_yaw: float = 0.0, moon_age: float | None = None,
                  clouds: float | None = None, panorama_sun: bool = False, altitude: float | None = None) -> None:
        """The command line's sky options: ``--sky`` draws the level's Skybox (one made if it has
        none) as ``model`` ("atmosphere": a physically based sky with a night's stars beyond its
        air, ``engine.assets.star_field.star_faces``); ``--panorama`` makes its faces an
        equirectangular panorama file (``engine.assets.panorama.sky_faces_from_file``, 512 texels a
        face, turned ``panorama_yaw`` degrees; a gradient sky's faces are its whole sky, an
        atmosphere's the space beyond its air); ``--panorama-sun`` takes the panorama's sun out
        of it and gives its light, direction and size to the brightest ``DirectionalLight``
        (one made if there is none; ``engine/assets/panorama_sun.py``); ``--time`` puts a ``TimeOfDay`` at ``hour``
        (a summer's day, 45 degrees north) on the brightest ``DirectionalLight`` (one made if there
        is none), moving a whole day on in ``day_minutes`` of game time (``--day-minutes``);
        ``--moon`` adds a moon ``moon_age`` days old on the same clock (a dim, cool
        ``DirectionalLight`` whose body is "moon", casting no shadow); ``--clouds`` puts a
        ``CloudLayer`` of that coverage on the Skybox (one made if it has none; a level's own
        layer takes the coverage), drifting on a 10 m/s wind; ``--altitude`` stands the level
        ``altitude`` metres above sea level under its atmosphere (``Skybox.altitude``; a
        gradient sky has no air to thin: refused)."""
        world = self.world
        if panorama is not None:
            from engine.assets.panorama import sky_faces_from_file

            skies = world.query_one(Skybox)
            sky = skies[0][1] if skies else world.get(world.spawn(Skybox()), Skybox)
            try:
                sky.faces = sky_faces_from_file(panorama, 512, panorama_yaw, without_sun=panorama_sun)
            except AssetError as error:   # (the file's own error, said as the option's)
                raise StartOptionError(f"--panorama: {error}") from None
            if sky.faces.sun is not None:
                light = brightest_directional(world)
                if light is None:
                    light = world.get(world.spawn(DirectionalLight()), DirectionalLight)
                for name, value in sky.faces.sun.light_fields().items():
                    setattr(light, name, value)
        if model is not None:
            skies = world.query_one(Skybox)
            sky = skies[0][1] if skies else world.get(world.spawn(Skybox()), Skybox)
            if model == "atmosphere" and sky.faces is None:
                from engine.assets.star_field import star_faces

                sky.faces = star_faces()
            sky.model = model
        if altitude is not None:
            skies = world.query_one(Skybox)
            if not skies or skies[0][1].model != "atmosphere":
                raise StartOptionError(f"--altitude {altitude:g}: the level's sky is not an atmosphere (a gradient "
                                       "sky has no air to thin): add --sky atmosphere")
            skies[0][1].altitude = altitude
        if clouds is not None:
            layers = world.query_one(CloudLayer)
            if layers:
                layers[0][1].coverage = clouds
            else:
                skies = world.query_one(Skybox)
                entity = skies[0][0] if skies else world.spawn(Skybox())
                world.add_component(entity, CloudLayer(coverage=clouds))
        if hour is not None:
            light = brightest_directional(world)
            entity = next((e for e, candidate in world.query_one(DirectionalLight) if candidate is light), None)
            if entity is None:
                entity = world.spawn(DirectionalLight(intensity=4.0))
            speed = 0.0 if day_minutes is None else 24.0 / (60.0 * day_minutes)
            world.add_component(entity, TimeOfDay(hour=hour, hours_per_second=speed))
            if moon_age is not None:
                world.spawn(DirectionalLight(color=(0.75, 0.85, 1.0), intensity=0.08, shadows=False, body="moon"),
                            TimeOfDay(hour=hour, hours_per_second=speed, moon_age=moon_age))

    def close(self) -> None:
        """Delete every entity, release every GL resource, drop the world."""
        make_current(self.ctx)
        self.world.close()
        self.renderer.release()
