"""Fog (``components/fog.py``): exponential height fog on the active camera, in every view.

Real frames on llvmpipe against a second computation: each pixel's way from the eye is found
by casting its ray in float64 (to the floor; for a mirror's pixels to the mirror, then the
reflected ray on to the floor), the fog's optical depth along each straight stretch is
integrated numerically (not the shader's closed form), and the fogged frame must be the frame
without fog mixed towards the fog's colour by ``exp(-depth)``, in linear light, to the 8-bit
frames' rounding."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, Fog, Material, MeshRef, Mirror, Transform
from engine.assets.level_file import LevelError, load_level
from engine.assets.mesh import box, plane, quad
from engine.core.world import World
from tests.support import look_from, pixel_rays, srgb_to_linear

FOG_COLOR = np.array([0.55, 0.6, 0.7])
EYE = (0.0, 2.2, 7.0)
TOLERANCE = 0.006   # linear light: a unit of the 8-bit sRGB frames at these levels, and a little
MIRROR_Z = -2.0     # a mirror standing across the floor at z = -2, facing +z
SUN = (-0.3, -1.0, -0.5)   # the way the light goes
LOW_SUN = (0.0, -0.15, 1.0)  # low ahead of the eye (it looks towards -z): the fog glows that way
SUN_LIGHT = 0.8


def floor_material() -> Material:
    """A grey floor that reflects nothing of the light from all round (environment_reflection
    0): its colour is then the same from every direction, so a fogged frame is the clear one
    fogged along each pixel's way from the eye (a reflection is fogged along its ray too)."""
    return Material(color=(0.5, 0.5, 0.5), roughness=1.0, environment_reflection=0.0)


def _scene(fog: Fog | None, mirror: bool = False, sun=SUN):
    def build(world):
        camera = look_from(world, EYE, (0.0, 0.0, -1.0))
        if fog is not None:
            world.add_component(camera, fog)
        world.spawn(DirectionalLight(direction=sun, intensity=SUN_LIGHT, shadows=False))
        ids = world.resources["ids"] = {}
        ids["floor"] = world.spawn(Transform(), MeshRef(plane(60, 60)), floor_material())
        ids["crate"] = world.spawn(Transform(position=(-1.5, 0.5, 2.0)), MeshRef(box()),
                                   Material(color=(0.7, 0.3, 0.2)))
        if mirror:
            ids["mirror"] = world.spawn(Transform(position=(0.0, 1.5, MIRROR_Z)), MeshRef(quad(6.0, 3.0)), Material(),
                                        Mirror())
    return build


def _frame(scene, fog: Fog | None, mirror: bool = False, size=(320, 200), sun=SUN):
    runner = scene(_scene(fog, mirror, sun), size)
    runner.engine.renderer.antialias = "off"
    return runner, runner.frame()


def _depth(a: np.ndarray, b: np.ndarray, fog: Fog, samples: int = 400) -> np.ndarray:
    """The fog's optical depth along each straight stretch a -> b (rows), by the trapezoid
    rule over ``samples`` points: the density d exp(-k (y - h)) integrated along the way."""
    t = np.linspace(0.0, 1.0, samples)
    y = a[:, None, 1] + (b - a)[:, None, 1] * t[None, :]
    density = fog.density * np.exp(-fog.height_falloff * (y - fog.height))
    length = np.linalg.norm(b - a, axis=1)
    return np.trapezoid(density, t, axis=1) * length


def _floor_hits(origin: np.ndarray, rays: np.ndarray) -> np.ndarray:
    return origin + rays * (-origin[..., 1:2] / rays[..., 1:2])


def _close(error: np.ndarray) -> None:
    """Every pixel within the frames' rounding of its expected value (a few at edges, where a
    pixel's centre and its neighbours' differ most, within three times that)."""
    assert np.percentile(error, 99.5) < TOLERANCE and error.max() < 3 * TOLERANCE, (error.max(),
                                                                                   np.percentile(error, 99.5))


def _air_light(fog: Fog, dirs: np.ndarray, sun=SUN) -> np.ndarray:
    """The light the air scatters towards eyes looking along ``dirs`` (rows): the fog's colour
    and, with ``sun_scatter``, the glow max(cos, 0)^8 towards the sun (white, ``SUN_LIGHT``)."""
    to_sun = -np.asarray(sun, np.float64) / np.linalg.norm(sun)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    glow = fog.sun_scatter * SUN_LIGHT * np.maximum(dirs @ to_sun, 0.0) ** 8
    return np.array([fog.color.x, fog.color.y, fog.color.z]) + glow[:, None]


def _expected(clear: np.ndarray, depth: np.ndarray, fog: Fog, dirs: np.ndarray, sun=SUN) -> np.ndarray:
    """The clear frame's linear colours seen along ``dirs`` through optical depth ``depth``."""
    keep = np.exp(-depth)[:, None]
    return clear * keep + _air_light(fog, dirs, sun) * (1.0 - keep)


def _shown(linear: np.ndarray) -> np.ndarray:
    """What a camera without a Tonemap shows of linear colours: clamped to 1 (a glow towards
    the sun can pass it)."""
    return np.minimum(linear, 1.0)


FOGS = [(Fog(color=tuple(FOG_COLOR), density=0.08), SUN),
        (Fog(color=tuple(FOG_COLOR), density=0.3, height=0.5, height_falloff=1.2), SUN),
        (Fog(color=tuple(FOG_COLOR), density=0.08, sun_scatter=0.6), LOW_SUN)]
FOG_IDS = ["uniform", "height", "sun_scatter"]


@pytest.mark.parametrize("fog, sun", FOGS, ids=FOG_IDS)
def test_the_floor_is_fogged_by_the_air_between_it_and_the_eye(scene, fog, sun):
    """Each floor pixel is the clear frame's, fogged by the optical depth from the eye to its
    floor point; with height fog the air thins upwards, so a far point seen from up high is
    fogged less than the same distance along the ground would be; with sun scatter the air
    glows where the eye looks towards the sun."""
    clear_runner, clear = _frame(scene, None, sun=sun)
    runner, foggy = _frame(scene, fog, sun=sun)
    defines = runner.engine.renderer.fog.defines   # each term built in only where the fog has it
    assert ("FOG", "1") in defines and (("FOG_FALLOFF", "1") in defines) == (fog.height_falloff > 0.0) \
        and (("FOG_GLOW", "1") in defines) == (fog.sun_scatter > 0.0), defines
    floor = (runner.ids() == runner.world.resources["ids"]["floor"]).reshape(-1)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = _floor_hits(eye, rays).reshape(-1, 3)
    depth = _depth(np.tile(eye, (len(points), 1))[floor], points[floor], fog)
    assert depth.min() < 0.6 and depth.max() > 1.5   # near pixels keep most of their light, far ones little
    expected = _expected(srgb_to_linear(clear).reshape(-1, 3)[floor], depth, fog, rays.reshape(-1, 3)[floor], sun)
    got = srgb_to_linear(foggy).reshape(-1, 3)[floor]
    assert floor.sum() > 20000
    _close(np.abs(got - _shown(expected)).max(axis=1))


def test_the_sky_takes_its_share_of_the_fog(scene):
    """With the same density everywhere the sky is infinitely deep in fog: its pixels are the
    clear sky mixed ``sky_affect`` of the way to the fog's colour."""
    fog = Fog(color=tuple(FOG_COLOR), density=0.05, sky_affect=0.4)
    _, clear = _frame(scene, None)
    runner, foggy = _frame(scene, fog)
    sky = (runner.ids() == 0).reshape(-1)
    assert sky.sum() > 2000
    clear_sky = srgb_to_linear(clear).reshape(-1, 3)[sky]
    expected = clear_sky * 0.6 + FOG_COLOR * 0.4
    assert np.abs(srgb_to_linear(foggy).reshape(-1, 3)[sky] - expected).max() < TOLERANCE


@pytest.mark.parametrize("fog, sun", FOGS, ids=FOG_IDS)
def test_a_mirror_shows_the_floor_fogged_all_the_way_from_the_eye(scene, fog, sun):
    """In a perfect mirror, a floor point is fogged by the air from the eye to the mirror and
    from the mirror on to the point, each stretch integrated along its real way (heights
    and all) and glowing by its own direction (the eye's stretch looks towards the low sun,
    the reflected one away from it): the mirror's view fogs its own stretch, its composite
    the stretch before."""
    clear_runner, clear = _frame(scene, None, mirror=True, sun=sun)
    runner, foggy = _frame(scene, fog, mirror=True, sun=sun)
    ids = runner.world.resources["ids"]
    in_mirror = ((runner.engine.renderer.targets.read_surface_ids() == ids["mirror"])
                 & (runner.ids() == ids["floor"])).reshape(-1)
    assert in_mirror.sum() > 3000, in_mirror.sum()
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)[in_mirror]
    on_mirror = eye + rays * ((MIRROR_Z - eye[2]) / rays[:, 2])[:, None]
    turned = rays * np.array([1.0, 1.0, -1.0])
    points = _floor_hits(on_mirror, turned)
    near = _depth(np.tile(eye, (len(rays), 1)), on_mirror, fog)
    far = _depth(on_mirror, points, fog)
    # The far stretch fogged, then the near one over it.
    beyond = _expected(srgb_to_linear(clear).reshape(-1, 3)[in_mirror], far, fog, turned, sun)
    expected = _expected(beyond, near, fog, rays, sun)
    _close(np.abs(srgb_to_linear(foggy).reshape(-1, 3)[in_mirror] - _shown(expected)).max(axis=1))


WALL_Z = -3.75   # the wall's front face, facing +z


def _floor_mirror(fog: Fog | None):
    def build(world):
        camera = look_from(world, EYE, (0.0, 0.0, -1.0))
        if fog is not None:
            world.add_component(camera, fog)
        world.spawn(DirectionalLight(direction=(-0.3, -1.0, 0.5), intensity=0.8, shadows=False))
        ids = world.resources["ids"] = {}
        world.spawn(Transform(), MeshRef(plane(60, 60)), floor_material())
        ids["wall"] = world.spawn(Transform(position=(0.0, 3.0, WALL_Z - 0.25)), MeshRef(box((12.0, 6.0, 0.5))),
                                  Material(color=(0.3, 0.5, 0.7), roughness=1.0, environment_reflection=0.0))
        ids["mirror"] = world.spawn(Transform(position=(0.0, 0.01, 0.0),
                                              rotation=glm.angleAxis(-np.pi / 2.0, glm.vec3(1.0, 0.0, 0.0))),
                                    MeshRef(quad(6.0, 5.0)), Material(), Mirror())
    return build


def test_a_floor_mirror_in_height_fog_fogs_the_reflection_along_its_real_way_up(scene):
    """A mirror lying on the floor shows the wall beyond it: the light's real way climbs from
    the mirror to the wall through air that thins upwards, where the mirror image's way (the
    eye's image below the floor) would run through the thick air underground.  Each pixel
    is the clear one fogged along the real way, eye to mirror and mirror to wall."""
    fog = Fog(color=tuple(FOG_COLOR), density=0.3, height=0.5, height_falloff=1.2)
    frames = []
    for given in (None, fog):
        runner = scene(_floor_mirror(given), (320, 200))
        runner.engine.renderer.antialias = "off"
        frames.append(runner.frame())
    ids = runner.world.resources["ids"]
    in_mirror = ((runner.engine.renderer.targets.read_surface_ids() == ids["mirror"])
                 & (runner.ids() == ids["wall"])).reshape(-1)
    assert in_mirror.sum() > 2000, in_mirror.sum()
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)[in_mirror]
    on_mirror = eye + rays * ((0.01 - eye[1]) / rays[:, 1])[:, None]
    up = rays * np.array([1.0, -1.0, 1.0])
    points = on_mirror + up * ((WALL_Z - on_mirror[:, 2]) / up[:, 2])[:, None]
    real = _depth(np.tile(eye, (len(rays), 1)), on_mirror, fog) + _depth(on_mirror, points, fog)
    image = _depth(np.tile(eye * np.array([1.0, -1.0, 1.0]) + (0.0, 0.02, 0.0), (len(rays), 1)), points, fog)
    assert (image - real).min() > 0.5   # the image's way would be far foggier: the check tells them apart
    expected = _expected(srgb_to_linear(frames[0]).reshape(-1, 3)[in_mirror], real, fog, rays)   # (no glow)
    error = np.abs(srgb_to_linear(frames[1]).reshape(-1, 3)[in_mirror] - expected).max(axis=1)
    _close(error)


@pytest.mark.parametrize("field, value", [("density", -0.1), ("density", float("nan")), ("density", 2000.0),
                                          ("height_falloff", -1.0), ("sky_affect", 1.5), ("height", float("inf")),
                                          ("color", (1.0, -0.5, 0.0)), ("sun_scatter", -1.0),
                                          ("sun_scatter", float("nan"))])
def test_bad_fog_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"Fog.{field}"):
        Fog(**{field: value})


def test_level_files_carry_fog_and_a_density_of_zero_draws_the_clear_frame(scene, tmp_path):
    """A level's camera takes a Fog table; a bad value is refused naming the file and the
    field; and a fog of density 0 leaves every pixel as without fog (no FOG build)."""
    text = """[level]
name = "Misty"

[[entity]]
name = "eye"
[entity.Transform]
position = [0.0, 2.0, 5.0]
[entity.Camera]
[entity.Fog]
color = [0.5, 0.55, 0.6]
density = 0.04
height_falloff = 0.2
"""
    path = tmp_path / "misty.toml"
    path.write_text(text)
    world = World("misty")
    made = load_level(path).spawn(world)
    fog = world.get(made["eye"], Fog)
    assert (fog.density, fog.height_falloff) == (0.04, 0.2)
    path.write_text(text.replace("0.04", "-1.0"))
    with pytest.raises(LevelError, match=r"Fog\.density") as caught:
        load_level(path).spawn(World("refused"))
    assert str(path) in str(caught.value)
    _, clear = _frame(scene, None, mirror=True)
    runner, thin = _frame(scene, Fog(density=0.0), mirror=True)
    assert runner.engine.renderer.fog.defines == ()
    np.testing.assert_array_equal(thin, clear)


def test_the_batched_path_fogs_as_the_per_mirror_path_does(ctx):
    """The mirror ring in height fog drawn with every view of a level in one draw (its
    geometry stage hands each triangle its view's clip plane) and view by view: the same
    frame but for a rounding here and there."""
    from benchmarks.mirrors import MirrorRing
    from components import Camera
    from tests.support import engine_frames

    frames = {}
    for path in ("per_mirror", "batched"):
        def configure(engine, path=path):
            engine.reflection_system.path = path
            for entity, _ in engine.world.query_one(Camera):
                engine.world.add_component(entity, Fog(density=0.08, height=1.0, height_falloff=0.3))
        frames[path] = engine_frames(ctx, MirrorRing(8), 3, ((320, 180),), configure, None, dt=1 / 60)[0]
    clear = engine_frames(ctx, MirrorRing(8), 3, ((320, 180),), None, None, dt=1 / 60)[0]
    differ = np.abs(frames["per_mirror"].astype(int) - frames["batched"]).max(axis=-1) > 2
    assert differ.sum() <= 5, differ.sum()
    assert (np.abs(frames["batched"].astype(int) - clear).max(axis=-1) > 10).mean() > 0.5   # the fog is there


def test_a_portal_shows_what_lies_beyond_its_partner_fogged_along_the_carried_way(scene):
    """Through portal A (at z = 4, facing +z) the floor beyond B (at x = -6, facing +x): each
    pixel is fogged by the air from the eye to A and from B on to the floor point, the ray
    carried by the pair's transform (worked out here from the two portals' matrices)."""
    from components import Portal
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    fog = Fog(color=tuple(FOG_COLOR), density=0.12, height=0.5, height_falloff=0.8)
    frames = []
    for given in (None, fog):
        def build(world, given=given):
            camera = look_from(world, (0.5, 2.0, 8.5), (0.0, 1.0, 4.0))
            if given is not None:
                world.add_component(camera, given)
            world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=0.8, shadows=False))
            ids = world.resources["ids"] = {}
            ids["floor"] = world.spawn(Transform(), MeshRef(plane(60, 60)),
                                       floor_material())
            ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                                   glm.angleAxis(np.pi / 2.0, glm.vec3(0.0, 1.0, 0.0)))
        runner = scene(build, (320, 200))
        runner.engine.renderer.antialias = "off"
        frames.append(runner.frame())
    ids = runner.world.resources["ids"]
    assert runner.world.has(ids["a"], Portal)
    through = ((runner.engine.renderer.targets.read_surface_ids() == ids["a"])
               & (runner.ids() == ids["floor"])).reshape(-1)
    assert through.sum() > 2000, through.sum()
    carry = np.array(glm.dmat4(pair_transform(runner.world.get(ids["a"], Transform).world,
                                              runner.world.get(ids["b"], Transform).world)).to_list()).T
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)[through]
    at_a = eye + rays * ((4.0 - eye[2]) / rays[:, 2])[:, None]
    at_b = at_a @ carry[:3, :3].T + carry[:3, 3]
    points = _floor_hits(at_b, rays @ carry[:3, :3].T)
    assert np.abs(at_b[:, 0] + 6.0).max() < 1e-6   # carried onto B's plane
    depth = _depth(np.tile(eye, (len(rays), 1)), at_a, fog) + _depth(at_b, points, fog)
    expected = _expected(srgb_to_linear(frames[0]).reshape(-1, 3)[through], depth, fog, rays)   # (no glow)
    _close(np.abs(srgb_to_linear(frames[1]).reshape(-1, 3)[through] - expected).max(axis=1))


def test_the_overlays_toggle_turns_the_fog_off_and_on(scene, ctx):
    """The prepare stage's ``fog`` (the debug overlay's "fog" box): off, the frame is the
    clear one and no FOG build is asked for; on again, the fogged one."""
    size = (640, 480)   # room for the whole overlay
    _, clear = _frame(scene, None, size=size)
    runner, foggy = _frame(scene, Fog(color=tuple(FOG_COLOR), density=0.08), size=size)
    prepare = runner.engine.stages["prepare"]
    assert not np.array_equal(foggy, clear)
    prepare.fog = False
    np.testing.assert_array_equal(runner.frame(), clear)
    assert runner.engine.renderer.fog.defines == ()
    prepare.fog = True
    np.testing.assert_array_equal(runner.frame(), foggy)
    pytest.importorskip("imgui_bundle", reason="the debug overlay needs imgui-bundle (not installed here)")
    from shell.overlay import DebugOverlay

    overlay = DebugOverlay(ctx)
    try:
        overlay.draw(runner.engine, runner.capture.framebuffer, runner.size)
        x, y = overlay.widgets["fog"]
        for down in (None, True, False):
            overlay.mouse_moved(x, y)
            if down is not None:
                overlay.mouse_button(1, down)
            overlay.draw(runner.engine, runner.capture.framebuffer, runner.size)
        assert prepare.fog is False
    finally:
        overlay.release()


def test_a_chrome_ball_reflects_the_sky_as_fogged_as_the_background(scene):
    """A ball reflecting the sky (Reflective, mix 1) in fog the same everywhere, the sky
    taking all of it: the sky it reflects, infinitely deep in fog, is the fog's colour, and
    so is the ball (the stretch from the eye adds only more of it); without fog it shows
    the sky's own colours."""
    from components import Reflective, Skybox
    from engine.assets.mesh import sphere

    def build(fog):
        def run(world):
            camera = look_from(world, (0.0, 1.0, 4.0), (0.0, 1.0, 0.0))
            if fog is not None:
                world.add_component(camera, fog)
            world.spawn(Skybox(zenith=(0.1, 0.2, 0.6), horizon=(0.7, 0.6, 0.4), ground=(0.1, 0.3, 0.1)))
            world.resources["ball"] = world.spawn(Transform(position=(0.0, 1.0, 0.0)), MeshRef(sphere(1.0, 32, 16)),
                                                  Material(color=(1.0, 1.0, 1.0)), Reflective(mix=1.0))
        return run

    fog = Fog(color=tuple(FOG_COLOR), density=0.05)
    clear_runner = scene(build(None), (160, 120))
    clear = srgb_to_linear(clear_runner.frame())
    runner = scene(build(fog), (160, 120))
    runner.engine.renderer.antialias = "off"
    foggy = srgb_to_linear(runner.frame())
    ball = runner.ids() == runner.world.resources["ball"]
    assert ball.sum() > 2000
    assert np.abs(foggy[ball] - FOG_COLOR).max() < TOLERANCE
    assert np.abs(clear[ball] - FOG_COLOR).max(axis=-1).mean() > 0.1   # the test's fog colour is not the sky's


@pytest.mark.parametrize("kind", ["height_fog", "volume_this_side"])
def test_the_sky_beyond_a_portals_partner_is_fogged_from_the_partner_on(scene, kind):
    """Portal A low in the air (y 1 to 4) facing +z, its partner B high above the fog (y 20
    to 23) turned to face -z: a ray into A comes out of B going the way it went.  Through A
    the camera sees the sky beyond B, fogged by the air from the eye to A and from B on to
    the sky (the height fog's closed form there, k the falloff: d exp(-k (y - h)) / (k r_y)),
    nothing of the air on A's side past A.  "height_fog": the sky from B (21 m up) is all but
    clear, where from A it would be well fogged; "volume_this_side": a bank of mist behind A,
    which the sky past B never crosses (it does fog the pixels beside A whose rays cross it:
    it is there)."""
    from components import FogVolume, Portal
    from engine.assets.portals import spawn_portal_pair

    fog = Fog(color=tuple(FOG_COLOR), density=0.25, height=0.0, height_falloff=0.4) if kind == "height_fog" else None
    frames = []
    for fogged in (False, True):
        def build(world, fogged=fogged):
            camera = look_from(world, (0.0, 2.0, 9.0), (0.0, 3.5, 4.0))
            world.spawn(DirectionalLight(direction=SUN, intensity=SUN_LIGHT, shadows=False))
            ids = world.resources["ids"] = {}
            ids["floor"] = world.spawn(Transform(), MeshRef(plane(60, 60)), floor_material())
            ids["a"], ids["b"] = spawn_portal_pair(world, (0.0, 2.5, 4.0), None, (0.0, 21.5, -30.0),
                                                   glm.angleAxis(np.pi, glm.vec3(0.0, 1.0, 0.0)))
            if fogged and fog is not None:
                world.add_component(camera, fog)
            if fogged and fog is None:
                world.spawn(Transform(position=(0.0, 3.0, 1.0)), FogVolume(size=(8.0, 8.0, 5.0), density=2.0))
        runner = scene(build, (160, 100))
        runner.engine.renderer.antialias = "off"
        frames.append(srgb_to_linear(runner.frame()).reshape(-1, 3))
    ids = runner.world.resources["ids"]
    assert runner.world.has(ids["a"], Portal)
    through = ((runner.engine.renderer.targets.read_surface_ids() == ids["a"]) & (runner.ids() == 0)).reshape(-1)
    assert through.sum() > 1000, through.sum()
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    rays = rays.reshape(-1, 3)
    if fog is None:
        np.testing.assert_allclose(frames[1][through], frames[0][through], atol=TOLERANCE)
        beside = (runner.engine.renderer.targets.read_surface_ids() != ids["a"]).reshape(-1) \
            & (runner.ids() == 0).reshape(-1)
        assert (np.abs(frames[1][beside] - frames[0][beside]).max(axis=1) > 0.05).sum() > 200   # (the mist is there)
        return
    through &= rays[:, 1] > 0.05   # (rays going down from B pass the floor's end: the sky below the horizon)
    assert through.sum() > 600, through.sum()
    rays = rays[through]
    at_a = eye + rays * ((4.0 - eye[2]) / rays[:, 2])[:, None]
    at_b = at_a + np.array([0.0, 19.0, -34.0])   # (the pair's carry: a shift, B turned as the ray is)
    k = fog.height_falloff
    beyond = fog.density * np.exp(-k * (at_b[:, 1] - fog.height)) / (k * rays[:, 1])
    here = _depth(np.tile(eye, (len(rays), 1)), at_a, fog)
    assert beyond.max() < 0.01 and here.min() > 0.3   # (from A the sky would take ~0.3-1.5 more)
    expected = _expected(frames[0][through], here + beyond, fog, rays)
    _close(np.abs(frames[1][through] - _shown(expected)).max(axis=1))
