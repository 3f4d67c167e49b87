"""Spot light cookies (``PointLight.cookie``): the image a spot projects, as a slide projector
does.  The expectations are worked out here on their own: each pixel's ray cast at the lit
wall in float64, the line from the light to that point turned into the image's place by the
light's own frame (its Transform's axes, the cone's tangent), and, through a mirror, by
unfolding: the point's line to the light's image crosses the mirror where the real light's
ray struck it, and that ray, from the real light, says which texel it carried."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Mirror, PointLight, Skybox, Transform
from engine.assets.level_file import load_level, save_level
from engine.assets.mesh import quad
from engine.assets.texture_data import TextureData
from engine.core.errors import GLLimitWarning
from engine.core.world import World
from engine.render.spot_cookies import SpotCookies, cookie_texels
from tests.support import look_from, pixel_rays, srgb_to_linear

SIZE = (240, 180)
QUADRANTS = {"red": (255, 0, 0), "green": (0, 255, 0), "blue": (0, 0, 255), "white": (255, 255, 255)}


def quadrant_cookie(size: int = 64) -> TextureData:
    """Red top left, green top right, blue bottom left, white bottom right (row 0 the top)."""
    pixels = np.full((size, size, 4), 255, np.uint8)
    half = size // 2
    top, bottom, left, right = slice(0, half), slice(half, None), slice(0, half), slice(half, None)
    for rows, cols, name in ((top, left, "red"), (top, right, "green"), (bottom, left, "blue"),
                             (bottom, right, "white")):
        pixels[rows, cols, :3] = QUADRANTS[name]
    return TextureData(pixels, name="quadrants")


def dark_sky() -> Skybox:
    return Skybox(faces=np.zeros((6, 4, 4, 3), np.float32))


def matte(color=(1.0, 1.0, 1.0, 1.0)) -> Material:
    """A white Lambertian surface that reflects nothing of the (black) sky."""
    return Material(color=color, roughness=1.0, environment_reflection=0.0)


def lit_wall(cookie: TextureData | None, position=(0.0, 0.0, 3.0), rotation=None, **light):
    """A world-builder: a white matte wall at z = 0 seen head on from z = 6 under a black sky,
    lit by a spot at ``position`` (turned by ``rotation``) with ``cookie`` and ``light``'s fields."""
    def build(world):
        look_from(world, (0.0, 0.0, 6.0), (0.0, 0.0, 0.0))
        world.spawn(dark_sky())
        world.spawn(Transform(), MeshRef(quad(9.0, 7.0)), matte())
        world.spawn(Transform(position=tuple(position), rotation=rotation if rotation is not None else glm.quat()),
                    PointLight(range=30.0, cookie=cookie, **light))
    return build


def image_place(points: np.ndarray, light: np.ndarray, frame: glm.mat4, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the lines from ``light`` to ``points`` meet a projector's image: the light's unit
    right, top and forward (its frame's +X, +Y, -Z), the image filling the square about the
    cone of half-angle ``angle``; (u, v) from the image's left and bottom, and whether the
    point lies in front of the light."""
    m = np.array(frame.to_list(), np.float64).T
    right, up, forward = m[:3, 0], m[:3, 1], -m[:3, 2]
    right, up, forward = (a / np.linalg.norm(a) for a in (right, up, forward))
    d = points - light
    along = d @ forward
    t = math.tan(math.radians(angle))
    with np.errstate(divide="ignore", invalid="ignore"):
        u = 0.5 + 0.5 * (d @ right) / (along * t)
        v = 0.5 + 0.5 * (d @ up) / (along * t)
    return np.stack([u, v], axis=-1), along > 0


def quadrant_of(uv: np.ndarray) -> np.ndarray:
    """The colour name of the quadrant cookie at image places ``uv`` (v up: the top is v > 0.5)."""
    names = np.array([["blue", "white"], ["red", "green"]])
    return names[(uv[:, 1] > 0.5).astype(int), (uv[:, 0] > 0.5).astype(int)]


def wall_points(runner, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's ray met with the wall plane z = ``z``: the points (h, w, 3) and whether the ray meets it."""
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    t = (z - eye[2]) / rays[..., 2]
    return eye + rays * t[..., None], t > 0


def render(scene, build):
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame()), runner


def check_quadrants(linear: np.ndarray, uv: np.ndarray, inside: np.ndarray, margin: float = 0.06) -> int:
    """Each pixel well inside a quadrant of the image and of the cone shows that quadrant's
    colour: its own channels lit, the others dark.  Returns how many were checked."""
    centre = np.abs(uv - 0.5)
    keep = inside & (centre.min(axis=-1) > margin) & (np.linalg.norm(uv - 0.5, axis=-1) < 0.5 - margin)
    shown = linear[keep]
    expected = np.array([QUADRANTS[name] for name in quadrant_of(uv[keep])], np.float64) / 255.0
    brightness = shown.max(axis=-1, keepdims=True)
    assert (brightness > 0.05).all()
    assert np.abs(shown / brightness - expected).max() < 0.1
    return int(keep.sum())


def _save(name: str, linear: np.ndarray) -> None:
    """The frame as a PNG under /tmp (to look at; the assertions do not read it)."""
    from PIL import Image

    from tests.support import linear_to_srgb8
    Image.fromarray(linear_to_srgb8(linear).astype(np.uint8)).save(f"/tmp/spot_cookie_{name}.png")


# --- tests ---------------------------------------------------------------------------------------------
def test_a_cookie_projects_its_image_as_a_slide_projector_does(scene):
    """A spot turned about its axis and aimed a little aside throws the quadrant image on a wall:
    each pixel shows the quadrant the line from the light says, its top towards the light's
    +Y and its right towards its +X; the white quadrant is as bright as the light with no
    cookie, and nothing outside the cone is lit."""
    position = np.array([0.3, -0.2, 3.0])
    rotation = glm.angleAxis(glm.radians(8.0), glm.vec3(0, 1, 0)) * glm.angleAxis(glm.radians(90.0), glm.vec3(0, 0, 1))
    angle = 28.0
    frames = {}
    for name, cookie in (("cookie", quadrant_cookie()), ("none", None)):
        frames[name], runner = render(scene, lit_wall(cookie, position, rotation, intensity=12.0, spot_angle=angle,
                                                      spot_blend=0.0))
    points, hits = wall_points(runner)
    frame = glm.translate(glm.vec3(*position)) * glm.mat4_cast(rotation)
    uv, ahead = image_place(points.reshape(-1, 3), position, frame, angle)
    inside = hits.reshape(-1) & ahead
    _save("wall", frames["cookie"])
    linear = frames["cookie"].reshape(-1, 3)
    assert check_quadrants(linear, uv, inside) > 2000
    # White passes the light whole; outside the cone nothing is lit.
    white = inside & (quadrant_of(uv) == "white") & (np.abs(uv - 0.5).min(axis=-1) > 0.06) \
        & (np.linalg.norm(uv - 0.5, axis=-1) < 0.44)
    np.testing.assert_allclose(linear[white], frames["none"].reshape(-1, 3)[white], atol=0.02, rtol=0.03)
    outside = np.linalg.norm(uv - 0.5, axis=-1) > 0.56
    assert linear[outside & hits.reshape(-1)].max() < 0.01


def test_a_cookies_colour_is_its_linear_light(scene):
    """A cookie of one sRGB colour (255, 188, 54) multiplies the light by that colour in linear
    light (1, 0.503, 0.037), against the same light without one."""
    srgb = np.array([255, 188, 54])
    pixels = np.zeros((16, 16, 4), np.uint8)
    pixels[..., :3], pixels[..., 3] = srgb, 255
    frames = {}
    for name, cookie in (("cookie", TextureData(pixels, name="amber")), ("none", None)):
        frames[name], _ = render(scene, lit_wall(cookie, intensity=12.0, spot_angle=30.0, spot_blend=0.0))
    lit = frames["none"].max(axis=-1) > 0.15
    assert lit.sum() > 3000
    expected = srgb_to_linear(srgb.astype(np.uint8)[None])[0]
    ratio = np.median(frames["cookie"][lit] / frames["none"][lit][:, :1], axis=0)
    np.testing.assert_allclose(ratio, expected, atol=0.015)


def test_a_mirror_throws_the_image_the_other_way_round(scene):
    """A spot aimed at a mirror that reflects light (``Mirror.reflects_light``) lights a wall
    behind it through the mirror.  Each lit pixel of the wall shows the texel the real light
    sent: its line to the light's image crosses the mirror where the light's ray struck it,
    and that ray, from the light itself, says the quadrant.  A projector seen in a mirror is
    the other way round, which the unfolding gives and a cookie rebuilt the right way round
    about the reflected axis would not."""
    light_at = np.array([0.0, 0.0, 2.0])
    facing_mirror = glm.angleAxis(glm.radians(-90.0), glm.vec3(0, 1, 0))   # -Z turned to +X
    angle = 25.0

    def build(world):
        look_from(world, (1.5, 0.0, 2.0), (-4.0, 0.0, 2.0), fov=70.0)
        world.spawn(dark_sky())
        world.spawn(Transform(position=(-3.0, 0.0, 2.0), rotation=glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0))),
                    MeshRef(quad(9.0, 7.0)), matte())
        world.spawn(Transform(position=(3.0, 0.0, 2.0), rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(0, 1, 0))),
                    MeshRef(quad(8.0, 8.0)), Material(color=(1.0, 1.0, 1.0, 1.0)), Mirror(reflects_light=True))
        world.spawn(Transform(position=tuple(light_at), rotation=facing_mirror),
                    PointLight(intensity=40.0, range=40.0, spot_angle=angle, spot_blend=0.0, cookie=quadrant_cookie()))
    linear, runner = render(scene, build)
    assert runner.engine.renderer.stats.virtual_lights == 1
    _save("mirror", linear)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    t = (-3.0 - eye[0]) / rays[..., 0]
    wall = (eye + rays * t[..., None]).reshape(-1, 3)
    hits = (t > 0).reshape(-1) & (np.abs(wall[:, 1]) < 3.4) & (np.abs(wall[:, 2] - 2.0) < 4.4)
    image = light_at * np.array([-1.0, 1.0, 1.0]) + np.array([6.0, 0.0, 0.0])   # the light mirrored in x = 3
    towards = image - wall
    s = (3.0 - wall[:, 0]) / towards[:, 0]
    struck = wall + towards * s[:, None]   # where the line to the image crosses the mirror
    uv, ahead = image_place(struck, light_at, glm.translate(glm.vec3(*light_at)) * glm.mat4_cast(facing_mirror), angle)
    checked = check_quadrants(linear.reshape(-1, 3), uv, hits & ahead)
    assert checked > 1500
    # The rebuilt-about-the-reflected-axis answer differs: left and right swapped.
    swapped = uv.copy()
    swapped[:, 0] = 1.0 - swapped[:, 0]
    keep = hits & ahead & (np.abs(uv - 0.5).min(axis=-1) > 0.06) & (np.linalg.norm(uv - 0.5, axis=-1) < 0.44)
    assert (quadrant_of(swapped[keep]) != quadrant_of(uv[keep])).all()


def test_a_portal_carries_the_image_turned_not_mirrored(scene):
    """A spot aimed into portal A (facing +z) comes out of portal B (facing +x) onto a wall
    beyond B.  Each lit pixel shows the texel the real light sent: its line to the light's
    image crosses B's opening at a point the pair carries back to A's, and the ray from the
    light to that point says the quadrant; a portal turns the image, it does not mirror it."""
    from components import Portal, look_rotation
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    lamp = np.array([0.0, 1.5, 5.5])
    angle = 18.0
    names = {}

    def build(world):
        look_from(world, (-5.0, 1.5, 3.0), (-2.0, 1.5, 0.0), fov=70.0)
        world.spawn(dark_sky())
        world.spawn(Transform(position=(-2.0, 1.5, 0.0), rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(0, 1, 0))),
                    MeshRef(quad(8.0, 6.0)), matte())
        world.spawn(Transform(position=tuple(lamp)),
                    PointLight(intensity=30.0, range=30.0, spot_angle=angle, spot_blend=0.0, cookie=quadrant_cookie()))
        names["a"], names["b"] = spawn_portal_pair(world, (0.0, 1.5, 4.0), None, (-6.0, 1.5, 0.0),
                                                   look_rotation(glm.vec3(-1, 0, 0)))
        world.get(names["a"], Portal).carries_light = True
    linear, runner = render(scene, build)
    assert runner.engine.renderer.stats.virtual_lights == 1
    _save("portal", linear)
    world = runner.engine.world
    carry = np.array(glm.dmat4(pair_transform(world.get(names["a"], Transform).world,
                                              world.get(names["b"], Transform).world)).to_list(), np.float64).T
    image = carry[:3, :3] @ lamp + carry[:3, 3]
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    t = (-2.0 - eye[0]) / rays[..., 0]
    wall = (eye + rays * t[..., None]).reshape(-1, 3)
    towards = image - wall
    s = (-6.0 - wall[:, 0]) / towards[:, 0]
    crossing = wall + towards * s[:, None]   # where the line to the image crosses B's plane
    through = (t.reshape(-1) > 0) & (np.abs(crossing[:, 1] - 1.5) < 1.4) & (np.abs(crossing[:, 2]) < 0.9) \
        & (np.abs(wall[:, 1] - 1.5) < 2.9) & (np.abs(wall[:, 2]) < 3.9)
    back = np.linalg.inv(carry)
    at_a = crossing @ back[:3, :3].T + back[:3, 3]
    uv, ahead = image_place(at_a, lamp, glm.translate(glm.vec3(*lamp)), angle)
    assert check_quadrants(linear.reshape(-1, 3), uv, through & ahead) > 1000


def test_a_cookie_is_refused_where_a_spot_cannot_project_it():
    """A cookie on a spot wider than 80 degrees (but not all round), a spot widened past it
    while it has one, and a cookie that is not an image: each refused when given, naming the
    field and the reason.  An all-round light takes one (wrapped about it)."""
    cookie = quadrant_cookie(8)
    assert PointLight(cookie=cookie).cookie is cookie   # all round: wrapped (test_point_cookies.py)
    with pytest.raises(ComponentValueError, match=r"PointLight.cookie: .*up to 80 degrees.*spot_angle is 85"):
        PointLight(spot_angle=85.0, cookie=cookie)
    light = PointLight(spot_angle=80.0, cookie=cookie)
    with pytest.raises(ComponentValueError, match=r"PointLight.spot_angle = 81: this light has a cookie"):
        light.spot_angle = 81.0
    assert light.spot_angle == 80.0
    light.spot_angle = 180.0   # all round: the image wrapped about it
    assert light.spot_angle == 180.0
    light.cookie = None
    light.spot_angle = 120.0
    with pytest.raises(ComponentValueError, match=r"PointLight.cookie must be an engine.assets.texture_data"):
        PointLight(spot_angle=30.0, cookie=np.zeros((4, 4, 3)))


def test_cookie_images_hold_a_layer_while_a_kept_light_shows_them_and_go_with_it(scene):
    """Two lights sharing one image and a third with its own: two layers; the array and the
    SPOT_COOKIES build go when the last light with a cookie goes; a cookie swapped for another
    is drawn next frame."""
    first, second = quadrant_cookie(16), TextureData(np.full((8, 8, 4), 255, np.uint8), name="white")
    names = {}

    def build(world):
        look_from(world, (0.0, 0.0, 6.0), (0.0, 0.0, 0.0))
        world.spawn(dark_sky())
        world.spawn(Transform(), MeshRef(quad(9.0, 7.0)), matte())
        names["lamps"] = [world.spawn(Transform(position=(x, 0.0, 3.0)),
                                      PointLight(intensity=3.0, spot_angle=20.0, cookie=cookie))
                          for x, cookie in ((-2.0, first), (0.0, first), (2.0, second))]
    runner = scene(build, SIZE)
    runner.frame()
    renderer, world = runner.engine.renderer, runner.engine.world
    cookies = renderer.spot_cookies
    assert cookies.layer(first) != cookies.layer(second) and {cookies.layer(first), cookies.layer(second)} == {0, 1}
    assert renderer.resource_counts()["spot_cookies"] == 1 and cookies.defines == (("SPOT_COOKIES", "1"),)
    before = runner.frame().astype(int)
    world.get(names["lamps"][0], PointLight).cookie = second
    after = runner.frame().astype(int)
    left = (slice(None), slice(0, SIZE[0] // 3))
    assert (after[left][..., 1] - before[left][..., 1]).max() > 40   # its red quadrant turned white
    for lamp in names["lamps"]:
        world.delete_entity(lamp)
    runner.frame()
    assert renderer.resource_counts()["spot_cookies"] == 0 and cookies.defines == () and cookies.layer(second) == -1


def test_on_a_context_of_16_texture_units_lights_shine_without_their_cookies(scene, ctx):
    """Where the fragment stage has no 17th sampler the light shines as though it had no
    cookie, and a GLLimitWarning names the light and the limit, once."""
    frames = {}
    for name, cookie in (("cookie", quadrant_cookie()), ("none", None)):
        runner = scene(lit_wall(cookie, intensity=3.0, spot_angle=30.0), SIZE)
        runner.engine.renderer.spot_cookies.release()
        runner.engine.renderer.spot_cookies = SpotCookies(ctx, texture_units=16)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            runner.frame()
            frames[name] = runner.frame()
        said = [w for w in caught if issubclass(w.category, GLLimitWarning)]
        assert len(said) == (1 if cookie is not None else 0)
        if said:
            message = str(said[0].message)
            assert "PointLight of entity" in message and "GL_MAX_TEXTURE_IMAGE_UNITS" in message
    np.testing.assert_array_equal(frames["cookie"], frames["none"])


def test_the_cookie_copy_is_the_image_in_linear_light():
    """The array's copy of an image: decoded from sRGB, resampled to the square, rows from the
    bottom (GL's): an image's top rows end up in the copy's last rows."""
    pixels = np.zeros((32, 32, 4), np.uint8)
    pixels[:16, :, :3] = 255
    pixels[16:, :, :3] = 188
    copy = cookie_texels(TextureData(pixels), size=8)
    assert copy.shape == (8, 8, 3)
    np.testing.assert_allclose(copy[-1], 1.0, atol=1e-3)
    np.testing.assert_allclose(copy[0], srgb_to_linear(np.array([188], np.uint8))[0], atol=2e-3)


def test_a_cookie_file_is_named_in_a_level_and_loads_again(tmp_path):
    """``cookie = { file = "..." }`` in a level: read as a colour image, saved by its file."""
    from PIL import Image

    Image.fromarray(quadrant_cookie(16).pixels[..., :3]).save(tmp_path / "gobo.png")
    (tmp_path / "level.toml").write_text(
        '[level]\nname = "lamp"\n\n[[entity]]\nname = "lamp"\n[entity.Transform]\nposition = [0.0, 2.0, 0.0]\n'
        '[entity.PointLight]\nspot_angle = 30.0\ncookie = { file = "gobo.png" }\n')
    world = World("lamp")
    names = load_level(tmp_path / "level.toml").spawn(world)
    light = world.get(names["lamp"], PointLight)
    np.testing.assert_array_equal(light.cookie.pixels, quadrant_cookie(16).pixels)
    saved = save_level(world, tmp_path / "saved.toml", names, name="lamp")
    assert 'cookie = { file = "gobo.png" }' in saved.read_text()
    again = World("again")
    names_again = load_level(saved).spawn(again)
    np.testing.assert_array_equal(again.get(names_again["lamp"], PointLight).cookie.pixels, light.cookie.pixels)


def test_the_editor_sets_a_cookie_as_a_level_file_names_it(tmp_path):
    """The inspector's image field: a cookie typed as a level file's table names it, shown
    back the same way, refused on a light too wide for one with the component's own words,
    and undone."""
    from PIL import Image

    from shell.editor import EditError, Editor

    Image.fromarray(quadrant_cookie(16).pixels[..., :3]).save(tmp_path / "gobo.png")
    world = World("lamps")
    spot = world.spawn(Transform(), PointLight(spot_angle=30.0))
    lamp = world.spawn(Transform(), PointLight(spot_angle=120.0))   # too wide to project, not all round
    editor = Editor(world, level_path=tmp_path / "level.toml")
    editor.set_texture(spot, "cookie", 'file = "gobo.png"', "PointLight")
    assert editor.texture_text(spot, "cookie", "PointLight") == 'file = "gobo.png"'
    np.testing.assert_array_equal(world.get(spot, PointLight).cookie.pixels, quadrant_cookie(16).pixels)
    with pytest.raises(ComponentValueError, match="up to 80 degrees"):
        editor.set_texture(lamp, "cookie", "checker = [64, 4]", "PointLight")
    assert world.get(lamp, PointLight).cookie is None
    with pytest.raises(EditError, match="PointLight.range is not an image"):
        editor.set_texture(spot, "range", "checker = [64, 4]", "PointLight")
    assert editor.undo() and world.get(spot, PointLight).cookie is None


@pytest.mark.parametrize("how", ["mirror", "portal"])
def test_a_cookies_image_on_a_wall_seen_in_a_mirror_or_through_a_portal_is_the_one_the_rays_meet(scene, how):
    """The turned spot of the first test throws the quadrant image on the wall; the eye sees
    the wall only in a mirror (at z = 5, facing it) or through a portal (A aside, B at z = 4.2
    facing the wall).  Each pixel's ray, reflected in the mirror's plane or carried by the
    pair's transform in float64, meets the wall where the line from the light says the
    quadrant it shows (the view reads the light's cookie as the eye does)."""
    from components import Portal
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    position = np.array([0.3, -0.2, 3.0])
    rotation = glm.angleAxis(glm.radians(8.0), glm.vec3(0, 1, 0)) * glm.angleAxis(glm.radians(90.0), glm.vec3(0, 0, 1))
    angle = 28.0
    turned_round = glm.angleAxis(glm.radians(180.0), glm.vec3(0, 1, 0))   # a quad facing -z
    names = {}

    def build(world):
        world.spawn(dark_sky())
        world.spawn(Transform(), MeshRef(quad(9.0, 7.0)), matte())
        world.spawn(Transform(position=tuple(position), rotation=rotation),
                    PointLight(range=30.0, cookie=quadrant_cookie(), intensity=12.0, spot_angle=angle, spot_blend=0.0))
        if how == "mirror":
            look_from(world, (0.4, 0.3, 1.0), (0.0, 0.0, 5.0), fov=45.0)
            names["surface"] = world.spawn(Transform(position=(0.0, 0.0, 5.0), rotation=turned_round),
                                           MeshRef(quad(8.0, 6.0)), Material(), Mirror())
        else:
            look_from(world, (10.3, 0.2, 1.2), (10.0, 0.0, 0.0), fov=70.0)
            names["surface"], names["b"] = spawn_portal_pair(world, (10.0, 0.0, 0.0), None, (0.0, 0.0, 4.2),
                                                             turned_round, size=(5.0, 4.0))
            assert world.get(names["surface"], Portal).partner == names["b"]
    linear, runner = render(scene, build)
    _save(f"seen_{how}", linear)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    rays = rays.reshape(-1, 3)
    if how == "mirror":
        at = eye + rays * ((5.0 - eye[2]) / rays[:, 2])[:, None]
        turned = rays * np.array([1.0, 1.0, -1.0])
    else:
        world = runner.engine.world
        carry = np.array(glm.dmat4(pair_transform(world.get(names["surface"], Transform).world,
                                                  world.get(names["b"], Transform).world)).to_list(), np.float64).T
        at = (eye + rays * (-eye[2] / rays[:, 2])[:, None]) @ carry[:3, :3].T + carry[:3, 3]
        turned = rays @ carry[:3, :3].T
    wall = at + turned * (-at[:, 2] / turned[:, 2])[:, None]
    seen = (runner.engine.renderer.targets.read_surface_ids() == names["surface"]).reshape(-1) \
        & (np.abs(wall[:, 0]) < 4.4) & (np.abs(wall[:, 1]) < 3.4)
    frame = glm.translate(glm.vec3(*position)) * glm.mat4_cast(rotation)
    uv, ahead = image_place(wall, position, frame, angle)
    assert check_quadrants(linear.reshape(-1, 3), uv, seen & ahead) > 1500
