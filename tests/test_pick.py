"""Picking by pixel from a real frame's id images: a box seen directly, the same box seen in a
mirror, and (with the surface modifier) the mirror it was seen in; where each lands on the
screen is worked out by projection and reflection math, not read from the renderer."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from shell.editor import Editor, pick
from tests.test_level_edit import edit_scene
from tests.test_mirrors import reflected_pixel

BOX = (-1.0, 1.2, 0.0)


def test_pick_a_box_directly_in_a_mirror_and_the_mirror_itself(scene):
    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), (160, 120))
    rgb = runner.frame()
    assert rgb.std() > 10
    ids, surfaces = runner.ids(), runner.engine.renderer.targets.read_surface_ids()
    editor = Editor(runner.world)
    direct = runner.project(BOX)
    mirrored = reflected_pixel(runner, BOX)
    assert direct != mirrored

    assert editor.pick(ids, surfaces, *direct) == ents["box"] == editor.selected
    assert editor.pick(ids, surfaces, *mirrored) == ents["box"]  # the box, though the pixel is the mirror's
    assert editor.pick(ids, surfaces, *mirrored, surface=True) == ents["mirror"]
    assert editor.pick(ids, surfaces, *direct, surface=True) == ents["box"]  # nothing between: the box itself
    # The mirror's glass where the box is not seen in it: the modifier picks the mirror, a
    # plain click what the mirror shows there (the sky or the floor, not the box).
    beside = (mirrored[0] + 25, mirrored[1])
    assert surfaces[beside[1], beside[0]] == ents["mirror"]
    assert pick(ids, surfaces, *beside, surface=True) == ents["mirror"]
    assert pick(ids, surfaces, *beside) != ents["box"]
    # The sky above everything is nothing; a pixel off the image is nothing.
    assert editor.pick(ids, surfaces, 80, 2) is None and editor.selected is None
    assert pick(ids, surfaces, -1, 5) is None and pick(ids, surfaces, 160, 5) is None
    # Every pixel the box covers, directly or in the mirror, picks the box.
    rows, cols = np.nonzero(ids == ents["box"])
    assert len(rows) > 20 and all(pick(ids, surfaces, c, r) == ents["box"] for r, c in zip(rows, cols, strict=True))


def test_the_selection_is_outlined_directly_and_in_the_mirror(scene):
    """The outline pass over the frame: exactly the pixels next to (not on) the selection's
    pixels in the id image, worked out here with numpy (a 3x3 dilation), are the outline's
    colour; the box's outline shows both where it stands and in the mirror."""
    from engine.render.outline import SelectionOutline, outline_ids

    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), (160, 120))
    frame = runner.frame()
    ids = runner.ids()
    renderer = runner.engine.renderer
    outline = SelectionOutline(runner.ctx, renderer.shaders)
    try:
        source = outline_ids(renderer.targets, runner.world, ents["box"])
        assert source is renderer.targets.seen
        outline.draw(source, runner.capture.framebuffer, runner.size, ents["box"], color=(1.0, 0.0, 1.0, 1.0))
        outlined = runner.capture.read_rgb()
        # The mirror, selected, is outlined round its own pixels (the surface-id image).
        runner.frame()
        source = outline_ids(renderer.targets, runner.world, ents["mirror"])
        assert source is renderer.targets.surface
        outline.draw(source, runner.capture.framebuffer, runner.size, ents["mirror"], color=(1.0, 0.0, 1.0, 1.0))
        mirror_outlined = runner.capture.read_rgb()
    finally:
        outline.release()
    glass = renderer.targets.read_surface_ids() == ents["mirror"]
    ring = dilated(glass) & ~glass
    assert ring.sum() > 100
    assert np.array_equal(np.all(mirror_outlined == (255, 0, 255), axis=-1), ring)
    mask = ids == ents["box"]
    expected = dilated(mask) & ~mask
    magenta = np.all(outlined == (255, 0, 255), axis=-1)
    assert np.array_equal(magenta, expected)
    assert np.array_equal(outlined[~expected], frame[~expected])  # nothing else drawn over
    # Both of the box's shapes (itself, its image in the mirror) have their outline.
    direct, mirrored = runner.project(BOX), reflected_pixel(runner, BOX)
    for col, row in (direct, mirrored):
        assert magenta[max(row - 12, 0):row + 12, max(col - 12, 0):col + 12].sum() > 8
    assert not magenta[:, :min(direct[0], mirrored[0]) - 20].any()


def dilated(mask: np.ndarray) -> np.ndarray:
    """``mask`` grown by one pixel each way (a 3x3 square), in numpy."""
    padded = np.pad(mask, 1)
    near = np.zeros_like(mask)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= padded[1 + dy:1 + dy + mask.shape[0], 1 + dx:1 + dx + mask.shape[1]]
    return near


@pytest.mark.parametrize("veil", [False, True, "morphed", "skinned"], ids=["bare", "veiled", "morphed", "skinned"])
def test_a_click_on_a_monitors_screen_picks_what_its_picture_shows_there(scene, veil):
    """The monitors' studio: the active camera before the screen, whose picture shows the red
    box the lens watches.  A pixel where the frame shows the box on the screen (red: the GPU's
    picture) picks the box (the main view's ray to the screen, its texture coordinates there,
    the lens's ray through that pixel of the picture, cast on the CPU:
    ``shell/picture_pick.py``); a pixel of the screen showing the black sky picks nothing; the
    surface modifier picks the screen.  ``veiled``: a wall between the lens and the box on a
    layer the lens hides (``Camera.hides_layers``): its picture shows the box through it, and
    the click picks the box, not the wall.  ``morphed``: the screen's mesh wears a morph target
    that moves it 0.4 m to the right: its texture coordinates at the point are read off the
    triangle as posed, not as modelled (a quarter of the picture's width off).  ``skinned``:
    the screen's mesh is bent by a ``Skin`` instead, its right edge on a joint that carries it
    0.8 m further right (the screen stretched to half as wide again) and 0.2 m towards the
    eye (no longer flat in its plane), so a point's texture coordinates are the stretched
    triangle's (a sixth of the picture's width off at the screen's middle)."""
    from components import Camera, Material, MeshRef, Monitor, Transform, Visibility
    from engine.assets.mesh import quad
    from shell.handles import view_ray
    from shell.picture_pick import into_pictures
    from tests.test_monitors import BOX_AT, DT, PICTURE, studio

    made, held = studio(Monitor(size=PICTURE))

    def build(world):
        made(world)
        if veil == "morphed":
            from components import Morph
            from engine.assets.mesh import Mesh
            from tests.test_monitors import SCREEN_SIZE

            flat = quad(*SCREEN_SIZE)
            right = np.tile([0.4, 0.0, 0.0], (len(flat.positions), 1))[None]
            world.get(held["screen"], MeshRef).mesh = Mesh(flat.positions, flat.normals, flat.uvs,
                                                            np.asarray(flat.indices).reshape(-1, 3), name="slid screen",
                                                            morph_positions=right, morph_normals=np.zeros_like(right))
            world.add_component(held["screen"], Morph((1.0,)))
        elif veil == "skinned":
            from components import Skin
            from engine.assets.mesh import Mesh
            from tests.test_monitors import SCREEN_SIZE

            flat = quad(*SCREEN_SIZE)
            right = (np.asarray(flat.positions)[:, 0] > 0).astype(np.uint16)   # (the right edge's two corners)
            stretch = np.stack([np.eye(4), np.eye(4)])
            stretch[1, :3, 3] = (0.8, 0.0, 0.2)   # (points as columns: M @ (x, y, z, 1))
            world.get(held["screen"], MeshRef).mesh = Mesh(flat.positions, flat.normals, flat.uvs,
                                                            np.asarray(flat.indices).reshape(-1, 3),
                                                            name="stretched screen",
                                                            joints=np.stack([right, 0 * right], axis=1),
                                                            weights=np.tile([1.0, 0.0], (len(right), 1)))
            world.add_component(held["screen"], Skin(stretch))
        elif veil:
            world.get(held["lens"], Camera).hides_layers = [3]
            held["veil"] = world.spawn(Transform(position=(0.0, 1.0, (BOX_AT[2] + 0.0) / 2.0)), MeshRef(quad(6.0, 4.0)),
                                       Material(color=(0.0, 1.0, 0.0, 1.0), unlit=True), Visibility(layers=[3]))

    runner = scene(build, (160, 120))
    runner.engine.renderer.antialias = "off"
    runner.frame(DT)
    rgb = runner.frame(DT).astype(np.int32)
    ids, surfaces = runner.ids(), runner.engine.renderer.targets.read_surface_ids()
    screen = ids == held["screen"]
    red = screen & (rgb[..., 0] - rgb[..., 1] > 50)
    inner = red.copy()   # (away from the box's edges, where a pixel's ray and the picture's texels part)
    for _ in range(2 if veil == "skinned" else 1):   # (stretched: a texel's blend spans two pixels)
        inner = inner & np.roll(inner, 1, 0) & np.roll(inner, -1, 0) & np.roll(inner, 1, 1) & np.roll(inner, -1, 1)
    dark = screen & (rgb.max(axis=-1) < 10)
    assert inner.sum() > 5 and dark.sum() > 50
    editor = Editor(runner.world)
    view = runner.engine.main_view

    def click(x, y, surface=False):
        follow = into_pictures(runner.world, runner.engine.renderer.monitors.entities,
                               *view_ray(view.view_proj, runner.size, (x + 0.5, y + 0.5)))
        return editor.pick(ids, surfaces, x, y, surface, follow)

    for row, column in zip(*np.nonzero(inner), strict=True):
        assert click(column, row) == held["box"], (column, row)
    rows, columns = np.nonzero(dark)
    for row, column in list(zip(rows, columns, strict=True))[::10]:
        assert click(column, row) is None, (column, row)
    row, column = np.argwhere(inner)[0]
    assert click(column, row, surface=True) == held["screen"]


GHOST = (-0.75, 1.26, -0.9)   # on the way from the mirror to the box's image in it
VAMPIRE = (0.6, 1.0, 0.3)


def test_a_cast_from_a_view_meets_in_each_stretch_what_the_view_there_draws(scene):
    """``raycast_seen`` with the main view's mask agrees with the GPU's id image pixel by pixel
    over the mirror: a box hidden in mirror views (``Visibility(in_mirrors=False)``) standing
    between the red box and the mirror is met where the view sees it directly and passed
    through in the mirror (the red box behind it is met there), and a box hidden in direct
    views is met only in the mirror.  The view through the mirror is ``mask_through`` it; the
    direct view's mask on every stretch met the first box in the mirror and missed the second."""
    from components import Material, MeshRef, Transform, Visibility
    from engine.assets.mesh import box
    from engine.rules.raycast import raycast_seen
    from shell.handles import view_ray

    ents = {}

    def build(world):
        edit_scene(world, ents)
        ents["ghost"] = world.spawn(Transform(position=GHOST, scale=(0.35, 0.35, 0.35)), MeshRef(box()),
                                    Material(color=(0.1, 0.9, 0.1)), Visibility(in_mirrors=False))
        ents["vampire"] = world.spawn(Transform(position=VAMPIRE, scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                                      Material(color=(0.1, 0.1, 0.9)), Visibility(direct=False))

    runner = scene(build, (160, 120))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    ids, surfaces = runner.ids(), runner.engine.renderer.targets.read_surface_ids()
    view = runner.engine.main_view
    glass = surfaces == ents["mirror"]
    inner = glass.copy()   # (away from any edge in the id image, where a pixel's centre ray and the raster part)
    for axis in (0, 1):
        for step in (1, -1):
            inner &= np.roll(ids, step, axis=axis) == ids
    found = {name: 0 for name in ents}
    wrong = []
    for row, column in zip(*np.nonzero(inner), strict=True):
        origin, direction = view_ray(view.view_proj, runner.size, (column + 0.5, row + 0.5))
        seen = raycast_seen(runner.world, origin, direction, view_mask=view.view_mask)
        cast = 0 if seen is None else seen.hit.entity
        if cast != ids[row, column]:
            wrong.append((column, row, cast, int(ids[row, column])))
        for name, entity in ents.items():
            found[name] += ids[row, column] == entity
    assert found["box"] > 20 and found["vampire"] > 20 and found["ghost"] == 0, found
    assert len(wrong) <= inner.sum() // 100, wrong[:10]
    # Straight ahead the ghost is met, the vampire is not: the sky behind it is.
    origin, direction = view_ray(view.view_proj, runner.size, np.add(runner.project(GHOST), 0.5))
    assert raycast_seen(runner.world, origin, direction, view_mask=view.view_mask).hit.entity == ents["ghost"]
    origin, direction = view_ray(view.view_proj, runner.size, np.add(runner.project(VAMPIRE), 0.5))
    assert raycast_seen(runner.world, origin, direction, view_mask=view.view_mask) is None   # (the sky)
    assert raycast_seen(runner.world, origin, direction).hit.entity == ents["vampire"]   # (no mask: anything)


def test_a_cast_through_a_portal_meets_what_the_portals_view_draws(scene):
    """``raycast_seen`` with the main view's mask through a portal (portal A hiding layer 3,
    its partner B turned a quarter about y, 10 m off and out of the camera's sight) agrees
    with the GPU's id image pixel by pixel over portal A: beyond B a box hidden in portal
    views (``Visibility(in_portals=False)``) and one on layer 3 stand before the boxes
    behind them and are passed through (those are met), while a box hidden in direct views
    and one hidden in mirror views are met (the view through a portal is no longer direct,
    and is a portal's, not a mirror's: ``mask_through`` with ``mirror`` False and A's
    layers).  Cast without the mask, the two passed through are met there."""
    from components import Material, MeshRef, Portal, Transform, Visibility
    from engine.assets.mesh import box
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform
    from engine.rules.raycast import raycast_seen
    from shell.handles import view_ray
    from tests.support import look_from
    from tests.test_mirrors import base_scene

    turn = glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0))
    a_at, b_at = glm.vec3(0.0, 1.5, 0.0), glm.vec3(10.0, 1.5, 0.0)
    carry = pair_transform(glm.translate(a_at), glm.translate(b_at) * glm.mat4_cast(turn))
    # Where each stands as seen through A (behind A's plane), its scale, what hides it.
    seen_at = {"box": ((0.35, 1.2, -2.0), 1.0, None),
               "ghost": ((0.34, 1.29, -0.8), 0.5, Visibility(in_portals=False)),
               "vampire": ((-0.45, 1.0, -2.3), 1.0, Visibility(direct=False)),
               "veiled": ((-0.26, 1.15, -0.9), 0.5, Visibility(layers=[3])),
               "mirror_shy": ((0.0, 2.3, -2.0), 0.7, Visibility(in_mirrors=False))}
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.3, 1.6, 3.2), (0.0, 1.5, 0.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, a_at, None, b_at, turn)
        world.get(ents["a"], Portal).hides_layers = [3]
        for name, (image, scale, hidden) in seen_at.items():
            at = glm.vec3(carry * glm.vec4(glm.vec3(image), 1.0))
            ents[name] = world.spawn(Transform(position=at, scale=(scale, scale, scale)), MeshRef(box()),
                                     Material(color=(0.8, 0.3, 0.1)), *([hidden] if hidden else []))

    runner = scene(build, (160, 120))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    ids, surfaces = runner.ids(), runner.engine.renderer.targets.read_surface_ids()
    view = runner.engine.main_view
    inner = surfaces == ents["a"]   # (away from any edge in the id image)
    for axis in (0, 1):
        for step in (1, -1):
            inner &= (np.roll(ids, step, axis=axis) == ids) & (np.roll(surfaces, step, axis=axis) == surfaces)
    assert inner.sum() > 1000, inner.sum()
    found = {name: 0 for name in seen_at}
    wrong = []
    for row, column in zip(*np.nonzero(inner), strict=True):
        origin, direction = view_ray(view.view_proj, runner.size, (column + 0.5, row + 0.5))
        seen = raycast_seen(runner.world, origin, direction, view_mask=view.view_mask)
        cast = 0 if seen is None else seen.hit.entity
        if cast != ids[row, column] or (seen is not None and seen.through != (ents["a"],)):
            wrong.append((column, row, cast, int(ids[row, column])))
        for name in seen_at:
            found[name] += ids[row, column] == ents[name]
    assert all(found[name] > 50 for name in ("box", "vampire", "mirror_shy")), found
    assert found["ghost"] == 0 and found["veiled"] == 0, found
    # Where each of the two stands in the way, the id image shows the box behind it, and the
    # cast without the mask meets it.
    for name, behind in (("ghost", "box"), ("veiled", "vampire")):
        column, row = runner.project(seen_at[name][0])
        assert inner[row, column] and ids[row, column] == ents[behind], (name, column, row)
        origin, direction = view_ray(view.view_proj, runner.size, (column + 0.5, row + 0.5))
        assert raycast_seen(runner.world, origin, direction).hit.entity == ents[name]
    assert len(wrong) <= inner.sum() // 100, wrong[:10]


def test_a_click_through_a_thing_hidden_in_direct_views_picks_what_the_screen_behind_shows(scene, ctx):
    """The monitors' studio with a slab hidden in direct views (``Visibility(direct=False)``)
    between the active camera and the screen: the frame shows the screen through it.  The
    overlay's click on a pixel where the screen shows the red box selects the box (the main
    view's cast to the screen meets only what the main view draws: its mask, passed to
    ``into_pictures``), not the screen, as a click on the same pixel with no slab does."""
    pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
    from components import Material, MeshRef, Monitor, Transform, Visibility
    from engine.assets.mesh import box
    from shell.overlay import DebugOverlay
    from tests.test_monitors import DT, PICTURE, SCREEN_AT, studio

    size = (96, 72)
    chosen = {}
    for slab in (False, True):
        made, held = studio(Monitor(size=PICTURE))

        def build(world, made=made, held=held, slab=slab):
            made(world)
            if slab:
                held["slab"] = world.spawn(Transform(position=(SCREEN_AT[0], SCREEN_AT[1], SCREEN_AT[2] + 0.6)),
                                           MeshRef(box((2.4, 1.6, 0.1))), Material(color=(0.1, 0.9, 0.1)),
                                           Visibility(direct=False))

        runner = scene(build, size)
        runner.engine.renderer.antialias = "off"
        runner.frame(DT)
        rgb = runner.frame(DT).astype(np.int32)
        ids = runner.ids()
        red = (ids == held["screen"]) & (rgb[..., 0] - rgb[..., 1] > 50)
        inner = red.copy()   # (away from the box's edges, where a pixel's ray and the picture's texels part)
        for axis in (0, 1):
            for step in (1, -1):
                inner &= np.roll(red, step, axis=axis)
        assert inner.sum() > 5, inner.sum()
        overlay = DebugOverlay(ctx)
        try:
            overlay.draw(runner.engine, runner.capture.framebuffer, size)
            editor = overlay.editing(runner.engine)
            picked = []
            for row, column in np.argwhere(inner)[::3]:
                assert overlay.click(runner.engine, column + 0.5, row + 0.5)
                picked.append(editor.selected)
        finally:
            overlay.release()
        assert set(picked) == {held["box"]}, (slab, set(picked), held)
        chosen[slab] = np.argwhere(inner)
    np.testing.assert_array_equal(chosen[True], chosen[False])   # (the slab hides nothing of the frame)
