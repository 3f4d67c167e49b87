"""The generated sky is drawn from its function at the screen's resolution: the sky pass
evaluates ``shaders/include/sky_model.glsl`` per pixel, and that must give what
``engine.render.sky.sky_radiance`` (the rule's owner) gives along each pixel's ray, the sun's
disc included, however far a narrow lens magnifies it (from the 128-texel cube it was a
blocky blob); a Skybox of given faces is still drawn from its cube map."""
from __future__ import annotations

import numpy as np
from pyglm import glm

from components import Camera, DirectionalLight, Skybox, Transform, look_rotation
from components.rendering import DEFAULT_SUN_DIRECTION
from engine.render.sky import build_faces, sky_radiance
from engine.rules.light_rules import SkySun

SIZE = (160, 120)
SUN = glm.normalize(glm.vec3(0.3, 0.5, -0.8))
SKY = dict(zenith=(0.10, 0.25, 0.65), horizon=(0.65, 0.75, 0.90), ground=(0.18, 0.14, 0.10),
           sun_direction=tuple(SUN), sun_color=(6.0, 5.4, 4.2))


def _hdr_frame(scene, skybox: Skybox, fov: float, look: glm.vec3):
    """A frame of ``skybox`` through a camera of ``fov`` looking along ``look``: level 0's
    colour and rays (``_read``), and the runner."""

    def build(world):
        world.spawn(Transform(rotation=look_rotation(look)), Camera(fov_y=fov, near=0.1, far=100.0))
        world.spawn(skybox)

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return (*_read(runner), runner)


def _read(runner):
    """Level 0's linear HDR colour (h, w, 3; row 0 at the top) and each pixel centre's
    world ray, from the camera's own matrices (numpy, float64)."""
    w, h = SIZE
    colour = np.frombuffer(runner.engine.renderer.levels[0].color.read(), np.float16)
    colour = colour.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
    view = runner.engine.main_view
    to_world = np.array(glm.inverse(view.view_proj).to_list(), np.float64).T  # glm is column-major
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    ndc = np.stack([(cols + 0.5) / w * 2 - 1, 1 - (rows + 0.5) / h * 2, np.ones((h, w)), np.ones((h, w))], -1)
    far = ndc @ to_world.T
    rays = far[..., :3] / far[..., 3:] - np.array(view.eye, np.float64)
    return colour, rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def test_the_sun_is_drawn_from_the_skys_function_at_the_screens_resolution(scene):
    """A 10-degree lens on the sun: its disc is about 60 pixels across, 30 cube texels' worth
    of screen a texel.  Every pixel is the function's value along its ray (a half float's
    rounding apart), and the disc covers exactly the pixels the function says."""
    skybox = Skybox(**SKY)
    colour, rays, _ = _hdr_frame(scene, skybox, fov=10.0, look=SUN)
    want = sky_radiance(skybox, rays)
    np.testing.assert_allclose(colour, want, rtol=4e-3, atol=4e-3)
    lit = colour[..., 0] > 3.0               # brighter than half the sun: inside the disc's ramp
    inside = want[..., 0] > 3.0
    assert inside.sum() > 2000               # the disc is in view, and large
    assert (lit == inside).all(), f"{int((lit != inside).sum())} pixels on the wrong side of the disc's edge"


def test_the_sky_away_from_the_sun_is_the_function_too(scene):
    """A wide lens across the horizon (where the ground's fade bends): the function again."""
    skybox = Skybox(**SKY)
    colour, rays, _ = _hdr_frame(scene, skybox, fov=90.0, look=glm.vec3(-0.3, 0.05, 1.0))
    np.testing.assert_allclose(colour, sky_radiance(skybox, rays), rtol=4e-3, atol=4e-3)


def test_a_skybox_of_given_faces_is_drawn_from_its_cube_map(scene):
    """Given faces are drawn as given: here the generated sky's own faces with the zenith's
    face painted red, so the top of a view up the +Y axis is red, as the cube map says."""
    generated = Skybox(**SKY)
    faces = build_faces(generated).copy()
    faces[2] = (1.0, 0.0, 0.0)  # +Y
    colour, rays, _ = _hdr_frame(scene, Skybox(faces=faces), fov=40.0, look=glm.vec3(0.0, 1.0, 0.001))
    np.testing.assert_allclose(colour[SIZE[1] // 2, SIZE[0] // 2], (1.0, 0.0, 0.0), atol=2e-3)
    # Sideways, below the +Y face's reach, the generated faces' colours (bilinear texels of
    # 128 a face, not the exact function: near, not equal).
    colour, rays, _ = _hdr_frame(scene, Skybox(faces=faces), fov=40.0, look=glm.vec3(-1.0, -0.1, 0.0))
    np.testing.assert_allclose(colour[SIZE[1] // 2, SIZE[0] // 2],
                               sky_radiance(generated, rays[SIZE[1] // 2, SIZE[0] // 2]), atol=0.02)


def test_a_changed_sky_is_drawn_changed(scene):
    """The sun moved and recoloured and the zenith changed after a frame: the next frame
    draws the new sky (the sky pass's program is given the new colours), not the first."""
    skybox = Skybox(**SKY)
    _, _, runner = _hdr_frame(scene, skybox, fov=20.0, look=SUN)
    skybox.sun_direction = SUN + glm.vec3(0.05, -0.04, 0.0)
    skybox.sun_color = (2.0, 6.0, 1.0)
    skybox.zenith = (0.3, 0.1, 0.1)
    runner.frame()
    colour, rays = _read(runner)
    want = sky_radiance(skybox, rays)
    assert (want[..., 1] > 3.0).sum() > 500  # the moved, green sun is in view
    np.testing.assert_allclose(colour, want, rtol=4e-3, atol=4e-3)


# -- the sun follows the brightest directional light (Skybox.sun_direction None) ---------------

FOLLOWING = {k: v for k, v in SKY.items() if k != "sun_direction"}  # sun_direction None: follow


def _cube_faces(runner) -> np.ndarray:
    """The sky cube map the renderer holds (what reflections, refraction and the sky's light
    read), as (6, n, n, 3) float32 in GL face order."""
    cube = runner.engine.renderer.sky
    n, channels = cube.size[0], cube.components
    return np.stack([np.frombuffer(cube.read(face), np.float16).reshape(n, n, channels)[..., :3]
                     for face in range(6)]).astype(np.float32)


def _following_scene(scene, lights: list[DirectionalLight], look: glm.vec3, skybox: Skybox | None = None):
    """A 10-degree lens along ``look`` under a generated sky (``FOLLOWING`` unless given) and
    ``lights``: (colour, rays, runner) of its first frame."""
    skybox = skybox or Skybox(**FOLLOWING)

    def build(world):
        world.spawn(Transform(rotation=look_rotation(look)), Camera(fov_y=10.0, near=0.1, far=100.0))
        world.spawn(skybox)
        for light in lights:
            world.spawn(light)

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return (*_read(runner), runner)


def _disc_pixels(colour: np.ndarray) -> int:
    """Pixels brighter than half the sun's red (inside its disc's ramp)."""
    return int((colour[..., 0] > 3.0).sum())


def test_an_unpinned_sun_stands_where_the_brightest_directional_light_shines_from(scene):
    """Two suns, the brighter made second, evening red: the sky's disc and glow are drawn
    against the brighter one's direction, the disc in its colour (the sky pass, pixel by
    pixel; the disc's centre is sun_color x the light's colour), and the cube map that
    reflections and the sky's light read is the sky made with that sun, not the default."""
    red = (1.0, 0.45, 0.2)
    dim = DirectionalLight(direction=(0.2, -1.0, 0.6), intensity=1.0)
    bright = DirectionalLight(direction=(-0.5, -0.6, 0.4), color=red, intensity=3.0)
    towards = -glm.normalize(glm.vec3(-0.5, -0.6, 0.4))
    colour, rays, runner = _following_scene(scene, [dim, bright], towards)
    skybox = Skybox(**FOLLOWING)
    sun = SkySun(tuple(towards), red)
    np.testing.assert_allclose(colour, sky_radiance(skybox, rays, sun=sun), rtol=4e-3, atol=4e-3)
    assert _disc_pixels(colour) > 2000  # the disc is where the light comes from
    glow = 0.25 * np.array([1.0, 0.55, 0.25])  # (at the disc's centre, the sun's warm band is whole)
    centre = colour[SIZE[1] // 2, SIZE[0] // 2] - glow - np.array(SKY["zenith"])  # less the sky, about
    np.testing.assert_allclose(centre / np.array(SKY["sun_color"]), red, atol=0.06)
    faces = _cube_faces(runner)
    np.testing.assert_allclose(faces, build_faces(skybox, sun).astype(np.float16), rtol=2e-3, atol=2e-3)
    assert np.abs(faces - build_faces(skybox)).max() > 1.0  # (the default sun's sky differs: the disc)


def test_the_sky_follows_when_its_sun_turns_and_only_then(scene, monkeypatch):
    """Turning the brightest light moves the disc the next frame (the sky made again);
    turning a dimmer one, or the brightest one by nothing (or by a rounding), makes no sky;
    deleting the brightest hands the sun to the next."""
    first = glm.normalize(glm.vec3(0.3, -0.8, 0.5))
    dim = DirectionalLight(direction=(0.2, -1.0, -0.6), intensity=0.5)
    bright = DirectionalLight(direction=first, intensity=2.0)
    colour, _, runner = _following_scene(scene, [dim, bright], -first)
    assert _disc_pixels(colour) > 2000
    renderer = runner.engine.renderer
    made = renderer.sky_version
    dim.direction = (0.0, -1.0, -0.6)        # not the sun: no new sky
    bright.direction = first                 # written, the same way: no new sky
    runner.frame()
    assert renderer.sky_version == made
    bright.direction = (0.3, -0.8, -0.5)     # the sun turns away from the lens
    runner.frame()
    colour, rays = _read(runner)
    assert renderer.sky_version == made + 1
    assert _disc_pixels(colour) == 0
    np.testing.assert_allclose(colour, sky_radiance(Skybox(**FOLLOWING), rays, sun=SkySun((-0.3, 0.8, 0.5))),
                               rtol=4e-3, atol=4e-3)
    cube = renderer.sky
    for _ in range(3):  # written again as it is: normalised again, it moves by a rounding, once
        bright.direction = bright.direction
        runner.frame()
    assert renderer.sky is cube              # no cube made for a rounding
    import systems.prepare_system

    asked, ask = [], systems.prepare_system.sky_sun
    monkeypatch.setattr(systems.prepare_system, "sky_sun", lambda *args: asked.append(args) or ask(*args))
    for _ in range(3):
        runner.frame()
    assert not asked                         # and a still sky asks nothing after it
    sun_entity = next(e for e, light in runner.world.query_one(DirectionalLight) if light is bright)
    runner.world.delete_entity(sun_entity)
    runner.frame()
    colour, rays = _read(runner)
    np.testing.assert_allclose(colour, sky_radiance(Skybox(**FOLLOWING), rays, sun=SkySun((0.0, 1.0, 0.6))),
                               rtol=4e-3, atol=4e-3)


def test_a_pinned_sun_stays_and_no_lit_sun_means_the_default(scene):
    """``sun_direction`` given: the disc stays there whatever the light; a black light is no
    sun, so with no other the disc stands at ``DEFAULT_SUN_DIRECTION``."""
    light = DirectionalLight(direction=(0.3, -0.8, 0.5), intensity=2.0)
    colour, _, _ = _following_scene(scene, [light], SUN, skybox=Skybox(**SKY))
    assert _disc_pixels(colour) > 2000
    black = DirectionalLight(direction=(0.3, -0.8, 0.5), intensity=0.0)
    default = glm.vec3(*DEFAULT_SUN_DIRECTION)
    colour, rays, _ = _following_scene(scene, [black], default)
    assert _disc_pixels(colour) > 2000
    np.testing.assert_allclose(colour, sky_radiance(Skybox(**FOLLOWING), rays, sun=SkySun(DEFAULT_SUN_DIRECTION)),
                               rtol=4e-3, atol=4e-3)


def test_while_the_sun_turns_the_sky_pass_follows_each_frame_and_the_cube_within_a_degree(scene):
    """A sun turning 0.3 degrees a frame: every frame the sky pass draws the disc where the
    light is now (pixel by pixel); the cube map (reflections, the sky's light: tens of
    milliseconds to make) is made again only once the sun is past a degree from it, and once
    more when the sun stands still, so a still sky's cube is exact."""
    start = glm.normalize(glm.vec3(-0.3, 0.8, -0.5))
    axis = glm.normalize(glm.cross(start, glm.vec3(0, 1, 0)))  # square to it: it turns by the angle

    def light_towards(degrees: float) -> glm.vec3:  # the sun's direction, turned on
        return glm.vec3(glm.rotate(glm.radians(degrees), axis) * glm.vec4(start, 0.0))

    sun = DirectionalLight(direction=-light_towards(0.0), intensity=2.0)
    _, _, runner = _following_scene(scene, [sun], light_towards(0.0))
    renderer = runner.engine.renderer
    made = [renderer.sky]
    for step in range(1, 6):
        sun.direction = -light_towards(0.3 * step)
        runner.frame()
        colour, rays = _read(runner)
        np.testing.assert_allclose(colour, sky_radiance(Skybox(**FOLLOWING), rays, sun=SkySun(tuple(
            glm.normalize(light_towards(0.3 * step))))), rtol=4e-3, atol=4e-3)
        if renderer.sky is not made[-1]:
            made.append(renderer.sky)
            assert step == 4, f"the cube was made again {0.3 * step:.1f} degrees on"  # past 1 degree: 1.2
    assert len(made) == 2
    runner.frame()  # standing still at 1.5 degrees, 0.3 from the cube: made exact
    assert renderer.sky is not made[-1]
    faces = _cube_faces(runner)
    want = build_faces(Skybox(**FOLLOWING), SkySun(tuple(glm.normalize(light_towards(1.5)))))
    np.testing.assert_allclose(faces, want.astype(np.float16), rtol=2e-3, atol=2e-3)
    still = renderer.sky
    runner.frame()
    assert renderer.sky is still  # and then left alone


def test_a_sharp_mirror_shows_the_generated_sky_as_the_sky_pass_draws_it(scene):
    """A 10-degree lens on a mirror that throws the eye's rays at the sun: every pixel is the
    sky's function along its reflected ray (the composite evaluates it per pixel, as the sky
    pass does: from the 128-texel cube the disc was a blob of texels), the disc whole."""
    from components import Material, MeshRef, Mirror
    from components.transform import yaw_pitch_rotation
    from engine.assets.mesh import quad

    skybox = Skybox(**SKY)
    look = glm.normalize(glm.vec3(SUN.x, SUN.y, -SUN.z))   # reflected in a plane z = const: the sun

    def build(world):
        world.spawn(Transform(rotation=look_rotation(look)), Camera(fov_y=10.0, near=0.1, far=100.0))
        world.spawn(skybox)
        world.spawn(Transform(position=tuple(look * (2.0 / look.z)), rotation=yaw_pitch_rotation(180, 0)),
                    MeshRef(quad(3, 3)), Material(), Mirror())

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    colour, rays = _read(runner)
    reflected = rays * np.array([1.0, 1.0, -1.0])
    np.testing.assert_allclose(colour, sky_radiance(skybox, reflected), rtol=6e-3, atol=6e-3)
    assert (colour[..., 0] > 3.0).sum() > 2000   # the disc, large and sharp
