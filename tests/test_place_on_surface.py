"""Placing things on what the picture shows: ``raycast_seen`` follows a ray on through mirrors
and portals (against the unfolded geometry, by hand), ``Editor.place`` puts a decal into a
surface and a crate on it in one undo step, and the overlay's Shift+click puts the selection
on a floor seen in a mirror, where that floor really is."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import Decal, Material, MeshRef, Transform
from engine.assets.mesh import box, plane
from engine.assets.portals import spawn_portal_pair
from engine.core.portal_math import pair_transform
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix
from engine.core.transforms import current_world_matrix
from engine.rules.raycast import raycast_seen
from shell.editor import Editor
from shell.handles import screen_point
from tests.support import look_from
from tests.test_mirrors import base_scene, mirror_wall

SIZE = (160, 120)
EYE = glm.vec3(1.5, 1.8, 5.0)
FLOOR_SPOT = glm.vec3(0.5, 0.0, 1.0)   # in front of the mirror (the plane z = -2)
MIRRORED = reflection_matrix(plane_from_point_normal((0, 1.5, -2), (0, 0, 1)))


def mirror_room(world, ents):
    base_scene(world)
    look_from(world, EYE)
    ents["mirror"] = mirror_wall(world)
    ents["floor"] = world.spawn(Transform(), MeshRef(plane(20, 20)), Material(color=(0.5, 0.5, 0.5)))
    ents["crate"] = world.spawn(Transform(position=(-1.5, 0.3, 3.0), rotation=glm.angleAxis(0.6, glm.vec3(1, 0, 0)),
                                          scale=(0.6, 0.6, 0.6)), MeshRef(box()), Material(color=(0.8, 0.5, 0.2)))
    ents["decal"] = world.spawn(Transform(position=(2.0, 0.5, 2.0), scale=(0.8, 0.8, 0.4)),
                                Decal(color=(0.1, 0.05, 0.02, 0.9)))


def test_a_ray_goes_on_through_a_mirror_to_the_floor_it_shows(scene):
    """Aimed at the floor spot's mirror image, the cast meets the mirror, is reflected and
    finds the real spot; its way is the eye's distance to the image (the unfolded ray)."""
    ents = {}
    runner = scene(lambda world: mirror_room(world, ents), SIZE)
    runner.frame()   # (the surfaces stage's mirrors)
    image = glm.vec3(MIRRORED * glm.vec4(FLOOR_SPOT, 1.0))
    seen = raycast_seen(runner.world, EYE, image - EYE)
    assert seen is not None and seen.hit.entity == ents["floor"] and seen.through == (ents["mirror"],)
    np.testing.assert_allclose(seen.hit.point, FLOOR_SPOT, atol=1e-4)
    np.testing.assert_allclose(seen.hit.normal, (0, 1, 0), atol=1e-6)
    assert seen.way == pytest.approx(glm.distance(EYE, image), rel=1e-6)
    # From behind the mirror is a wall: the cast stops on it.
    behind = raycast_seen(runner.world, glm.vec3(0.0, 1.5, -4.0), glm.vec3(0.0, 0.0, 1.0))
    assert behind is not None and behind.hit.entity == ents["mirror"] and behind.through == ()


def test_a_ray_goes_on_through_a_portal_to_beyond_its_partner(scene):
    """Aimed at the image of a box beyond the look-out portal (the box carried back by the
    pair), the cast crosses the look-in portal and meets the box there; its way is the
    distance to the image of the point it met."""
    ents = {}
    turn = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))

    def build(world):
        base_scene(world)
        look_from(world, (0.5, 1.6, 6.0), (0, 1.5, 0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (10, 1.5, 0), turn)
        ents["box"] = world.spawn(Transform(position=(13.0, 1.2, 0.4), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                                  Material(color=(0.1, 0.9, 0.1)))

    runner = scene(build, SIZE)
    runner.frame()
    world = runner.world
    carry = pair_transform(world.get(ents["a"], Transform).world, world.get(ents["b"], Transform).world)
    back = glm.inverse(carry)
    eye = glm.vec3(0.5, 1.6, 6.0)
    image = glm.vec3(back * glm.vec4(13.0, 1.2, 0.4, 1.0))
    seen = raycast_seen(world, eye, image - eye)
    assert seen is not None and seen.hit.entity == ents["box"] and seen.through == (ents["a"],)
    met = glm.vec3(back * glm.vec4(seen.hit.point, 1.0))   # the point met, as seen on this side
    assert glm.length(glm.cross(glm.normalize(met - eye), glm.normalize(image - eye))) < 1e-5   # on the ray
    assert seen.way == pytest.approx(glm.distance(eye, met), rel=1e-5)


def test_a_decal_is_put_into_a_wall_and_a_crate_on_the_floor_in_one_step_each(scene):
    ents = {}
    runner = scene(lambda world: mirror_room(world, ents), SIZE)
    runner.frame()
    world = runner.world
    editor = Editor(world)
    decal = world.get(ents["decal"], Transform)
    before = (glm.vec3(decal.position), glm.quat(decal.rotation))
    spot, normal = glm.vec3(-1.0, 1.0, -2.0), glm.normalize(glm.vec3(0.2, 0.0, 1.0))
    editor.place(ents["decal"], spot, normal)
    matrix = current_world_matrix(world, decal)
    throws = glm.normalize(glm.vec3(matrix * glm.vec4(0, 0, -1, 0)))
    np.testing.assert_allclose(throws, -normal, atol=1e-6)   # its image thrown into the surface
    up = glm.normalize(glm.vec3(matrix * glm.vec4(0, 1, 0, 0)))
    assert up.y > 0.98                                       # upright on a wall
    np.testing.assert_allclose(decal.position, spot, atol=1e-6)
    assert editor.undo() and not editor.can_undo             # one step: both fields back
    assert decal.position == before[0] and decal.rotation == before[1]
    # A turned crate: moved, not turned, until its lowest corner lies on the floor at the spot.
    crate = world.get(ents["crate"], Transform)
    rotation = glm.quat(crate.rotation)
    editor.place(ents["crate"], FLOOR_SPOT, glm.vec3(0, 1, 0))
    matrix = current_world_matrix(world, crate)
    corners = [glm.vec3(matrix * glm.vec4(x, y, z, 1.0)) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    assert min(c.y for c in corners) == pytest.approx(0.0, abs=1e-5)
    assert (crate.position.x, crate.position.z) == pytest.approx((FLOOR_SPOT.x, FLOOR_SPOT.z), abs=1e-6)
    assert crate.rotation == rotation


@pytest.mark.parametrize("slab", [False, True], ids=["floor", "slab_hidden_in_mirrors"])
def test_shift_click_puts_the_selection_on_the_floor_seen_in_the_mirror(scene, ctx, slab):
    """With the overlay shown, Shift+click on the floor's image in the mirror puts the
    selected crate on the real floor there (not on the glass, nor behind it).  ``slab``: a
    slab on the floor there hidden in mirror views (``Visibility(in_mirrors=False)``): the
    mirror shows the floor, and the crate is put on the floor, not on the slab."""
    pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
    from components import Visibility
    from shell.overlay import DebugOverlay

    ents = {}

    def build(world):
        mirror_room(world, ents)
        if slab:
            world.spawn(Transform(position=(FLOOR_SPOT.x, 0.15, FLOOR_SPOT.z), scale=(1.0, 0.3, 1.0)), MeshRef(box()),
                        Material(color=(0.2, 0.6, 0.2)), Visibility(in_mirrors=False))

    runner = scene(build, SIZE)
    runner.frame()
    overlay = DebugOverlay(ctx)
    try:
        overlay.draw(runner.engine, runner.capture.framebuffer, SIZE)
        editor = overlay.editing(runner.engine)
        editor.select(ents["crate"])
        image = glm.vec3(MIRRORED * glm.vec4(FLOOR_SPOT, 1.0))
        at = screen_point(runner.engine.main_view.view_proj, SIZE, image)   # (the image's own point, not a pixel)
        assert overlay.click(runner.engine, *at, place=True)
        crate = runner.world.get(ents["crate"], Transform)
        assert (crate.position.x, crate.position.z) == pytest.approx((FLOOR_SPOT.x, FLOOR_SPOT.z), abs=1e-3)
        matrix = current_world_matrix(runner.world, crate)
        lowest = min(glm.vec3(matrix * glm.vec4(x, y, z, 1.0)).y for x in (-0.5, 0.5) for y in (-0.5, 0.5)
                     for z in (-0.5, 0.5))
        assert lowest == pytest.approx(0.0, abs=1e-4)
        assert editor.undo() and runner.world.get(ents["crate"], Transform).position.z == pytest.approx(3.0)
    finally:
        overlay.release()
