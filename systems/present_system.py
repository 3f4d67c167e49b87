"""Present: the finished level-0 image (reflections composited in) goes to the output,
bloomed, exposed, graded and tone mapped as the active camera's ``Bloom``, ``Tonemap`` and
``ColorGrading`` say (``components/post.py``; a camera with none of them keeps the plain look)."""
from __future__ import annotations

import warnings

import esper
import moderngl

from components.post import (
    TONEMAP_CURVES,
    Bloom,
    ChromaticAberration,
    ColorGrading,
    DepthOfField,
    FilmGrain,
    LensFlare,
    MotionBlur,
    Tonemap,
    Vignette,
)
from components.tracking import ComponentWarning
from engine.core.frame_io import Output
from engine.core.world import World
from engine.render.frame_views import FrameViews
from engine.render.present import CameraPost
from engine.render.renderer import Renderer
from engine.resources import PortalCrossings
from engine.rules.frame_rules import active_camera_parts


class PresentSystem(esper.Processor):
    """Settings the debug overlay writes (a developer's switches over every camera):
    ``bloom`` (False: no camera's Bloom is drawn), ``grade`` (False: no camera's
    ColorGrading or Vignette) and ``curve`` (None: each camera's own; else one of ``TONEMAP_CURVES`` for
    every camera, with or without a Tonemap)."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.bloom = True
        self.grade = True
        # The debug overlay's "AO only": the camera's ambient occlusion as grey in place of the
        # picture (when the camera has one this frame).
        self.show_occlusion = False
        self._curve: str | None = None
        self.tonemap: Tonemap | None = None   # what the last frame presented with (the overlay shows it)
        self.bloomed: Bloom | None = None
        self.graded: ColorGrading | None = None
        self.vignetted: Vignette | None = None
        self.focused: DepthOfField | None = None
        self.streaked: MotionBlur | None = None
        self.fringed: ChromaticAberration | None = None
        self.grained: FilmGrain | None = None
        self._said_no_flare: tuple[int, LensFlare] | None = None   # (the camera, its flare) said to want a Bloom
        # The debug overlay's switches: False draws no camera's DepthOfField, MotionBlur.
        self.depth_of_field = True
        self.motion_blur = True

    @property
    def curve(self) -> str | None:
        return self._curve

    @curve.setter
    def curve(self, value: str | None) -> None:
        if value is not None and value not in TONEMAP_CURVES:
            raise ValueError(f"PresentSystem.curve must be None or one of {TONEMAP_CURVES}, got {value!r}")
        self._curve = value

    def process(self, dt: float) -> None:
        output: Output | None = self.world.resources.get(Output)
        views: FrameViews | None = self.world.resources.get(FrameViews)
        if output is None or views is None or views.main is None:
            if views is not None and views.main is None and active_camera_parts(self.world) is None:
                # No camera (not a minimised window): its bloom, exposure and colour table go,
                # and the frame shows nothing (black, under any screen text).
                self.renderer.present_pass.release_post_targets()
                if output is not None and output.size[0] > 0 and output.size[1] > 0:
                    self.renderer.present_pass.show_nothing(output.framebuffer, output.size)
            return
        self.present_into(output.framebuffer, output.size, dt)

    def present_into(self, framebuffer: moderngl.Framebuffer, size: tuple[int, int], dt: float = 0.0) -> None:
        """Present the last finished frame (the main stage's ``FrameViews.image``, with the
        reflections composited in) into ``framebuffer`` as this stage does, with the active
        camera's Bloom, Tonemap and ColorGrading: the frame and a screenshot of it (``dt`` 0: an automatic
        exposure does not move on for a second presentation)."""
        parts = active_camera_parts(self.world)
        camera = parts[0] if parts is not None else None
        tonemap = bloom = grading = vignette = focus = motion = aberration = grain = flare = None
        fov_y = None
        if camera is not None:
            focus = self.world.try_get(camera, DepthOfField) if self.depth_of_field else None
            fov_y = parts[1].fov_y if parts[1].projection == "perspective" else None
            motion = self.world.try_get(camera, MotionBlur) if self.motion_blur else None
            if motion is not None and dt > 0.0:  # (a camera carried through a portal: its last view with it)
                for crossing in self.world.resources.get(PortalCrossings, ()):
                    if crossing.entity == camera:
                        self.renderer.present_pass.motion_blur.carry(crossing.carry)
            tonemap = self.world.try_get(camera, Tonemap)
            bloom = self.world.try_get(camera, Bloom) if self.bloom else None
            if bloom is not None and bloom.dirt is not None:   # (a dirt image this OpenGL cannot hold: refused)
                self.renderer.check_texture(bloom.dirt, "Bloom.dirt")
            grading = self.world.try_get(camera, ColorGrading) if self.grade else None
            vignette = self.world.try_get(camera, Vignette) if self.grade else None
            aberration = self.world.try_get(camera, ChromaticAberration) if self.grade else None
            grain = self.world.try_get(camera, FilmGrain) if self.grade else None
            flare = self.world.try_get(camera, LensFlare) if self.bloom else None
            if flare is not None and (bloom is None or bloom.intensity <= 0.0):
                if self._said_no_flare != (camera, flare):
                    self._said_no_flare = (camera, flare)
                    warnings.warn(ComponentWarning(
                        f"LensFlare on entity {camera} has no Bloom with an intensity beside it (its ghosts are the "
                        "bloom's image turned about the middle), so it adds nothing"), stacklevel=3)
                flare = None
        self.tonemap, self.bloomed, self.graded, self.vignetted = tonemap, bloom, grading, vignette
        self.focused, self.streaked, self.fringed, self.grained = focus, motion, aberration, grain
        views: FrameViews | None = self.world.resources.get(FrameViews)
        main = views.main if views is not None else None
        post = CameraPost(tonemap=tonemap, bloom=bloom, grading=grading, vignette=vignette, focus=focus,
                          motion=motion, aberration=aberration, grain=grain, flare=flare, view=main, fov_y=fov_y)
        self.renderer.present(framebuffer, size, post, self._curve, camera, dt,
                              views.image if views is not None else None)
        shares = self.renderer.screen_occlusion
        if self.show_occlusion and shares is not None:
            self.renderer.present_pass.draw_occlusion(shares, framebuffer, size)
