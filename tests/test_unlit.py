"""Unlit materials (``Material.unlit``, glTF's ``KHR_materials_unlit``): the colour as it is
(colour x texture x vertex colour), whatever lights, shadows, sky and fog-free surroundings
there are; the same pixel values under a bright sun and in the dark, equal to the colour's
own sRGB encoding."""
from __future__ import annotations

import numpy as np
import pytest

from components import DirectionalLight, Material, MeshRef, PointLight, Skybox, Transform
from engine.assets.mesh import quad, sphere
from engine.core.color import linear_to_srgb
from tests.support import look_from

SIZE = (64, 48)
COLOUR = (0.6, 0.25, 0.1)


def scene_with(material: Material, lit: bool):
    def build(world):
        look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=50.0)
        if lit:
            world.spawn(Skybox(faces=np.full((6, 4, 4, 3), 0.8, np.float32)))
            world.spawn(DirectionalLight(direction=(-0.5, -0.4, -1.0), intensity=2.0))
            world.spawn(Transform(position=(0.5, 0.5, 1.5)), PointLight(intensity=3.0, range=8.0))
            world.spawn(Transform(position=(-0.3, 0.6, 1.2)), MeshRef(sphere(0.15)), Material())  # casts on it
        world.spawn(Transform(), MeshRef(quad(2.0, 2.0)), material)
    return build


def test_an_unlit_material_shows_its_colour_whatever_light_there_is(scene):
    frames = []
    for lit in (True, False):
        runner = scene(scene_with(Material(color=(*COLOUR, 1.0), roughness=0.2, unlit=True), lit), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        frames.append(runner.frame().astype(int))
    h, w = SIZE[1], SIZE[0]
    middle = (slice(h // 2 - 8, h // 2 + 8), slice(w // 2 - 8, w // 2 + 8))
    expected = np.round(np.asarray(linear_to_srgb(np.array(COLOUR))) * 255.0)
    for frame in frames:
        assert np.abs(frame[middle] - expected).max() <= 1, frame[middle][0, 0]
    lit_plain = scene(scene_with(Material(color=(*COLOUR, 1.0), roughness=0.2), True), SIZE)
    lit_plain.engine.renderer.antialias = "off"
    lit_plain.frame()
    assert np.abs(lit_plain.frame().astype(int)[middle] - expected).max() > 20   # (a lit one is not)


def test_unlit_is_checked_and_read_from_gltf(tmp_path):
    from components import ComponentValueError
    from engine.assets.mesh import load_model
    from engine.assets.models import spawn_model
    from engine.core.world import World
    from tests.test_materials_from_files import write_glb

    with pytest.raises(ComponentValueError, match=r"Material.unlit"):
        Material(unlit="yes")
    material = {"name": "sign", "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1.0]},
                "extensions": {"KHR_materials_unlit": {}}}
    path = write_glb(tmp_path / "sign.glb", quad(1.0, 1.0), material, [],
                     {"extensionsUsed": ["KHR_materials_unlit"], "extensionsRequired": ["KHR_materials_unlit"]})
    (part,) = load_model(path)
    assert part.unlit
    world = World("sign")
    spawn_model(world, path)
    ((_, sign),) = list(world.query_one(Material))
    assert sign.unlit and sign.metallic == 0.0
