"""The sample level shows its lighting: the sun's shadows fall where the camera sees them,
and the mirror that carries light throws a patch of sun onto the floor.  Each place is
worked out here from the level file's own numbers (the sun's direction, the lamp post's
box, the mirror's outline) by plain ray geometry, then read in two rendered frames, one
with the feature off; pixels where something else stands in front of the floor (the id
buffer says which entity is seen) are left out."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import DirectionalLight, Mirror
from engine.core.frame_io import Output
from engine.render.targets import CaptureTarget
from games.hall_of_mirrors.level import HallOfMirrors
from shell.app import Engine
from tests.support import small_probes

SIZE = (480, 270)


def _frame(ctx, pose, change=None):
    """The hall from ``pose`` (x, y, z, yaw, pitch) after two frames, with ``change(world,
    names)`` applied before the first: (rgb as int, ids, the main view's view-projection,
    names, the sun's unit direction)."""
    game = HallOfMirrors()
    engine = Engine(game, ctx)
    capture = CaptureTarget(ctx, SIZE)
    try:
        engine.renderer.antialias = "off"
        engine.place_camera(*pose)
        names = game.names
        small_probes(engine.world)   # (what is read here is not in them)
        if change is not None:
            change(engine.world, names)
        for _ in range(2):
            engine.frame(1.0 / 60.0, Output(capture.framebuffer, SIZE))
        sun = glm.normalize(engine.world.get(names["sun"], DirectionalLight).direction)
        return (capture.read_rgb().astype(int), engine.renderer.targets.read_ids(),
                glm.mat4(engine.main_view.view_proj), dict(names), sun)
    finally:
        capture.release()
        engine.close()


def _pixels(view_proj, points):
    """(column, row from the top) of each world point in the frame, None where off screen."""
    w, h = SIZE
    found = []
    for point in points:
        clip = view_proj * glm.vec4(glm.vec3(*point), 1.0)
        if clip.w <= 0:
            found.append(None)
            continue
        x, y = (clip.x / clip.w * 0.5 + 0.5) * w, (1.0 - (clip.y / clip.w * 0.5 + 0.5)) * h
        found.append((int(x), int(y)) if 0 <= x < w and 0 <= y < h else None)
    return found


def _on_floor(ids, floor, pixels):
    """The pixels that see the floor directly, with their neighbours (the edge's filtering)."""
    kept = []
    for pixel in pixels:
        if pixel is None:
            continue
        x, y = pixel
        if (ids[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2] == floor).all():
            kept.append(pixel)
    return kept


def _darkening(lit, shaded, pixels):
    return np.array([lit[y, x].mean() - shaded[y, x].mean() for x, y in pixels])


@pytest.fixture(scope="module")
def start(ctx):
    """From beside the start pose, where the lamp post's shadow lies in the open."""
    pose = (3.5, 2.2, 3.5, 35.9, -24.0)
    shadowed = _frame(ctx, pose)
    unshadowed = _frame(ctx, pose, lambda world, names: setattr(world.get(names["sun"], DirectionalLight),
                                                                "shadows", False))
    return shadowed, unshadowed


def test_the_lamp_posts_shadow_falls_where_the_sun_puts_it(start):
    (rgb, ids, view_proj, names, sun), (plain, _, _, _, _) = start
    # The post is a 0.12 m box 1.5 m tall standing on the floor at (2, 0, 0.5): its shadow runs
    # from its foot away from the sun, 1.5 / tan(elevation) long.
    post = glm.vec3(2.0, 0.0, 0.5)
    away = glm.normalize(glm.vec3(sun.x, 0.0, sun.z))
    length = 1.5 * glm.length(glm.vec2(sun.x, sun.z)) / -sun.y
    inside = [post + away * (length * t) for t in np.linspace(0.15, 0.85, 24)]
    # The same line on the sun's side of the post: lit with shadows on and off alike.
    outside = [post - away * (length * t) for t in np.linspace(0.15, 0.85, 24)]
    floor = names["floor"]
    in_pixels = _on_floor(ids, floor, _pixels(view_proj, inside))
    out_pixels = _on_floor(ids, floor, _pixels(view_proj, outside))
    assert len(in_pixels) >= 12 and len(out_pixels) >= 12, (len(in_pixels), len(out_pixels))
    darker = _darkening(plain, rgb, in_pixels)
    assert (darker > 12).mean() >= 0.8, darker
    assert np.abs(_darkening(plain, rgb, out_pixels)).max() <= 3, _darkening(plain, rgb, out_pixels)


def test_the_start_frame_shows_shadows(ctx):
    """The picture a newcomer sees first: at the start pose the sun's shadows darken a few
    percent of the frame (its sun once stood high behind the camera, and they hid behind
    what cast them: 1.6% at 640x360, against 5.4% now)."""
    pose = (0.0, 1.7, 6.5, 0.0, -8.0)
    rgb, _, _, _, _ = _frame(ctx, pose)
    plain, _, _, _, _ = _frame(ctx, pose, lambda world, names: setattr(world.get(names["sun"], DirectionalLight),
                                                                       "shadows", False))
    darker = (plain - rgb).max(axis=2)
    assert (darker > 8).mean() >= 0.03, (darker > 8).mean()
    assert (rgb - plain).max() <= 3  # a shadow takes light away, never adds it


def test_the_light_carrying_mirror_throws_the_sun_onto_the_floor(ctx):
    pose = (-1.0, 3.0, -1.0, 23.0, -38.0)  # above the floor before the wall

    def no_reflected_light(world, names):
        world.get(names["mirror_3"], Mirror).reflects_light = False

    rgb, ids, view_proj, names, sun = _frame(ctx, pose)
    plain, _, _, _, _ = _frame(ctx, pose, no_reflected_light)
    # mirror_3: a 3.2 x 2.8 m quad at (0, 1.6, -6), unturned, so facing +z.  The sun's ray
    # through a point of it goes on mirrored in z, down to the floor.
    bounced = glm.vec3(sun.x, sun.y, -sun.z)

    def landing(u, v):
        at = glm.vec3(u, 1.6 + v, -6.0)
        return at + bounced * (at.y / -bounced.y)

    # The left half of the mirror: the green crate's shadow in the thrown light crosses where
    # the right half's light lands.
    patch = [landing(u, v) for u in np.linspace(-1.2, 0.4, 6) for v in np.linspace(-0.3, 0.9, 5)]
    beside = [landing(u, v) for u in (-2.2, 2.2) for v in np.linspace(-0.3, 0.9, 5)]
    floor = names["floor"]
    in_pixels = _on_floor(ids, floor, _pixels(view_proj, patch))
    out_pixels = _on_floor(ids, floor, _pixels(view_proj, beside))
    assert len(in_pixels) >= 12 and len(out_pixels) >= 4, (len(in_pixels), len(out_pixels))
    brighter = -_darkening(plain, rgb, in_pixels)
    assert (brighter > 10).mean() >= 0.7, brighter
    assert np.abs(_darkening(plain, rgb, out_pixels)).max() <= 3, _darkening(plain, rgb, out_pixels)
