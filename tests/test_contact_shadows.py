"""Contact shadows (``ContactShadows`` on the camera; ``engine/render/screen_occlusion.py``'s
``contact_shadow``, the find pass's ``CONTACT_SHADOWS`` build): a box on a floor under a sun
whose shadow maps are off, so every shadow in the frame is a contact shadow.  Each floor pixel's
ray towards the sun is cast against the box in float64 (a second path): where it meets the box
within ``length`` the sun's light is gone, where it does not (the box's shadow past the
ray's reach included) it stays; ``opacity`` takes that share of it; past ``distance`` there
are none; with ambient occlusion at half size they are found there too; an orthographic
camera refuses them; bad values are refused naming the field."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    AmbientOcclusion,
    Camera,
    ComponentValueError,
    ComponentWarning,
    ContactShadows,
    DirectionalLight,
    HemisphereLight,
    Material,
    MeshRef,
    Monitor,
    PointLight,
    Transform,
)
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import box
from engine.core.errors import GLLimitWarning, LightLimitWarning
from engine.core.world import World
from shell.overlay_text import post_lines
from tests.support import box_hits, look_from, pixel_rays, srgb_to_linear

SIZE = (192, 144)
SUN = glm.normalize(glm.vec3(1.0, -1.0, 0.0))   # the way the light travels: 45 degrees down, towards +x
BOX = (np.array([0.0, 0.2, 0.0]), np.array([0.2, 0.2, 0.2]))   # centre, half sizes: a 0.4 m cube on the floor
MARGIN = 0.03   # metres either side of a ray's reach left out (a texel's width and the march's steps)


def _floor_and_box(world, components, eye=(0.3, 2.0, 0.05)) -> dict:
    """The box on the floor, the light from all round and a camera at ``eye`` with
    ``components`` (None left out), looking almost straight down: what lies behind the box as
    the camera sees it is the box itself (a ray's sample under its top is inside it, under by
    at most its height), so the depth image's answer is the geometry's where the thickness
    spans the box."""
    camera = look_from(world, eye, (0.3, 0.0, 0.0))
    for component in components:
        if component is not None:
            world.add_component(camera, component)
    world.spawn(HemisphereLight(sky=(0.3, 0.3, 0.3), ground=(0.3, 0.3, 0.3)))
    floor = world.spawn(Transform(position=(0.0, -0.05, 0.0)), MeshRef(box((12.0, 0.1, 12.0))),
                        Material(color=(0.6, 0.6, 0.6), roughness=1.0))
    world.spawn(Transform(position=tuple(BOX[0])), MeshRef(box(tuple(2.0 * BOX[1]))),
                Material(color=(0.6, 0.6, 0.6), roughness=1.0))
    return {"camera": camera, "floor": floor}


def _scene(world, contact: ContactShadows | None, sun: float = 1.0, occlusion: AmbientOcclusion | None = None,
           eye=(0.3, 2.0, 0.05), watched: bool = False) -> dict:
    """The box on the floor under a sun without shadow maps; ``watched``: ``contact`` and
    ``occlusion`` on a monitor's camera where the active one stands instead (the active camera
    none), its picture the frame's size, the screen out of both cameras' sight."""
    names = _floor_and_box(world, () if watched else (contact, occlusion), eye)
    world.spawn(DirectionalLight(direction=SUN, intensity=sun, shadows=False))
    if watched:
        active = world.get(names["camera"], Transform)
        lens = world.spawn(Transform(position=active.position, rotation=active.rotation),
                           Camera(fov_y=world.get(names["camera"], Camera).fov_y, active=False),
                           *[component for component in (contact, occlusion) if component is not None])
        names["screen"] = world.spawn(Transform(position=(-6.0, 1.0, 0.0)), MeshRef(box((0.1, 0.9, 1.6))),
                                      Material(color=(0.0, 0.0, 0.0), roughness=1.0), Monitor(camera=lens, size=SIZE))
    return names


def _frame(scene, build=None, **options) -> tuple[np.ndarray, object, dict]:
    """The second frame of ``build(world, **options)`` (the sun's scene by default), in linear
    light, its runner and names (``watched``: the monitor's picture, linear as drawn)."""
    names: dict = {}
    runner = scene(lambda world: names.update((build or _scene)(world, **options)), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    frame = srgb_to_linear(runner.frame())
    if options.get("watched"):
        frame = runner.engine.renderer.monitors.read(names["screen"])[..., :3]
    return frame, runner, names


def _sun_kept(scene, contact: ContactShadows, **options) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each floor pixel's share of the sun's light kept under ``contact`` (linear, the mean of
    its channels: (with - without the sun) / (no contact shadows - without the sun)), and
    per pixel whether the ray towards the sun from its floor point meets the box within
    ``contact.length`` less and plus the margin (the pixels to judge: surely in, surely out)."""
    shadowed, runner, names = _frame(scene, contact=contact, **options)
    lit, _, _ = _frame(scene, contact=None, **options)
    dark, _, _ = _frame(scene, contact=None, sun=0.0, **options)
    sun_light = (lit - dark).mean(axis=-1)
    kept = (shadowed - dark).mean(axis=-1) / np.maximum(sun_light, 1e-6)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    floor = (runner.ids() == names["floor"]) & (sun_light > 0.02)
    points = eye + rays * (-eye[1] / rays[..., 1])[..., None]
    towards = -np.array(SUN, np.float64)
    rows = points[floor]
    ways = np.broadcast_to(towards, rows.shape)
    inside = np.zeros(SIZE[::-1], bool)
    outside = np.zeros(SIZE[::-1], bool)
    inside[floor] = box_hits(rows, ways, *BOX, limit=contact.length - MARGIN)
    outside[floor] = ~box_hits(rows, ways, *BOX, limit=contact.length + MARGIN)
    # (and clear of the box's own foot, where the floor meets it: a texel's blend of the two)
    foot = np.abs(points[..., 0] - BOX[1][0]) < MARGIN
    return kept, inside & ~foot, outside & ~foot


def test_the_sun_is_gone_where_its_ray_meets_the_box_within_the_length(scene):
    """A 0.3 m ray: the floor within 0.21 m of the box's side away from the sun loses the
    sun; the rest of the box's true shadow (0.4 m out at 45 degrees), past the ray's reach,
    keeps it, as does the floor round it."""
    kept, inside, outside = _sun_kept(scene, ContactShadows(length=0.3, thickness=0.5))
    assert inside.sum() > 150 and outside.sum() > 5000, (inside.sum(), outside.sum())
    assert np.median(kept[inside]) < 0.05 and np.percentile(kept[inside], 90) < 0.25, kept[inside]
    assert np.percentile(kept[outside], 0.5) > 0.9, np.percentile(kept[outside], 0.5)
    # The box's shadow past the reach (where a 2 m ray meets it and a 0.3 m one does not) stays lit.
    longer, _, _ = _sun_kept(scene, ContactShadows(length=2.0, thickness=0.5))
    far_part = outside & (longer < 0.5)
    assert far_part.sum() > 100, far_part.sum()
    assert np.median(kept[far_part]) > 0.95, np.median(kept[far_part])


def test_opacity_takes_its_share_and_distance_ends_them(scene):
    kept, inside, _ = _sun_kept(scene, ContactShadows(length=0.3, thickness=0.5, opacity=0.5))
    assert abs(np.median(kept[inside]) - 0.5) < 0.05, np.median(kept[inside])
    kept, inside, _ = _sun_kept(scene, ContactShadows(length=0.3, thickness=0.5, distance=1.2))   # the box is 2 m off
    assert np.percentile(kept[inside], 5) > 0.97, np.percentile(kept[inside], 5)


def test_with_half_size_ambient_occlusion_they_are_found_at_its_size(scene):
    """The camera's AmbientOcclusion at half size (intensity 0: it darkens nothing): the
    contact shadow is found in its images, softer at the edges but as dark within."""
    occlusion = AmbientOcclusion(intensity=0.0)
    kept, inside, outside = _sun_kept(scene, ContactShadows(length=0.3, thickness=0.5), occlusion=occlusion)
    deep = inside & (np.abs(kept - np.median(kept[inside])) < 1.0)
    assert np.median(kept[deep]) < 0.1, np.median(kept[deep])
    assert np.percentile(kept[outside], 2) > 0.85, np.percentile(kept[outside], 2)


def test_at_half_resolution_alone_they_are_as_dark_within(scene):
    """``half_resolution``: the images half the view's size each way; dark within the ray's
    reach, lit outside it, as at full size (the edges softer)."""
    kept, inside, outside = _sun_kept(scene, ContactShadows(length=0.3, thickness=0.5, half_resolution=True))
    assert np.median(kept[inside]) < 0.1, np.median(kept[inside])
    assert np.percentile(kept[outside], 2) > 0.85, np.percentile(kept[outside], 2)


def test_the_images_and_passes(scene):
    """Contact shadows alone: the depth and normals pass, the find (the march alone) and the
    filter, at the view's size; gone when the camera lets them go."""
    _, runner, names = _frame(scene, contact=ContactShadows())
    occlusion = runner.engine.renderer.occlusion
    assert occlusion.target_count() == 4 and occlusion._targets.size == SIZE
    runner.world.get(names["camera"], ContactShadows).half_resolution = True
    runner.frame()
    assert occlusion._targets.size == (SIZE[0] // 2, SIZE[1] // 2)
    runner.world.remove_component(names["camera"], ContactShadows)
    runner.frame()
    assert occlusion.target_count() == 0


def test_the_command_line_flag_puts_them_on_the_active_camera(scene):
    """``--contact-shadows``: the parser's flag, and ``Engine.start_from`` giving the active
    camera a ``ContactShadows()`` where it has none (the overlay's line names it)."""
    from shell.runner import build_parser

    _, runner, names = _frame(scene, contact=None)
    args = build_parser(type(runner.engine.game)).parse_args(["--headless", "--contact-shadows"])
    runner.engine.start_from(args)
    given = runner.world.try_get(names["camera"], ContactShadows)
    assert given is not None and given.length == ContactShadows().length
    runner.frame()
    assert any("contact shadows 0.3 m" in line for line in post_lines(runner.engine))


def test_without_a_sun_they_say_so_once_and_darken_nothing(scene):
    """No DirectionalLight that shines: a ComponentWarning naming the camera's entity, once,
    and the frame is the one without them."""
    with pytest.warns(ComponentWarning, match=r"ContactShadows on entity \d+: the world has no DirectionalLight"):
        shadowed, runner, _ = _frame(scene, contact=ContactShadows(), sun=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()
    plain, _, _ = _frame(scene, contact=None, sun=0.0)
    np.testing.assert_array_equal(shadowed, plain)


def test_a_level_file_keeps_them(tmp_path):
    (tmp_path / "yard.toml").write_text("""[level]
name = "yard"

[[entity]]
name = "camera"
Transform = { position = [0.0, 1.0, 3.0] }
Camera = {}
ContactShadows = { length = 0.5, thickness = 0.1, opacity = 0.8, distance = 20.0, samples = 16, half_resolution = true }
""")
    world = World()
    names = load_level(tmp_path / "yard.toml").spawn(world)
    shadows = world.get(names["camera"], ContactShadows)
    wanted = (0.5, 0.1, 0.8, 20.0, 16, True)
    fields = ("length", "thickness", "opacity", "distance", "samples", "half_resolution")
    assert tuple(getattr(shadows, name) for name in fields) == pytest.approx(wanted)
    again = World()
    names = load_level(save_level(world, tmp_path / "again.toml", names, name="yard")).spawn(again)
    assert tuple(getattr(again.get(names["camera"], ContactShadows), name) for name in fields) == pytest.approx(wanted)
    (tmp_path / "bad.toml").write_text(
        '[level]\nname = "bad"\n\n[[entity]]\nname = "camera"\nCamera = {}\nContactShadows = { samples = 64 }\n')
    with pytest.raises(LevelError, match="samples"):
        load_level(tmp_path / "bad.toml")


def test_an_orthographic_camera_refuses_them():
    world = World()
    camera = world.spawn(Transform(), Camera(projection="orthographic"))
    with pytest.raises(ComponentValueError, match="ContactShadows on an orthographic Camera"):
        world.add_component(camera, ContactShadows())


@pytest.mark.parametrize(("field", "value"), [("length", 0.0), ("length", 6.0), ("thickness", -1.0),
                                              ("opacity", 1.5), ("distance", float("nan")), ("samples", 3),
                                              ("samples", 33), ("samples", 8.0),
                                              ("half_resolution", 1)])
def test_bad_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"ContactShadows.{field}"):
        ContactShadows(**{field: value})


LAMP = np.array([-0.8, 0.8, 0.1])   # a lamp up and to the left of the box: its contact shadow falls to the right


def test_a_monitors_camera_finds_its_pictures_contact_shadows(scene):
    """A monitor's camera with ``ContactShadows`` (the active camera, at the same place, none):
    its picture loses the sun where the floor point's ray meets the box within the length, as
    the active camera's view does (``_sun_kept``'s rays, cast in float64), and keeps it
    elsewhere."""
    kept, inside, outside = _sun_kept(scene, ContactShadows(length=0.3, thickness=0.5), watched=True)
    assert inside.sum() > 150 and outside.sum() > 5000, (inside.sum(), outside.sum())
    assert np.median(kept[inside]) < 0.05 and np.percentile(kept[inside], 90) < 0.25, kept[inside]
    assert np.percentile(kept[outside], 0.5) > 0.9, np.percentile(kept[outside], 0.5)
    # With no sun and no lamp that has them they darken nothing, and that is said once.
    names: dict = {}
    runner = scene(lambda world: names.update(_scene(world, ContactShadows(), sun=0.0, watched=True)), SIZE)
    with pytest.warns(ComponentWarning, match=r"the camera of monitor \d+.*darken nothing in its picture"):
        runner.frame()
    runner.world.get(names["screen"], Monitor).every = 1   # (drawn again: nothing more said)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()


def _lamp_scene(world, contact: ContactShadows | None, intensity: float = 3.0, flagged: bool = True,
                others: int = 0, copies: int = 1) -> dict:
    """The box on the floor lit by a lamp (a PointLight without shadow maps; ``copies`` lamps in
    one place sharing its intensity) and the light from all round, no sun; ``others`` more
    lamps with contact shadows, dim, far off to the side."""
    names = _floor_and_box(world, (contact,))
    for _ in range(copies):
        world.spawn(Transform(position=tuple(LAMP)),
                    PointLight(intensity=intensity / copies, range=8.0, contact_shadows=flagged))
    for index in range(others):
        world.spawn(Transform(position=(6.0 + index, 3.0, 6.0)), PointLight(intensity=0.01, range=2.0,
                                                                           contact_shadows=True))
    return names


def _lamp_kept(scene, contact: ContactShadows, **options):
    """Each floor pixel's share of the lamp's light kept under ``contact``, and whether the ray
    from its floor point towards the lamp meets the box within the reach (less and plus the
    margin): as ``_sun_kept``, the lamp's way a point's own."""
    shadowed, runner, names = _frame(scene, _lamp_scene, contact=contact, **options)
    lit, _, _ = _frame(scene, _lamp_scene, contact=None, **options)
    dark, _, _ = _frame(scene, _lamp_scene, contact=None, intensity=0.0, **options)
    lamp_light = (lit - dark).mean(axis=-1)
    kept = (shadowed - dark).mean(axis=-1) / np.maximum(lamp_light, 1e-6)
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    floor = (runner.ids() == names["floor"]) & (lamp_light > 0.02)
    points = eye + rays * (-eye[1] / rays[..., 1])[..., None]
    rows = points[floor]
    ways = LAMP - rows
    reach = np.linalg.norm(ways, axis=-1)
    ways /= reach[:, None]
    inside = np.zeros(SIZE[::-1], bool)
    outside = np.zeros(SIZE[::-1], bool)
    # Surely in: the ray meets the box shrunk by the margin; surely out: it misses it grown by
    # the margin (a ray grazing a side, as those from the floor along the box's sides do, meets
    # a texel's blend of the box's top and the floor there).
    inside[floor] = box_hits(rows, ways, BOX[0], BOX[1] - MARGIN, limit=np.minimum(contact.length - MARGIN, reach))
    outside[floor] = ~box_hits(rows, ways, BOX[0], BOX[1] + MARGIN, limit=np.minimum(contact.length + MARGIN, reach))
    foot = (np.abs(points[..., 0]) < BOX[1][0] + MARGIN) & (np.abs(points[..., 2]) < BOX[1][2] + MARGIN)
    return kept, inside & ~foot, outside & ~foot, runner


@pytest.mark.filterwarnings("ignore:ContactShadows on entity")  # (the unflagged lamp's frame: none to darken)
def test_a_lamp_with_contact_shadows_loses_its_light_where_its_ray_meets_the_box(scene):
    """``PointLight.contact_shadows``: each floor point's ray towards the lamp (its own way, a
    point light's) cast against the box in float64: within the camera's ContactShadows length
    the lamp's light is gone, outside it kept; the same lamp without the flag keeps it all."""
    contact = ContactShadows(length=0.3, thickness=0.5)
    kept, inside, outside, runner = _lamp_kept(scene, contact)
    assert inside.sum() > 100 and outside.sum() > 5000, (inside.sum(), outside.sum())
    assert np.median(kept[inside]) < 0.05 and np.percentile(kept[inside], 90) < 0.3, kept[inside]
    assert np.percentile(kept[outside], 0.5) > 0.9, np.percentile(kept[outside], 0.5)
    assert runner.engine.renderer.screen_contact_lamps is not None and runner.stats.contact_lamps_cut == 0
    assert any("contact shadows 0.3 m, 1 mirror level, 1 lamp" in line for line in post_lines(runner.engine))
    unflagged, _, _, _ = _lamp_kept(scene, contact, flagged=False)   # (no sun and no lamp: they darken nothing)
    assert np.percentile(unflagged[inside], 5) > 0.97


@pytest.mark.filterwarnings("ignore:6 point lights with contact_shadows")  # (the ground truth's frames say it too)
def test_past_four_lamps_the_rest_shine_without_and_it_is_said_once(scene):
    """At most MAX_CONTACT_LAMPS (4) lamps have them: the lamp that matters most keeps its
    contact shadow, the two lamps past the limit (of five more, dim and far) are counted and
    a LightLimitWarning says so, once."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        shadowed, runner, _ = _frame(scene, _lamp_scene, contact=ContactShadows(length=0.3, thickness=0.5), others=5)
        runner.frame()
    assert runner.stats.contact_lamps_cut == 2
    said = [w for w in caught if issubclass(w.category, LightLimitWarning) and "contact_shadows" in str(w.message)]
    assert len(said) == 1 and "at most 4" in str(said[0].message), [str(w.message) for w in said]
    kept, inside, _, _ = _lamp_kept(scene, ContactShadows(length=0.3, thickness=0.5), others=5)
    assert np.median(kept[inside]) < 0.05


def test_a_context_short_of_texture_units_lights_lamps_without_them(scene):
    """Where the fragment stage lacks the unit the lamps' image takes (ScreenOcclusion.
    lamps_supported False), the lamp shines as without contact shadows, and a GLLimitWarning
    says so, once."""
    frames = []
    for short in (True, False):
        names: dict = {}
        contact = ContactShadows(length=0.3, thickness=0.5) if short else None
        runner = scene(lambda world, names=names, contact=contact: names.update(_lamp_scene(world, contact)), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.renderer.occlusion.lamps_supported = not short
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            runner.frame()
            frames.append(runner.frame())
        said = [w for w in caught if issubclass(w.category, GLLimitWarning)]
        assert len(said) == (1 if short else 0)
    np.testing.assert_array_equal(frames[0], frames[1])


def test_four_lamps_in_one_place_each_take_their_own_channel(scene):
    """Four lamps in the lamp's place, a quarter of its light each: every channel of the lamps'
    image (the fourth, alpha, too) darkens its own lamp, so the floor within the reach loses
    all their light as it loses the one lamp's (one channel left out would keep a quarter)."""
    kept, inside, outside, runner = _lamp_kept(scene, ContactShadows(length=0.3, thickness=0.5), copies=4)
    assert runner.stats.contact_lamps_cut == 0 and inside.sum() > 100
    assert np.median(kept[inside]) < 0.05 and np.percentile(kept[inside], 75) < 0.1, kept[inside]
    assert np.percentile(kept[outside], 0.5) > 0.9


def test_contact_shadows_is_a_bool():
    with pytest.raises(ComponentValueError, match="PointLight.contact_shadows"):
        PointLight(contact_shadows="yes")
