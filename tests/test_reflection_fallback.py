"""The reflection fallback chain (issue 36 item 4): a mirror or portal seen with no view of its
own (cut by the view budget, faded out, past the depth limit) shows the reflection its surface
would get from the probe whose influence box holds it, else the sky, at its reflect rate and
tint, never its bare material; a partly faded mirror mixes its view and that fallback.

Every expected colour is worked out here in numpy, apart from the renderer: each pixel's ray
from the main view's matrices, reflected in the mirror's plane, the generated sky's formula
(``engine.render.sky.sky_radiance``) or the probe's faces read back and looked up by the cube
face table, Schlick's Fresnel with the tint as F0 (the composite's GGXReflect at roughness 0),
then the sRGB encoding."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    ReflectionProbe,
    Reflective,
    Skybox,
    Transform,
)
from engine.assets.mesh import box, quad, sphere
from engine.assets.portals import spawn_portal_pair
from engine.core.cube_faces import CUBE_FACES
from engine.core.world import World
from engine.render.mirror_passes import MirrorPasses
from engine.render.sky import sky_radiance
from engine.resources import ViewBudget
from engine.rules.light_rules import SkySun
from tests.support import linear_to_srgb8, look_from, srgb_to_linear

SIZE = (160, 120)
EYE = (0.0, 2.2, 2.6)
TINT = (0.95, 0.85, 1.0)
FACING_UP = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))  # a quad's +Z turned to +Y
MATERIAL = (0.6, 0.08, 0.08)  # the mirror's own colour: red, far from the sky's
SUN_LIGHT = (0.3, -1.0, -0.4)  # the way the sun's light travels: the sky's sun stands against it
SKY_SUN = SkySun(tuple(-glm.normalize(glm.vec3(SUN_LIGHT))))


def _floor_mirror(ents: dict, mirror: Mirror, budget: ViewBudget | None = None, probe: bool = False,
                  eye=EYE):
    """A 3 x 3 mirror on the floor facing up, seen from above at a slant, so its reflections
    look up into the sky (smooth there, away from the horizon); a grey crate beside it for the
    views to show.  With ``probe``, a probe above the mirror whose box holds it, under an orange
    glowing ceiling, so the probe's reflection differs from the sky's."""
    def build(world) -> None:
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=SUN_LIGHT, intensity=1.5))
        ents["camera"] = look_from(world, eye, target=(0.0, 0.0, 0.0), fov=50.0)
        ents["mirror"] = world.spawn(Transform(rotation=FACING_UP), MeshRef(quad(3.0, 3.0)),
                                     Material(color=MATERIAL), mirror)
        world.spawn(Transform(position=(0.0, 0.5, -2.2)), MeshRef(box()), Material(color=(0.5, 0.5, 0.5)))
        if probe:
            ents["probe"] = world.spawn(Transform(position=(0.0, 1.0, 0.0)),
                                        ReflectionProbe(resolution=32, refresh="once", influence=(6.0, 6.0, 6.0)))
            world.spawn(Transform(position=(0.0, 3.0, 0.0), rotation=glm.angleAxis(math.pi / 2, glm.vec3(1, 0, 0))),
                        MeshRef(quad(30.0, 30.0)), Material(color=(1.0, 0.45, 0.1)), Emissive(1.0))
        if budget is not None:
            world.resources[ViewBudget] = budget
    return build


def _render(scene, build, frames: int = 2):
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"  # each pixel its own
    for _ in range(frames):
        image = runner.frame()
    return runner, image


def _rays(runner) -> np.ndarray:
    """(h, w, 3) unit world directions of each pixel's ray (row 0 at the top), float64."""
    view = runner.engine.main_view
    inverse = np.array(glm.inverse(view.view_proj).to_list(), np.float64).T
    w, h = SIZE
    x = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    y = 1.0 - (np.arange(h) + 0.5) / h * 2.0
    ndc = np.stack(np.broadcast_arrays(x[None, :], y[:, None], 1.0, 1.0), axis=-1)
    far = ndc @ inverse.T
    d = far[..., :3] / far[..., 3:4] - np.array(view.eye, np.float64)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _mirror_pixels(runner, entity: int, margin: int = 2) -> np.ndarray:
    """(h, w) bool: the pixels where the main view drew the mirror (or portal), ``margin``
    pixels in from its edges."""
    mask = runner.engine.renderer.targets.read_surface_ids() == entity
    inner = mask.copy()
    for dy in range(-margin, margin + 1):
        for dx in range(-margin, margin + 1):
            inner &= np.roll(np.roll(mask, dy, axis=0), dx, axis=1)
    return inner


def _fresnel(reflected: np.ndarray, normal: np.ndarray, f0) -> np.ndarray:
    """Schlick's Fresnel with ``f0`` (the tint) at the angle of ``reflected`` to ``normal``."""
    cosine = np.clip((reflected * normal).sum(axis=-1, keepdims=True), 0.0, 1.0)
    f0 = np.asarray(f0, np.float64)
    return f0 + (1.0 - f0) * (1.0 - cosine) ** 5


def _reflected_sky(runner, rate: float = 1.0, own: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """What the floor mirror's fallback is, by the formulas: per pixel the sky along the ray
    reflected in y = 0, times Fresnel (tint as F0) and the reflect rate, over ``own`` (the
    mirror's own shading, linear) x (1 - rate); and the reflected directions."""
    rays = _rays(runner)
    normal = np.array([0.0, 1.0, 0.0])
    reflected = rays - 2.0 * (rays * normal).sum(axis=-1, keepdims=True) * normal
    radiance = _fresnel(reflected, normal, TINT) * sky_radiance(Skybox(), reflected, sun=SKY_SUN)
    expected = rate * radiance + (0.0 if own is None else (1.0 - rate) * own)
    return expected, reflected


def _away_from_the_sun(reflected: np.ndarray) -> np.ndarray:
    """Pixels whose reflection is far from the sun's glow and disc (steep there)."""
    sun = np.array(SKY_SUN.direction, np.float64)
    return (reflected @ (sun / np.linalg.norm(sun))) < 0.8


CUTS = {
    "budget": dict(budget=ViewBudget(views=0)),                 # the frame's view budget has no views
    "faded": dict(mirror=dict(fade_distance=(0.2, 0.8))),      # past the end of its distance fade
    "depth": dict(mirror=dict(max_depth=0)),                    # its own depth limit allows no view
    "switched_off": dict(mirror=dict(enabled=False)),
}


@pytest.mark.parametrize("cut", list(CUTS))
def test_a_mirror_without_its_view_shows_the_skys_reflection(scene, cut):
    """Cut by the budget, faded out, past its depth limit or switched off: the mirror's pixels
    are the sky along each pixel's reflected ray, at the tint's Fresnel and the reflect rate,
    over its own shading by the rest; not its bare material."""
    how = CUTS[cut]
    ents = {}
    rate = 0.8
    runner, image = _render(scene, _floor_mirror(ents, Mirror(color=TINT, reflect_rate=rate, **how.get("mirror", {})),
                                                 how.get("budget")))
    stats = runner.stats
    assert stats.reflection_views == 0 and stats.reflection_fallbacks == 1
    if cut == "budget":
        assert stats.views_cut == 1
    if cut == "faded":
        assert stats.reflection_views_faded == 1
    mask = _mirror_pixels(runner, ents["mirror"])
    own_runner, own = _render(scene, _floor_mirror({}, Mirror(color=TINT, reflect_rate=0.0), ViewBudget(views=0)))
    expected, reflected = _reflected_sky(runner, rate, srgb_to_linear(own))
    mask &= _away_from_the_sun(reflected)
    assert mask.sum() > 2000
    difference = np.abs(image[mask].astype(float) - linear_to_srgb8(expected[mask]))
    # Within the sky cube's texels against the sky's formula (and 8-bit rounding).
    assert difference.max() <= 4.0, difference.max()
    assert difference.mean() < 1.0
    # Not the bare material: far from the mirror's own red.
    assert np.abs(image[mask].astype(float) - own[mask]).max(axis=1).mean() > 30.0


def _cube_lookup(faces: list[np.ndarray], directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each direction looked up in a cube map's faces (GL's face table, bilinear within the
    face), and whether the lookup stays a texel inside its face (no seam to filter across)."""
    d = directions.reshape(-1, 3)
    axis = np.abs(d).argmax(axis=1)
    sign = np.sign(d[np.arange(len(d)), axis])
    face = 2 * axis + (sign < 0)
    n = faces[0].shape[0]
    out = np.zeros_like(d)
    inside = np.zeros(len(d), bool)
    for f in range(6):
        at = face == f
        if not at.any():
            continue
        forward, s_axis, t_axis = (np.array(a, np.float64) for a in CUBE_FACES[f])
        major = d[at] @ forward
        s = (d[at] @ s_axis) / major
        t = (d[at] @ t_axis) / major
        col = (s + 1.0) * 0.5 * n - 0.5
        row = (t + 1.0) * 0.5 * n - 0.5
        inside[at] = (col > 0.5) & (col < n - 1.5) & (row > 0.5) & (row < n - 1.5)
        c0 = np.clip(np.floor(col).astype(int), 0, n - 2)
        r0 = np.clip(np.floor(row).astype(int), 0, n - 2)
        fc = np.clip(col - c0, 0.0, 1.0)[:, None]
        fr = np.clip(row - r0, 0.0, 1.0)[:, None]
        image = faces[f]
        out[at] = ((image[r0, c0] * (1 - fc) + image[r0, c0 + 1] * fc) * (1 - fr)
                   + (image[r0 + 1, c0] * (1 - fc) + image[r0 + 1, c0 + 1] * fc) * fr)
    return out.reshape(directions.shape), inside.reshape(directions.shape[:-1])


def test_inside_a_probes_box_a_cut_mirror_shows_the_probes_reflection(scene):
    """The mirror past its depth limit inside a probe's influence box (a view budget of no
    views would hold the probe's capture back too): its pixels are the probe's capture (its
    faces read back) along each reflected ray, at the tint's Fresnel; the same mirror outside
    every box shows the sky."""
    ents = {}
    runner, image = _render(scene, _floor_mirror(ents, Mirror(color=TINT, max_depth=0), probe=True), 3)
    assert runner.stats.reflection_fallbacks == 1
    probes = runner.engine.renderer.probes
    faces = [probes.read_face(ents["probe"], face) for face in range(6)]
    rays = _rays(runner)
    normal = np.array([0.0, 1.0, 0.0])
    reflected = rays - 2.0 * (rays * normal).sum(axis=-1, keepdims=True) * normal
    seen, inside = _cube_lookup(faces, reflected)
    expected = _fresnel(reflected, normal, TINT) * seen
    mask = _mirror_pixels(runner, ents["mirror"]) & inside
    assert mask.sum() > 2000
    difference = np.abs(image[mask].astype(float) - linear_to_srgb8(expected[mask]))
    assert difference.max() <= 4.0, difference.max()
    assert difference.mean() < 1.0
    # The probe shows the orange ceiling, not the sky: the fallback is the probe's.
    sky, _ = _reflected_sky(runner)
    assert np.abs(image[mask].astype(float) - linear_to_srgb8(sky[mask])).max(axis=1).mean() > 30.0
    # Moved out of the box (and the camera with it), the same mirror shows the sky again.
    world = runner.world
    world.get(ents["mirror"], Transform).position = glm.vec3(20.0, 0.0, 0.0)
    world.get(ents["camera"], Transform).position = glm.vec3(20.0, EYE[1], EYE[2])
    image = runner.frame()
    sky, reflected = _reflected_sky(runner)
    mask = _mirror_pixels(runner, ents["mirror"]) & _away_from_the_sun(reflected)
    assert mask.sum() > 2000
    assert np.abs(image[mask].astype(float) - linear_to_srgb8(sky[mask])).max() <= 4.0


def test_a_partly_faded_mirror_is_between_its_view_and_its_fallback(scene):
    """Halfway down its distance fade the mirror is its drawn reflection and its fallback mixed
    by the fade's weight, in linear light (no pop at either end of the fade)."""
    distance = math.dist(EYE, (0.0, 0.0, 0.0)) - math.sqrt(2.0) * 1.5  # to the mirror's bounding sphere
    fade = (distance - 1.0, distance + 1.0)  # the weight is 0.5 here
    ents = {}
    runner, faded = _render(scene, _floor_mirror(ents, Mirror(color=TINT, reflect_rate=0.8, fade_distance=fade)))
    (view,) = runner.engine.reflection_system.views[1:]
    assert view.fade == pytest.approx(0.5, abs=1e-6)
    assert runner.stats.reflection_fallbacks == 1
    _, drawn = _render(scene, _floor_mirror({}, Mirror(color=TINT, reflect_rate=0.8)))
    _, cut = _render(scene, _floor_mirror({}, Mirror(color=TINT, reflect_rate=0.8), ViewBudget(views=0)))
    mask = _mirror_pixels(runner, ents["mirror"])
    expected = linear_to_srgb8(0.5 * srgb_to_linear(drawn) + 0.5 * srgb_to_linear(cut))
    assert np.abs(faded[mask].astype(float) - expected[mask]).max() <= 2.0
    # Between the two, where they differ (the crate's reflection).
    differ = mask & (np.abs(drawn.astype(float) - cut).max(axis=2) > 30)
    assert differ.sum() > 50
    assert np.abs(faded[differ].astype(float) - drawn[differ]).max(axis=1).mean() > 10
    assert np.abs(faded[differ].astype(float) - cut[differ]).max(axis=1).mean() > 10


def test_a_drawn_mirror_is_untouched_by_the_fallback(scene, monkeypatch):
    """A mirror whose view is drawn shows no fallback: nothing is counted, and the frame is the
    same, byte for byte, with the fallback pass taken out."""
    ents = {}
    runner, image = _render(scene, _floor_mirror(ents, Mirror(color=TINT, reflect_rate=0.8, roughness=0.2)))
    assert runner.stats.reflection_views == 1 and runner.stats.reflection_fallbacks == 0
    monkeypatch.setattr(MirrorPasses, "draw_fallbacks", lambda *args, **kwargs: None)
    _, again = _render(scene, _floor_mirror({}, Mirror(color=TINT, reflect_rate=0.8, roughness=0.2)))
    assert np.array_equal(image, again)


def test_a_portal_cut_by_the_budget_shows_the_sky_beyond_its_partner(scene):
    """Portal A looks out of B, turned a quarter turn: cut by the budget, A shows the sky along
    each pixel's ray carried through the pair (B's rotation x a half turn x A's inverse), not
    its closed colour, at full weight."""
    turn = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))
    ents = {}

    def build(world) -> None:
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=SUN_LIGHT, intensity=1.5))
        look_from(world, (0.3, 1.4, 3.0), target=(0.0, 1.8, 0.0), fov=50.0)
        ents["a"], ents["b"] = spawn_portal_pair(world, (0.0, 1.5, 0.0), None, (10.0, 1.5, 0.0), turn,
                                                 size=(2.0, 2.5))
        world.resources[ViewBudget] = ViewBudget(views=0)

    runner, image = _render(scene, build)
    assert runner.stats.reflection_views == 0 and runner.stats.reflection_fallbacks == 1
    rotation = np.array(glm.mat3_cast(turn * glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))).to_list(), np.float64).T
    carried = _rays(runner) @ rotation.T
    expected = sky_radiance(Skybox(), carried, sun=SKY_SUN)
    # (Away from the sun and the horizon, where the sky's formula is steep for its cube's texels.)
    mask = _mirror_pixels(runner, ents["a"]) & _away_from_the_sun(carried) & (np.abs(carried[..., 1]) > 0.1)
    assert mask.sum() > 1000
    difference = np.abs(image[mask].astype(float) - linear_to_srgb8(expected[mask]))
    # (llvmpipe: 4.4 at most, where the ground's colour stops changing at 14 degrees down: a
    # kink the cube's texels round off.)
    assert difference.max() <= 5.0, difference.max()
    assert difference.mean() < 1.0


def test_the_overlay_says_how_many_surfaces_showed_the_fallback(scene):
    """``RenderStats.reflection_fallbacks`` in the overlay's words: the mirror cut by a view
    budget of none shows the fallback, then with no budget, its view."""
    from shell.overlay_text import overlay_lines

    runner, _ = _render(scene, _floor_mirror({}, Mirror(color=TINT), ViewBudget(views=0)))
    assert runner.stats.reflection_fallbacks == 1
    assert "reflection views 0, dropped 0, capped 0, faded 0, fallbacks 1" in overlay_lines(runner.engine, [0.02])
    del runner.world.resources[ViewBudget]
    runner.frame()
    assert runner.stats.reflection_views == 1 and runner.stats.reflection_fallbacks == 0
    assert "reflection views 1, dropped 0, capped 0, faded 0, fallbacks 0" in overlay_lines(runner.engine, [0.02])


# --- probe blending reaches curved objects ---------------------------------------------------
def _two_rooms_with_a_ball(ents: dict):
    """test_probe_blending's two rooms (A's box x in [-7, 1], B's in [-1, 7], a red wall where
    A's reflections look, a blue one for B), with a chrome ball, curved: a probe of its own."""
    from tests.test_probe_blending import two_rooms

    rooms = two_rooms(ents)

    def build(world) -> None:
        rooms(world)
        world.delete_entity(ents["quad"])
        ents["quad"] = world.spawn(Transform(), MeshRef(sphere(0.5)),
                                   Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"))
    return build


def test_a_curved_objects_blend_follows_the_boxes_with_its_own_probe_for_the_rest():
    """The rules: a chrome ball (an automatic probe) where two boxes overlap blends them by the
    oracle's weights (test_probe_blending.expected_weights: normalised past 1); in a lone box's
    falloff its own probe takes what the box leaves, in place of the sky; outside both boxes,
    its own probe alone."""
    from engine.rules.probe_rules import has_own_probe, probe_blend
    from systems.transform_system import TransformSystem
    from tests.test_probe_blending import expected_weights

    world = World("curved-blend")
    world.add_system(TransformSystem(world), priority=1)
    try:
        ents = {}
        _two_rooms_with_a_ball(ents)(world)
        ball = ents["quad"]
        for x in (-8.0, -6.6, -3.0, -0.7, 0.0, 0.4, 0.95, 3.0, 6.5, 7.5):
            world.get(ball, Transform).position = glm.vec3(x, 0.0, 0.0)
            world.step(1 / 60)
            assert has_own_probe(world, ball)
            blend = probe_blend(world, ball)
            a, b, left = expected_weights(x)
            got = dict(zip(blend.probes, blend.weights, strict=True))
            if a == b == 0.0:
                assert blend.probes == (ball,) and blend.weights == (1.0,), x
                continue
            assert got.get(ents["a"], 0.0) == pytest.approx(a, abs=1e-6), x
            assert got.get(ents["b"], 0.0) == pytest.approx(b, abs=1e-6), x
            assert blend.sky == 0.0, x
            assert blend.left == pytest.approx(left, abs=1e-6), x
            assert blend.rest == (ball if left > 0.0 else 0), x
    finally:
        world.close()


def _assert_mixed_by_the_oracles_weights(runner, ents) -> None:
    """The ball (``ents["quad"]``) in the two rooms of ``tests/test_probe_blending.py``: in the
    overlap its middle is the two rooms' colours mixed by the oracle's weights, each room's
    measured where its box alone holds the ball; in A's falloff alone (x = -6.5: A at 0.5) its
    own probe takes the other half, not the sky (its own capture, measured outside both boxes
    at x = -8, sees the red wall there too, and the sky is green)."""
    from tests.test_probe_blending import expected_weights, place

    runner.engine.stages["probes"].recapture_after_present = False  # the ball's own probe where it is now
    pure = {"a": place(runner, ents, -3.0), "b": place(runner, ents, 3.0)}
    assert pure["a"][0] > 3 * pure["a"][2] and pure["b"][2] > 3 * pure["b"][0]
    spread = np.abs(pure["a"] - pure["b"]).max()
    for x in (-0.7, -0.3, 0.0, 0.4, 0.8):
        a, b, left = expected_weights(x)
        assert abs(left) < 1e-9 and 0.0 < a < 1.0
        seen = place(runner, ents, x)
        expect = a * pure["a"] + b * pure["b"]
        assert np.abs(seen - expect).max() < 0.03 * spread + 0.004, (x, (a, b), seen, expect)
    # In A's falloff alone (x = -6.5: A at 0.5), the ball's own probe takes the other half, not
    # the sky: its own capture sees the red wall there too (measured outside both boxes, at
    # x = -8, where it is sampled alone), and the sky is green.
    a, b, left = expected_weights(-6.5)
    assert (a, b) == pytest.approx((0.5, 0.0)) and left == pytest.approx(0.5)
    own = place(runner, ents, -8.0)
    seen = place(runner, ents, -6.5)
    expect = a * pure["a"] + left * own
    assert np.abs(seen - expect).max() < 0.03 * spread + 0.004, (seen, expect)
    assert seen[1] < 0.5 * seen[0]  # no green sky in it


def test_a_curved_object_in_two_overlapping_boxes_shows_them_mixed_by_the_oracles_weights(scene):
    """The chrome ball's middle pixel (its reflection looks straight back, at the walls behind
    the camera) in the overlap is the two rooms' colours mixed by the oracle's weights, each
    room's colour measured where its box alone holds the ball at full weight; its own probe
    alone would show one wall or the other, switching at x = 0."""

    ents = {}
    runner = scene(_two_rooms_with_a_ball(ents), (64, 48))
    runner.engine.renderer.antialias = "off"
    _assert_mixed_by_the_oracles_weights(runner, ents)


def test_a_glass_ball_in_two_overlapping_boxes_refracts_them_mixed_by_the_oracles_weights(scene):
    """The glass half of "a chrome or glass object": a clear (alpha 0) solid glass ball
    (``Refractive``, ``screen=False``: its probes' images alone) with a probe of its own, walls before it as well
    as behind the camera (red where room A's probe looks through it, blue for B).  Its middle
    (the ray straight through it, and Fresnel's few percent reflected) in the overlap is the
    two rooms' colours mixed by the oracle's weights, each measured where its box alone holds
    the ball; seen directly (the ball not drawn) or through its own probe alone it would be one
    wall's colour, switching at x = 0.  In A's falloff alone its own probe takes the rest, not
    the green sky."""
    from components import Refractive
    from tests.test_probe_blending import two_rooms

    ents = {}
    rooms = two_rooms(ents)

    def build(world) -> None:
        rooms(world)
        world.delete_entity(ents["quad"])
        for x, colour in ((-6.0, (0.6, 0.05, 0.05)), (6.0, (0.05, 0.05, 0.6))):   # before the ball, facing it
            world.spawn(Transform(position=(x, 0.0, -6.0)), MeshRef(quad(12, 12)), Material(color=colour),
                        Emissive(1.0))
        ents["quad"] = world.spawn(Transform(), MeshRef(sphere(0.5)), Material(color=(1, 1, 1, 0), roughness=0.0),
                                   Refractive(ior=1.5, solid=True, screen=False))

    runner = scene(build, (64, 48))
    runner.engine.renderer.antialias = "off"
    _assert_mixed_by_the_oracles_weights(runner, ents)


def test_a_cut_water_surface_weighs_its_fallback_by_fresnel(scene):
    """Water (a still pond: no normal map) cut by the budget: the sky's reflection, tinted,
    over its own shading by Schlick's Fresnel for its index at each pixel's angle (the
    weight its drawn reflection gets), not by a fixed reflect rate."""
    from components import Water

    ior = 1.5
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
    ents = {}
    runner, image = _render(scene, _floor_mirror(ents, Mirror(color=TINT), ViewBudget(views=0)))
    world = runner.world
    world.add_component(ents["mirror"], Water(ior=ior, speed=0.0))
    image = runner.frame()
    assert runner.stats.reflection_fallbacks == 1
    _, own = _render(scene, _floor_mirror({}, Mirror(color=TINT, reflect_rate=0.0), ViewBudget(views=0)))
    rays = _rays(runner)
    normal = np.array([0.0, 1.0, 0.0])
    reflected = rays - 2.0 * (rays * normal).sum(axis=-1, keepdims=True) * normal
    cosine = np.clip(-(rays * normal).sum(axis=-1, keepdims=True), 0.0, 1.0)
    weight = f0 + (1.0 - f0) * (1.0 - cosine) ** 5
    sky = sky_radiance(Skybox(), reflected, sun=SKY_SUN)
    expected = weight * np.asarray(TINT) * sky + (1.0 - weight) * srgb_to_linear(own)
    mask = _mirror_pixels(runner, ents["mirror"]) & _away_from_the_sun(reflected)
    assert mask.sum() > 2000
    difference = np.abs(image[mask].astype(float) - linear_to_srgb8(expected[mask]))
    assert difference.max() <= 4.0, difference.max()
    assert weight[mask].max() < 0.5  # mostly its own shading: Fresnel, not the mirror's rate of 1


def test_an_end_views_pixels_its_image_does_not_hold_show_the_fallback(ctx, monkeypatch):
    """Turned round in one frame, every end view's pixels lie off last frame's image: they show
    the fallback, as the pair without end images does (the same frame, exactly), not the
    mirrors' material (what the frame is with the fallback pass taken out)."""
    from engine.rules.frame_rules import active_camera
    from tests.test_end_images import _facing_pair, _frames

    def turn(runner, frame):
        yaw = math.pi if frame < 3 else 0.0
        runner.world.get(active_camera(runner.world), Transform).rotation = glm.quat(
            glm.angleAxis(-yaw, glm.vec3(0, 1, 0)))

    counts = []
    turned, ends = _frames(ctx, _facing_pair(3), 4, turn, fxaa=False,
                           after=lambda runner: counts.append(runner.stats.reflection_fallbacks))
    closed, _ = _frames(ctx, _facing_pair(3, end_image=False), 4, turn, fxaa=False)
    assert ends[3] >= 1 and counts[0] >= ends[3]  # each end view's holes are a fallback
    assert np.array_equal(turned[3], closed[3])
    monkeypatch.setattr(MirrorPasses, "draw_fallbacks", lambda *args, **kwargs: None)
    bare, _ = _frames(ctx, _facing_pair(3), 4, turn, fxaa=False)
    assert (np.abs(bare[3] - turned[3]).max(axis=2) > 10).sum() >= 100


def test_a_mirror_inside_one_uncovered_this_frame_shows_its_fallback_in_predicted_mode(scene, monkeypatch):
    """Predicted visibility: the views inside a mirror uncovered this frame wait a frame
    (tests/test_predicted_visibility.py); meanwhile the facing mirror seen in it shows its
    fallback, not its material: the frame differs from the one drawn with the fallback pass
    taken out, and only inside the uncovered mirror."""
    from tests.test_predicted_visibility import _covered_mirrors

    frames = []
    for fallback in (True, False):
        if not fallback:
            monkeypatch.setattr(MirrorPasses, "draw_fallbacks", lambda *args, **kwargs: None)
        ents: dict = {}
        runner = scene(lambda world, ents=ents: _covered_mirrors(world, ents, True), (200, 150))
        runner.engine.reflection_system.visibility = "predicted"
        runner.engine.renderer.antialias = "off"
        for _ in range(3):
            runner.frame()
        runner.world.get(ents["cover"], Transform).position = (0.0, 1.5, 30.0)
        frames.append(runner.frame().astype(float))
        if fallback:
            assert runner.stats.reflection_views_unseen >= 1 and runner.stats.reflection_fallbacks >= 1
            in_mirror = runner.engine.renderer.targets.read_surface_ids() == ents["mirror"]
    differs = np.abs(frames[0] - frames[1]).max(axis=2) > 10
    assert differs.sum() > 50 and not (differs & ~in_mirror).any()


# --- the transparent slot over a fallback ------------------------------------------------------
SLOT_SIZE = (96, 72)
BEHIND = glm.angleAxis(math.pi, glm.vec3(0, 1, 0))  # a quad turned to face -z


def _slot_things(world, ents: dict, case: str) -> None:
    """A pane of red emissive glass (alpha 0.5) and a lit blue ribbon (a trail of a prewarmed
    emitter blowing along x, alpha 0.7) in front of the cut surface as the view showing it sees
    it: over the floor mirror, seen by the camera ("mirror"); between the camera and the
    portal ("portal"); behind the camera, over the mirror it faces, seen only in the mirror
    before the camera ("level 1")."""
    from components import ParticleEmitter

    size, width, speed = ((1.8, 1.4), 0.3, 1.6) if case == "level 1" else ((0.9, 0.7), 0.15, 0.8)
    if case == "mirror":
        pane, turn, trail = (-0.5, 0.45, 0.3), glm.quat(), (0.05, 0.35, 0.5)
    elif case == "portal":
        pane, turn, trail = (-0.45, 1.3, 0.9), glm.quat(), (0.05, 1.9, 0.9)
    else:
        pane, turn, trail = (-0.9, 1.0, 3.6), BEHIND, (-0.6, 2.2, 3.6)
    ents["pane"] = world.spawn(Transform(position=pane, rotation=turn), MeshRef(quad(*size)),
                               Material(color=(0.9, 0.15, 0.1, 0.5)), Emissive(0.6))
    ents["ribbon"] = world.spawn(Transform(position=trail), ParticleEmitter(
        rate=60.0, burst=0, speed=speed, spread=0.0, direction=(1.0, 0.0, 0.0), lifetime=1.0, angle=(0.0, 0.0),
        size=width, color=(0.1, 0.3, 0.9, 0.7), end_color=(0.1, 0.3, 0.9, 0.7), blend="alpha", lit=True,
        ribbon=True, prewarm=True))


def _slot_scene(ents: dict, case: str, backdrop: float | None, things: bool):
    """``case``'s cut surface (``_slot_things``), or, with ``backdrop``, an unlit grey quad of
    that level in its place (no mirror, no portal); ``things``: the pane and the ribbon too."""
    from engine.assets.mesh import box as a_box

    def surface(world, place, turn, size, cut):
        if backdrop is not None:
            return world.spawn(Transform(position=place, rotation=turn), MeshRef(quad(*size)),
                               Material(color=(backdrop,) * 3, unlit=True))
        return world.spawn(Transform(position=place, rotation=turn), MeshRef(quad(*size)),
                           Material(color=MATERIAL), Mirror(color=TINT, **cut))

    def build(world) -> None:
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=SUN_LIGHT, intensity=1.5))
        world.spawn(Transform(position=(1.2, 0.5, -2.2)), MeshRef(a_box()), Material(color=(0.5, 0.5, 0.5)))
        if case == "mirror":
            look_from(world, EYE, target=(0.0, 0.0, 0.0), fov=50.0)
            ents["surface"] = surface(world, (0.0, 0.0, 0.0), FACING_UP, (3.0, 3.0), dict(max_depth=0))
        elif case == "portal":
            look_from(world, (0.3, 1.4, 3.0), target=(0.0, 1.6, 0.0), fov=50.0)
            turn = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))
            if backdrop is None:
                ents["surface"], _ = spawn_portal_pair(world, (0.0, 1.5, 0.0), None, (10.0, 1.5, 0.0), turn,
                                                       size=(2.0, 2.5))
                world.resources[ViewBudget] = ViewBudget(views=0)
            else:
                ents["surface"] = surface(world, (0.0, 1.5, 0.0), glm.quat(), (2.0, 2.5), {})
        else:  # (mirror A before the camera, drawn; B behind it, past its depth in A: a fallback in level 1)
            look_from(world, (0.0, 1.5, 2.0), target=(0.0, 1.5, -2.0), fov=40.0)
            ents["a"] = world.spawn(Transform(position=(0.0, 1.5, -2.0)), MeshRef(quad(4.0, 3.0)), Material(),
                                    Mirror())
            ents["surface"] = surface(world, (0.0, 1.5, 4.5), BEHIND, (6.0, 4.0), dict(max_depth=1))
        if things:
            _slot_things(world, ents, case)
    return build


def _slot_frame(scene, case: str, path: str, keep: bool, backdrop: float | None, things: bool) -> dict:
    """The third frame of ``_slot_scene`` (``keep``: a still tree kept from the frame before, as
    ``keep_still_views``): level 0's linear colour (h, w, 3), the seen ids, the surface ids of
    levels 0 and 1, the runner, the entities."""
    ents: dict = {}
    runner = scene(_slot_scene(ents, case, backdrop, things), SLOT_SIZE)
    runner.engine.renderer.antialias = "off"
    runner.engine.reflection_system.path = path
    runner.engine.reflection_system.keep_still_views = keep
    for _ in range(3):
        runner.frame()
    levels = runner.engine.renderer.levels
    w, h = SLOT_SIZE
    colour = np.frombuffer(levels[0].color.read(), np.float16).reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
    return {"colour": colour, "seen": runner.ids(), "surface": levels[0].read_surface_ids(),
            "level1": levels[1].read_surface_ids() if len(levels) > 1 else None, "runner": runner, "ents": ents}


@pytest.mark.parametrize("case,path,keep", [("mirror", "per_mirror", True), ("mirror", "per_mirror", False),
                                            ("portal", "per_mirror", False), ("level 1", "per_mirror", False),
                                            ("level 1", "batched", False)])
def test_glass_and_a_ribbon_in_front_of_a_cut_surface_blend_over_its_fallback(scene, case, path, keep):
    """A pane of glass and a lit ribbon (the transparent slot: ``_slot_things``) in front of a
    surface with no view of its own: a floor mirror past its depth limit, a portal cut by the
    budget, and a mirror seen in a mirror past its depth there (its fallback drawn into level
    1, the pane and the ribbon only in that level).  Whatever the slot draws at a pixel is an
    "over" blend, affine in what lies behind (glass by its alpha, a particle premultiplied):
    drawn over two unlit backdrops of known grey in the surface's place it gives, pixel by
    pixel and channel by channel, its own light P and what it lets through K; over the
    fallback F (the same surface drawn without the pane and the ribbon) the frame must be
    P + K F.  A slot blended under the fallback (the fallback painted over the glass) would
    show F there.  And both are there: the pane's id over the surface, and the ribbon's
    colour over it where the pane is not.  The tree drawn whole, and (level 0) kept from the
    frame before (``StillTree.keep``: the fallbacks drawn again, then the root's slot)."""
    frames = {(backdrop, things): _slot_frame(scene, case, path, keep, backdrop, things)
              for backdrop in (None, 0.1, 0.8) for things in (False, True)}
    cut, bare = frames[None, True], frames[None, False]
    stats = cut["runner"].stats
    assert stats.reflection_fallbacks >= 1
    # (the surface's pixels as drawn without the slot: the glass takes its pixels' surface ids)
    if case == "level 1":
        assert stats.reflection_views == 1 and stats.reflection_path == path
        where = (bare["surface"] == bare["ents"]["a"]) & (bare["level1"] == bare["ents"]["surface"])
    else:
        assert stats.reflection_views == 0
        where = bare["surface"] == bare["ents"]["surface"]
    backdrop = frames[0.1, False]
    where &= backdrop["seen"] == backdrop["ents"]["surface"]  # (the backdrop there too, seen directly or in A)
    low, high = frames[0.1, True]["colour"], frames[0.8, True]["colour"]
    with np.errstate(divide="ignore", invalid="ignore"):   # (0 / 0 off the backdrop)
        let_through = (high - low) / (frames[0.8, False]["colour"] - frames[0.1, False]["colour"])
    own = low - let_through * frames[0.1, False]["colour"]
    fallback = bare["colour"]
    want = own + let_through * fallback
    pane = where & (cut["seen"] == cut["ents"]["pane"])
    ribbon = where & ~pane & (np.abs(cut["colour"] - fallback).max(axis=-1) > 0.05)
    assert pane.sum() > 60 and ribbon.sum() > 20, (pane.sum(), ribbon.sum())
    assert np.abs(cut["colour"][pane] - fallback[pane]).max(axis=-1).min() > 0.05
    bad = ~np.isclose(cut["colour"][where], want[where], rtol=5e-3, atol=4e-3).all(axis=-1)
    assert not bad.any(), (f"{int(bad.sum())} of {int(where.sum())} pixels are not the slot over the fallback; "
                           f"worst {np.abs(cut['colour'][where] - want[where]).max():.4f}")
