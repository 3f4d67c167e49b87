"""Monitors' pictures (``components.Monitor``): what a camera sees, drawn into a texture its
screen shows (render to texture, as a security camera's feed in a game).

**How a picture is drawn.**  The monitor stage (``systems/monitor_system.py``) gives each due
monitor its camera's ``View``; ``MonitorPictures.draw`` draws it with the scene pass every
view is drawn with, into a level stack of the picture's size (the same targets as the main
view's: colour, ids, depth), as a root: the mirrors and portals in it get their own view
tree to the monitor's ``depth`` (``ViewTree``, one for every monitor: its per-root records are
kept by the view's name), or show their fallbacks at depth 0; then, as the main view's root,
its waters' foam, its refracting surfaces and its glass (``ScenePass.finish_root``: a
picture at depth 0, or of a world with no mirror, refracts as the camera's view does).  The colour (linear HDR, what
the camera sees before any tone curve) is then copied into the picture and its mips built.

**How it is shown.**  Each picture has a stand-in ``TextureData`` (a texel; never uploaded)
that the GPU holds as the picture (``Gpu.hold_texture``): the extract stage gives the
monitor's screen that stand-in as its emissive map (and ``Monitor.brightness`` as its
emission), so the screen's batch samples the picture as any batch samples its emissive map,
in every view (a mirror that sees the screen shows its picture).  The picture a screen shows
is copied at the end of its drawing, so a monitor its own camera sees shows its picture of
the draw before, never the one being drawn (no texture is read while it is written).

**What a drawing read.**  Each drawing of a picture gives it a new ``version`` (a new
picture, black, has one too), and notes the pictures its views may have shown, with their
versions then (``shown``: the screens, batches whose emissive map is a picture, whose
instances' boxes reach any of its views' volumes, ``batch_cull.batch_reach``, conservative,
less a flat one-sided screen a view sees from behind), and whether it read anything from
before the frame (``repeatable``: no end view showing last frame's image, no level drawn on
last frame's visibility counts).  What the drawings moved ``Gpu.scene_version`` on by is kept
apart (``scene_version``: the scene's version less the pictures'), so the monitor stage
can tell a picture whose camera, scene and shown pictures are as they were at its last
drawing, and keep it rather than draw it again (``MonitorSystem.keep_still_pictures``).
So are the reflection probes' captures, probe by probe (``ProbeCaptures.moved_by``): a
drawing notes the probes it may have sampled, with their stamps then (``probes_read``),
and is as it was while those are (``probes_unchanged``).  A probe the picture could not
sample is no input of it: were every capture one, an every-frame probe that sees the
screen would draw the picture again after each capture, and that picture (a new version)
the probe's face that shows it, a face and a picture every frame of a still scene.

A picture is made black (a GPU hands back new textures holding anything), remade at a new
size, and let go with its monitor; the batch that samples it keeps it until it goes too."""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Protocol

import moderngl
import numpy as np
from pyglm import glm

from components.fog import VolumetricFog
from components.screen_reflections import ScreenReflections
from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitError
from engine.render.batch_cull import batch_reach
from engine.render.bindings import PassState, apply_pass_state
from engine.render.gpu import Gpu
from engine.render.scene_options import TREE_ROOT
from engine.render.scene_pass import ScenePass
from engine.render.surface_table import NO_BLENDS, SurfaceBlends
from engine.render.targets import HDR_FORMAT, LevelStack, release_framebuffer
from engine.render.tree_walk import TreeSettings
from engine.render.view_plan import SurfaceTable
from engine.render.view_tree import ViewTree
from engine.render.views import View
from engine.resources import VolumetricLamps


class ProbeStamps(Protocol):
    """What a picture reads of the reflection probes' captures (``engine.render.probes.
    ProbeCaptures``, which imports this module: named by its shape, not imported)."""

    moved_by: dict[int, int]   # probe -> the stamp of its last capture that moved the version
    boxed: set[int]            # the probes whose last capture had an influence box


MAX_MONITORS = 8   # monitors drawn a frame (the longest waiting; the rest wait a frame: monitors_cut)
# A picture's light shafts: its camera's VolumetricFog, the lamps it scatters, the sun's or
# moon's slot and way, the images' shares (VolumetricFogPass.begin_picture's arguments).
PictureShafts = tuple[VolumetricFog, VolumetricLamps, tuple[int, tuple[float, float, float]] | None,
                      tuple[float, ...]]
_BLIT = PassState()  # the picture's blit into its texture tests nothing but the scissor (none)
# A picture's root, by (its camera's ambient occlusion found, its screen reflections drawn):
# made once, as options are compared by identity.
_ROOTS = {(occluded, reflecting): replace(TREE_ROOT, occlusion=occluded, reflections=reflecting)
          for occluded in (False, True) for reflecting in (False, True)}


@dataclass
class _Picture:
    """One monitor's picture: the texture its screen samples (and a framebuffer over it, which
    the picture is blitted into), the stand-in it is known by, the targets its view is drawn
    into."""

    texture: moderngl.Texture
    framebuffer: moderngl.Framebuffer
    stand_in: TextureData
    levels: LevelStack
    size: tuple[int, int]
    version: int                     # moved on by each drawing (a number no other picture had)
    shown: dict[int, int] = field(default_factory=dict)   # pictures its last drawing showed: their versions
    repeatable: bool = False         # its last drawing read nothing from the frame before
    probes: dict[int, int] = field(default_factory=dict)   # probes its last drawing may have sampled: their stamps
    views: list[View] = field(default_factory=list)   # its last drawing's views (the root, its tree's)


class MonitorPictures:
    """Every monitor's picture, by its entity, drawn through ``scene_pass``."""

    def __init__(self, renderer: Gpu, scene_pass: ScenePass) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self.scene_pass = scene_pass
        self.tree = ViewTree(renderer, scene_pass)
        self._pictures: dict[int, _Picture] = {}
        self._versions = itertools.count(1)
        # How the pictures' trees learn their views' pixels (``ReflectionSystem.visibility``'s
        # choices; "auto": exact on a software rasteriser, predicted on a GPU).  A drawing on
        # predicted counts (last drawing's) is not kept (``repeatable``): the monitor stage
        # draws a picture whose inputs did not change once more with exact counts, then keeps it.
        self.visibility = "auto"
        self._moved_on = 0   # what the drawings moved Gpu.scene_version on by

    @property
    def scene_version(self) -> int:
        """``Gpu.scene_version`` less what drawing pictures moved it on by: the version of
        everything a picture shows but the pictures (which each has its own ``version``)."""
        return self.renderer.scene_version - self._moved_on

    def shown_unchanged(self, entity: int) -> bool:
        """Whether each picture the last drawing of ``entity``'s showed is still the one it showed."""
        pictures = self._pictures
        return all(other in pictures and pictures[other].version == version
                   for other, version in pictures[entity].shown.items())

    def probes_unchanged(self, entity: int, captures: ProbeStamps) -> bool:
        """Whether no probe the last drawing of ``entity``'s picture may have sampled was
        captured since into anything new (``ProbeCaptures.moved_by``, as ``probes_read`` noted it)."""
        moved = captures.moved_by
        return all(moved.get(probe, 0) == count for probe, count in self._pictures[entity].probes.items())

    def probes_read(self, views: list[View], captures: ProbeStamps) -> dict[int, int]:
        """The reflection probes a drawing of ``views`` may have sampled, with the stamps of
        their last captures that moved the version (``ProbeCaptures.moved_by``): the probes
        of the batches whose instances' boxes reach a view (``batch_reach``, conservative: a
        batch's probe, its second and the one taking the rest), and every probe with an
        influence box (``ProbeCaptures.boxed``: its irradiance row lights whatever stands in
        its box, pixel by pixel, and the mirrors' and portals' fallbacks there show its cube).
        A probe with no box lights only what samples it (``probe_rules.probe_blend``)."""
        sampled = set(captures.boxed)
        batches = [batch for batch in self.renderer.batches.values()
                   if batch.count and (batch.probe or batch.second_probe or batch.rest_probe)]
        if batches:
            by_size: dict[tuple[int, int], list[View]] = {}
            for view in views:
                by_size.setdefault(tuple(view.size), []).append(view)
            for size, group in by_size.items():
                for reach in batch_reach(group, size, batches):
                    sampled.update(probe for batch, hit in zip(batches, reach, strict=True) if hit
                                   for probe in (batch.probe, batch.second_probe, batch.rest_probe) if probe)
        return {probe: captures.moved_by.get(probe, 0) for probe in sampled}

    def last_views(self, entities: set[int]) -> list[View]:
        """The views of the last drawings of ``entities``' pictures (what their cameras saw)."""
        return [view for entity in entities if entity in self._pictures for view in self._pictures[entity].views]

    def repeatable(self, entity: int) -> bool:
        """Whether the last drawing of ``entity``'s picture read nothing from before its frame
        (no end view showing last frame's image, no level drawn on last frame's counts): drawn
        again from the same inputs it would be the same."""
        return self._pictures[entity].repeatable

    @property
    def entities(self) -> set[int]:
        """The monitors that have a picture."""
        return set(self._pictures)

    def picture(self, entity: int, size: tuple[int, int]) -> TextureData:
        """The stand-in of monitor ``entity``'s picture of ``size`` (width, height): made black
        the first time, made again at another size (the old one let go)."""
        held = self._pictures.get(entity)
        if held is not None and held.size == tuple(size):
            return held.stand_in
        self.drop(entity)
        limit = self.renderer.caps.max_texture_size
        if max(size) > limit:
            raise GLLimitError(f"Monitor on entity {entity}: a picture of {size[0]}x{size[1]} pixels is over this "
                               f"OpenGL's ({self.renderer.caps.renderer}) {limit} (GL_MAX_TEXTURE_SIZE); make "
                               "Monitor.size smaller")
        texture = self.ctx.texture(tuple(size), 4, dtype=HDR_FORMAT)
        texture.write(np.zeros((size[1], size[0], 4), np.float16).tobytes())
        texture.build_mipmaps()
        texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        stand_in = TextureData(np.zeros((1, 1, 4), np.uint8), name=f"monitor {entity}'s picture")
        self.renderer.hold_texture(stand_in, texture)
        self._pictures[entity] = _Picture(texture, self.ctx.framebuffer([texture]), stand_in, LevelStack(self.ctx),
                                          tuple(size), next(self._versions))
        return stand_in

    def draw(self, entity: int, view: View, surfaces: SurfaceTable | None, depth: int,
             blends: SurfaceBlends = NO_BLENDS, exact: bool = False,
             faces: dict[int, tuple[glm.vec3, glm.vec3]] | None = None, occluded: bool = False,
             reflections: ScreenReflections | None = None, shafts: PictureShafts | None = None,
             captures: ProbeStamps | None = None) -> int:
        """Draw monitor ``entity``'s picture from ``view`` (of the picture's size): the scene
        pass as a root, the view tree below it to ``depth`` where ``surfaces`` is given (the
        mirrors and portals; ``exact``: its visibility exact whatever ``visibility`` says),
        then the colour copied into the picture and its mips built.  ``faces``: the screens
        seen from one side only, as (point, front normal), by monitor (what ``shown`` leaves
        out where a view's eye is behind one).  ``occluded``: the root's ambient occlusion and
        contact shadows were found (``ScreenOcclusion.draw_picture``), and its draw reads them;
        ``reflections``: its camera's ``ScreenReflections`` (``ScreenReflectionPass.begin_picture``;
        None: none, and its images are let go); ``shafts``: its camera's light shafts
        (``VolumetricFogPass.begin_picture``'s settings, lamps, sky light and shares; None: none,
        and its image is let go).  ``captures``: the probes' (what the drawing notes it may have
        sampled, ``probes_read``; None: none).  Returns the views drawn (the root and its tree's)."""
        held = self._pictures[entity]
        if view.size != held.size:
            raise ValueError(f"monitor {entity}: a view of {view.size} for a picture of {held.size}")
        targets = held.levels.get(0, held.size)
        drawn, repeatable = [view], True
        before = self.renderer.scene_version
        # As the main view: the root without its glass, then (after its tree, if any) what
        # a root does last: its waters' foam, its refracting surfaces and its glass.
        screen = self.scene_pass.screen_reflections
        air = self.scene_pass.volumetric_fog
        try:
            if screen is not None:
                if reflections is not None:
                    screen.begin_picture(entity, view, targets, reflections)
                else:
                    screen.drop_picture(entity)
            if air is not None:
                if shafts is not None:
                    air.begin_picture(entity, view, targets, *shafts)
                else:
                    air.drop_picture(entity)
            options = _ROOTS[occluded, reflections is not None and screen is not None]
            self.scene_pass.draw([view], targets, options)
            if surfaces is not None and depth > 0:
                settings = TreeSettings(depth_cap=depth, visibility="exact" if exact else self.visibility)
                # (its camera's occlusion and reflections in the levels its components reach:
                # draw_picture's frame, begin_picture's settings)
                self.tree.occlusion = self.renderer.occlusion if occluded else None
                self.tree.reflections = screen if reflections is not None else None
                result = self.tree.render(view, held.levels, surfaces, settings, blends, options)
                drawn += [node.view for node in result.views[1:]]
                repeatable = not result.end_views and result.visibility != "predicted"
            else:
                self.scene_pass.finish_root(view, targets, options)
        finally:   # (the active camera's state back, whatever the picture's draw raised)
            self.tree.occlusion = self.tree.reflections = None
            if screen is not None:
                screen.end_picture()
            if air is not None:
                air.end_picture()
        # Blitted, framebuffer to framebuffer: moderngl copies into a texture by glCopyTexImage2D
        # with an unsized format (GL_RGBA), which makes the picture 8-bit, its light over 1 cut.
        held.framebuffer.use()
        apply_pass_state(self.ctx, _BLIT, (0, 0, *held.size))
        self.ctx.copy_framebuffer(held.framebuffer, targets.color_framebuffer)
        held.texture.build_mipmaps()
        held.shown = {other: self._pictures[other].version for other in self.screens_reaching(drawn, faces or {})}
        held.probes = {} if captures is None else self.probes_read(drawn, captures)
        held.version, held.repeatable, held.views = next(self._versions), repeatable, drawn
        self.renderer.note_scene_change()   # (a screen's picture is what views show: no tree kept over it)
        self._moved_on += self.renderer.scene_version - before
        self.renderer.checkpoint(f"monitor {entity}")
        return len(drawn)

    def screens_reaching(self, views: list[View], faces: dict[int, tuple[glm.vec3, glm.vec3]]) -> set[int]:
        """The monitors whose screens can draw a sample in any of ``views`` (each drawn into a
        viewport of its own size): the batches whose emissive map is their picture, tested
        by their instances' boxes against each view's volume (``batch_reach``, conservative),
        less a one-sided screen (``faces``) whose front the view's eye is behind."""
        return set().union(*self.screens_reaching_each(views, faces))

    def screens_reaching_each(self, views: list[View],
                              faces: dict[int, tuple[glm.vec3, glm.vec3]]) -> list[set[int]]:
        """``screens_reaching`` view by view: for each of ``views``, the monitors whose screens
        it can draw a sample of."""
        reached: list[set[int]] = [set() for _ in views]
        pictures = {id(held.texture): entity for entity, held in self._pictures.items()}
        screens = [batch for batch in self.renderer.batches.values()
                   if batch.count and batch.emissive_map is not None and id(batch.emissive_map) in pictures]
        if not screens:
            return reached
        by_size: dict[tuple[int, int], list[int]] = {}
        for index, view in enumerate(views):   # (one test for the views of a size: a level's, the main view's)
            by_size.setdefault(tuple(view.size), []).append(index)
        for size, indices in by_size.items():
            group = [views[index] for index in indices]
            for index, view, reach in zip(indices, group, batch_reach(group, size, screens), strict=True):
                for batch, hit in zip(screens, reach, strict=True):
                    entity = pictures[id(batch.emissive_map)]
                    if hit and not _behind(view, faces.get(entity)):
                        reached[index].add(entity)
        return reached

    def versions_shown(self, views: list[View]) -> list[tuple[tuple[int, int], ...]]:
        """For each of ``views``, the pictures its drawing now may show, with their versions
        ((monitor, version), by monitor; a one-sided screen counts from behind too): a
        drawing kept as it is shows what it showed only while these are as they were (a
        probe face's record, ``ProbeCaptures._keep_plan``)."""
        if not self._pictures:
            return [() for _ in views]
        return [tuple(sorted((entity, self._pictures[entity].version) for entity in reached))
                for reached in self.screens_reaching_each(views, {})]

    def texture(self, entity: int) -> moderngl.Texture:
        """The texture of monitor ``entity``'s picture (what its screen's batch samples)."""
        return self._pictures[entity].texture

    def read(self, entity: int) -> np.ndarray:
        """Monitor ``entity``'s picture, linear RGBA float32 (height, width, 4), row 0 at the top."""
        held = self._pictures[entity]
        w, h = held.size
        pixels = np.frombuffer(held.texture.read(), np.float16).reshape(h, w, 4)
        return pixels[::-1].astype(np.float32)

    def drop_effects(self, entity: int) -> None:
        """Let go of monitor ``entity``'s screen reflections' and light shafts' images (it went,
        or its camera did)."""
        if self.scene_pass.screen_reflections is not None:
            self.scene_pass.screen_reflections.drop_picture(entity)
        if self.scene_pass.volumetric_fog is not None:
            self.scene_pass.volumetric_fog.drop_picture(entity)

    def drop(self, entity: int) -> None:
        """Let go of monitor ``entity``'s picture (the GPU keeps it while a batch samples it),
        and its screen effects' images."""
        self.drop_effects(entity)
        held = self._pictures.pop(entity, None)
        if held is not None:
            held.levels.release()
            release_framebuffer(held.framebuffer)
            self.renderer.let_go_texture(held.stand_in)

    def release(self) -> None:
        """Let go of every picture and the tree (at the renderer's release: the textures go with
        its table of shared textures)."""
        for entity in list(self._pictures):
            self.drop(entity)
        self.tree.release()


def _behind(view: View, face: tuple[glm.vec3, glm.vec3] | None) -> bool:
    """Whether ``view`` sees only the back of a one-sided ``face`` (point, front normal): its
    eye behind the plane (an orthographic view: looking along the normal's way), by a margin
    (a face seen edge on counts as seen)."""
    if face is None:
        return False
    point, normal = face
    if view.parallel:
        return glm.dot(view.axis, normal) < -1e-6
    offset = view.eye - point
    return glm.dot(offset, normal) < -1e-6 * max(glm.length(offset), 1.0)
