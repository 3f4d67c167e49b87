"""A mesh that casts no shadow (``MeshRef.casts_shadows = False``, hidden in every view)
moving is no shadow change: the sun's map, a lamp's cube and a light's image through a
mirror are kept, and a probe's face that its shadow would have fallen in counts as
unchanged.  (Glass takes its alpha's share of a sun's or a lamp's light, in the light's
see-through map: its move draws the light's map again, as a caster's does.)
Each frame is held to the one a fresh engine with the mesh already at its new place draws
(the kept maps are right, not merely kept), and the same move of a casting mesh draws the
maps again (the test can fail)."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    ReflectionProbe,
    Refractive,
    Transform,
    Visibility,
    look_rotation,
)
from engine.assets.mesh import box, plane, quad
from engine.rules.probe_schedule import ProbeSchedule
from tests.support import look_from

START, END = (-1.0, 0.5, 0.0), (-1.5, 0.5, -0.8)
HOW = ["casts_shadows", "hidden_everywhere"]   # (glass dims every light: it casts)


def _level(box_at, how: str | None, light: str = "sun", mirror: bool = False):
    """A floor, a sphere-like block that always casts and the box (``how``: why it casts
    nothing; None: it casts), lit by the sun or a lamp, with a mirror carrying light."""
    def build(world):
        ids = world.resources["ids"] = {}
        look_from(world, (0.5, 5.0, 6.5), (0.0, 0.0, 0.0))
        if light == "sun":
            ids["light"] = world.spawn(DirectionalLight(direction=(-1.0, -0.75, -0.5), intensity=2.5))
        else:
            ids["light"] = world.spawn(Transform(position=(2.5, 2.2, 0.8)),
                                       PointLight(intensity=12.0, range=9.0, shadows=True))
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(14, 14)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        ids["block"] = world.spawn(Transform(position=(1.2, 0.4, 0.5)), MeshRef(box((0.8, 0.8, 0.8))),
                                   Material(color=(0.3, 0.5, 0.8)))
        parts = [Transform(position=box_at), MeshRef(box(), casts_shadows=how != "casts_shadows"),
                 Material(color=(0.8, 0.3, 0.2))]
        if how == "glass":
            parts.append(Refractive())
        elif how == "hidden_everywhere":
            parts.append(Visibility(direct=False, in_mirrors=False, in_portals=False, in_probes=False))
        ids["box"] = world.spawn(*parts)
        if mirror:
            # Facing +x, where the sun comes from: its image lights the floor back towards +x.
            ids["mirror"] = world.spawn(Transform(position=(-3.5, 1.5, 0.0),
                                                  rotation=look_rotation(glm.vec3(-1, 0, 0))),
                                        MeshRef(quad(3.0, 2.5)), Material(), Mirror(reflects_light=True))
    return build


def _moved_and_fresh(scene, how, light="sun", mirror=False):
    runner = scene(_level(START, how, light, mirror), (160, 120))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    runner.world.get(runner.world.resources["ids"]["box"], Transform).position = glm.vec3(END)
    moved = runner.frame()
    drawn = runner.stats.shadow_maps_drawn
    if how == "glass":
        # Glass reflects and refracts its own probe, recaptured where the box went after this
        # frame and sampled from the next (the probes_after stage): that frame is the fresh one's.
        moved = runner.frame()
        drawn += runner.stats.shadow_maps_drawn
    fresh = scene(_level(END, how, light, mirror), (160, 120))
    fresh.engine.renderer.antialias = "off"
    return runner, drawn, moved, fresh.frame()


@pytest.mark.filterwarnings("ignore:Visibility hides the entity in every kind of view")
@pytest.mark.parametrize("light, how", [(light, how) for light in ("sun", "lamp") for how in HOW])
def test_a_moving_mesh_that_casts_nothing_keeps_the_lights_maps(scene, light, how):
    runner, drawn, moved, fresh = _moved_and_fresh(scene, how, light)
    assert drawn == 0 and runner.stats.shadow_maps_kept == 1, (drawn, runner.stats.shadow_maps_kept)
    np.testing.assert_array_equal(moved, fresh)


@pytest.mark.parametrize("light, how", [("sun", None), ("lamp", None), ("sun", "glass"), ("lamp", "glass")])
def test_the_same_move_of_a_casting_mesh_draws_the_map_again(scene, light, how):
    """A caster's move draws the map again; so does glass's in a sun's or a lamp's light (the
    share it lets through, its see-through map: alpha 1 here, none)."""
    runner, drawn, moved, fresh = _moved_and_fresh(scene, how, light)
    assert drawn == 1   # (glass: on the move's frame; the next, the probe's, keeps it)
    np.testing.assert_array_equal(moved, fresh)


@pytest.mark.parametrize("how", [None, "casts_shadows"])
def test_a_light_through_a_mirror_keeps_its_map_while_only_non_casters_move(scene, how):
    """The sun's image in a mirror that carries light has a map of its own, drawn again when
    a caster changes; a mesh casting nothing moving keeps it (and the sun's)."""
    runner, drawn, moved, fresh = _moved_and_fresh(scene, how, mirror=True)
    assert runner.stats.virtual_lights == 1
    assert drawn == (0 if how else 2), drawn
    np.testing.assert_array_equal(moved, fresh)


def test_changing_only_a_material_keeps_the_light_through_a_mirrors_map(scene):
    """A row written for its colour alone changes no shadow: every map is kept."""
    runner = scene(_level(START, None, mirror=True), (160, 120))
    runner.frame()
    runner.frame()
    runner.world.get(runner.world.resources["ids"]["block"], Material).color = (0.9, 0.9, 0.2)
    runner.frame()
    assert runner.stats.virtual_lights == 1 and runner.stats.shadow_maps_drawn == 0


@pytest.mark.parametrize("how", [None, "casts_shadows", "glass"])
def test_a_probe_face_a_non_casters_shadow_would_reach_stays_unchanged(scene, how):
    """A periodic probe above the floor, its ``far`` short of the box: the box beside it is
    in none of its faces, but a caster's shadow there falls on the floor its -Y face (3)
    shows, so that face changes when a caster moves and is published ``unchanged`` when
    the box casts nothing; an ``on_change`` probe is not due at all then.  Glass in the
    sun's light moves the share of it the glass lets through: as a caster's."""
    def build(world):
        look_from(world, (0, 3, 6), (0, 0, 0))
        world.spawn(DirectionalLight(direction=(-1.0, -1.5, 0.0), intensity=2.0))
        world.spawn(Transform(), MeshRef(plane(60, 60)), Material())
        world.resources["periodic"] = world.spawn(Transform(position=(0.0, 0.6, 0.0)),
                                                  ReflectionProbe(resolution=16, far=2.0, refresh="every_frame"))
        world.resources["watching"] = world.spawn(Transform(position=(0.0, 0.6, 0.3)),
                                                  ReflectionProbe(resolution=16, far=2.0))
        world.resources["caster"] = world.spawn(Transform(position=(2.2, 2.6, 0.0)),
                                                MeshRef(box(), casts_shadows=how != "casts_shadows"), Material(),
                                                *([Refractive()] if how == "glass" else []))

    runner = scene(build)
    runner.frame()
    runner.frame()
    runner.world.get(runner.world.resources["caster"], Transform).position += glm.vec3(0.0, 0.0, 0.2)
    runner.frame()
    due = runner.world.resources[ProbeSchedule].due
    periodic, watching = runner.world.resources["periodic"], runner.world.resources["watching"]
    assert 3 in due[periodic].faces
    if how != "casts_shadows":
        assert 3 not in due[periodic].unchanged and watching in due and 3 in due[watching].faces, due
    else:
        assert due[periodic].unchanged == due[periodic].faces and watching not in due, due

