"""``MeshRef.receives_shadows = False``: the floor is lit as though nothing stood in the
lights' way (the sun's, a lamp's, the sun's image through a mirror), directly and in a
mirror, while everything else is shaded as before and still casts.  Held against a second
path to the same light: the frame in which nothing casts (every mesh's ``casts_shadows``
off), where no map darkens any point."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Transform,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad, sphere
from tests.support import look_from

BIT = 1.0 / 255.0


def _level(light: str):
    """A floor, a box, a ball and a slab lit by ``light``: "sun", "lamp" (a point light with
    shadows) or "mirror" (the sun and a mirror throwing its light back over the floor);
    a second mirror behind shows the floor from the other side."""
    def build(world):
        ids = world.resources["ids"] = {}
        look_from(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))
        if light == "lamp":
            ids["light"] = world.spawn(Transform(position=(0.3, 2.4, 1.4)),
                                       PointLight(intensity=14.0, range=9.0, shadows=True))
        else:
            direction = (-1.0, -0.75, -0.5) if light == "sun" else (-1.0, -1.0, 0.0)
            ids["light"] = world.spawn(DirectionalLight(direction=direction, intensity=2.5))
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        ids["box"] = world.spawn(Transform(position=(-1.0, 0.5, 0.0)), MeshRef(box()), Material(color=(0.8, 0.3, 0.2)))
        ids["ball"] = world.spawn(Transform(position=(1.2, 0.7, 0.5)), MeshRef(sphere(0.7, segments=32)),
                                  Material(color=(0.3, 0.5, 0.8)))
        ids["back"] = world.spawn(Transform(position=(0.0, 1.5, -3.5)), MeshRef(quad(8.0, 3.0)), Material(), Mirror())
        # A low slab where the box's shadow falls under each light: a receiver beside the floor.
        ids["slab"] = world.spawn(Transform(position=(-2.4, 0.05, -0.6)), MeshRef(box((1.0, 0.1, 1.0))),
                                  Material(color=(0.7, 0.7, 0.6)))
        if light == "mirror":
            facing_x = look_rotation(glm.vec3(-1, 0, 0))
            ids["mirror"] = world.spawn(Transform(position=(-3.5, 1.5, 0.0), rotation=facing_x),
                                        MeshRef(quad(4.0, 3.0)), Material(), Mirror(reflects_light=True))
    return build


def _meshes(runner) -> list[MeshRef]:
    return [runner.world.get(entity, MeshRef) for entity in runner.world.resources["ids"].values()
            if runner.world.has(entity, MeshRef)]


@pytest.mark.parametrize("light", ["sun", "lamp", "mirror"])
def test_a_floor_that_receives_no_shadow_is_lit_as_where_nothing_casts(scene, light):
    runner = scene(_level(light), (240, 180))
    runner.engine.renderer.antialias = "off"
    ids = runner.world.resources["ids"]
    shadowed = runner.frame()
    floor = runner.ids() == ids["floor"]   # seen directly or in the mirror behind
    if light == "mirror":
        assert runner.stats.virtual_lights == 1
    for mesh_ref in _meshes(runner):
        mesh_ref.casts_shadows = False
    nothing_casts = runner.frame()
    for mesh_ref in _meshes(runner):
        mesh_ref.casts_shadows = True
    runner.world.get(ids["floor"], MeshRef).receives_shadows = False
    unshadowed_floor = runner.frame()
    assert np.array_equal(runner.ids() == ids["floor"], floor)

    darker = (shadowed.astype(int) - nothing_casts.astype(int)).sum(axis=-1) < -30
    assert (darker & floor).sum() > 300, (darker & floor).sum()   # the floor had shadows to lose
    difference = np.abs(unshadowed_floor.astype(int) - nothing_casts.astype(int)).max(axis=-1)
    assert difference[floor].max() <= 1, difference[floor].max()  # lit as where nothing casts
    # Everything else as before: the slab still in the box's shadow, every pixel the same.
    rest = ~floor
    slab = runner.ids() == ids["slab"]
    assert (darker & slab).sum() > 30, (darker & slab).sum()
    np.testing.assert_array_equal(unshadowed_floor[rest], shadowed[rest])

    runner.world.get(ids["floor"], MeshRef).receives_shadows = True
    np.testing.assert_array_equal(runner.frame(), shadowed)


def test_a_mesh_that_receives_no_shadow_still_casts(scene):
    """The box receives none but casts: the floor's shadows are as they were."""
    runner = scene(_level("sun"), (240, 180))
    runner.engine.renderer.antialias = "off"
    ids = runner.world.resources["ids"]
    before = runner.frame()
    runner.world.get(ids["box"], MeshRef).receives_shadows = False
    after = runner.frame()
    floor = runner.ids() == ids["floor"]
    np.testing.assert_array_equal(after[floor], before[floor])


def test_receives_shadows_is_checked():
    """(Level files carry it: ``tests/test_shadows.py``'s level test.)"""
    with pytest.raises(ComponentValueError, match="MeshRef.receives_shadows"):
        MeshRef(box(), receives_shadows="no")
