"""Screen-space refraction (``Refractive.screen``, ``engine/render/screen_refraction.py``):
glass shows what its view drew behind it, bent by Snell's law.  Checked against second paths:
a pane of index 1 (no bend, no reflection) leaves the frame as it was drawn without it, in
the camera's view and in a mirror's; a tilted pane of index 1.5 shows a stripe behind it
where rays refracted in numpy meet it; the march's find fades to the probe's or sky's image
where the ray finds nothing, and a build without room for the copy's sampler refracts the
sky (with a warning)."""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Fog,
    Material,
    MeshRef,
    Mirror,
    Refractive,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.mesh import Mesh, box, quad, sphere
from engine.core.errors import GLLimitWarning
from tests.support import box_hits, linear_to_srgb8, look_from, pixel_rays, srgb_to_linear

SIZE = (160, 120)
CLEAR = dict(roughness=0.0, reflectance=0.0, environment_reflection=0.0)  # a surface that reflects nothing


def room(world) -> None:
    """A floor, a red post and a blue block under a gradient sky."""
    world.spawn(Skybox())
    world.spawn(Transform(), MeshRef(box((8.0, 0.1, 8.0))), Material(color=(0.6, 0.6, 0.6, 1.0)))
    world.spawn(Transform(position=(0.3, 1.0, -2.0)), MeshRef(box((0.3, 2.0, 0.3))),
                Material(color=(0.9, 0.1, 0.1, 1.0)))
    world.spawn(Transform(position=(-0.8, 0.6, -1.5)), MeshRef(box((0.5, 1.2, 0.5))),
                Material(color=(0.1, 0.2, 0.9, 1.0)))


def frame(scene, build, size=SIZE) -> np.ndarray:
    return framed(scene, build, size)[1]


def framed(scene, build, size=SIZE):
    """``build``'s runner and its second frame (linear, FXAA off)."""
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return runner, srgb_to_linear(runner.frame())


def pane(world, ior: float, screen: bool = True, position=(0.0, 1.0, 1.0), turn: float = 0.0,
         tint: float = 1.0) -> int:
    """A 1.6 m square of clear glass (``tint``: the share of the light behind it it lets through)."""
    return world.spawn(Transform(position=position, rotation=glm.quat(glm.vec3(0.0, turn, 0.0))),
                       MeshRef(quad(1.6, 1.6)), Material(color=(tint, tint, tint, 0.0), double_sided=True, **CLEAR),
                       Refractive(ior=ior, screen=screen))


TINT = 0.5   # the probe tests' panes let through half of what lies behind them: seen drawn, and marched


def assert_tinted(seen: np.ndarray, drawn: np.ndarray, covered: np.ndarray) -> None:
    """Where the pane covers (``covered``) what the view drew bright enough to judge, the view
    with the pane shows TINT of it (linear): the pane is drawn there and shows what lies
    behind it (the pane undrawn shows all of it; one refracting the sky, the sky)."""
    judged = covered[..., None] & (drawn > 0.02)
    assert judged.sum() > 100, judged.sum()
    ratio = seen[judged] / drawn[judged]
    assert abs(float(np.median(ratio)) - TINT) < 0.02 and np.quantile(np.abs(ratio - TINT), 0.95) < 0.05, \
        np.quantile(ratio, [0.01, 0.05, 0.5, 0.95, 0.99])


def on_quad(eye, rays, at, half) -> np.ndarray:
    """Which of the pixel ``rays`` from ``eye`` meet the square of half-size ``half`` about
    ``at`` that faces +z (its plane z = at.z)."""
    hit = eye + ((at[2] - eye[2]) / rays[..., 2])[..., None] * rays
    return (np.abs(hit[..., 0] - at[0]) < half) & (np.abs(hit[..., 1] - at[1]) < half)


def small_pane(world, position, side: float) -> None:
    """A square refracting pane of index 1 that reflects nothing, ``side`` metres, facing +z."""
    world.spawn(Transform(position=position), MeshRef(quad(side, side)),
                Material(color=(1.0, 1.0, 1.0, 0.0), double_sided=True, **CLEAR), Refractive(ior=1.0))


def two_squares(world, yellow_at, yellow_side: float, green_at, green_side: float, green_colour) -> None:
    """The room seen from (0, 1.2, 4), a half see-through yellow square of ``yellow_side``
    metres at ``yellow_at`` and one of ``green_colour`` at ``green_at``, both facing +z."""
    look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
    room(world)
    world.spawn(Transform(position=tuple(yellow_at)), MeshRef(quad(yellow_side, yellow_side)),
                Material(color=(0.9, 0.9, 0.1, 0.5), double_sided=True))
    world.spawn(Transform(position=tuple(green_at)), MeshRef(quad(green_side, green_side)),
                Material(color=(*green_colour, 0.5), double_sided=True))


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_a_pane_of_index_one_shows_the_frame_behind_it_as_drawn(scene, projection):
    """(An orthographic camera's rays are parallel: the march's window depth and 1 / w are
    affine along the screen all the same.)"""
    def without(world):
        camera = look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
        world.get(camera, Camera).projection = projection
        world.get(camera, Camera).ortho_height = 3.0
        room(world)

    def through(screen):
        def build(world):
            without(world)
            world.resources["pane"] = pane(world, 1.0, screen)
        return build

    drawn = frame(scene, without)
    runner, seen = framed(scene, through(True))
    sky_only = frame(scene, through(False))
    covered = np.abs(sky_only - drawn).max(axis=-1) > 0.05  # where the pane hides the room without it
    assert covered.sum() > 1000
    assert (runner.ids()[covered] == runner.world.resources["pane"]).all()   # (the pane drawn there)
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(drawn)).max(axis=-1)
    # (the sky through it is the sky's cube map, a level or two from the sky drawn a pixel
    # each; a ray along the eye's may land on a pixel's neighbour at a shadow's edge)
    assert np.quantile(levels[covered], 0.99) <= 2.0 and levels[covered].mean() < 0.3


@pytest.mark.parametrize("air", ["clear", "fog"])
def test_glass_over_the_sky_shows_the_sky_the_view_drew(scene, air):
    """A pane of index 1 that reflects nothing, before the sun low in the sky: its rays run
    on to the sky along the eye's, so it shows the sky the view drew around it, fog and all
    (read where the ray's vanishing point lies, the sky all the way there), the sun's disc
    as sharp as the sky pass draws it per pixel, not as the sky's cube map holds it (its
    texels blur the disc's edge)."""
    def without(world):
        camera = look_from(world, (0.0, 1.2, 4.0), (0.0, 2.2, 0.0), fov=50.0)
        if air == "fog":
            # (height fog: thinning upwards, the sky is fogged only partly; the sun's disc shows)
            world.add_component(camera, Fog(color=(0.7, 0.7, 0.7, 1.0), density=0.08, height_falloff=0.5))
        room(world)
        world.spawn(DirectionalLight(direction=(0.05, -0.3, 1.0), intensity=3.0))

    def with_pane(world):
        without(world)
        pane(world, 1.0, position=(0.0, 2.2, 1.0))

    drawn = frame(scene, without)
    runner, seen = framed(scene, with_pane)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    t = (1.0 - eye[2]) / rays[..., 2]
    hit = eye + t[..., None] * rays
    inside = (np.abs(hit[..., 0]) < 0.75) & (np.abs(hit[..., 1] - 2.2) < 0.75)
    sky = inside & (rays[..., 1] > 0.05)   # (the room's post and block stand lower)
    assert sky.sum() > 1500
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(drawn)).max(axis=-1)
    assert np.quantile(levels[sky], 0.99) <= 1.5 and levels[sky].mean() < 0.2, \
        (np.quantile(levels[sky], 0.99), levels[sky].mean())


def striped_wall(world, stripe: np.ndarray, stripe_half: np.ndarray, fov: float) -> None:
    """A camera 4 m before a grey wall (3 m behind the origin) with a red stripe on it (a box
    at ``stripe`` of half sizes ``stripe_half``), both unlit: exact colours to find."""
    look_from(world, (0.0, 1.0, 4.0), (0.0, 1.0, 0.0), fov=fov)
    world.spawn(Skybox())
    world.spawn(Transform(position=(0.0, 1.0, -3.0)), MeshRef(box((8.0, 6.0, 0.1))),
                Material(color=(0.3, 0.3, 0.3, 1.0), unlit=True))
    world.spawn(Transform(position=tuple(stripe)), MeshRef(box(tuple(2.0 * stripe_half))),
                Material(color=(1.0, 0.0, 0.0, 1.0), unlit=True))


def middle_row(scene, build, size=(200, 100)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``build``'s second frame's middle row (linear, FXAA off), the eye and that row's pixel rays."""
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame())
    eye, rays = pixel_rays(runner.engine.main_view, size)
    return shown[size[1] // 2], eye, rays[size[1] // 2]


def test_a_tilted_pane_bends_what_is_behind_it_as_snells_law_says(scene):
    """A thin pane (one interface: ``Refractive(solid=False)``) of index 1.5 turned 35 degrees
    before a red stripe on a grey wall (both unlit): along the middle row, the stripe shows
    through the pane where the pixels' rays, refracted at the pane's plane in numpy, meet it,
    and that is well away from where it shows without the bend."""
    turn = np.radians(35.0)
    stripe_half = np.array([0.08, 1.5, 0.02])

    def build(world):
        striped_wall(world, np.array([0.0, 1.0, -2.9]), stripe_half, fov=40.0)
        pane(world, 1.5, position=(0.0, 1.0, 1.0), turn=float(turn))

    shown_row, eye, d = middle_row(scene, build)
    normal = np.array([np.sin(turn), 0.0, np.cos(turn)])     # the quad's +z turned about y
    right = np.array([np.cos(turn), 0.0, -np.sin(turn)])
    centre = np.array([0.0, 1.0, 1.0])
    t = ((centre - eye) @ normal) / (d @ normal)
    hit = eye + t[:, None] * d
    across = np.abs((hit - centre) @ right)
    through = (t > 0) & (across < 0.75)                      # (inside the 1.6 m pane, its edges left out)
    eta = 1.0 / 1.5
    cos_i = -(d @ normal)
    k = 1.0 - eta ** 2 * (1.0 - cos_i ** 2)
    bent = eta * d + (eta * cos_i - np.sqrt(k))[:, None] * normal
    stripe = np.array([0.0, 1.0, -2.9])
    expected = box_hits(hit, bent, stripe, stripe_half) & through
    straight = box_hits(np.repeat(eye[None], len(d), 0), d, stripe, stripe_half) & through
    red = (shown_row[:, 0] > 0.5) & (shown_row[:, 1] < 0.2)
    assert expected.sum() >= 3 and straight.sum() >= 3
    moved = abs(np.flatnonzero(expected).mean() - np.flatnonzero(straight).mean())
    assert moved > 8                                         # the bend shows: the stripe moved that many pixels
    assert (red[through] != expected[through]).sum() <= 2   # (a pixel each side where an edge falls)


def test_a_solid_ball_shows_what_is_behind_it_where_a_ball_lens_puts_it(scene):
    """A solid glass ball (``Refractive(solid=True)``, index 1.5) before a red stripe on a grey
    wall, the stripe off to one side: along the middle row the stripe shows through the ball
    where rays traced into the sphere, along its chord and out (in numpy) meet it, on the
    other side of the ball's middle (a ball lens turns the picture over)."""
    radius, centre = 0.6, np.array([0.0, 1.0, 0.0])
    stripe, stripe_half = np.array([0.35, 1.0, -2.9]), np.array([0.08, 1.5, 0.02])

    def build(world):
        striped_wall(world, stripe, stripe_half, fov=30.0)
        world.spawn(Transform(position=tuple(centre)), MeshRef(sphere(radius, 128, 64)),
                    Material(color=(1.0, 1.0, 1.0, 0.0), **CLEAR), Refractive(ior=1.5, solid=True))

    shown_row, eye, d = middle_row(scene, build)
    # Into the sphere (the nearer root), along the chord, out of it.
    b = d @ (eye - centre)
    disc = b ** 2 - (eye - centre) @ (eye - centre) + radius ** 2
    inside_ball = disc > 0.0
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    entry = eye + t[:, None] * d
    normal = (entry - centre) / radius
    deep = np.abs(np.sum(normal * d, axis=1)) > 0.3  # (away from the rim, where pixels straddle it)

    def refract(incident, n, eta):
        cos_i = -np.sum(incident * n, axis=1)
        k = 1.0 - eta ** 2 * (1.0 - cos_i ** 2)
        return eta * incident + (eta * cos_i - np.sqrt(np.maximum(k, 0.0)))[:, None] * n

    inside = refract(d, normal, 1.0 / 1.5)
    chord = 2.0 * np.sum((centre - entry) * inside, axis=1)
    exit_point = entry + chord[:, None] * inside
    out = refract(inside, -(exit_point - centre) / radius, 1.5)
    expected = box_hits(exit_point, out, stripe, stripe_half) & inside_ball & deep
    red = (shown_row[:, 0] > 0.5) & (shown_row[:, 1] < 0.2)
    through = inside_ball & deep
    assert expected.sum() >= 3
    middle = np.flatnonzero(inside_ball).mean()
    assert np.flatnonzero(expected).mean() < middle         # (the stripe is right of it: seen on the left)
    assert (red[through] != expected[through]).sum() <= 2


def test_a_pane_in_a_mirror_shows_what_the_mirrors_view_drew_behind_it(scene):
    """Behind the camera, a red post and before it a pane of index 1, seen only in the mirror
    the camera faces: the mirror's view refracts its own image (a reflection level's copy),
    so the pane shows the post as the mirror shows it without the pane; refracting the sky
    instead (``screen`` False) hides it."""
    without, through, through_sky = through_mirror()
    drawn, (runner, seen), sky_only = frame(scene, without), framed(scene, through), frame(scene, through_sky)
    red = (drawn[..., 0] > 0.3) & (drawn[..., 1] < 0.1)
    assert red.sum() > 60                                                      # the post, in the mirror
    assert (runner.ids()[red] == runner.world.resources["pane"]).mean() > 0.6  # the pane drawn over it
    assert ((sky_only[..., 0] > 0.3) & (sky_only[..., 1] < 0.1)).sum() < red.sum() / 4  # hidden by the sky's image
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(drawn)).max(axis=-1)
    assert np.quantile(levels, 0.99) <= 2.0 and levels[red].max() <= 3.0


def through_mirror():
    """The mirror's scene: without the pane, with it, with it refracting the sky."""
    def without(world):
        look_from(world, (0.0, 1.2, 2.0), (0.0, 1.2, -2.0), fov=50.0)
        world.spawn(Skybox())
        world.spawn(Transform(), MeshRef(box((10.0, 0.1, 16.0))), Material(color=(0.6, 0.6, 0.6, 1.0)))
        world.spawn(Transform(position=(0.0, 1.2, -2.0)), MeshRef(quad(3.0, 2.4)), Material(), Mirror())
        world.spawn(Transform(position=(0.2, 1.0, 6.0)), MeshRef(box((0.8, 2.0, 0.4))),
                    Material(color=(1.0, 0.0, 0.0, 1.0), unlit=True))

    def through(screen):
        def build(world):
            without(world)
            world.resources["pane"] = pane(world, 1.0, screen, position=(0.0, 1.2, 4.5), turn=float(np.pi))
        return build

    return without, through(True), through(False)


def test_a_pane_through_a_portal_shows_what_the_portals_view_drew_behind_it(scene):
    """The camera looks into portal A; beyond its partner B (10 m off, turned a quarter) stand
    a red post and before it a pane of index 1, seen only through the portal: the portal's
    view refracts its own image (its level's copy), so the pane shows the post as the portal
    shows it without the pane; refracting the sky instead (``screen`` False) hides it."""
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    a_at, b_at = glm.vec3(0.0, 1.2, -2.0), glm.vec3(10.0, 1.2, 0.0)
    turn = glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0))
    carry = pair_transform(glm.translate(a_at), glm.translate(b_at) * glm.mat4_cast(turn))

    def carried(at) -> tuple[glm.vec3, glm.quat]:
        """Where a thing seen through A at ``at`` stands, and its turn."""
        return glm.vec3(carry * glm.vec4(glm.vec3(at), 1.0)), glm.quat_cast(carry)

    def without(world):
        look_from(world, (0.0, 1.2, 2.0), (0.0, 1.2, -2.0), fov=50.0)
        world.spawn(Skybox())
        spawn_portal_pair(world, a_at, None, b_at, turn, size=(3.0, 2.4))
        at, rotation = carried((0.0, 0.0, -8.0))
        world.spawn(Transform(position=at, rotation=rotation), MeshRef(box((10.0, 0.1, 12.0))),
                    Material(color=(0.6, 0.6, 0.6, 1.0)))
        at, rotation = carried((0.2, 1.0, -8.0))
        world.spawn(Transform(position=at, rotation=rotation), MeshRef(box((0.8, 2.0, 0.4))),
                    Material(color=(1.0, 0.0, 0.0, 1.0), unlit=True))

    def through(screen):
        def build(world):
            without(world)
            at, rotation = carried((0.0, 1.2, -5.5))
            world.resources["pane"] = world.spawn(Transform(position=at, rotation=rotation), MeshRef(quad(1.6, 1.6)),
                                                  Material(color=(1.0, 1.0, 1.0, 0.0), double_sided=True, **CLEAR),
                                                  Refractive(ior=1.0, screen=screen))
        return build

    runner, drawn = framed(scene, without)
    assert runner.stats.reflection_views >= 1
    (runner, seen), sky_only = framed(scene, through(True)), frame(scene, through(False))
    red = (drawn[..., 0] > 0.3) & (drawn[..., 1] < 0.1)
    assert red.sum() > 60, red.sum()                                           # the post, through the portal
    assert (runner.ids()[red] == runner.world.resources["pane"]).mean() > 0.6  # the pane drawn over it (not its foot)
    assert ((sky_only[..., 0] > 0.3) & (sky_only[..., 1] < 0.1)).sum() < red.sum() / 4  # hidden by the sky's image
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(drawn)).max(axis=-1)
    assert np.quantile(levels, 0.99) <= 2.0 and levels[red].max() <= 3.0


def test_a_still_tree_keeps_refracting_surfaces_as_drawn_whole(scene):
    """Two facing mirrors (end images that settle over frames: the still tree's refill draws
    each level's last part again over a copy of it) and a refracting ball between: kept
    levels give the frames a whole-drawn engine gives, bit for bit."""
    from tests.support import kept_frames_equal_drawn

    def build(world):
        look_from(world, (0.3, 1.2, 1.5), (0.0, 1.0, -2.0), fov=60.0)
        room(world)
        world.spawn(Transform(position=(0.0, 1.2, -3.0)), MeshRef(quad(3.0, 2.4)), Material(), Mirror())
        world.spawn(Transform(position=(0.0, 1.2, 3.0), rotation=glm.quat(glm.vec3(0.0, np.pi, 0.0))),
                    MeshRef(quad(3.0, 2.4)), Material(), Mirror())
        world.spawn(Transform(position=(0.0, 0.9, -0.5)), MeshRef(sphere(0.4)),
                    Material(color=(1.0, 1.0, 1.0, 0.0), roughness=0.05), Refractive(ior=1.5, solid=True))

    keeping, drawing = scene(build, (96, 64)), scene(build, (96, 64))
    assert kept_frames_equal_drawn(keeping, drawing, frames=5) >= 2
    assert keeping.engine.renderer.scene_pass.refraction_copy.copies > 0


def test_a_build_with_no_room_for_the_copy_refracts_the_sky_and_says_so(scene):
    """A context whose fragment stage has too few samplers for the march's (a 16-unit
    driver's fullest builds; here the limit is lowered): the refracting surfaces keep the
    sky's image, drawn as with ``screen`` False, and a GLLimitWarning names the field."""
    def build(screen):
        def make(world):
            look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
            room(world)
            pane(world, 1.0, screen)
        return make

    runner = scene(build(True), SIZE)
    renderer = runner.engine.renderer
    renderer.antialias = "off"
    renderer.caps = dataclasses.replace(renderer.caps, max_texture_image_units=4)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        runner.frame()
        limited = srgb_to_linear(runner.frame())
    assert any(issubclass(w.category, GLLimitWarning) and "Refractive.screen" in str(w.message) for w in caught)
    np.testing.assert_allclose(limited, frame(scene, build(False)), atol=1e-6)


def test_screen_is_checked():
    with pytest.raises(ComponentValueError, match=r"Refractive.screen"):
        Refractive(screen="yes")
    assert Refractive().screen


def test_copies_are_taken_only_where_glass_is_seen_and_go_with_the_last_of_it(scene):
    """A level whose views no refracting surface reaches copies nothing (the pane turned out
    of the camera's sight); one that sees it copies once a frame; deleting the last
    refracting entity lets the copy image go once a whole frame has taken none."""
    glass = []

    def build(world):
        look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
        room(world)
        glass.append(pane(world, 1.0, position=(0.0, 1.0, 8.0)))  # behind the camera

    runner = scene(build, SIZE)
    copy = runner.engine.renderer.scene_pass.refraction_copy
    runner.frame()
    assert copy.copies == 0 and copy.held() == 0
    runner.world.get(glass[0], Transform).position = glm.vec3(0.0, 1.0, 1.0)
    runner.frame()
    runner.frame()
    assert copy.copies == 2 and copy.held() == 1
    runner.world.delete_entity(glass[0])
    runner.frame()
    assert copy.held() == 1  # (its last frame took it)
    runner.frame()
    assert copy.held() == 0 and copy.copies == 2


def test_a_rough_pane_shows_what_is_behind_it_blurred(scene):
    """A rough pane of index 1 reads a blurrier level of the copy (its lobe's width where the
    ray meets what is behind): the red post's edges through it spread over several pixels,
    where a clear pane keeps them as the frame drew them (a pixel or two)."""
    def build(roughness):
        def make(world):
            look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
            room(world)
            world.spawn(Transform(position=(0.0, 1.0, 1.0)), MeshRef(quad(1.6, 1.6)),
                        Material(color=(1.0, 1.0, 1.0, 0.0), double_sided=True,
                                 **{**CLEAR, "roughness": roughness}), Refractive(ior=1.0))
        return make

    def edge_width(image) -> int:
        red = image[58:62, :, 0] - image[58:62, :, 1]      # (rows through the post, behind the pane)
        row = red.mean(axis=0)
        top, floor = row.max(), np.median(row)
        return int(((row > floor + 0.1 * (top - floor)) & (row < top - 0.1 * (top - floor))).sum())

    clear, rough = frame(scene, build(0.0)), frame(scene, build(0.6))
    assert edge_width(clear) <= 4
    assert edge_width(rough) >= edge_width(clear) + 6


def tinted_pane(world, position, tint, mesh=None, material=None) -> int:
    """A thin pane of index 1 that reflects nothing (what it lets through is times ``tint``),
    facing the camera, 1.2 m square unless ``mesh`` says otherwise (its colour is instance
    data: panes of one mesh are one batch)."""
    return world.spawn(Transform(position=position), MeshRef(mesh or quad(1.2, 1.2)),
                       material or Material(color=(*tint, 0.0), double_sided=True, **CLEAR),
                       Refractive(ior=1.0, solid=False))


def own_quad(side: float) -> Mesh:
    """A square facing +Z, a mesh of its own (``quad``'s are one unit mesh, scaled: one batch)."""
    h = side / 2.0
    return Mesh(np.array([(-h, -h, 0.0), (h, -h, 0.0), (h, h, 0.0), (-h, h, 0.0)]), np.tile((0.0, 0.0, 1.0), (4, 1)),
                np.array([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]), np.array([(0, 1, 2), (0, 2, 3)]),
                name="own_quad")


@pytest.mark.parametrize("batches", ["two", "one"])
def test_glass_behind_glass_shows_through_it(scene, batches):
    """Two panes of index 1 that reflect nothing, one behind the other and offset so they
    overlap on screen: each multiplies what it lets through by its colour, so through both
    the room shows times both colours (the nearer pane's copy holds the farther pane: they are
    drawn in two layers, ``refraction_layers``), through one times its own, elsewhere as drawn
    without them; the pixels each pane covers found by casting the pixel rays at the panes in
    numpy.  "one": panes of one mesh (one batch, its colours its instances' own), drawn a
    layer each as runs of its rows; "two": the farther one a larger square of its own mesh (a
    batch of its own)."""
    near_tint, far_tint = np.array([0.4, 0.7, 1.0]), np.array([1.0, 0.6, 0.3])
    near_at, far_at = np.array([0.3, 1.1, 1.5]), np.array([-0.6, 0.9, 0.0])
    halves = {"near": 0.6, "far": 0.6 if batches == "one" else 0.7}

    def without(world):
        look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
        room(world)

    def with_panes(world):
        without(world)
        mesh = quad(1.2, 1.2)
        tinted_pane(world, tuple(far_at), far_tint, mesh if batches == "one" else own_quad(1.4))
        tinted_pane(world, tuple(near_at), near_tint, mesh)

    drawn = frame(scene, without)
    runner, seen = framed(scene, with_panes)
    stats = runner.engine.renderer.stats
    assert stats.refraction_layers == 2 and stats.refraction_layers_cut == 0
    assert len(runner.engine.renderer.refracting_batches()) == (1 if batches == "one" else 2)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)

    def covers(centre, half, margin):  # rays meeting the pane's square (z = its plane) within margin of its edge
        t = (centre[2] - eye[2]) / rays[..., 2]
        hit = eye + t[..., None] * rays
        inside = (np.abs(hit[..., 0] - centre[0]) < half - margin) & (np.abs(hit[..., 1] - centre[1]) < half - margin)
        outside = (np.abs(hit[..., 0] - centre[0]) > half + margin) | (np.abs(hit[..., 1] - centre[1]) > half + margin)
        return inside, outside

    near_in, near_out = covers(near_at, halves["near"], 0.03)
    far_in, far_out = covers(far_at, halves["far"], 0.03)
    both = near_in & far_in
    assert both.sum() > 300 and (near_in & far_out).sum() > 300 and (far_in & near_out).sum() > 300
    expected = drawn * np.where(near_in[..., None], near_tint, 1.0) * np.where(far_in[..., None], far_tint, 1.0)
    known = (near_in | near_out) & (far_in | far_out)
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(expected)).max(axis=-1)
    assert np.quantile(levels[known & both], 0.99) <= 3.0, np.quantile(levels[known & both], 0.99)
    assert np.quantile(levels[known], 0.99) <= 3.0 and levels[known].mean() < 0.5


def test_glass_past_the_layers_limit_is_said_and_counted(scene):
    """More refracting panes behind one another on screen than MAX_REFRACTION_LAYERS: those
    past it are drawn in the last layer, counted in RenderStats.refraction_layers_cut and
    said once (RefractionLimitWarning)."""
    from engine.core.errors import RefractionLimitWarning
    from engine.render.screen_refraction import MAX_REFRACTION_LAYERS

    def build(world):
        look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
        room(world)
        for k in range(MAX_REFRACTION_LAYERS + 2):
            tinted_pane(world, (0.0, 1.0, 1.5 - 0.4 * k), (0.9, 0.9, 0.9))

    runner = scene(build, SIZE)
    with pytest.warns(RefractionLimitWarning, match="MAX_REFRACTION_LAYERS"):
        runner.frame()
    stats = runner.engine.renderer.stats
    assert stats.refraction_layers == MAX_REFRACTION_LAYERS and stats.refraction_layers_cut == 2
    with warnings.catch_warnings():
        warnings.simplefilter("error", RefractionLimitWarning)
        runner.frame()  # (said once)
    assert runner.engine.renderer.stats.refraction_layers_cut == 2


@pytest.mark.parametrize("in_front", [False, True])
def test_see_through_things_behind_glass_show_through_it(scene, in_front):
    """A see-through green pane (alpha 0.5: the transparent slot, blended) behind a refracting
    pane of index 1 that reflects nothing: drawn before the glass, into the copy the glass
    marches (``ScenePass._slot_and_glass``), it shows through the glass as the frame drawn
    without the glass shows it.  With a second see-through pane, yellow, in front of the
    glass and over part of it, the slot is cut between them, back to front: the green pane
    before the glass, the yellow one after it, over it (``RenderStats.slot_after_glass``);
    both show as they do without the glass."""
    green_at, yellow_at = np.array([0.1, 1.0, -0.5]), np.array([-0.45, 1.0, 2.2])

    def without(world):
        look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
        room(world)
        world.spawn(Transform(position=tuple(green_at)), MeshRef(quad(1.0, 1.0)),
                    Material(color=(0.1, 0.9, 0.1, 0.5), double_sided=True))
        if in_front:
            world.spawn(Transform(position=tuple(yellow_at)), MeshRef(quad(0.3, 0.3)),
                        Material(color=(0.9, 0.9, 0.1, 0.5), double_sided=True))

    def with_glass(world):
        without(world)
        pane(world, 1.0, position=(0.0, 1.0, 1.0))

    drawn = frame(scene, without)
    runner, seen = framed(scene, with_glass)
    assert (runner.engine.renderer.stats.slot_after_glass > 0) == in_front
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)

    glass = on_quad(eye, rays, np.array([0.0, 1.0, 1.0]), 0.75)
    green = on_quad(eye, rays, green_at, 0.45) & glass & ~on_quad(eye, rays, yellow_at, 0.17)
    assert green.sum() > 500
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(drawn)).max(axis=-1)
    assert np.quantile(levels[green], 0.99) <= 2.0, np.quantile(levels[green], 0.99)
    if in_front:  # (over the glass: blended after it)
        yellow = on_quad(eye, rays, yellow_at, 0.13) & glass
        assert yellow.sum() > 50 and np.quantile(levels[yellow], 0.99) <= 2.0, (yellow.sum(), levels[yellow].max())


def test_a_see_through_thing_behind_glass_goes_before_one_in_front_of_other_glass_apart_on_screen(scene):
    """Two refracting panes of index 1, one far on the left with a yellow see-through square
    in front of it, one near on the right with a green one behind it; the green square is
    nearer the eye than the yellow, so it comes after it in the slot's order, but the two are
    apart on screen (they blend in either order): the green is drawn before the glass and
    shows through the near pane, the yellow after, over the far one; both as without the
    panes (``ScenePass._slot_before``)."""
    yellow_at, green_at = np.array([-0.9, 1.0, 0.5]), np.array([0.9, 1.0, 1.9])

    def without(world):
        two_squares(world, yellow_at, 0.4, green_at, 0.3, (0.1, 0.9, 0.1))

    def with_glass(world):
        without(world)
        small_pane(world, (-0.9, 1.0, 0.0), 0.9)
        small_pane(world, (0.9, 1.0, 2.5), 0.6)

    drawn = frame(scene, without)
    runner, seen = framed(scene, with_glass)
    assert runner.engine.renderer.stats.slot_after_glass > 0
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)

    green = on_quad(eye, rays, green_at, 0.13) & on_quad(eye, rays, np.array([0.9, 1.0, 2.5]), 0.28)
    yellow = on_quad(eye, rays, yellow_at, 0.18) & on_quad(eye, rays, np.array([-0.9, 1.0, 0.0]), 0.43)
    assert green.sum() > 50 and yellow.sum() > 50, (green.sum(), yellow.sum())
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(drawn)).max(axis=-1)
    assert np.quantile(levels[green], 0.99) <= 2.0, np.quantile(levels[green], 0.99)
    assert np.quantile(levels[yellow], 0.99) <= 2.0, np.quantile(levels[yellow], 0.99)


def test_a_see_through_thing_that_covers_one_drawn_after_the_glass_is_drawn_after_it(scene):
    """A yellow see-through square in front of a small far pane (so drawn after the glass) and
    a green one nearer, behind a small near pane, over part of the yellow on screen: the
    green must blend over the yellow, so it is drawn after the glass too, in its order, and
    where the two overlap outside the near pane they show as without the panes (drawn before
    the glass, the green would lie under the yellow there)."""
    yellow_at, green_at = np.array([-0.2, 1.0, -0.5]), np.array([0.25, 1.0, 1.5])

    def without(world):
        two_squares(world, yellow_at, 1.0, green_at, 0.3, (0.1, 0.3, 0.9))

    def with_glass(world):
        without(world)
        small_pane(world, (-0.6, 1.0, -1.0), 0.4)
        small_pane(world, (0.5, 1.0, 2.5), 0.3)

    drawn = frame(scene, without)
    runner, seen = framed(scene, with_glass)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)

    both = on_quad(eye, rays, green_at, 0.13) & on_quad(eye, rays, yellow_at, 0.48) \
        & ~on_quad(eye, rays, np.array([0.5, 1.0, 2.5]), 0.17)  # (outside the near pane)
    assert both.sum() > 20, both.sum()
    levels = np.abs(linear_to_srgb8(seen) - linear_to_srgb8(drawn)).max(axis=-1)
    assert np.quantile(levels[both], 0.99) <= 2.0, np.quantile(levels[both], 0.99)


@pytest.mark.parametrize("path,with_square", [("per_mirror", True), ("batched", True), ("batched", False)])
def test_the_slot_is_cut_about_the_glass_thing_by_thing_in_every_view(scene, path, with_square):
    """A refracting pane of index 1 that reflects nothing, a mirror behind it, and the slot on
    both sides of the pane: a spark and a green see-through square behind it, a second spark
    in front of it, over it.  Seen from the camera the slot is cut between them (the far two
    before the glass, the near spark after); seen in the mirror, from behind, the other way
    about.  Every one of them shows, in the camera's view and in the mirror's, as it does
    without the pane (per-mirror and batched reflection levels; the sparks alone too, the
    slot's particles-only draw)."""
    from components import ParticleEmitter
    from engine.assets.texture_data import TextureData

    white = TextureData(np.full((4, 4, 4), 255, np.uint8), name="white")
    sparks = [glm.vec3(0.25, 1.0, -0.6), glm.vec3(-0.35, 1.25, 0.7)]
    square = glm.vec3(-0.3, 0.75, -0.5)

    def build(glass):
        def make(world):
            look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
            room(world)
            world.spawn(Transform(position=(0.0, 1.0, -2.5)), MeshRef(quad(6.0, 4.0)), Mirror())
            if with_square:
                world.spawn(Transform(position=tuple(square)), MeshRef(quad(0.3, 0.3)),
                            Material(color=(0.1, 0.9, 0.1, 0.5), double_sided=True))
            for at in sparks:
                world.spawn(Transform(position=at), ParticleEmitter(
                    rate=0.0, burst=1, speed=0.0, lifetime=1000.0, angle=(0.0, 0.0), size=0.2, texture=white,
                    color=(1.0, 0.3, 0.6, 1.0), end_color=(1.0, 0.3, 0.6, 1.0)))
            if glass:
                pane(world, 1.0, position=(0.0, 1.0, 0.0))
        return make

    frames = []
    for glass in (False, True):
        runner = scene(build(glass), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        runner.frame()
        frames.append(runner.frame().astype(int))
    assert runner.engine.renderer.stats.slot_after_glass >= 1
    levels = np.abs(frames[1] - frames[0]).max(axis=-1)
    for at in [*sparks, square] if with_square else sparks:
        for seen in (at, glm.vec3(at.x, at.y, -5.0 - at.z)):  # (its image in the mirror at z = -2.5)
            col, row = runner.project(seen)
            assert levels[row - 1:row + 2, col - 1:col + 2].max() <= 3, (path, at, seen, levels[row - 1:row + 2,
                                                                                               col - 1:col + 2])


def test_the_layers_put_each_glass_after_the_farther_glass_it_meets_on_screen(monkeypatch):
    """``refraction_layers`` on random boxes (no GL): every instance lies in a later layer
    than each farther instance whose widened rectangle meets its own, up to the layers'
    limit (those past it counted as cut); the runs cover every row once; the plain-Python
    ordering of a few instances and numpy's of many give the same layers."""
    from engine.render import screen_refraction as sr

    class Boxes:  # (what refraction_layers reads of a batch)
        def __init__(self, boxes):
            self.row_boxes, self.count = boxes, len(boxes)

    eye = glm.vec3(0.0, 1.0, 6.0)
    view = dataclasses.make_dataclass("V", ["scissor", "eye", "view_proj"])(
        None, eye, glm.perspective(1.0, 1.6, 0.1, 100.0) * glm.lookAt(eye, glm.vec3(0, 1, 0), glm.vec3(0, 1, 0)))
    rng = np.random.default_rng(7)
    for n in (2, 9, 40):
        centres = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-1, 3, n), rng.uniform(-6, 3, n)])
        k = max(n // 3, 1)
        batches = [Boxes(np.stack([centres[:k] - 0.3, centres[:k] + 0.3], axis=1)),
                   Boxes(np.stack([centres[k:] - 0.3, centres[k:] + 0.3], axis=1))]
        layers = sr.refraction_layers(view, SIZE, batches)
        layer_of = {}
        for k_layer, runs in enumerate(layers.runs):
            for batch, first, past in runs:
                for row in range(first, past):
                    assert (id(batch), row) not in layer_of
                    layer_of[id(batch), row] = k_layer
        assert len(layer_of) == n
        rows = [(id(b), r) for b in batches for r in range(b.count)]
        boxes = np.concatenate([b.row_boxes for b in batches])
        drawn = sr.box_rects(view, SIZE, boxes)
        reach = (drawn[:, 2:] - drawn[:, :2]) * sr.LAYER_REACH
        rects = np.concatenate([drawn[:, :2] - reach, drawn[:, 2:] + reach], axis=1)
        distance = np.linalg.norm(boxes.mean(axis=1) - np.array(eye), axis=1)
        for i in range(n):
            for j in range(n):
                meets = rects[i, 0] < rects[j, 2] and rects[j, 0] < rects[i, 2] and \
                    rects[i, 1] < rects[j, 3] and rects[j, 1] < rects[i, 3]
                if i != j and meets and distance[j] > distance[i] and layer_of[rows[j]] < sr.MAX_REFRACTION_LAYERS - 1:
                    assert layer_of[rows[i]] > layer_of[rows[j]], (n, i, j)
        monkeypatch.setattr(sr, "LAYOUT_IN_PYTHON", 0 if n <= 24 else 10 ** 6)
        other = sr.refraction_layers(view, SIZE, batches)
        monkeypatch.undo()
        assert [[(id(b), f, p) for b, f, p in runs] for runs in other.runs] == \
            [[(id(b), f, p) for b, f, p in runs] for runs in layers.runs] and other.cut == layers.cut


def test_glass_reflects_what_its_view_drew(scene):
    """A pane of index 1.5 turned 60 degrees and a red box (unlit) off to its side, in the
    view: the pane's own reflection is the screen's where its reflected ray finds what the
    view drew (a refracting surface's screen-space reflection, along the same march as what
    it lets through), so the pixels whose rays, reflected at the pane's plane in numpy, meet
    the box are redder than in the same frame without the box, by about the pane's Fresnel
    reflectance there times the red it adds over the grey wall it reflected instead; the
    pane's other pixels (those whose rays refracted through it miss the box too) are not."""
    turn = np.radians(60.0)
    box_at, box_half = np.array([1.9, 1.0, -1.2]), np.array([0.35, 0.5, 0.35])

    def build(with_box):
        def make(world):
            look_from(world, (0.0, 1.2, 4.0), (0.4, 1.0, 0.0), fov=50.0)
            world.spawn(Skybox())
            world.spawn(Transform(position=(0.0, 1.0, -4.0)), MeshRef(box((12.0, 6.0, 0.1))),
                        Material(color=(0.3, 0.3, 0.3, 1.0), unlit=True))
            if with_box:
                world.spawn(Transform(position=tuple(box_at)), MeshRef(box(tuple(2.0 * box_half))),
                            Material(color=(1.0, 0.0, 0.0, 1.0), unlit=True))
            world.spawn(Transform(position=(0.0, 1.0, 0.0), rotation=glm.quat(glm.vec3(0.0, float(turn), 0.0))),
                        MeshRef(quad(1.6, 1.6)), Material(color=(1.0, 1.0, 1.0, 0.0), roughness=0.0),
                        Refractive(ior=1.5))
        return make

    runner, seen = framed(scene, build(True))
    without = frame(scene, build(False))
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    normal = np.array([np.sin(turn), 0.0, np.cos(turn)])
    right = np.array([np.cos(turn), 0.0, -np.sin(turn)])
    centre = np.array([0.0, 1.0, 0.0])
    t = ((centre - eye) @ normal) / (rays @ normal)
    hit = eye + t[..., None] * rays
    on_pane = (t > 0) & (np.abs((hit - centre) @ right) < 0.72) & (np.abs(hit[..., 1] - 1.0) < 0.72)
    flat, at = rays.reshape(-1, 3), hit.reshape(-1, 3)
    cos_i = np.abs(flat @ normal)
    facing = np.where((flat @ normal)[:, None] < 0.0, normal, -normal)
    reflected = flat + 2.0 * cos_i[:, None] * facing
    eta = 1.0 / 1.5
    bent = eta * flat + (eta * cos_i - np.sqrt(1.0 - eta ** 2 * (1.0 - cos_i ** 2)))[:, None] * facing
    meets = box_hits(at, reflected, box_at, box_half).reshape(on_pane.shape)
    through = box_hits(at, bent, box_at, box_half).reshape(on_pane.shape)
    shows_box, shows_none = on_pane & meets & ~through, on_pane & ~meets & ~through
    assert shows_box.sum() > 100 and shows_none.sum() > 300, (shows_box.sum(), shows_none.sum())
    redder = (seen[..., 0] - without[..., 0])
    fresnel = (0.04 + 0.96 * (1.0 - cos_i) ** 5).reshape(on_pane.shape)   # Schlick's, F0 of index 1.5
    share = np.median(redder[shows_box] / (0.7 * fresnel[shows_box]))
    assert 0.3 < share < 1.5, share  # (the split sum's weight is not quite Schlick's)
    assert np.quantile(np.abs(redder[shows_none]), 0.9) < 0.01


def _box_distance(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    """How far along each ray (rows) it enters the box (the slab test); inf where it misses."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (centre - half - origin) / direction, (centre + half - origin) / direction
    near, far = np.nanmax(np.minimum(t1, t2), axis=1), np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((near <= far) & (far > 1e-6), np.maximum(near, 0.0), np.inf)


def test_a_balls_reflection_reads_the_screen_only_where_its_pixels_rays_stay_close(scene):
    """A black glass ball of index 1.5 (what it lets through hidden: its colour's alpha 1,
    so the pixel is its reflection) with a red box (unlit) close beside it and a wall of
    white bars far behind: where a pixel's reflected ray, cast in numpy, meets the box and its
    neighbours' rays land within a copy pixel or so of it there, the ball reflects the red
    the view drew; where a pixel's ray meets the wall and its neighbours' land more than 8 of
    the wall's pixels apart (towards its rim, where the ball's reflection is minified most),
    one texel of the copy, a bar or the gap between, would be noise (``REFRACTION_SPREAD``,
    4 pixels), so the ball reflects what it does without the screen (``Refractive.screen``
    False: its probe's capture, read at the mip level of that footprint) instead."""
    centre, radius = np.array([0.0, 1.0, 0.0]), 0.8
    box_at, box_half = np.array([0.95, 1.0, 0.75]), np.array([0.25, 0.5, 0.25])
    wall_z = -3.0

    def build(screen, with_box=True):
        def make(world):
            look_from(world, (0.0, 1.2, 4.0), (0.3, 1.0, 0.0), fov=50.0)
            world.spawn(Skybox())
            world.spawn(Transform(position=(0.0, 1.0, wall_z)), MeshRef(box((12.0, 6.0, 0.1))),
                        Material(color=(0.0, 0.05, 0.0, 1.0), unlit=True))
            for x in np.arange(-5.75, 6.0, 0.5):  # white bars a quarter metre wide on it
                world.spawn(Transform(position=(float(x), 1.0, wall_z + 0.1)), MeshRef(box((0.25, 6.0, 0.1))),
                            Material(color=(1.0, 1.0, 1.0, 1.0), unlit=True))
            if with_box:
                world.spawn(Transform(position=tuple(box_at)), MeshRef(box(tuple(2.0 * box_half))),
                            Material(color=(1.0, 0.0, 0.0, 1.0), unlit=True))
            world.spawn(Transform(position=tuple(centre)), MeshRef(sphere(radius, 128, 64)),
                        Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.0), Refractive(ior=1.5, screen=screen))
        return make

    runner, seen = framed(scene, build(True))
    plain = frame(scene, build(False))
    view = runner.engine.main_view
    eye, rays = pixel_rays(view, SIZE)
    # The nearer meeting of each pixel's ray with the ball, unless the box is in front.
    along = eye - centre
    b = rays @ along
    disc = b * b - (along @ along - radius * radius)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    eyes = np.broadcast_to(eye, rays.shape).reshape(-1, 3)
    on_ball = (disc > 0.0) & (_box_distance(eyes, rays.reshape(-1, 3), box_at, box_half).reshape(t.shape) > t)
    hit = eye + t[..., None] * rays
    normal = (hit - centre) / radius
    cos_i = -np.sum(rays * normal, axis=-1)
    reflected = rays + 2.0 * cos_i[..., None] * normal
    to_box = _box_distance(hit.reshape(-1, 3), reflected.reshape(-1, 3), box_at, box_half).reshape(t.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        to_wall = np.where(reflected[..., 2] < 0.0, (wall_z + 0.05 - hit[..., 2]) / reflected[..., 2], np.inf)
    way = np.minimum(to_box, to_wall)
    # How far apart, in pixels where it lands, the reflected rays of a pixel and its next
    # neighbours land (the rays' turn from one pixel to the next times the way).
    turn = np.full(t.shape, np.inf)
    turn[:-1, :-1] = np.maximum(np.linalg.norm(reflected[1:, :-1] - reflected[:-1, :-1], axis=-1),
                                np.linalg.norm(reflected[:-1, 1:] - reflected[:-1, :-1], axis=-1))
    to_view = np.array(view.view.to_list(), np.float64).T
    landed = hit + np.where(np.isfinite(way), way, 0.0)[..., None] * reflected
    depth = -(landed @ to_view[2, :3] + to_view[2, 3])
    apart = turn * way * float(view.proj[1][1]) * 0.5 * SIZE[1] / depth
    # (each pixel and its four neighbours on the ball; what it lands on in the view)
    inside = on_ball.copy()
    inside[1:-1, 1:-1] &= on_ball[:-2, 1:-1] & on_ball[2:, 1:-1] & on_ball[1:-1, :-2] & on_ball[1:-1, 2:]
    clip = np.concatenate([landed, np.ones(t.shape + (1,))], axis=-1) @ np.array(view.view_proj.to_list()).T.T
    in_view = (clip[..., 3] > 0.0) & np.all(np.abs(clip[..., :2] / clip[..., 3:]) < 0.95, axis=-1)
    close = inside & in_view & (to_box < to_wall) & (apart < 1.5)
    # (on the ball's side away from the box: a ray that passes close behind the box on screen
    # is taken to meet it, REFRACTION_THICKNESS)
    away = (hit[..., 0] < centre[0]) & (np.abs(landed[..., 1] - 1.0) < 3.0)
    spread = inside & in_view & away & (to_wall < to_box) & (apart > 8.0)
    assert close.sum() > 40 and spread.sum() > 10, (close.sum(), spread.sum())
    redder = seen[..., 0] - plain[..., 0]
    fresnel = 0.04 + 0.96 * (1.0 - cos_i) ** 5   # Schlick's, F0 of index 1.5
    share = np.median(redder[close] / (0.7 * fresnel[close]))
    assert 0.3 < share < 1.5, share
    off = np.abs(seen - plain).max(axis=-1)[spread]
    assert np.quantile(off, 0.9) < 0.02, np.sort(off)


@pytest.mark.parametrize("depth", [0, 1])
def test_a_monitors_picture_bends_what_is_behind_a_pane_as_the_cameras_view_does(scene, depth):
    """A monitor's camera where the active camera stands, before the tilted pane of index 1.5
    and the red stripe (a world with no mirror or portal; the monitor's ``depth`` 0 or 1): its
    picture's middle row shows the stripe where the rays refracted in numpy meet it, as the
    camera's view does (``test_a_tilted_pane_bends_what_is_behind_it_as_snells_law_says``), and
    equals the frame's own middle row, both drawn by the scene pass and ``finish_root``."""
    from components import Monitor

    turn = np.radians(35.0)
    stripe_half = np.array([0.08, 1.5, 0.02])
    size = (200, 100)
    held = {}

    def build(world):
        striped_wall(world, np.array([0.0, 1.0, -2.9]), stripe_half, fov=40.0)
        pane(world, 1.5, position=(0.0, 1.0, 1.0), turn=float(turn))
        lens = look_from(world, (0.0, 1.0, 4.0), (0.0, 1.0, 0.0), fov=40.0)
        world.get(lens, Camera).active = False
        held["screen"] = world.spawn(Transform(position=(0.0, 1.0, 8.0)), MeshRef(quad(1.6, 0.8)),
                                     Material(color=(0.0, 0.0, 0.0, 1.0), **CLEAR),
                                     Monitor(camera=lens, size=size, depth=depth))

    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame())[size[1] // 2]
    picture = runner.engine.renderer.monitors.read(held["screen"])[size[1] // 2, :, :3]
    eye, rays = pixel_rays(runner.engine.main_view, size)
    d = rays[size[1] // 2]
    normal = np.array([np.sin(turn), 0.0, np.cos(turn)])     # the quad's +z turned about y
    right = np.array([np.cos(turn), 0.0, -np.sin(turn)])
    centre = np.array([0.0, 1.0, 1.0])
    t = ((centre - eye) @ normal) / (d @ normal)
    hit = eye + t[:, None] * d
    through = (t > 0) & (np.abs((hit - centre) @ right) < 0.75)
    eta = 1.0 / 1.5
    cos_i = -(d @ normal)
    bent = eta * d + (eta * cos_i - np.sqrt(1.0 - eta ** 2 * (1.0 - cos_i ** 2)))[:, None] * normal
    expected = box_hits(hit, bent, np.array([0.0, 1.0, -2.9]), stripe_half) & through
    assert expected.sum() >= 3
    red = (picture[:, 0] > 0.5) & (picture[:, 1] < 0.2)
    assert (red[through] != expected[through]).sum() <= 2, (np.flatnonzero(red), np.flatnonzero(expected))
    # (the frame is tone-mapped and 8-bit: the picture, linear and half-float, within that)
    np.testing.assert_allclose(linear_to_srgb8(np.clip(picture, 0.0, 1.0)).astype(float),
                               linear_to_srgb8(np.clip(shown, 0.0, 1.0)).astype(float), atol=3)


@pytest.mark.parametrize("depth", [0, 1])
def test_a_probe_face_shows_what_is_behind_a_pane_as_it_drew_it(scene, depth):
    """A probe behind a pane of index 1 (a world with no mirror or portal; the probe's
    ``depth`` 0 or 1): its -Z face, which looks through the pane at the room, is the face
    drawn without the pane (the face is finished as a root is and the pane marches its copy,
    ``ProbeCaptures._finished``), where the pane refracting the probe's or sky's image alone
    (``screen=False``) shows the sky over the red post and the blue block."""
    from components import ReflectionProbe
    from engine.core.cube_faces import FACE_NAMES

    face = FACE_NAMES.index("-Z")

    def captured(with_pane: bool, screen: bool = True) -> np.ndarray:
        held = {}

        def build(world):
            look_from(world, (0.0, 1.2, 4.0), (0.0, 1.0, 0.0), fov=50.0)
            room(world)
            if with_pane:
                pane(world, 1.0, screen, tint=TINT)
            held["probe"] = world.spawn(Transform(position=(0.0, 1.0, 2.5)),
                                        ReflectionProbe(resolution=64, depth=depth, refresh="once"))

        runner, _ = framed(scene, build)
        return runner.engine.renderer.probes.read_face(held["probe"], face)[..., :3].astype(np.float64)

    drawn, seen, sky_only = captured(False), captured(True), captured(True, screen=False)
    covered = np.abs(sky_only - drawn).max(axis=-1) > 0.05   # where the pane hides the room without the march
    assert covered.sum() > 300, covered.sum()
    assert_tinted(seen, drawn, covered)


@pytest.mark.parametrize("face", range(6))
def test_every_face_of_a_probe_shows_what_is_behind_a_pane_as_it_drew_it(scene, face):
    """Each cube face in turn looks through a pane of index 1 at a red and a blue block before
    a grey wall (all set along the face's axis from the probe, the camera looking elsewhere):
    the face is the face drawn without the pane, where the pane refracting the probe's or
    sky's image alone (``screen=False``) shows the sky.  Faces drawn as a root once marched
    only in face 0 (+X): a face view's node was its face, the root's node image all 0."""
    from components import ReflectionProbe
    from engine.core.cube_faces import CUBE_FACES

    forward, right, up = (np.array(axis) for axis in CUBE_FACES[face])
    at = np.array([0.0, 3.0, 0.0])

    def floats(v) -> tuple[float, ...]:
        return tuple(float(x) for x in v)

    def spawn_box(world, centre, half, colour):
        world.spawn(Transform(position=floats(centre)), MeshRef(box(floats(2.0 * np.abs(half) + 0.02))),
                    Material(color=(*colour, 1.0)))

    def captured(with_pane: bool, screen: bool = True) -> np.ndarray:
        held = {}

        def build(world):
            look_from(world, floats(at - 6.0 * forward + 0.5 * up), floats(at - 9.0 * forward), fov=50.0)
            world.spawn(Skybox())
            world.spawn(DirectionalLight(direction=floats(forward - up * 0.5), intensity=2.0))
            spawn_box(world, at + 4.0 * forward, 1.8 * (np.abs(right) + np.abs(up)), (0.5, 0.5, 0.5))
            spawn_box(world, at + 2.5 * forward + 0.4 * right, 0.15 * (np.abs(right) + np.abs(up) + np.abs(forward)),
                      (0.9, 0.1, 0.1))
            spawn_box(world, at + 2.5 * forward - 0.4 * right - 0.3 * up,
                      0.2 * (np.abs(right) + np.abs(up) + np.abs(forward)), (0.1, 0.2, 0.9))
            if with_pane:
                world.spawn(Transform(position=floats(at + 1.0 * forward), rotation=look_rotation(floats(forward))),
                            MeshRef(quad(1.4, 1.4)),
                            Material(color=(TINT, TINT, TINT, 0.0), double_sided=True, **CLEAR),
                            Refractive(ior=1.0, screen=screen))
            held["probe"] = world.spawn(Transform(position=floats(at)),
                                        ReflectionProbe(resolution=32, depth=0, refresh="once"))

        runner, _ = framed(scene, build, (32, 24))
        return runner.engine.renderer.probes.read_face(held["probe"], face)[..., :3].astype(np.float64)

    drawn, seen, sky_only = captured(False), captured(True), captured(True, screen=False)
    covered = np.abs(sky_only - drawn).max(axis=-1) > 0.05   # where the pane hides the blocks and the wall, unmarched
    assert covered.sum() > 100, covered.sum()
    assert_tinted(seen, drawn, covered)
