"""Double-sided materials (``Material.double_sided``, glTF's ``doubleSided``): both faces of
each triangle are drawn, the back lit as a surface facing the other way.

The second computation: a double-sided quad seen from behind is the same picture as a
single-sided quad turned to face the camera (an untextured quad looks the same either way
round), byte for byte; in a mirror behind a quad facing away from it, the pixels whose
reflected ray (cast here in float64) meets the quad see it only when it is double-sided."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, Material, MeshRef, Mirror, Portal, Transform
from engine.assets.mesh import plane, quad
from engine.assets.models import spawn_model
from engine.core.world import World
from tests.support import look_from, pixel_rays
from tests.test_materials_from_files import write_glb

SIZE = (160, 120)
TURNED = glm.angleAxis(np.pi, glm.vec3(0.0, 1.0, 0.0))


def _sheet(world, double_sided: bool = False, turned: bool = False, mirror: bool = False) -> dict:
    """A 2 m sheet standing at the origin facing +z (or turned to face -z), the camera behind
    it at -z, a sun lighting its -z side; with ``mirror`` the camera is in front (+z) and a
    mirror behind the sheet faces it, so the mirror sees the sheet's back."""
    ids = {}
    if mirror:
        ids["camera"] = look_from(world, (2.6, 1.6, 3.5), (-0.5, 1.2, -2.0))
        ids["mirror"] = world.spawn(Transform(position=(0.0, 1.5, -2.0)), MeshRef(quad(5.0, 3.0)), Material(),
                                    Mirror())
    else:
        ids["camera"] = look_from(world, (0.5, 1.3, -3.5), (0.0, 1.0, 0.0))
    world.spawn(DirectionalLight(direction=glm.vec3(0.3, -0.6, 1.0), intensity=2.0))
    world.spawn(Transform(), MeshRef(plane(12, 12)), Material(color=(0.5, 0.5, 0.5), roughness=1.0))
    ids["sheet"] = world.spawn(Transform(position=(0.0, 1.0, 0.0), rotation=TURNED if turned else glm.quat()),
                               MeshRef(quad(2.0, 2.0)),
                               Material(color=(0.9, 0.3, 0.2), roughness=0.6, double_sided=double_sided))
    world.resources["ids"] = ids
    return ids


def test_a_double_sided_sheet_seen_from_behind_is_the_sheet_turned_round(scene):
    """From behind, a single-sided sheet is not drawn (the ids show the floor and sky); a
    double-sided one draws the frame of a single-sided sheet turned to face the camera:
    the same pixels, lit by the sun on that side."""
    single = scene(_sheet, SIZE)
    double = scene(lambda w: _sheet(w, double_sided=True), SIZE)
    turned = scene(lambda w: _sheet(w, turned=True), SIZE)
    single_rgb, double_rgb, turned_rgb = single.frame(), double.frame(), turned.frame()
    sheet = turned.ids() == turned.world.resources["ids"]["sheet"]
    assert sheet.sum() > 2000
    assert not (single.ids() == single.world.resources["ids"]["sheet"]).any()
    assert ((double.ids() == double.world.resources["ids"]["sheet"]) == sheet).all()
    np.testing.assert_array_equal(double_rgb, turned_rgb)
    assert np.abs(single_rgb[sheet].astype(int) - double_rgb[sheet]).max() > 40


@pytest.mark.parametrize("path", ["batched", "per_mirror"])
def test_a_mirror_behind_a_double_sided_sheet_shows_its_back(scene, path):
    """The camera sees the sheet's front; the mirror behind it sees its back.  Mirror pixels
    whose reflected ray meets the sheet show it when it is double-sided and not otherwise."""
    def build(world, double_sided):
        _sheet(world, double_sided=double_sided, mirror=True)

    runners, rgb = {}, {}
    for double_sided in (False, True):
        runner = runners[double_sided] = scene(lambda w, d=double_sided: build(w, d), SIZE)
        runner.engine.reflection_system.path = path
        rgb[double_sided] = runner.frame()
    runner = runners[True]
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = (-2.0 - eye[2]) / rays[..., 2]
    on = eye + rays * t[..., None]
    at_mirror = (t > 0) & (np.abs(on[..., 0]) < 2.4) & (np.abs(on[..., 1] - 1.5) < 1.4)
    s = (0.0 - eye[2]) / rays[..., 2]   # the sheet's plane (z = 0), on the way to the mirror
    through = eye + rays * s[..., None]
    in_front = (np.abs(through[..., 0]) < 1.1) & (np.abs(through[..., 1] - 1.0) < 1.1)
    reflected = rays * np.array([1.0, 1.0, -1.0])
    back = (0.0 - on[..., 2]) / reflected[..., 2]
    hit = on + reflected * back[..., None]
    sees_sheet = at_mirror & ~in_front & (np.abs(hit[..., 0]) < 0.9) & (np.abs(hit[..., 1] - 1.0) < 0.9)
    assert sees_sheet.sum() > 300, sees_sheet.sum()
    sheet = runner.world.resources["ids"]["sheet"]
    assert (runners[True].ids()[sees_sheet] == sheet).all()
    assert not (runners[False].ids()[sees_sheet] == sheet).any()
    # Its back in the mirror is the back of a one-sided sheet turned round, seen there as its
    # front: the side the mirror's view sees is lit (the mirrored view's winding turns which
    # face is the front; a back taken for the front is dark on the sun's side).
    turned = scene(lambda w: _sheet(w, turned=True, mirror=True), SIZE)
    turned.engine.reflection_system.path = path
    turned_rgb = turned.frame()
    assert (turned.ids()[sees_sheet] == turned.world.resources["ids"]["sheet"]).all()
    np.testing.assert_array_equal(rgb[True][sees_sheet], turned_rgb[sees_sheet])
    assert np.abs(rgb[True][sees_sheet].astype(int) - rgb[False][sees_sheet]).max() > 40


def test_double_sided_is_a_checked_switch_and_never_a_surfaces():
    with pytest.raises(ComponentValueError, match=r"Material\.double_sided"):
        Material(double_sided="yes")
    world = World()
    for kind in (Mirror, Portal):
        with pytest.raises(ComponentValueError, match=f"double_sided on a {kind.__name__}"):
            world.spawn(Transform(), MeshRef(quad()), Material(double_sided=True), kind())
        held = world.spawn(Transform(), MeshRef(quad()), Material(), kind())
        with pytest.raises(ComponentValueError, match=f"double_sided on a {kind.__name__}"):
            world.get(held, Material).double_sided = True
        assert world.get(held, Material).double_sided is False


def test_a_gltf_double_sided_material_reaches_the_material(tmp_path):
    for sides in (True, False):
        material = {"name": "leaf", "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.6, 0.2, 1.0]},
                    "doubleSided": sides}
        world = World()
        root = spawn_model(world, write_glb(tmp_path / f"leaf_{sides}.glb", quad(1.0, 1.0), material, []))
        (part,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
        assert world.get(part, Material).double_sided is sides
