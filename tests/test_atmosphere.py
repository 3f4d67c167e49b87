"""A physically based sky (``Skybox(model="atmosphere")``, ``engine/render/atmosphere.py``):
its tables against integrals written here (a straight march through the air's densities, and
the closed form of a sun overhead), the sky pass and the cube map against the CPU twin pixel
by pixel, what the light of a real sky does as the sun goes down, and the sun's own light
reddened by the same air; from a level's altitude, the thinner air above it."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.mesh import box, plane
from engine.render import atmosphere as atm
from engine.render.irradiance import generated_sky_sh, project_faces
from engine.render.sky import air_of, build_faces, model_radiance, model_sky, sky_model, sky_radiance
from engine.rules.light_rules import SkySun
from tests.test_generated_sky import SIZE, _cube_faces, _read

EARTH = atm.Air()


def _toward(elevation: float, azimuth: float = 0.0) -> np.ndarray:
    """The unit way at ``elevation`` degrees over the horizon, ``azimuth`` degrees from -Z towards +X."""
    e, a = math.radians(elevation), math.radians(azimuth)
    return np.array([math.cos(e) * math.sin(a), math.sin(e), -math.cos(e) * math.cos(a)])


def _optical_depth(air: atm.Air, r: float, mu: float, steps: int = 20000) -> np.ndarray:
    """The air's optical depth (3,) from radius ``r`` along a way of cosine ``mu`` to space,
    by the midpoint rule over ``steps`` (written from the densities' definitions, not the tables)."""
    length = -r * mu + math.sqrt(r * r * (mu * mu - 1.0) + atm.TOP_KM ** 2)
    t = (np.arange(steps) + 0.5) / steps * length
    h = np.sqrt(r * r + t * t + 2.0 * r * mu * t) - atm.GROUND_KM
    rayleigh = air.rayleigh * np.exp(-h / 8.0)
    mie = air.haze * np.exp(-h / 1.2)
    ozone = air.rayleigh * np.maximum(0.0, 1.0 - np.abs(h - 25.0) / 15.0)
    sigma = (np.outer(rayleigh, [5.802e-3, 13.558e-3, 33.1e-3]) + np.outer(mie, [4.4e-3] * 3)
             + np.outer(ozone, [0.650e-3, 1.881e-3, 0.085e-3]))
    return sigma.sum(axis=0) * (length / steps)


@pytest.mark.parametrize("eye_km", [atm.EYE_KM, 4.0])
@pytest.mark.parametrize("elevation", [90.0, 30.0, 8.0, 2.0, 0.3])
def test_the_sunlight_that_crosses_the_air_is_its_optical_depths_exponential(elevation, eye_km):
    """The transmittance table (Bruneton's mapping, 40 steps a ray) against a 20,000-step
    march from the eye (200 m up, and 4 km: the sunlight's share as ``sunlight_share`` reads
    it for a level that high): within 1% of the light (2% at the last degree, where 0.3
    degrees leaves a 25th of the blue)."""
    r = atm.GROUND_KM + eye_km
    mu = math.sin(math.radians(elevation))
    want = np.exp(-_optical_depth(EARTH, r, mu))
    got = atm.sunlight_share(atm.Air(eye_km=eye_km), _toward(elevation))
    np.testing.assert_allclose(got, want, rtol=0.02 if elevation < 1.0 else 0.01, atol=2e-4)
    assert not atm.transmittance(EARTH, np.float64(r), np.float64(-0.2)).any()   # into the ground: none


@pytest.mark.parametrize("eye", [atm.EYE_KM, 3.0])
def test_a_sun_overhead_seen_overhead_is_the_closed_form_of_single_scattering(eye):
    """Sun and eye both on the vertical: the sun's light reaches each height through the air
    above it and the eye through the air below, so every height's light is dimmed by the
    whole column, and L = E exp(-tau) (beta_R P_R(1) H_R + beta_M P_M(1) H_M) (the
    densities' integrals over the column above the eye: 200 m up, and 3 km).  The table
    (multiple scattering off) within 2% (measured 1.2% in the red, where the 1.2 km of haze
    is crossed in a few of its 30 steps; it closes as 1 / steps^2)."""
    air = atm.Air(multiple=False, eye_km=eye)
    table = atm.sky_view_table(air, 90.0)

    def column(height: float) -> float:   # a density of scale ``height``'s integral from the eye up
        return height * (math.exp(-eye / height) - math.exp(-(atm.TOP_KM - atm.GROUND_KM) / height))

    tau = _optical_depth(air, atm.GROUND_KM + eye, 1.0)
    rayleigh = np.array([5.802e-3, 13.558e-3, 33.1e-3]) * 3.0 / (16.0 * math.pi) * 2.0 * column(8.0)
    g = 0.8
    mie_phase = 3.0 / (8.0 * math.pi) * (1 - g * g) * 2.0 / ((2 + g * g) * (1 + g * g - 2 * g) ** 1.5)
    want = np.exp(-tau) * (rayleigh + 3.996e-3 * mie_phase * column(1.2))
    np.testing.assert_allclose(table[-1, 0, :3], want, rtol=0.02)
    np.testing.assert_allclose(table[-1, 0, 3], np.exp(-tau[1]), rtol=0.01)   # (straight up, beyond the air: its green)
    # ... and multiple scattering only adds light (the table's other orders).
    assert (atm.sky_view_table(atm.Air(eye_km=eye), 90.0)[..., :3] >= table[..., :3] - 1e-6).all()


def test_the_sky_does_what_a_real_one_does_as_the_sun_goes_down():
    """Noon: blue overhead (blue > green > red), whiter at the horizon.  Sunset (sun 2
    degrees up): the horizon under the sun red > green > blue, redder and brighter than the
    horizon opposite it.  Ten degrees after sunset: the sky under a hundredth of noon's.  More haze:
    the horizon whiter; more molecules: the low sun's light redder."""
    noon = sky_model(Skybox(model="atmosphere"), SkySun(tuple(_toward(60.0))))
    zenith, horizon = model_radiance(noon, np.array([_toward(90.0), _toward(1.0, 90.0)]))
    assert zenith[2] > zenith[1] > zenith[0]
    assert horizon[2] / horizon[0] < zenith[2] / zenith[0]
    dusk = sky_model(Skybox(model="atmosphere"), SkySun(tuple(_toward(2.0))))
    under, opposite = model_radiance(dusk, np.array([_toward(1.0, 10.0), _toward(1.0, 180.0)]))
    assert under[0] > under[1] > under[2]
    assert under[0] / under[2] > 1.5 * opposite[0] / opposite[2]   # (measured 2.5: the Belt of Venus is pink too)
    assert under.sum() > 3.0 * opposite.sum()                         # (4.6)
    night = sky_model(Skybox(model="atmosphere"), SkySun(tuple(_toward(-10.0))))
    ways = np.array([_toward(e, a) for e in (1.0, 10.0, 45.0, 89.0) for a in (0.0, 90.0, 180.0)])
    assert model_radiance(night, ways).max() < 0.01 * model_radiance(noon, ways).max()
    hazy = sky_model(Skybox(model="atmosphere", haze=6.0), SkySun(tuple(_toward(60.0))))
    h = model_radiance(hazy, _toward(1.0, 90.0))
    assert h[2] / h[0] < horizon[2] / horizon[0]
    thick = atm.sunlight_share(atm.Air(rayleigh=3.0), _toward(5.0))
    thin = atm.sunlight_share(EARTH, _toward(5.0))
    assert thick[0] / thick[2] > 2.0 * thin[0] / thin[2]


def test_the_skys_light_is_its_projection(ctx):
    """The sky's irradiance coefficients (projected from 32-texel faces, the disc in closed
    form) against the projection of 128-texel faces of the same sky: within 1% of the largest
    (a sun 4 degrees up, its glow the sharpest: 0.6% measured against 256-texel faces)."""
    for elevation in (50.0, 4.0):
        skybox, sun = Skybox(model="atmosphere"), SkySun(tuple(_toward(elevation, 30.0)))
        got = generated_sky_sh(sky_model(skybox, sun))
        want = project_faces(build_faces(Skybox(model="atmosphere", face_size=128), sun))
        assert np.abs(got - want).max() < 0.01 * np.abs(want).max()


def _frame(scene, skybox: Skybox, light: DirectionalLight, look: np.ndarray, fov: float = 60.0):
    def build(world):
        world.spawn(Transform(rotation=look_rotation(glm.vec3(*look))), Camera(fov_y=fov, near=0.1, far=100.0))
        world.spawn(skybox)
        world.spawn(light)

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return (*_read(runner), runner)


@pytest.mark.parametrize("elevation", [35.0, 3.0])
def test_the_sky_pass_and_the_cube_map_draw_the_cpu_twin(scene, elevation):
    """Every pixel of the sky (above and below the horizon, the disc in view) is the twin's
    (``sky_radiance``: the same table read bilinearly) along its ray; the cube map the
    reflections read holds the twin's faces."""
    sun = _toward(elevation, 20.0)
    skybox = Skybox(model="atmosphere")
    light = DirectionalLight(direction=tuple(-sun), intensity=3.0)
    colour, rays, runner = _frame(scene, skybox, light, _toward(0.5 * elevation - 8.0, 10.0))
    want = sky_radiance(skybox, rays, SkySun(tuple(sun)))
    assert (rays[..., 1] < 0.0).any() and (want[..., 0] > 3.0).any()   # the ground and the disc in view
    np.testing.assert_allclose(colour, want, rtol=1e-2, atol=2e-3)
    faces = _cube_faces(runner)
    want_faces = build_faces(Skybox(model="atmosphere"), SkySun(tuple(sun)))
    np.testing.assert_allclose(faces, want_faces, rtol=1e-2, atol=2e-3)


def test_the_sunlight_is_reddened_by_the_air_it_crosses(scene):
    """A floor under a sun 6 degrees up, part of it in a low wall's shadow: the sun's own
    light (lit less shadowed: the sky's light is on both) over the same with
    ``tints_sunlight`` off is the air's transmittance towards the sun over its transmittance
    from overhead, both from the march written here, channel by channel within 3%."""
    sun = _toward(6.0)   # from -Z
    frames = {}
    for tints in (True, False):
        def build(world, tints=tints):
            world.spawn(Transform(position=(0.0, 6.0, 0.0), rotation=look_rotation(glm.vec3(0.0, -1.0, -0.001))),
                        Camera(fov_y=60.0, near=0.1, far=100.0))
            world.spawn(Skybox(model="atmosphere", tints_sunlight=tints))
            world.spawn(DirectionalLight(direction=tuple(-sun), intensity=3.0, shadows=True))
            world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
            # 0.3 m high at z = -4: its shadow reaches 2.85 m past it, to z = -1.1
            world.spawn(Transform(position=(0.0, 0.15, -4.0)), MeshRef(box((20.0, 0.3, 0.1))), Material())

        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        frames[tints], rays = _read(runner)
    eye = np.array(runner.engine.main_view.eye, np.float64)
    z = eye[2] + rays[..., 2] * (-eye[1] / rays[..., 1])   # where each pixel's ray meets the floor
    shaded, lit = (z > -3.5) & (z < -1.6), z > 0.0
    assert shaded.sum() > 100 and lit.sum() > 100
    direct = {t: frames[t][lit].mean(axis=0) - frames[t][shaded].mean(axis=0) for t in frames}
    assert (direct[False] > 0.05).all()   # the shadow is there (3 x sin 6 degrees x 0.8 / pi: 0.08)
    r = atm.GROUND_KM + atm.EYE_KM
    want = np.exp(-_optical_depth(EARTH, r, sun[1])) / np.exp(-_optical_depth(EARTH, r, 1.0))
    np.testing.assert_allclose(direct[True] / direct[False], want, rtol=0.03)


def test_the_table_is_drawn_again_as_the_sun_moves_and_goes_with_the_sky(scene):
    """The sky-view table is drawn on the GPU again when the sun moves (a still frame draws
    none), the sky pass then the twin's at the new elevation; the table is released once the
    sky is a gradient again, and with the Skybox."""
    sun = _toward(20.0)
    light = DirectionalLight(direction=tuple(-sun), intensity=3.0)
    skybox = Skybox(model="atmosphere")
    _, _, runner = _frame(scene, skybox, light, _toward(10.0))
    renderer = runner.engine.renderer
    drawn = renderer.sky_view_pass.draws
    assert drawn >= 1 and renderer.resource_counts()["sky_view"] == 1
    runner.frame()
    assert renderer.sky_view_pass.draws == drawn   # still: kept
    light.direction = tuple(-_toward(21.0, 40.0))
    runner.frame()
    assert renderer.sky_view_pass.draws == drawn + 1
    colour, rays = _read(runner)
    np.testing.assert_allclose(colour, sky_radiance(skybox, rays, SkySun(tuple(_toward(21.0, 40.0)))),
                               rtol=1e-2, atol=2e-3)
    skybox.model = "gradient"
    runner.frame()
    assert renderer.resource_counts()["sky_view"] == 0 and renderer.sky_view is None
    assert renderer.sky_view_pass.texture is None
    skybox.model = "atmosphere"
    runner.frame()
    assert renderer.resource_counts()["sky_view"] == 1
    world = runner.engine.world
    world.delete_entity(next(entity for entity, _ in world.query_one(Skybox)))
    runner.frame()
    assert renderer.resource_counts()["sky_view"] == 0 and renderer.sky_view_pass.texture is None


def test_the_gpus_table_is_the_numpy_one(scene):
    """The table the GPU draws (``shaders/sky_view.frag``) against ``sky_view_table``'s march
    in float64, for a high sun and a setting one, hazy air and thick: within 1% of the light
    (half floats, the two tables read with the GPU's filtering)."""
    runner = scene(lambda world: None, (16, 16))
    sky_view = runner.engine.renderer.sky_view_pass
    for air, elevation in ((EARTH, 50.0), (EARTH, 1.5), (atm.Air(haze=4.0, rayleigh=2.0), 12.0),
                           (atm.Air(eye_km=6.0), 3.0)):
        texture = sky_view.draw(air, elevation)
        rows, columns = atm.VIEW_SIZE
        got = np.frombuffer(texture.read(), np.float16).reshape(rows, columns, 4).astype(np.float64)
        want = atm.sky_view_table(air, elevation)
        np.testing.assert_allclose(got[..., :3], want[..., :3], rtol=0.01, atol=2e-5 * want[..., :3].max())
        np.testing.assert_allclose(got[..., 3], want[..., 3], rtol=0.01, atol=1e-3)   # (what crosses the air)


def test_a_higher_level_sees_the_thinner_air_above_it():
    """From 5 km up (``Skybox.altitude``): the zenith darker and bluer than from 200 m (half
    the molecules and almost none of the haze above), a low sun's light stronger (less air on
    its way) and its sky redder beside it no more than from below; the air's two tables are
    made once for every altitude (they do not depend on the eye)."""
    low, high = Skybox(model="atmosphere"), Skybox(model="atmosphere", altitude=5000.0)
    assert air_of(high).eye_km == 5.0 and air_of(low).eye_km == pytest.approx(atm.EYE_KM)
    noon = SkySun(tuple(_toward(60.0)))
    below, above = (model_radiance(sky_model(sky, noon), _toward(89.0)) for sky in (low, high))
    assert above.sum() < 0.75 * below.sum() and above[2] / above[0] > below[2] / below[0]
    sunset = _toward(3.0)
    share_low, share_high = (atm.sunlight_share(air_of(sky), sunset) for sky in (low, high))
    assert (share_high > 1.3 * share_low).all() and share_high[0] / share_high[2] < share_low[0] / share_low[2]
    assert atm.transmittance_table(air_of(high)) is atm.transmittance_table(air_of(low))
    assert atm.multiple_scattering_table(air_of(high)) is atm.multiple_scattering_table(air_of(low))


@pytest.mark.parametrize("eye_km", [0.2, 3.0, 8.0])
def test_the_true_horizon_lies_where_the_grounds_tangent_does(eye_km):
    """``horizon_sine`` against the ground's own intersection rule (``_meets_ground``): a way
    a hair above the true horizon crosses the air to space, a hair below it meets the ground
    (0.45 degrees down at 200 m, 2.9 at 8 km)."""
    sine = atm.horizon_sine(atm.Air(eye_km=eye_km))
    r = np.float64(atm.GROUND_KM + eye_km)
    assert not atm._meets_ground(r, np.float64(-sine + 1e-6)) and atm._meets_ground(r, np.float64(-sine - 1e-6))
    assert math.degrees(math.asin(sine)) == pytest.approx(math.degrees(math.acos(atm.GROUND_KM / float(r))))


def test_from_up_high_the_sky_reaches_below_the_level_horizon(scene):
    """From 8 km the ways between the level horizon and the true one, 2.9 degrees below it,
    show the sky (the twin's, pixel by pixel: the table's horizon row), where from 200 m the
    ground has faded in."""
    sun = _toward(25.0, 20.0)
    light = DirectionalLight(direction=tuple(-sun), intensity=3.0)
    high, rays, _ = _frame(scene, Skybox(model="atmosphere", altitude=8000.0), light, _toward(-2.0, 10.0))
    low, *_ = _frame(scene, Skybox(model="atmosphere"), DirectionalLight(direction=tuple(-sun), intensity=3.0),
                     _toward(-2.0, 10.0))
    peak = Skybox(model="atmosphere", altitude=8000.0)
    np.testing.assert_allclose(high, sky_radiance(peak, rays, SkySun(tuple(sun))), rtol=1e-2, atol=2e-3)
    between = (rays[..., 1] < -0.03) & (rays[..., 1] > -0.045)
    assert between.sum() > 50
    flat = rays * np.array([1.0, 0.0, 1.0])
    flat /= np.linalg.norm(flat, axis=-1, keepdims=True)
    level = sky_radiance(peak, flat, SkySun(tuple(sun)))   # (straight out)
    np.testing.assert_allclose(high[between], level[between], rtol=1e-2, atol=2e-3)   # the sky, as level with the eye
    assert (np.abs(low[between] - level[between]).max(axis=-1) > 0.1 * level[between].max()).mean() > 0.9


def test_a_skyboxs_altitude_draws_its_sky_and_a_level_file_keeps_it(scene, tmp_path):
    """The sky pass at 3 km draws the twin's sky for that height (not 200 m's), and a level
    file names the altitude and writes it back."""
    from engine.assets.level_read import load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    sun = _toward(25.0, 20.0)
    skybox = Skybox(model="atmosphere", altitude=3000.0)
    colour, rays, _ = _frame(scene, skybox, DirectionalLight(direction=tuple(-sun), intensity=3.0), _toward(20.0))
    up = rays[..., 1] > 0.05
    want = sky_radiance(skybox, rays, SkySun(tuple(sun)))
    np.testing.assert_allclose(colour[up], want[up], rtol=1e-2, atol=2e-3)
    low = sky_radiance(Skybox(model="atmosphere"), rays, SkySun(tuple(sun)))
    assert np.abs(colour[up] - low[up]).max() > 0.05 * low[up].max()
    level = tmp_path / "peak.toml"
    level.write_text('[level]\nname = "peak"\n[[entity]]\nname = "sky"\n'
                     'Skybox = { model = "atmosphere", altitude = 3000.0 }\n')
    world = World()
    load_level(level).spawn(world)
    assert world.query_one(Skybox)[0][1].altitude == 3000.0
    save_level(world, tmp_path / "again.toml")
    assert "altitude = 3000" in (tmp_path / "again.toml").read_text()


def test_the_runners_altitude_stands_the_level_in_its_atmosphere(tmp_path):
    """``--altitude`` with ``--sky atmosphere`` draws the hall under the thinner air (its sky
    darker than at 200 m); without an atmosphere, or past 10,000 m, one line says why."""
    from PIL import Image

    from tests.support import run_level

    def run(*extra):
        return run_level("--headless", "--frames", "1", "--size", "64x36", "--aa", "off", *extra)

    pictures = {}
    for metres in ("200", "8000"):
        result = run("--sky", "atmosphere", "--altitude", metres, "--out", str(tmp_path / metres))
        assert result.returncode == 0, result.stderr
        pictures[metres] = np.asarray(Image.open(tmp_path / metres / "frame_0000.png")).astype(float)
    top = slice(0, 6)   # (the sky over the hall's far end)
    assert pictures["8000"][top].mean() < pictures["200"][top].mean() - 2.0
    for extra, words in ((("--altitude", "3000"), "the level's sky is not an atmosphere"),
                         (("--sky", "atmosphere", "--altitude", "20000"), "--altitude must be metres from 0 to")):
        result = run(*extra, "--out", str(tmp_path / "bad"))
        assert result.returncode != 0 and words in result.stderr.splitlines()[-1], result.stderr


@pytest.mark.parametrize("field, value, words", [
    ("model", "sunset", "model"), ("haze", -1.0, "haze"), ("rayleigh", 25.0, "rayleigh"),
    ("altitude", -1.0, "altitude"), ("altitude", 20000.0, "altitude"), ("altitude", float("inf"), "altitude"),
    ("haze", float("nan"), "haze"), ("tints_sunlight", "yes", "tints_sunlight")])
def test_bad_air_is_refused_when_given(field, value, words):
    with pytest.raises(ComponentValueError, match=words):
        Skybox(**{field: value})
    skybox = Skybox(model="atmosphere")
    with pytest.raises(ComponentValueError, match=words):
        setattr(skybox, field, value)


def test_the_air_of_a_skybox():
    air = air_of(Skybox(model="atmosphere", rayleigh=2.0, haze=0.5, ground=(0.1, 0.2, 0.3)))
    assert (air.rayleigh, air.haze) == (2.0, 0.5)
    assert air.ground == pytest.approx((0.1, 0.2, 0.3))


def test_a_level_file_names_the_air_and_refuses_a_sky_it_does_not_know(tmp_path):
    from engine.assets.level_read import LevelError, load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    good = tmp_path / "air.toml"
    good.write_text('[level]\nname = "air"\n[[entity]]\nname = "sky"\n'
                    'Skybox = { model = "atmosphere", haze = 2.0, rayleigh = 1.5, tints_sunlight = false }\n')
    world = World()
    load_level(good).spawn(world)
    sky = world.query_one(Skybox)[0][1]
    assert (sky.model, sky.haze, sky.rayleigh, sky.tints_sunlight) == ("atmosphere", 2.0, 1.5, False)
    save_level(world, tmp_path / "again.toml")
    again = World()
    load_level(tmp_path / "again.toml").spawn(again)
    assert again.query_one(Skybox)[0][1].model == "atmosphere" and again.query_one(Skybox)[0][1].haze == 2.0
    bad = tmp_path / "bad.toml"
    bad.write_text('[level]\nname = "x"\n[[entity]]\nname = "sky"\n[entity.Skybox]\nmodel = "dusk"\n')
    with pytest.raises(LevelError, match=r"bad.toml:6: entity 'sky': Skybox.model.* must be one of"):
        load_level(bad)


# -- space beyond the air (an atmosphere's given faces) -----------------------------------------
def space_faces(n: int = 16) -> np.ndarray:
    """A smooth, dim space: each texel's colour from its direction (no two faces alike)."""
    from engine.core.cube_faces import face_directions

    return np.stack([0.02 + 0.03 * (face_directions(face, n) + 1.0) for face in range(6)]).astype(np.float32)


@pytest.mark.parametrize("elevation", [-8.0, 25.0])
def test_space_shows_through_the_air(scene, elevation):
    """An atmosphere given faces shows them beyond its air: each sky pixel above the horizon
    is the air's light (the twin of the same sky without them) plus the faces' colour there
    (the same faces drawn as a plain given-faces Skybox: the cube map's own sampling) times
    the share the air lets through (the table's fourth channel) and the share that shows
    through air that bright (``space_shown``); below the horizon the ground as before.  At
    night the faces are most of the sky; by day nothing of them shows."""
    faces = space_faces()
    sun = _toward(elevation, 20.0)
    look = _toward(10.0, 10.0)
    light = DirectionalLight(direction=tuple(-sun), intensity=3.0)
    shown, rays, runner = _frame(scene, Skybox(model="atmosphere", faces=faces), light, look)
    beyond, *_ = _frame(scene, Skybox(faces=faces), DirectionalLight(direction=tuple(-sun), intensity=3.0), look)
    air = sky_radiance(Skybox(model="atmosphere"), rays, SkySun(tuple(sun)))
    model = sky_model(Skybox(model="atmosphere"), SkySun(tuple(sun)))
    table = atm.sky_view_table(model.air, model.air_elevation)
    through = atm.air_transmittance(table, rays, sun) * atm.space_shown(atm.air_radiance(table, rays, sun))
    up = rays[..., 1] > 0.01
    assert up.sum() > 2000 and (~up).sum() > 500
    want = air + beyond * through * up[..., None]
    np.testing.assert_allclose(shown, want, rtol=1e-2, atol=2e-3)
    if elevation < 0.0:
        assert (beyond * through)[up].sum() > 5.0 * air[up].sum()   # (the night sky is the space's)
    else:
        assert (beyond * through)[up].max() < 1e-5 * air[up].mean()   # (lost in the day's sky)
    assert runner.engine.renderer.resource_counts()["sky_space"] == 1


@pytest.mark.parametrize("elevation", [60.0, 20.0, -2.0, -13.0])
def test_the_stars_come_out_at_night_and_are_lost_in_the_days_sky(scene, elevation):
    """The night sky the window's ``--sky atmosphere`` gives (``star_faces``: stars bright
    enough to see at night, 0.05 to 2 against a noon zenith's 0.05 to 0.15) looking up:
    with the sun up, or just set, no star adds a fifth of the sky's light where it stands
    (the day's blue with the stars added showed dots at noon); past dusk they stand out,
    the brightest at nearly their own light (the air lets most of it through)."""
    from engine.assets.star_field import star_faces

    sun = _toward(elevation, 40.0)
    look = _toward(70.0, 200.0)
    stars = star_faces(size=128, stars=2000, seed=3)
    with_stars, _, _ = _frame(scene, Skybox(model="atmosphere", faces=stars),
                              DirectionalLight(direction=tuple(-sun), intensity=3.0), look)
    without, _, _ = _frame(scene, Skybox(model="atmosphere"), DirectionalLight(direction=tuple(-sun), intensity=3.0),
                           look)
    added = (with_stars - without).max(axis=2)
    if elevation > -5.0:
        contrast = added / without.max(axis=2)
        assert contrast.max() < 0.2, (elevation, contrast.max())
    else:
        assert added.max() > 0.5 and (added > 0.05).sum() >= 20, (added.max(), (added > 0.05).sum())


def test_space_is_in_the_cube_map_and_the_skys_light(scene):
    """The cube map the reflections read holds the space through the air (``build_faces``, at
    the faces' own texels), and the sky's light counts it: its coefficients less the same
    sky's without space are the projection of the faces times the air's share, above the
    horizon (within 5% of that difference's largest coefficient)."""
    from engine.core.cube_faces import face_directions

    faces = space_faces(32)
    sun = _toward(-6.0, 50.0)
    skybox = Skybox(model="atmosphere", faces=faces, face_size=32)
    _, _, runner = _frame(scene, skybox, DirectionalLight(direction=tuple(-sun), intensity=3.0), _toward(20.0))
    np.testing.assert_allclose(_cube_faces(runner), build_faces(skybox, SkySun(tuple(sun))), rtol=1e-2, atol=2e-3)
    with_space = generated_sky_sh(sky_model(skybox, SkySun(tuple(sun))))
    without = generated_sky_sh(sky_model(Skybox(model="atmosphere"), SkySun(tuple(sun))))
    model = sky_model(skybox, SkySun(tuple(sun)))
    table = atm.sky_view_table(model.air, model.air_elevation)
    through = np.stack([faces[f] * atm.air_transmittance(table, face_directions(f, 32), sun)
                        * atm.space_shown(atm.air_radiance(table, face_directions(f, 32), sun))
                        * (face_directions(f, 32)[..., 1:2] >= 0.0) for f in range(6)])
    want = project_faces(through)
    assert np.abs((with_space - without) - want).max() < 0.05 * np.abs(want).max()


def test_space_is_uploaded_once_and_goes_with_its_faces(scene):
    faces = space_faces()
    sun = DirectionalLight(direction=tuple(-_toward(10.0)), intensity=3.0)
    skybox = Skybox(model="atmosphere", faces=faces)
    _, _, runner = _frame(scene, skybox, sun, _toward(10.0))
    renderer = runner.engine.renderer
    space = renderer.sky_space
    sun.direction = tuple(-_toward(12.0, 30.0))
    runner.frame()
    runner.frame()
    assert renderer.sky_space is space                     # the sun moved: the same space
    skybox.faces = space_faces(8)
    runner.frame()
    assert renderer.sky_space is not space and renderer.resource_counts()["sky_space"] == 1
    skybox.faces = None
    runner.frame()
    assert renderer.sky_space is None and renderer.resource_counts()["sky_space"] == 0


def test_star_faces_put_each_star_in_its_texel():
    """``star_faces``: every star lights the texel its direction falls in (the count of lit
    texels is the stars' less the few that share one), within the brightness range, and bad
    arguments are refused naming them."""
    from engine.assets.star_field import star_faces
    from engine.core.errors import AssetError

    faces = star_faces(size=64, stars=300, brightness=2.0, seed=3)
    assert faces.shape == (6, 64, 64, 3) and faces.dtype == np.float32
    lit = faces.max(axis=-1) > 0.0
    assert 280 <= lit.sum() <= 300
    assert faces.max() <= 2.0 * 0.05 * 40.0 * 1.0 + 1e-6 and faces[lit].max(axis=-1).min() >= 2.0 * 0.05 * 0.72 - 1e-6
    assert np.array_equal(star_faces(size=64, stars=300, brightness=2.0, seed=3), faces)
    for bad in (dict(size=8), dict(stars=-1), dict(brightness=float("nan")), dict(size=True)):
        with pytest.raises(AssetError, match=next(iter(bad))):
            star_faces(**bad)


def test_a_probe_captures_the_atmosphere_and_its_space(scene, ctx):
    """A reflection probe alone under an atmosphere with stars: its capture (the sky pass's
    layered or per-face build, each texel the sky along its centre) is the CPU's faces of the
    same sky at the probe's size."""
    from components import ReflectionProbe
    from engine.render.bindings import SCRATCH_UNIT
    from engine.render.raw_gl import read_cube_level

    faces = space_faces(32)
    sun = _toward(-9.0, 120.0)   # (a night sky: the space shows)
    skybox = Skybox(model="atmosphere", faces=faces, face_size=32)

    def build(world):
        world.spawn(Transform(position=(0.0, 0.0, 4.0)), Camera(fov_y=60.0, near=0.1, far=100.0))
        world.spawn(skybox)
        world.spawn(DirectionalLight(direction=tuple(-sun), intensity=3.0))
        world.spawn(Transform(), ReflectionProbe(resolution=32, far=10.0, refresh="every_frame"))

    runner = scene(build, SIZE)
    for _ in range(3):
        runner.frame()
    probes = runner.engine.renderer.probes
    (texture,) = [cube.texture for cube in probes.cubes.values()]
    got = np.stack([read_cube_level(ctx, texture, face, 0, SCRATCH_UNIT)[..., :3] for face in range(6)])
    assert got.max() > 0.03 and got[:, :, :, 2].std() > 0.005   # (the space through the air: not black)
    np.testing.assert_allclose(got, build_faces(skybox, SkySun(tuple(sun))), rtol=2e-2, atol=2e-3)


def test_the_light_a_mirror_throws_is_reddened_as_the_suns_own(scene):
    """A mirror throwing a low sun back onto the floor (``Mirror.reflects_light``): the thrown
    light (the floor with the mirror throwing less the floor without) under the atmosphere over
    the same with ``tints_sunlight`` off is the air's tint of the sun, as its direct light's."""
    from components import Mirror
    from engine.assets.mesh import quad

    sun = _toward(20.0, 180.0)   # from +Z, its light travelling towards the mirror at -Z
    thrown = {}
    for tints in (True, False):
        frames = []
        for throws in (True, False):
            def build(world, tints=tints, throws=throws):
                world.spawn(Transform(position=(0.0, 7.0, 2.0), rotation=look_rotation(glm.vec3(0.0, -1.0, -0.001))),
                            Camera(fov_y=60.0, near=0.1, far=100.0))
                world.spawn(Skybox(model="atmosphere", tints_sunlight=tints))
                world.spawn(DirectionalLight(direction=tuple(-sun), intensity=3.0, shadows=True))
                world.spawn(Transform(), MeshRef(plane(40, 40)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
                world.spawn(Transform(position=(0.0, 1.5, -1.0)), MeshRef(quad(6.0, 3.0)), Material(),
                            Mirror(reflects_light=throws))

            runner = scene(build, SIZE)
            runner.engine.renderer.antialias = "off"
            runner.frame()
            frames.append(_read(runner)[0])
        thrown[tints] = frames[0] - frames[1]
    patch = thrown[False].sum(axis=-1) > 0.1
    assert patch.sum() > 200
    r = atm.GROUND_KM + atm.EYE_KM
    want = np.exp(-_optical_depth(EARTH, r, sun[1])) / np.exp(-_optical_depth(EARTH, r, 1.0))
    np.testing.assert_allclose(thrown[True][patch].mean(axis=0) / thrown[False][patch].mean(axis=0), want, rtol=0.03)


def _cube_bilinear(faces: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``faces`` (6, n, n, 3) sampled along unit ``directions`` (..., 3) as GL's LINEAR reads a
    cube map's level 0 (GL's face selection, bilinear between the texel centres of the face),
    and the mask of the directions whose four texels lie on their own face (off it, a seamless
    cube map blends in the next face's)."""
    from engine.core.cube_faces import CUBE_FACES

    d = np.asarray(directions, np.float64).reshape(-1, 3)
    n = faces.shape[1]
    axis = np.argmax(np.abs(d), axis=1)
    face = axis * 2 + (d[np.arange(len(d)), axis] < 0.0)
    table = np.array(CUBE_FACES, np.float64)[face]
    major = np.abs(np.einsum("nk,nk->n", d, table[:, 0]))
    x = (np.einsum("nk,nk->n", d, table[:, 1]) / major + 1.0) * 0.5 * n - 0.5
    y = (np.einsum("nk,nk->n", d, table[:, 2]) / major + 1.0) * 0.5 * n - 0.5
    inside = (x >= 0.0) & (x <= n - 1.0) & (y >= 0.0) & (y <= n - 1.0)
    x0, y0 = np.clip(np.floor(x).astype(int), 0, n - 2), np.clip(np.floor(y).astype(int), 0, n - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    f = np.asarray(faces, np.float64)
    top = f[face, y0, x0] * (1 - fx) + f[face, y0, x0 + 1] * fx
    bottom = f[face, y0 + 1, x0] * (1 - fx) + f[face, y0 + 1, x0 + 1] * fx
    shape = np.shape(directions)[:-1]
    return (top * (1 - fy) + bottom * fy).reshape(*shape, 3), inside.reshape(shape)


def test_a_sharp_mirror_shows_the_stars_as_the_twin_along_its_reflected_rays(scene):
    """A mirror across the view, facing the camera, under a night atmosphere with stars
    (``star_faces``, 32 texels a face): each of its pixels is the air's light along the pixel's
    ray reflected in it (the twin, ``model_sky``) plus the stars' faces sampled there in numpy
    (GL's bilinear filter between texel centres; the pixels whose four texels cross a face's
    edge left out) times the share the air lets through and the share that shows through air
    that bright (as ``build_faces`` adds them); stars stand out in it, and they are the
    reflected rays' stars, not those straight ahead (the mirror is there)."""
    from components import Mirror
    from engine.assets.mesh import quad
    from engine.assets.star_field import star_faces

    n = 32
    stars = star_faces(size=n, stars=1000, seed=5)
    sun = _toward(-14.0, 150.0)   # (past dusk: the stars are out)
    skybox = Skybox(model="atmosphere", faces=stars, face_size=n)
    target = _toward(35.0, -30.0)   # the sky the mirror shows, over -Z
    look = target * np.array([1.0, 1.0, -1.0])   # what a plane z = 2 reflects to it

    def build(world):
        world.spawn(Transform(rotation=look_rotation(glm.vec3(*look))), Camera(fov_y=40.0, near=0.1, far=100.0))
        world.spawn(skybox)
        world.spawn(DirectionalLight(direction=tuple(-sun), intensity=3.0))
        world.spawn(Transform(position=(0.0, 0.0, 2.0), rotation=glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))),
                    MeshRef(quad(40.0, 40.0)), Material(), Mirror())

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    colour, rays = _read(runner)
    assert runner.stats.reflection_views == 1
    on_mirror = rays[..., 2] > 0.05
    hit = rays * (2.0 / np.where(on_mirror, rays[..., 2], 1.0))[..., None]
    on_mirror &= (np.abs(hit[..., 0]) < 19.0) & (np.abs(hit[..., 1]) < 19.0)
    assert on_mirror.mean() > 0.95
    model = sky_model(skybox, SkySun(tuple(sun)))
    table = atm.sky_view_table(model.air, model.air_elevation)

    def twin(ways):
        beyond, whole = _cube_bilinear(stars, ways)
        through = atm.air_transmittance(table, ways, sun) * atm.space_shown(atm.air_radiance(table, ways, sun))
        return model_sky(model, ways) + beyond * through * (ways[..., 1:2] >= -atm.horizon_sine(model.air)), whole

    reflected = rays * np.array([1.0, 1.0, -1.0])
    want, whole = twin(reflected)
    air = model_sky(model, reflected)
    checked = on_mirror & whole
    assert checked.sum() > 0.6 * on_mirror.sum()
    np.testing.assert_allclose(colour[checked], want[checked], rtol=1e-2, atol=2e-3)
    starry = (want - air).max(axis=-1) > 0.05
    assert (starry & checked).sum() > 100                                            # (the stars are in it)
    assert ((colour - air).max(axis=-1)[starry & checked] > 0.03).all()
    ahead, _ = twin(rays)
    assert np.abs(colour - ahead)[checked].max() > 0.2                               # (the mirror is drawn)


def test_a_portal_turning_the_view_shows_the_stars_as_the_twin_along_its_carried_rays(scene):
    """A portal filling the view, its partner turned to face another part of the night sky:
    each pixel is the twin (the air's light, ``model_sky``, and the stars' faces sampled in
    numpy as in the mirror's test) along the pixel's ray carried by the pair's transform
    (float64, from the Transforms), not along its own ray; stars stand out in it, and the
    pixels are the portal's."""
    from engine.assets.portals import spawn_portal_pair
    from engine.assets.star_field import star_faces

    n = 32
    stars = star_faces(size=n, stars=1000, seed=5)
    sun = _toward(-14.0, 150.0)   # (past dusk: the stars are out)
    skybox = Skybox(model="atmosphere", faces=stars, face_size=n)
    look, target = _toward(15.0, 100.0), _toward(35.0, -30.0)   # the camera's way; the sky beyond the partner
    ents = {}

    def build(world):
        world.spawn(Transform(rotation=look_rotation(glm.vec3(*look))), Camera(fov_y=40.0, near=0.1, far=100.0))
        world.spawn(skybox)
        world.spawn(DirectionalLight(direction=tuple(-sun), intensity=3.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, tuple(2.0 * look), look_rotation(glm.vec3(*look)),
                                                 (0.0, 0.0, 30.0), look_rotation(glm.vec3(*-target)), size=(40.0, 40.0))

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    colour, rays = _read(runner)
    assert runner.stats.reflection_views == 1
    on_a = runner.engine.renderer.targets.read_surface_ids() == ents["a"]
    assert on_a.all()
    a_world, b_world = (np.array(glm.dmat4(runner.world.get(ents[e], Transform).world).to_list()).T for e in "ab")
    turn = np.array(glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))).to_list()).T
    carry = (b_world @ turn @ np.linalg.inv(a_world))[:3, :3]
    np.testing.assert_allclose(carry @ look, target, atol=1e-6)   # (the pair turns the view's way to the target)
    model = sky_model(skybox, SkySun(tuple(sun)))
    table = atm.sky_view_table(model.air, model.air_elevation)

    def twin(ways):
        beyond, whole = _cube_bilinear(stars, ways)
        through = atm.air_transmittance(table, ways, sun) * atm.space_shown(atm.air_radiance(table, ways, sun))
        return model_sky(model, ways) + beyond * through * (ways[..., 1:2] >= -atm.horizon_sine(model.air)), whole

    carried = rays @ carry.T
    want, whole = twin(carried)
    assert whole.mean() > 0.6
    np.testing.assert_allclose(colour[whole], want[whole], rtol=1e-2, atol=2e-3)
    air = model_sky(model, carried)
    starry = (want - air).max(axis=-1) > 0.05
    assert (starry & whole).sum() > 100                                              # (the stars are in it)
    assert ((colour - air).max(axis=-1)[starry & whole] > 0.03).all()
    own, _ = twin(rays)
    assert np.abs(colour - own)[whole].max() > 0.2                                   # (not the camera's own sky)


def test_a_monitors_picture_shows_the_stars_as_the_twin_along_its_cameras_rays(scene):
    """A monitor whose camera (not the active one) looks up at another part of the night
    sky than the active camera, which looks at its screen: each texel of the picture (read
    back, linear) is the twin (the air's light, ``model_sky``, and the stars' faces sampled in
    numpy as in the mirror's test) along the monitor camera's ray through it (its own view
    worked out from its Transform, fov and the picture's size), not along the active
    camera's; stars stand out in it."""
    from components import Monitor
    from engine.assets.mesh import quad
    from engine.assets.star_field import star_faces
    from engine.render.views import camera_view
    from tests.support import pixel_rays

    n = 32
    stars = star_faces(size=n, stars=1000, seed=5)
    sun = _toward(-14.0, 150.0)   # (past dusk: the stars are out)
    skybox = Skybox(model="atmosphere", faces=stars, face_size=n)
    lens_look, fov, picture = _toward(35.0, -30.0), 40.0, (64, 48)
    ents = {}

    def build(world):
        world.spawn(Transform(position=(0.0, 0.0, 3.0)), Camera(fov_y=40.0, near=0.1, far=100.0))   # down -z
        world.spawn(skybox)
        world.spawn(DirectionalLight(direction=tuple(-sun), intensity=3.0))
        ents["lens"] = world.spawn(Transform(rotation=look_rotation(glm.vec3(*lens_look))),
                                   Camera(fov_y=fov, near=0.1, far=100.0, active=False))
        ents["screen"] = world.spawn(Transform(), MeshRef(quad(1.6, 1.2)),
                                     Material(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0, environment_reflection=0.0),
                                     Monitor(camera=ents["lens"], size=picture))

    runner = scene(build, (64, 48))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = runner.engine.renderer.monitors.read(ents["screen"])[..., :3].astype(np.float64)
    assert shown.shape == (picture[1], picture[0], 3)
    lens = runner.world.get(ents["lens"], Transform).world
    _, rays = pixel_rays(camera_view(lens, fov, 0.1, 100.0, picture), picture)
    np.testing.assert_allclose(rays[picture[1] // 2 - 1:picture[1] // 2 + 1, picture[0] // 2 - 1:picture[0] // 2 + 1]
                               .mean(axis=(0, 1)), lens_look, atol=0.02)   # (the lens's way)
    model = sky_model(skybox, SkySun(tuple(sun)))
    table = atm.sky_view_table(model.air, model.air_elevation)

    def twin(ways):
        beyond, whole = _cube_bilinear(stars, ways)
        through = atm.air_transmittance(table, ways, sun) * atm.space_shown(atm.air_radiance(table, ways, sun))
        return model_sky(model, ways) + beyond * through * (ways[..., 1:2] >= -atm.horizon_sine(model.air)), whole

    want, whole = twin(rays)
    assert whole.mean() > 0.6
    np.testing.assert_allclose(shown[whole], want[whole], rtol=1e-2, atol=2e-3)
    air = model_sky(model, rays)
    starry = (want - air).max(axis=-1) > 0.05
    assert (starry & whole).sum() > 20                                               # (the stars are in it)
    assert ((shown - air).max(axis=-1)[starry & whole] > 0.03).all()
    _, active_rays = pixel_rays(runner.engine.main_view, picture)
    other, _ = twin(active_rays)
    assert np.abs(shown - other)[whole].max() > 0.2                                 # (the lens's sky, not the frame's)
