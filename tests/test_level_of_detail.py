"""Levels of detail (``LevelOfDetail``; ``systems/detail_system.py``): the mesh drawn is the one
the distance from the nearest eye picks (the picture the same as the same entity given that
mesh plainly), with a hysteresis band on the way back in; an object close behind a portal's
far side keeps its fine mesh however far it is from the camera; the rule's refusals; a level
file's meshes."""
from __future__ import annotations

import textwrap

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    LevelOfDetail,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    Transform,
)
from engine.assets.mesh import box, quad, sphere
from engine.assets.portals import spawn_portal_pair
from tests.support import look_from

FINE, MIDDLE, COARSE = box((1.0, 1.0, 1.0), name="fine"), sphere(0.5, 12, 6, name="middle"), \
    box((0.6, 0.6, 0.6), name="coarse")


def detailed(camera_z, plain_mesh=None, hysteresis=0.0):
    def build(world):
        world.camera = look_from(world, (0.0, 0.0, camera_z), (0.0, 0.0, 0.0), fov=40.0)
        if plain_mesh is not None:
            world.thing = world.spawn(Transform(), MeshRef(plain_mesh), Material(color=(0.8, 0.3, 0.2)))
        else:
            world.thing = world.spawn(Transform(), MeshRef(FINE), Material(color=(0.8, 0.3, 0.2)),
                                      LevelOfDetail(meshes=(FINE, MIDDLE, COARSE), distances=(6.0, 12.0),
                                                    hysteresis=hysteresis))
    return build


@pytest.mark.parametrize("camera_z, expected", [(4.0, FINE), (9.0, MIDDLE), (20.0, COARSE)])
def test_the_distance_picks_the_mesh_and_the_picture_is_that_meshs(scene, camera_z, expected):
    runner = scene(detailed(camera_z), (96, 72))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    image, ids = runner.frame(), runner.ids()
    assert runner.world.get(runner.world.thing, MeshRef).mesh is expected
    plain = scene(detailed(camera_z, plain_mesh=expected), (96, 72))
    plain.engine.renderer.antialias = "off"
    plain.frame()
    np.testing.assert_array_equal(image, plain.frame())
    assert (ids == runner.world.thing).sum() > 10  # (it is drawn: the comparison is of something)


def test_a_switch_back_to_finer_waits_out_the_hysteresis_band(scene):
    runner = scene(detailed(9.0, hysteresis=0.2), (64, 48))
    world = runner.world
    camera = world.get(world.camera, Transform)
    seen = []
    for z in (9.0, 5.5, 4.0, 7.0, 13.0, 11.0, 9.0):  # thresholds 6 and 12; back in below 4.8 and 9.6
        camera.position = glm.vec3(0.0, 0.0, z)
        runner.frame()
        seen.append(world.get(world.thing, MeshRef).mesh.name)
    assert seen == ["middle", "middle", "fine", "middle", "coarse", "coarse", "middle"]


def test_an_object_near_a_portals_far_side_keeps_its_fine_mesh(scene):
    """The camera 3 m from portal A, the object 1.5 m in front of portal B, 60 m away: seen
    through the portal it is close, so after the portal's view has been drawn once it is fine."""
    def build(world):
        look_from(world, (0.0, 1.5, 3.0), (0.0, 1.5, 0.0), fov=60.0)
        spawn_portal_pair(world, (0.0, 1.5, 0.0), None, (60.0, 1.5, 0.0), glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0)))
        world.thing = world.spawn(Transform(position=glm.vec3(60.0, 1.5, -1.5)), MeshRef(FINE),
                                  Material(color=(0.8, 0.3, 0.2)),
                                  LevelOfDetail(meshes=(FINE, MIDDLE, COARSE), distances=(6.0, 12.0)))
    runner = scene(build, (96, 72))
    for _ in range(3):
        runner.frame()
    assert runner.world.get(runner.world.thing, MeshRef).mesh is FINE
    assert runner.stats.reflection_views >= 1


@pytest.mark.parametrize("screen", ["ahead", "behind", "in_a_mirror"])
def test_an_object_a_monitors_camera_sees_close_keeps_its_fine_mesh(scene, screen):
    """The camera 3 m from a screen, the object 1.5 m from the screen's monitor's camera, 60 m
    away: in the picture it is close, so from the frame after the picture's first drawing it
    is fine; so too where the screen stands behind the camera and a mirror ahead shows it
    (last frame's mirror view sees it); with the screen behind the camera and no mirror, the
    picture's eye counts for nothing and the object is coarse."""
    def build(world):
        look_from(world, (0.0, 1.5, 3.0), (0.0, 1.5, 0.0), fov=60.0)
        lens = look_from(world, (60.0, 1.5, 0.0), (60.0, 1.5, -1.5), fov=60.0)
        world.get(lens, Camera).active = False
        if screen == "in_a_mirror":
            world.spawn(Transform(position=(0.0, 1.5, 0.0)), MeshRef(quad(3.0, 2.0)), Material(), Mirror())
        world.spawn(Transform(position=(0.0, 1.5, 0.0 if screen == "ahead" else 6.0),
                              rotation=glm.angleAxis(0.0 if screen == "ahead" else glm.pi(), glm.vec3(0, 1, 0))),
                    MeshRef(quad(2.0, 1.5)), Material(), Monitor(camera=lens, size=(64, 48)))
        world.thing = world.spawn(Transform(position=glm.vec3(60.0, 1.5, -1.5)), MeshRef(FINE),
                                  Material(color=(0.8, 0.3, 0.2)),
                                  LevelOfDetail(meshes=(FINE, MIDDLE, COARSE), distances=(6.0, 12.0)))
    runner = scene(build, (96, 72))
    runner.frame()
    assert runner.world.get(runner.world.thing, MeshRef).mesh is COARSE   # (no picture drawn yet)
    for _ in range(2):
        runner.frame()
    assert runner.world.get(runner.world.thing, MeshRef).mesh is (COARSE if screen == "behind" else FINE)


def test_the_rule_refuses_what_it_cannot_do(scene):
    from engine.core.world import World

    world = World("lod")
    with pytest.raises(ComponentValueError, match="give the entity a MeshRef too"):
        world.spawn(Transform(), LevelOfDetail(meshes=(FINE, COARSE), distances=(5.0,)))
    with pytest.raises(ComponentValueError, match="a Mirror's mesh is its surface"):
        world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Mirror(), LevelOfDetail(meshes=(quad(1.0, 1.0),)))
    with pytest.raises(ComponentValueError, match="one fewer than its meshes"):
        LevelOfDetail(meshes=(FINE, COARSE), distances=(5.0, 9.0))
    with pytest.raises(ComponentValueError, match="must increase"):
        LevelOfDetail(meshes=(FINE, MIDDLE, COARSE), distances=(9.0, 5.0))
    with pytest.raises(ComponentValueError, match="Mesh objects, got a str"):
        LevelOfDetail(meshes=("fine.obj",))
    with pytest.raises(ComponentValueError, match="1 to 8 meshes"):
        LevelOfDetail(meshes=())


def tree_level(tmp_path, thresholds: str):
    """A level file of one tree with a LevelOfDetail (a box and a sphere) switching at
    ``thresholds`` (its line, e.g. ``distances = [15.0]``): loaded into a world, then saved and
    loaded into another.  Returns (its detail, its MeshRef's mesh, the saved text, the detail
    loaded again)."""
    from engine.assets.level_file import load_level, save_level
    from engine.core.world import World

    path = tmp_path / "lod.toml"
    path.write_text(textwrap.dedent("""
        [level]
        name = "lod"

        [[entity]]
        name = "tree"
        [entity.Transform]
        [entity.MeshRef]
        mesh = { box = [1.0, 2.0, 1.0] }
        [entity.LevelOfDetail]
        meshes = [{ box = [1.0, 2.0, 1.0] }, { sphere = 0.8 }]
        """) + thresholds + "\n")
    world = World("lod")
    names = load_level(path).spawn(world)
    saved = save_level(world, tmp_path / "saved.toml", names, name="lod")
    again = World("again")
    return (world.get(names["tree"], LevelOfDetail), world.get(names["tree"], MeshRef).mesh, saved.read_text(),
            again.get(load_level(saved).spawn(again)["tree"], LevelOfDetail))


def test_a_level_file_names_its_meshes_and_saves_them(tmp_path):
    detail, mesh, saved, again = tree_level(tmp_path, "distances = [15.0]")
    assert [m.name for m in detail.meshes] == ["box", "sphere"] and detail.distances == (15.0,)
    assert detail.meshes[0] is mesh  # (one file mesh, one object)
    assert "meshes = [{ box = [1.0, 2.0, 1.0] }, { sphere = 0.8 }]" in saved
    assert again.distances == (15.0,)


def test_a_moved_entity_and_a_changed_chain_are_seen(scene):
    """The entity itself moving out changes its mesh as the camera moving does; a new
    LevelOfDetail (other meshes and distances) is taken at once; taken away, the MeshRef keeps
    the mesh it has."""
    runner = scene(detailed(4.0), (64, 48))
    world = runner.world
    runner.frame()
    assert world.get(world.thing, MeshRef).mesh is FINE
    world.get(world.thing, Transform).position = glm.vec3(0.0, 0.0, -14.0)  # 18 m from the camera
    runner.frame()
    assert world.get(world.thing, MeshRef).mesh is COARSE
    other = box((0.3, 0.3, 0.3), name="other")
    world.add_component(world.thing, LevelOfDetail(meshes=(FINE, other), distances=(30.0,)))
    runner.frame()
    assert world.get(world.thing, MeshRef).mesh is FINE
    world.get(world.thing, LevelOfDetail).distances = (10.0,)
    runner.frame()
    assert world.get(world.thing, MeshRef).mesh is other
    world.remove_component(world.thing, LevelOfDetail)
    runner.frame()
    assert world.get(world.thing, MeshRef).mesh is other
    assert runner.engine.stages["detail"].entities == []


def test_the_editor_adds_a_chain_of_the_mesh_it_has(scene):
    from shell.editor import EditError, Editor

    runner = scene(detailed(4.0, plain_mesh=FINE), (32, 24))
    world = runner.world
    editor = Editor(world)
    added = editor.add_component(world.thing, "LevelOfDetail")
    assert added.meshes == (FINE,) and added.distances == ()
    with pytest.raises(ComponentValueError, match="give both at once"):
        editor.set_field(world.thing, "LevelOfDetail", "meshes", (FINE, COARSE))
    editor.remove_component(world.thing, "LevelOfDetail")
    editor.add_component(world.thing, "LevelOfDetail", meshes=(FINE, COARSE), distances=(2.0,))
    runner.frame()
    assert world.get(world.thing, MeshRef).mesh is COARSE
    editor.set_field(world.thing, "LevelOfDetail", "distances", (9.0,))  # (as many: one at a time is fine)
    runner.frame()
    assert world.get(world.thing, MeshRef).mesh is FINE
    bare = world.spawn(Transform())
    with pytest.raises(EditError, match="add a MeshRef first"):
        editor.add_component(bare, "LevelOfDetail")


def screened(fov: float | None, camera_z: float, ortho_height: float | None = None, by_screen: bool = True):
    """The 1 m fine box 10 m off (or ``camera_z``), its chain by screen height (0.2 of the
    view's height: fine above it) or by distance (6 m), seen by a camera of ``fov`` degrees or
    an orthographic one ``ortho_height`` tall."""
    from components import Camera, look_rotation

    def build(world):
        eye = glm.vec3(0.0, 0.0, camera_z)
        lens = Camera(projection="orthographic", ortho_height=ortho_height, near=0.1, far=100.0) \
            if ortho_height is not None else Camera(fov_y=fov)
        world.camera = world.spawn(Transform(position=eye, rotation=look_rotation(-eye)), lens)
        chain = dict(screen_heights=(0.2,)) if by_screen else dict(distances=(6.0,))
        world.thing = world.spawn(Transform(), MeshRef(FINE), Material(), LevelOfDetail(meshes=(FINE, COARSE), **chain))
    return build


@pytest.mark.parametrize("fov, expected", [(60.0, COARSE), (5.0, FINE)])
def test_by_screen_height_a_camera_zoomed_in_keeps_the_fine_mesh(scene, fov, expected):
    """At 10 m a 1 m box covers 1 / (2 x 10 x tan(fov / 2)) of the view's height: 0.087 at 60
    degrees (under 0.2: the coarse mesh), 1.14 at 5 (the fine); by distance (6 m) the zoom
    changes nothing."""
    runner = scene(screened(fov, 10.0), (32, 24))
    runner.frame()
    assert runner.world.get(runner.world.thing, MeshRef).mesh is expected
    by_distance = scene(screened(fov, 10.0, by_screen=False), (32, 24))
    by_distance.frame()
    assert by_distance.world.get(by_distance.world.thing, MeshRef).mesh is COARSE


@pytest.mark.parametrize("ortho_height, camera_z, expected", [(4.0, 40.0, FINE), (4.0, 3.0, FINE),
                                                               (10.0, 3.0, COARSE), (10.0, 40.0, COARSE)])
def test_by_screen_height_an_orthographic_view_picks_by_its_zoom_alone(scene, ortho_height, camera_z, expected):
    """An orthographic camera 4 m tall shows the 1 m box as a quarter of its height at any
    distance (fine), 10 m tall a tenth (coarse)."""
    runner = scene(screened(None, camera_z, ortho_height=ortho_height), (32, 24))
    runner.frame()
    assert runner.world.get(runner.world.thing, MeshRef).mesh is expected


def test_screen_heights_are_checked_and_written_in_level_files(tmp_path):
    with pytest.raises(ComponentValueError, match="distances or screen_heights, not both"):
        LevelOfDetail(meshes=(FINE, COARSE), distances=(3.0,), screen_heights=(0.2,))
    with pytest.raises(ComponentValueError, match="screen_heights must decrease"):
        LevelOfDetail(meshes=(FINE, MIDDLE, COARSE), screen_heights=(0.2, 0.3))
    with pytest.raises(ComponentValueError, match=r"screen_heights must be one fewer than its meshes"):
        LevelOfDetail(meshes=(FINE, MIDDLE, COARSE), screen_heights=(0.2,))
    detail, _, saved, again = tree_level(tmp_path, "screen_heights = [0.25]")
    assert detail.screen_heights == (0.25,)
    assert "screen_heights = [0.25]" in saved
    assert again.by_screen


@pytest.mark.parametrize("behind, expected", [(5.0, FINE), (9.0, MIDDLE)])
def test_an_object_seen_only_in_a_mirror_takes_the_level_of_the_nearest_eye_and_the_mirror_shows_it(
        scene, behind, expected):
    """The camera 2 m before a mirror, looking into it, the object ``behind`` metres behind the
    camera (out of its view): the camera's eye is ``behind`` from it, the mirror's eye (the
    camera's image, 4 m behind the glass) ``behind`` + 4; the nearest picks (thresholds 6
    and 12: 5 -> fine though the image's way is 9, 9 -> middle though it is 13), and the
    mirror's picture is that mesh's, pixel for pixel as the object given it plainly."""
    def build(plain):
        def made(world):
            world.camera = look_from(world, (0.0, 0.0, 1.5), (0.0, 0.0, -0.5), fov=30.0)
            world.spawn(DirectionalLight(direction=(0.3, -0.5, 1.0), intensity=3.0))   # (on the side the mirror sees)
            world.spawn(Transform(position=(0.0, 0.0, -0.5)), MeshRef(quad(6.0, 4.0)), Mirror())
            chain = () if plain else (LevelOfDetail(meshes=(FINE, MIDDLE, COARSE), distances=(6.0, 12.0)),)
            world.thing = world.spawn(Transform(position=(0.0, 0.0, 1.5 + behind)),
                                      MeshRef(expected if plain else FINE), Material(color=(0.8, 0.3, 0.2)), *chain)
        return made

    pictures = []
    for plain in (False, True):
        runner = scene(build(plain), (64, 48))
        runner.engine.renderer.antialias = "off"
        for _ in range(2):
            runner.frame()
        pictures.append(runner.frame())
        assert runner.stats.reflection_views >= 1
    assert runner.world.get(runner.world.thing, MeshRef).mesh is expected
    np.testing.assert_array_equal(pictures[0], pictures[1])
    assert (np.abs(pictures[0].astype(int) - pictures[0][0, 0]).max(axis=-1) > 30).sum() > 20   # (it is in the mirror)
