"""Dispersion (``Refractive.dispersion``, glTF's ``KHR_materials_dispersion``): each colour
refracted by its own index.  Checked against a second path: each channel of a dispersing
glass ball equals the same channel of a ball without dispersion whose index is that
channel's (ior -/+ (ior - 1) x 0.025 x dispersion for red and blue, ior for green), thin and
solid, and the split is there (the channels' images differ from the undispersed ball's)."""
from __future__ import annotations

import numpy as np
import pytest

from components import ComponentValueError, Material, MeshRef, Refractive, Skybox, Transform
from engine.assets.mesh import sphere
from tests.support import look_from, srgb_to_linear

SIZE = (96, 72)


def striped_sky() -> np.ndarray:
    """Six faces of vertical stripes, white and black, in every channel: what a prism splits."""
    face = np.zeros((32, 32, 3), np.float32)
    face[:, ::4] = face[:, 1::4] = 1.0
    return np.stack([face] * 6)


def glass(scene, ior: float, dispersion: float, solid: bool) -> np.ndarray:
    def build(world):
        look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=45.0)
        world.spawn(Skybox(faces=striped_sky()))
        world.spawn(Transform(), MeshRef(sphere(1.0, 64, 32)),
                    Material(color=(1.0, 1.0, 1.0, 0.0), roughness=0.0, environment_reflection=0.0),
                    Refractive(ior=ior, solid=solid, dispersion=dispersion))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame())


@pytest.mark.parametrize("solid", [False, True])
def test_each_channel_is_refracted_by_its_own_index(scene, solid):
    ior, dispersion = 1.5, 4.0
    spread = (ior - 1.0) * 0.025 * dispersion
    split = glass(scene, ior, dispersion, solid)
    for channel, index in enumerate((ior - spread, ior, ior + spread)):
        alone = glass(scene, index, 0.0, solid)
        np.testing.assert_allclose(split[..., channel], alone[..., channel], atol=0.009)
    plain = glass(scene, ior, 0.0, solid)
    np.testing.assert_allclose(split[..., 1], plain[..., 1], atol=0.009)       # green: the ior itself
    assert np.abs(split[..., 0] - plain[..., 0]).max() > 0.3                   # red and blue moved apart
    assert (np.abs(split[..., 0] - split[..., 2]) > 0.3).sum() > 50            # colour fringes


def test_dispersion_values_are_checked_and_read_from_gltf(tmp_path):
    with pytest.raises(ComponentValueError, match=r"Refractive.dispersion"):
        Refractive(dispersion=-1.0)
    with pytest.raises(ComponentValueError, match=r"Refractive.dispersion"):
        Refractive(dispersion=11.0)
    from engine.assets.mesh import load_model
    from engine.assets.models import spawn_model
    from engine.core.errors import AssetError
    from engine.core.world import World
    from tests.test_materials_from_files import write_glb

    def material(extensions: dict) -> dict:
        return {"name": "prism", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0]},
                "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                               "KHR_materials_volume": {"thicknessFactor": 1.0}, **extensions}}
    path = write_glb(tmp_path / "prism.glb", sphere(0.5), material({"KHR_materials_dispersion": {"dispersion": 0.7}}),
                     [], {"extensionsRequired": ["KHR_materials_dispersion"]})
    world = World("prism")
    spawn_model(world, path)
    ((_, refractive),) = list(world.query_one(Refractive))
    assert refractive.dispersion == pytest.approx(0.7) and refractive.solid
    bad = write_glb(tmp_path / "bad.glb", sphere(0.5), material({"KHR_materials_dispersion": {"dispersion": -2}}), [])
    with pytest.raises(AssetError, match=r"bad\.glb.*'prism'.*dispersion must be a number in \[0, 10"):
        load_model(bad)
