"""A panorama's sun taken out as a DirectionalLight (engine/assets/panorama_sun.py): a disc of
known radiance and size drawn (supersampled) into a smooth sky is found where it was put, with
the irradiance its radiance times its solid angle gives, its size, and the sky left in its place;
turned by ``yaw`` as the faces turn (their brightest texel faces it); none in an overcast sky; and
a white ball under the sky without it plus its light shows the closed form of a uniform sky and
a distant light (the sun counted once); the faces table, the runner and the command line."""
from __future__ import annotations

import math

import numpy as np
import pytest

from components import DirectionalLight, Skybox
from engine.assets.panorama import load_hdr, main, panorama_faces, save_hdr, sky_faces_from_file
from engine.assets.panorama_sun import SUN_KEPT, find_sun, pixel_directions
from engine.core.cube_faces import face_directions
from tests.support import grey_ball_under_sky, look_from


def sunny(sun_radiance, radius_deg: float, elevation: float, azimuth: float, sky=None,
          height: int = 128, width: int = 256, fine: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(panorama, the way towards its sun): a sky (``sky(ways)``, default a smooth gradient)
    with a disc of ``sun_radiance`` ``radius_deg`` across at that elevation and azimuth (degrees,
    0 ahead, -Z; 90 right, +X), each pixel the mean of ``fine`` x ``fine`` samples."""
    ways = pixel_directions(height * fine, width * fine)
    el, az = math.radians(elevation), math.radians(azimuth)
    towards = np.array([math.cos(el) * math.sin(az), math.sin(el), -math.cos(el) * math.cos(az)])
    if sky is None:
        background = np.stack([0.3 + 0.2 * ways[..., 1], 0.5 + 0.1 * ways[..., 0], 0.8 + 0.0 * ways[..., 2]], -1)
    else:
        background = sky(ways)
    inside = (ways @ towards) > math.cos(math.radians(radius_deg))
    image = np.where(inside[..., None], np.asarray(sun_radiance, float), background)
    return image.reshape(height, fine, width, fine, 3).mean(axis=(1, 3)), towards


@pytest.mark.parametrize("radius,elevation,azimuth", [(2.0, 35.0, 60.0), (0.8, 5.0, -120.0), (4.0, 70.0, 180.0)])
def test_the_sun_is_found_where_it_was_put_with_its_light_and_size(radius, elevation, azimuth):
    radiance = np.array([5000.0, 4000.0, 3000.0])
    image, towards = sunny(radiance, radius, elevation, azimuth, height=256, width=512)
    sun, without = find_sun(image)
    solid = 2.0 * math.pi * (1.0 - math.cos(math.radians(radius)))
    sky_there = np.array([0.3 + 0.2 * towards[1], 0.5 + 0.1 * towards[0], 0.8])
    irradiance = (radiance - sky_there) * solid
    angle = math.degrees(math.acos(np.clip(-np.array(sun.direction) @ towards, -1, 1)))
    assert angle < 0.1, angle
    np.testing.assert_allclose(np.array(sun.color) * sun.intensity, (1.0 - SUN_KEPT) * irradiance, rtol=0.02)
    assert sun.angular_diameter == pytest.approx(2.0 * radius, rel=0.1 if radius > 1 else 0.3)
    # The sky left in its place: the gradient there (within 3%) plus 1% of the sun (its light,
    # and each pixel's: the disc still drawn), the rest of the sky as it was.
    ways = pixel_directions(256, 512)
    near = (ways @ towards) > math.cos(math.radians(radius + 0.5))
    gradient = np.stack([0.3 + 0.2 * ways[..., 1], 0.5 + 0.1 * ways[..., 0], 0.8 + 0.0 * ways[..., 2]], -1)
    kept = gradient + SUN_KEPT * np.maximum(image - gradient, 0.0)
    np.testing.assert_allclose(without[near], kept[near], rtol=0.03)
    assert without[near].max() > 0.9 * SUN_KEPT * radiance.max()
    np.testing.assert_array_equal(without[~near & ((ways @ towards) < math.cos(math.radians(12)))],
                                  image[~near & ((ways @ towards) < math.cos(math.radians(12)))].astype(np.float32))


@pytest.mark.parametrize("yaw", [0.0, 90.0, -40.0])
def test_a_turned_panoramas_sun_is_where_its_faces_show_it(yaw):
    """The faces' own mapping (``panorama_faces``) is the second path: the face texel whose
    direction is nearest the found sun's is the brightest of all six faces."""
    image, _ = sunny([3000.0, 3000.0, 3000.0], 3.0, 25.0, 30.0)
    sun, _ = find_sun(image, yaw)
    faces = panorama_faces(image, 16, yaw)
    brightest = np.unravel_index(int(np.argmax(faces.sum(axis=-1))), faces.shape[:3])
    ways = np.stack([face_directions(face, 16) for face in range(6)])
    ways /= np.linalg.norm(ways, axis=-1, keepdims=True)
    nearest = np.unravel_index(int(np.argmax(ways @ -np.array(sun.direction))), ways.shape[:3])
    assert nearest == brightest


def test_an_overcast_sky_has_no_sun_and_bad_panoramas_are_refused():
    image, _ = sunny([2.0, 2.0, 2.0], 3.0, 40.0, 0.0)   # (brighter than the sky, not a sun)
    sun, without = find_sun(image)
    assert sun is None
    np.testing.assert_array_equal(without, image.astype(np.float32))
    for bad, words in ((np.ones((4, 4)), "an \\(height, width, 3\\) image"), (np.full((4, 8, 3), -1.0), "non-negative"),
                       (np.full((4, 8, 3), np.nan), "finite")):
        with pytest.raises(ValueError, match=words):
            find_sun(bad)


def test_a_ball_under_the_sky_without_its_sun_and_the_sun_as_a_light_shows_both_once(scene, tmp_path):
    """A uniform sky of radiance 0.3 with a sun of 300 two degrees across: a white ball (albedo
    0.8, diffuse only) shows 0.8 / pi (pi 0.3 + E max(n.l, 0)), E the disc's radiance less the
    sky times its solid angle: the sky's light counts no sun (left in, its light would count
    twice) and the light is the sun's."""
    image, towards = sunny([300.0, 300.0, 300.0], 2.0, 30.0, -50.0, sky=lambda ways: np.full(ways.shape, 0.3))
    path = save_hdr(tmp_path / "sun.hdr", image)
    faces = sky_faces_from_file(path, 32, without_sun=True)
    assert faces.source["without_sun"] is True and faces.sun is not None

    seen, inside, normal = grey_ball_under_sky(scene, faces, DirectionalLight(shadows=False,
                                                                           **faces.sun.light_fields()))
    e_sun = (300.0 - 0.3) * 2.0 * math.pi * (1.0 - math.cos(math.radians(2.0)))   # (1% of it in the sky's light)
    want = 0.8 / math.pi * (math.pi * 0.3 + e_sun * np.maximum(normal @ towards, 0.0))
    error = np.abs(seen[inside] - want[inside][:, None])
    assert inside.sum() > 400 and np.percentile(error, 95) < 0.02 and error.max() < 0.04, error.max()


def test_the_runner_and_a_level_file_take_the_sun_out_and_the_command_line_prints_it(scene, tmp_path, capsys):
    from engine.assets.level_read import load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    image, towards = sunny([800.0, 700.0, 600.0], 1.5, 40.0, 10.0)
    path = save_hdr(tmp_path / "sky.hdr", image)
    runner = scene(lambda world: look_from(world, (0.0, 0.0, 0.0), (0.0, 0.0, -1.0)), (16, 16))
    runner.engine.start_sky(None, panorama=str(path), panorama_yaw=20.0, panorama_sun=True)
    runner.frame()
    (_, light), = runner.world.query_one(DirectionalLight)
    sun, _ = find_sun(load_hdr(path), 20.0)   # (the file's colours: RGBE rounds them)
    np.testing.assert_allclose(np.array(light.direction), sun.direction, atol=1e-6)
    assert light.intensity == pytest.approx(sun.intensity) and light.angular_diameter == pytest.approx(
        sun.angular_diameter, abs=1e-6)
    level = tmp_path / "level.toml"
    level.write_text('[level]\nname = "sun"\n[[entity]]\nname = "sky"\n'
                     'Skybox = { faces = { panorama = "sky.hdr", face_size = 8, without_sun = true } }\n')
    world = World()
    load_level(level).spawn(world)
    faces = world.query_one(Skybox)[0][1].faces
    np.testing.assert_array_equal(faces, sky_faces_from_file(path, 8, without_sun=True))
    assert faces.max() < 0.02 * 800.0   # (1% of the sun left in them)
    save_level(world, tmp_path / "saved.toml")
    assert "without_sun = true" in (tmp_path / "saved.toml").read_text()
    assert main([str(path)]) == 0
    line = capsys.readouterr().out
    assert line.startswith("DirectionalLight = { direction = [") and "angular_diameter" in line
    assert main([str(tmp_path / "none.hdr")]) == 2 and "no such file" in capsys.readouterr().out


def test_the_command_line_reads_an_exr_layers_sun(tmp_path, capsys):
    """``--layer`` picks an OpenEXR file's layer: its sun printed; the file's first colours
    (an overcast grey) have none; a layer of an .hdr file is refused."""
    import OpenEXR

    image, _ = sunny([800.0, 700.0, 600.0], 1.5, 40.0, 10.0)
    grey = np.full_like(image, 0.4, np.float32)
    path = str(tmp_path / "sky.exr")
    channels = {c: np.ascontiguousarray(grey[..., i]) for i, c in enumerate("RGB")}
    channels.update({f"sunny.{c}": np.ascontiguousarray(image[..., i].astype(np.float32)) for i, c in enumerate("RGB")})
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels).write(path)
    assert main([path, "--layer", "sunny"]) == 0
    assert capsys.readouterr().out.startswith("DirectionalLight = { direction = [")
    assert main([path]) == 1 and "no sun" in capsys.readouterr().out
    hdr = save_hdr(tmp_path / "sky.hdr", image)
    assert main([str(hdr), "--layer", "sunny"]) == 2 and "only an OpenEXR" in capsys.readouterr().out


def test_the_command_line_refuses_a_panorama_sun_without_a_panorama_or_with_a_clock(capsys):
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.runner import parse_args

    for argv, words in ((["--panorama-sun"], "--panorama-sun needs --panorama"),
                        (["--panorama", "sky.exr", "--panorama-sun", "--time", "9"], "both place the sun")):
        with pytest.raises(SystemExit):
            parse_args(HallOfMirrors(), argv)
        assert words in capsys.readouterr().err


def test_the_runners_panorama_sun_casts_a_posts_shadow_away_from_the_brightest_texel(scene, tmp_path):
    """A panorama (256 x 512) with a sun 1 degree across at 40 degrees up, turned 25 degrees
    by ``--panorama-yaw``: the runner gives its light to the brighter of two lights (the dimmer
    left as it was), and a 2 m post's shadow on the floor (the darker pixels' floor points, seen
    from 12 m straight down) runs from its foot away from the brightest texel's way (its row's
    latitude and column's longitude, the middle column -Z and a quarter right +X, turned 25
    degrees about +Y, 90 bringing the middle round to -X), as long as 2 m over the tangent of
    its latitude."""
    from pyglm import glm

    from components import Camera, Material, MeshRef, Transform, look_rotation
    from engine.assets.mesh import box, plane
    from tests.support import pixel_rays

    image, _ = sunny([6000.0, 5600.0, 5000.0], 1.0, 40.0, 70.0, height=256, width=512,
                     sky=lambda ways: np.full(ways.shape, 0.4))
    path = save_hdr(tmp_path / "sky.hdr", image)
    row, column = np.unravel_index(int(np.argmax(image.sum(axis=-1))), image.shape[:2])
    latitude = math.pi / 2.0 - (row + 0.5) / 256 * math.pi
    longitude = ((column + 0.5) / 512 - 0.5) * 2.0 * math.pi
    ahead = glm.vec3(math.cos(latitude) * math.sin(longitude), math.sin(latitude),
                     -math.cos(latitude) * math.cos(longitude))
    towards = np.array(tuple(glm.angleAxis(math.radians(25.0), glm.vec3(0.0, 1.0, 0.0)) * ahead), np.float64)

    def build(world):
        world.spawn(Transform(position=(0.0, 12.0, 0.0), rotation=look_rotation(glm.vec3(0.0, -1.0, 0.0),
                                                                                 glm.vec3(0.0, 0.0, -1.0))),
                    Camera(fov_y=60.0, near=0.5, far=50.0))
        world.spawn(DirectionalLight(direction=(0.0, -1.0, 0.0), intensity=1.0, shadow_resolution=2048))
        world.spawn(DirectionalLight(direction=(0.3, -1.0, 0.0), intensity=0.05, shadows=False))
        grey = Material(color=(0.3, 0.3, 0.3), roughness=1.0)
        world.spawn(Transform(), MeshRef(plane(40.0, 40.0)), grey)
        world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(box((0.16, 2.0, 0.16))), grey)

    runner = scene(build, (96, 96))
    runner.engine.start_sky(None, panorama=str(path), panorama_yaw=25.0, panorama_sun=True)
    frame = runner.frame().astype(np.float64).sum(axis=-1)
    lights = runner.world.query_one(DirectionalLight)
    bright, dim = sorted((light for _, light in lights), key=lambda light: light.intensity, reverse=True)
    np.testing.assert_allclose(tuple(dim.direction), tuple(glm.normalize(glm.vec3(0.3, -1.0, 0.0))), atol=1e-6)
    assert dim.intensity == 0.05 and bright.angular_diameter == pytest.approx(2.0, rel=0.1)
    angle = math.degrees(math.acos(min(1.0, float(-np.array(tuple(bright.direction)) @ towards))))
    assert angle < 0.5, angle   # (half a texel: 0.35 degrees)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    dark = frame < 0.8 * np.median(frame)   # (the shadow's: 0.56 of it)
    floor = (eye + rays * (-eye[1] / rays[..., 1:2]))[dark][:, [0, 2]]
    away = -towards[[0, 2]] / np.linalg.norm(towards[[0, 2]])
    along, across = floor @ away, floor @ np.array([-away[1], away[0]])
    length = 2.0 / math.tan(latitude)
    assert len(floor) > 10 and along.max() == pytest.approx(length, abs=0.3), (len(floor), along.max(), length)
    assert along.min() > -0.3 and np.abs(across).max() < 0.2, (along.min(), np.abs(across).max())
