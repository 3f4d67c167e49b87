"""IES light profiles (``engine/assets/ies_profile.py``): a luminaire's candelas by direction
from an LM-63 file, worn by an all-round ``PointLight`` as its cookie.  The files here are
written by the tests from formulas (a cosine-squared downlight, a profile brighter across its
X than along it), and the floor a lamp lights is held to I(direction) / I(peak) times the same
lamp's light without the profile, in linear light, pixel by pixel (the cookie's 8-bit sRGB
steps and its filtering: within 0.02 of the lamp's share, 0.006 in the median)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Material, MeshRef, PointLight, Skybox, Transform, look_rotation
from engine.assets.ies_profile import ies_cookie, load_ies, parse_ies
from engine.assets.mesh import plane
from engine.core.errors import AssetError
from tests.support import look_from, pixel_rays, srgb_to_linear

SIZE = (128, 96)
LAMP = (0.0, 2.0, 0.0)


def ies_text(vertical, horizontal, candela, multiplier=1.0, kind=1, tilt="NONE") -> str:
    """An LM-63-2002 file: the header, TILT, the numbers (candela: a row of vertical values for
    each horizontal angle)."""
    head = f"IESNA:LM-63-2002\n[TEST] written by the tests\n[MANUFAC] none\nTILT={tilt}\n"
    numbers = [1, -1, multiplier, len(vertical), len(horizontal), kind, 2, 0.1, 0.1, 0.0, 1.0, 1.0, 20.0]
    rows = [" ".join(f"{v:g}" for v in numbers[:10]), " ".join(f"{v:g}" for v in numbers[10:]),
            " ".join(f"{v:g}" for v in vertical), " ".join(f"{v:g}" for v in horizontal)]
    rows += [" ".join(f"{v:g}" for v in row) for row in np.asarray(candela).reshape(len(horizontal), len(vertical))]
    return head + "\n".join(rows) + "\n"


VERTICAL = np.arange(0.0, 181.0, 5.0)


def downlight(gamma):
    """Candelas of a downlight: 1000 cos^2 below the horizon, none above."""
    g = np.radians(gamma)
    return np.where(gamma < 90.0, 1000.0 * np.cos(g) ** 2, 0.0)


def wide_across(gamma, phi):
    """Brighter across its X than along its Y: (0.3 + 0.7 cos^2 phi) of a downlight."""
    return downlight(gamma) * (0.3 + 0.7 * np.cos(np.radians(phi)) ** 2)


def test_a_file_is_read_with_its_multiplier_and_symmetry(tmp_path):
    path = tmp_path / "down.ies"
    path.write_text(ies_text(VERTICAL, [0.0], downlight(VERTICAL) / 2.0, multiplier=2.0))
    profile = load_ies(path)
    assert profile.peak == pytest.approx(1000.0)
    np.testing.assert_allclose(profile.intensity(np.array([0.0, 30.0, 60.0, 120.0]), np.array([0.0, 77.0, 200.0, 5.0])),
                               downlight(np.array([0.0, 30.0, 60.0, 120.0])), rtol=0.01, atol=1e-9)
    # A quarter (0 to 90) unfolds to the whole turn as the file's symmetry says.
    horizontal = np.arange(0.0, 91.0, 15.0)
    table = np.array([wide_across(VERTICAL, h) for h in horizontal])
    quarter = parse_ies(ies_text(VERTICAL, horizontal, table), "quarter")
    phi = np.array([0.0, 30.0, 150.0, 210.0, 300.0])
    np.testing.assert_allclose(quarter.intensity(np.full(5, 20.0), phi), wide_across(20.0, phi), rtol=0.02)


@pytest.mark.parametrize(("change", "match"), [
    (lambda t: t.replace("TILT=NONE", "TILT=INCLUDE"), "only TILT=NONE"),
    (lambda t: t.replace("TILT=NONE\n", ""), "no TILT="),
    (lambda t: t + "5\n", "angles and candelas after the header"),
    (lambda t: t.replace(" 1 2 0.1", " 3 2 0.1", 1), "photometric type 3"),
    (lambda t: t.replace("0 5 10", "0 10 5", 1), "vertical angles must rise"),
    (lambda t: t.replace("1000", "-1000", 1), "negative"),
    (lambda t: t.replace("1000", "x1000", 1), "not a number"),
])
def test_a_bad_file_is_refused_naming_it_and_why(tmp_path, change, match):
    path = tmp_path / "bad.ies"
    path.write_text(change(ies_text(VERTICAL, [0.0], downlight(VERTICAL))))
    with pytest.raises(AssetError, match=match) as caught:
        load_ies(path)
    assert "bad.ies" in str(caught.value)


def test_the_cookie_holds_each_directions_share_of_the_peak():
    """The panorama's texels (longitude across, the middle ahead: the light's -Z, the
    profile's nadir; the top row straight up) decoded from sRGB: each direction's share of the
    peak, to the 8-bit step (the profile's own interpolation between its angles; the formula
    it was written from within the file's steps)."""
    horizontal = np.arange(0.0, 361.0, 30.0)
    profile = parse_ies(ies_text(VERTICAL, horizontal, [wide_across(VERTICAL, h) for h in horizontal]), "wide")
    texture = ies_cookie(profile, 64, 32)
    shares = srgb_to_linear(texture.pixels[..., 0])
    rows, cols = np.mgrid[0:32, 0:64]
    lat = (0.5 - (rows + 0.5) / 32) * math.pi
    lon = ((cols + 0.5) / 64 - 0.5) * 2.0 * math.pi
    x, y, z = np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)
    gamma, phi = np.degrees(np.arccos(np.clip(z, -1, 1))), np.degrees(np.arctan2(y, x))
    np.testing.assert_allclose(shares, profile.intensity(gamma, phi) / profile.peak, atol=0.006)
    np.testing.assert_allclose(shares, wide_across(gamma, phi) / 1000.0, atol=0.05)   # (the file's 30-degree steps)
    assert shares[8:24, 24:40].max() > 0.8 and shares[0].max() < 0.01   # bright ahead (the nadir), dark up


def floor_light(scene, cookie) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floor's linear green under an all-round lamp 2 m up hung to shine down (its -Z: the
    profile's nadir), its X along the world's X, with ``cookie`` (None: none): the floor's
    pixels and their points."""
    def build(world):
        look_from(world, (0.0, 3.5, 4.5), (0.0, 0.0, 0.0), fov=60.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(plane(12.0, 12.0)),
                    Material(color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        down = look_rotation(glm.vec3(0.0, -1.0, 0.0), glm.vec3(0.0, 0.0, -1.0))
        world.spawn(Transform(position=LAMP, rotation=down), PointLight(intensity=6.0, range=20.0, cookie=cookie))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame())[..., 1].reshape(-1)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    rays = rays.reshape(-1, 3)
    t = -eye[1] / rays[:, 1]
    floor = (t > 0) & (t < 30.0)
    return shown[floor], (eye + rays * t[:, None])[floor], runner


def test_a_lamp_wearing_a_profile_lights_the_floor_by_it(scene):
    """Each floor pixel is the plain lamp's light times I(its direction from the lamp) / I(peak),
    the direction's vertical angle from straight down and horizontal angle from the lamp's +X
    (the world's X: the lamp hung facing down with its top towards -Z, so its +Y is the
    world's -Z)."""
    horizontal = np.arange(0.0, 181.0, 30.0)
    profile = parse_ies(ies_text(VERTICAL, horizontal, [wide_across(VERTICAL, h) for h in horizontal]), "wide")
    plain, points, _ = floor_light(scene, None)
    worn, _, runner = floor_light(scene, ies_cookie(profile))
    d = points - np.asarray(LAMP)
    gamma = np.degrees(np.arccos(np.clip(-d[:, 1] / np.linalg.norm(d, axis=1), -1.0, 1.0)))
    phi = np.degrees(np.arctan2(-d[:, 2], d[:, 0]))   # (the lamp's +Y is the world's -Z)
    share = wide_across(gamma, phi) / 1000.0
    lit = plain > 0.03
    assert lit.sum() > 2000 and share[lit].min() < 0.3 and share[lit].max() > 0.9
    error = np.abs(worn[lit] - plain[lit] * share[lit])
    assert np.median(error) < 0.006 and np.percentile(error, 99) < 0.02, (np.median(error), np.percentile(error, 99))
    assert runner.engine.renderer.spot_cookies.defines == (("SPOT_COOKIES", "1"),)


def test_a_level_file_names_a_profile(tmp_path):
    """``cookie = { ies = "lamp.ies" }`` on a PointLight: the profile's panorama, saved back as
    the same file (relative to the level)."""
    from tests.support import entity_level_round_trip

    (tmp_path / "lamp.ies").write_text(ies_text(VERTICAL, [0.0], downlight(VERTICAL)))
    world, it = entity_level_round_trip(
        tmp_path, '[entity.Transform]\nposition = [0.0, 3.0, 0.0]\n[entity.PointLight]\nintensity = 5.0\n'
        'cookie = { ies = "lamp.ies" }\n', ('ies = "lamp.ies"', 'ies = "none.ies"'), "cookie")
    cookie = world.get(it, PointLight).cookie
    assert cookie.source == {"ies": str(tmp_path / "lamp.ies")} and cookie.pixels.shape == (128, 256, 4)


def lopsided(phi):
    """A share by horizontal angle that differs in each of the four ways: 0.85 at 0 (the
    lamp's +X), 0.7 at 90 (its +Y), 0.25 at 180, 0.4 at 270."""
    phi = np.radians(phi)
    return 0.55 + 0.3 * np.cos(phi) + 0.15 * np.sin(phi)


def table_intensity(vertical, horizontal, table, gamma, phi):
    """Candelas from a whole-turn file's ``table`` (a row of vertical values for each
    horizontal angle, 0 to 360) at ``gamma`` and ``phi`` (degrees): linear between the
    vertical angles along each of the two horizontal rows about ``phi``, then between them."""
    phi = np.mod(phi, 360.0)
    k = np.clip(np.searchsorted(horizontal, phi, side="right") - 1, 0, len(horizontal) - 2)
    f = (phi - horizontal[k]) / (horizontal[k + 1] - horizontal[k])
    rows = np.array([np.interp(gamma, vertical, row) for row in table])   # (horizontal, points)
    index = np.arange(len(gamma))
    return rows[k, index] * (1.0 - f) + rows[k + 1, index] * f


def test_a_whole_turn_profile_lights_each_way_round_the_lamp_by_its_table(scene):
    """A whole-turn file (0 to 360 every 45 degrees, vertical every 10) lopsided all round: its
    horizontal angle 0 towards the lamp's +X (the world's +X) and 90 towards its +Y (the
    world's -Z: the lamp hangs facing down, its top towards -Z), each floor pixel the plain
    lamp's light times the file's table, interpolated here, at its direction over the peak:
    within 0.008 at the 99th percentile, 0.002 in the median (measured 0.0032 and 0.0002: the
    cookie's texels and 8-bit steps); the profile the other way round (phi turned to -phi, as
    a cookie built or wrapped inside out would be) misses by up to 0.1 and more.  (The
    profiles above are the same either way round.)"""
    vertical, horizontal = np.arange(0.0, 181.0, 10.0), np.arange(0.0, 361.0, 45.0)
    table = np.array([downlight(vertical) * lopsided(h) for h in horizontal])
    profile = parse_ies(ies_text(vertical, horizontal, table), "lopsided")
    plain, points, _ = floor_light(scene, None)
    worn, _, _ = floor_light(scene, ies_cookie(profile))
    d = points - np.asarray(LAMP)
    gamma = np.degrees(np.arccos(np.clip(-d[:, 1] / np.linalg.norm(d, axis=1), -1.0, 1.0)))
    phi = np.degrees(np.arctan2(-d[:, 2], d[:, 0]))   # (the lamp's +Y is the world's -Z)
    peak = table.max()
    share = table_intensity(vertical, horizontal, table, gamma, phi) / peak
    lit = plain > 0.03
    assert lit.sum() > 2000
    error = np.abs(worn[lit] - plain[lit] * share[lit])
    assert np.median(error) < 0.002 and np.percentile(error, 99) < 0.008, (np.median(error), np.percentile(error, 99))
    turned = table_intensity(vertical, horizontal, table, gamma, -phi) / peak
    assert np.abs(plain[lit] * (turned[lit] - share[lit])).max() > 0.1
    assert np.abs(worn[lit] - plain[lit] * turned[lit]).max() > 0.05


def test_a_half_turn_file_is_mirrored_about_its_0_to_180_plane():
    """A half (0 to 180) unfolds as its symmetry says: the intensity at 360 - phi is the one
    at phi; a whole-turn file's own values are read at each phi, the 0 and 360 rows alike."""
    vertical = np.arange(0.0, 181.0, 10.0)
    half = np.arange(0.0, 181.0, 30.0)
    profile = parse_ies(ies_text(vertical, half, [downlight(vertical) * (0.5 + 0.4 * np.cos(np.radians(h)))
                                                   for h in half]), "half")
    phi = np.array([0.0, 30.0, 90.0, 150.0, 180.0, 45.0, 100.0])
    gamma = np.full(len(phi), 20.0)
    np.testing.assert_allclose(profile.intensity(gamma, 360.0 - phi), profile.intensity(gamma, phi), rtol=1e-12)
    np.testing.assert_allclose(profile.intensity(gamma[:5], phi[:5]),   # (to the file's 6 digits)
                               downlight(20.0) * (0.5 + 0.4 * np.cos(np.radians(phi[:5]))), rtol=1e-5)
    whole = np.arange(0.0, 361.0, 45.0)
    table = np.array([downlight(vertical) * lopsided(h) for h in whole])
    full = parse_ies(ies_text(vertical, whole, table), "whole")
    phi = np.array([0.0, 45.0, 100.0, 200.0, 270.0, 315.0, 359.0, 360.0])
    np.testing.assert_allclose(full.intensity(np.full(len(phi), 35.0), phi),
                               table_intensity(vertical, whole, table, np.full(len(phi), 35.0), phi), rtol=1e-5)
