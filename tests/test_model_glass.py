"""Glass from glTF files (``KHR_materials_transmission``, ``KHR_materials_ior``,
``KHR_materials_volume``): a curved part refracts its own probe (``Refractive``), a flat pane
is see-through with its reflections whole (``Material.blend`` "transparent").  Each file's
frame is checked against the same scene built by hand from the components the mapping names,
and against what lies behind it (a red wall seen through clear glass is red)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from components import DirectionalLight, Emissive, Material, MeshRef, Refractive, Skybox, Transform
from components.water import f0_from_ior
from engine.assets.mesh import load_model, quad, sphere
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from, srgb_to_linear
from tests.test_materials_from_files import write_glb

SIZE = (96, 72)


def glass(transmission: float, ior: float | None = None, thickness: float | None = None,
          color=(0.8, 1.0, 0.8, 1.0)) -> dict:
    extensions: dict = {"KHR_materials_transmission": {"transmissionFactor": transmission}}
    if ior is not None:
        extensions["KHR_materials_ior"] = {"ior": ior}
    if thickness is not None:
        extensions["KHR_materials_volume"] = {"thicknessFactor": thickness}
    return {"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": list(color), "metallicFactor": 0.0,
                                                      "roughnessFactor": 0.05}, "extensions": extensions}


def room(world):
    """A red wall behind the origin under a grey sky and a sun, seen from 4 m in front."""
    look_from(world, (0.0, 0.0, 4.0), (0.0, 0.0, 0.0), fov=40.0)
    world.spawn(Skybox(faces=np.full((6, 4, 4, 3), 0.4, np.float32)))
    world.spawn(DirectionalLight(direction=(0.2, -0.5, -1.0), intensity=1.0, shadows=False))
    world.spawn(Transform(position=(0.0, 0.0, -2.0)), MeshRef(quad(10.0, 8.0)),
                Material(color=(0.6, 0.05, 0.05, 1.0), environment_reflection=0.0), Emissive(power=0.4))


def frame(scene, build) -> np.ndarray:
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    runner.frame()
    return srgb_to_linear(runner.frame())


def test_a_curved_glass_part_refracts_as_the_same_refractive_built_by_hand(scene, tmp_path):
    path = write_glb(tmp_path / "ball.glb", sphere(0.8), glass(1.0, ior=1.33, thickness=1.0),
                     [], {"extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior",
                                             "KHR_materials_volume"]})
    world = World("ball")
    spawn_model(world, path)
    ((entity, refractive),) = list(world.query_one(Refractive))
    assert refractive.ior == pytest.approx(1.33) and refractive.solid
    material = world.get(entity, Material)
    assert material.color.w == 0.0 and material.blend == "fade"

    def from_file(world):
        room(world)
        spawn_model(world, path)

    def by_hand(world):
        room(world)
        reflectance = math.sqrt(f0_from_ior(1.33) / 0.16)   # (glass of index 1.33 reflects 2% head on)
        world.spawn(Transform(), MeshRef(sphere(0.8)),
                    Material(color=(0.8, 1.0, 0.8, 0.0), roughness=0.05, reflectance=reflectance),
                    Refractive(ior=1.33, solid=True))
    seen, hand = frame(scene, from_file), frame(scene, by_hand)
    np.testing.assert_allclose(seen, hand, atol=0.004)
    h, w = SIZE[1], SIZE[0]
    middle = seen[h // 2 - 3:h // 2 + 3, w // 2 - 3:w // 2 + 3].reshape(-1, 3)
    assert (middle[:, 0] > 2.0 * middle[:, 1]).all() and middle[:, 0].min() > 0.15   # the red wall, through the ball


def test_a_flat_glass_pane_shows_what_lies_behind_it_with_its_reflections_whole(scene, tmp_path):
    """A pane letting 0.8 through: alpha 0.2, "transparent" (no Refractive: a flat pane
    bends nothing), over the red wall: the frame is the hand-built pane's, and red through
    the pane, with (1 - 0.2) of the wall's light at least."""
    path = write_glb(tmp_path / "pane.glb", quad(2.0, 2.0), glass(0.8), [],
                     {"extensionsUsed": ["KHR_materials_transmission"]})
    world = World("pane")
    spawn_model(world, path)
    assert not list(world.query_one(Refractive))
    ((_, material),) = list(world.query_one(Material))
    assert material.color.w == pytest.approx(0.2) and material.blend == "transparent"

    def from_file(world):
        room(world)
        spawn_model(world, path)

    def by_hand(world):
        room(world)
        world.spawn(Transform(), MeshRef(quad(2.0, 2.0)),
                    Material(color=(0.8, 1.0, 0.8, 0.2), roughness=0.05, blend="transparent"))
    seen, hand, wall = frame(scene, from_file), frame(scene, by_hand), frame(scene, room)
    np.testing.assert_allclose(seen, hand, atol=0.004)
    h, w = SIZE[1], SIZE[0]
    middle = (slice(h // 2 - 5, h // 2 + 5), slice(w // 2 - 5, w // 2 + 5))
    assert (seen[middle][..., 0] >= 0.8 * wall[middle][..., 0] - 0.004).all()
    assert (seen[middle][..., 0] > 2.0 * seen[middle][..., 1]).all()


def test_curved_glass_past_the_probe_budget_is_a_see_through_pane(tmp_path):
    path = write_glb(tmp_path / "ball.glb", sphere(0.5), glass(0.9), [])
    world = World("ball")
    with pytest.warns(UserWarning, match=r"1 curved reflective or glass parts: 0 of them .* \(glass: see-through"):
        spawn_model(world, path, max_probes=0)
    assert not list(world.query_one(Refractive))
    ((_, material),) = list(world.query_one(Material))
    assert material.color.w == pytest.approx(0.1) and material.blend == "transparent"


@pytest.mark.parametrize("extensions, message", [
    ({"KHR_materials_transmission": {"transmissionFactor": 2}}, r"transmissionFactor must be a number in \[0, 1\]"),
    ({"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 0.5}},
     r"KHR_materials_ior.ior must be a number in \[1, 4\]"),
    ({"KHR_materials_volume": {"thicknessFactor": -1}}, r"thicknessFactor must be a number >= 0"),
    ({"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_volume": {
        "thicknessFactor": 1, "attenuationColor": [2, 0, 0]}}, r"attenuationColor must be three numbers in \[0, 1\]"),
    ({"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_volume": {
        "thicknessFactor": 1, "attenuationDistance": 0}}, r"attenuationDistance must be a number > 0"),
    ({"KHR_materials_transmission": 3}, r"KHR_materials_transmission must be an object"),
])
def test_bad_glass_is_refused_naming_the_material(tmp_path, extensions, message):
    material = glass(0.5)
    material["extensions"] = extensions
    path = write_glb(tmp_path / "bad.glb", sphere(0.5), material, [])
    with pytest.raises(AssetError, match=rf"bad\.glb.*'glass'.*{message}"):
        load_model(path)


def test_a_file_requiring_the_glass_extensions_is_read(tmp_path):
    path = write_glb(tmp_path / "ball.glb", sphere(0.5), glass(1.0, ior=1.5, thickness=0.2), [],
                     {"extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"],
                      "extensionsRequired": ["KHR_materials_transmission", "KHR_materials_volume"]})
    (part,) = load_model(path)
    assert part.transmission == 1.0 and part.thick and part.ior == 1.5


def test_a_volumes_attenuation_tints_thick_glass_by_beer_lambert_over_its_thickness(tmp_path):
    """Green-tinted thick glass (attenuationColor (0.5, 0.9, 0.8) every 0.5 m, 1 m thick): what
    passes keeps that colour squared, times the base colour; a thin wall or no distance
    absorbs nothing."""
    material = glass(1.0, ior=1.5, thickness=1.0, color=(0.9, 1.0, 1.0, 1.0))
    material["extensions"]["KHR_materials_volume"].update(attenuationColor=[0.5, 0.9, 0.8], attenuationDistance=0.5)
    (part,) = load_model(write_glb(tmp_path / "bottle.glb", sphere(0.5), material, []))
    # (the base colour as the file's factor is kept: 8 bits a channel, 0.9 read as 230 / 255)
    assert part.color[:3] == pytest.approx((0.9 * 0.25, 0.81, 0.64), abs=2e-3) and part.color[3] == 1.0
    material["extensions"]["KHR_materials_volume"]["thicknessFactor"] = 0.0   # a thin wall: no volume
    (thin,) = load_model(write_glb(tmp_path / "pane.glb", sphere(0.5), material, []))
    assert thin.color[:3] == pytest.approx((0.9, 1.0, 1.0), abs=2e-3)
