"""System tests of planar mirrors: real frames, facts about pixels, ids and pass counts."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, Emissive, Material, MeshRef, Mirror, Skybox, Transform
from engine.assets.mesh import box, plane, quad, sphere
from engine.assets.texture_data import TextureData, checker_texture
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix
from engine.render.sky import sky_radiance
from engine.resources import Surfaces
from tests.support import look_from, srgb_to_linear

SIZE = (200, 150)
FACING_BACK = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))


def mirror_wall(world, position=(0, 1.5, -2), size=(4, 3), rotation=None, **mirror):
    return world.spawn(Transform(position=position, rotation=rotation or glm.quat()), MeshRef(quad(*size)),
                       Material(color=(0.1, 0.1, 0.1)), Mirror(**mirror))


def base_scene(world):
    world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
    world.spawn(Skybox())


def reflected_pixel(runner, point, mirror_point=(0, 1.5, -2), normal=(0, 0, 1)):
    """Where the mirror image of ``point`` lands on screen (pure math, no renderer)."""
    m = reflection_matrix(plane_from_point_normal(mirror_point, normal))
    return runner.project(glm.vec3(m * glm.vec4(glm.vec3(point), 1.0)))


def test_box_in_front_appears_where_its_reflection_projects(scene):
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (1.5, 1.8, 5.0))
        ents["mirror"] = mirror_wall(world)
        ents["box"] = world.spawn(Transform(position=(-1.0, 1.2, 0.0), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                                  Material(color=(0.9, 0.05, 0.05)), Emissive(0.8))

    runner = scene(build, SIZE)
    rgb = runner.frame()
    col, row = reflected_pixel(runner, (-1.0, 1.2, 0.0))
    ids = runner.ids()
    assert runner.engine.renderer.targets.read_surface_ids()[row, col] == ents["mirror"]  # it is a mirror pixel
    assert ids[row, col] == ents["box"]  # the id follows the reflection to the box
    r, g, b = rgb[row, col].astype(int)
    assert r > 90 and r > 2 * g and r > 2 * b, rgb[row, col]
    assert runner.stats.reflection_views == 1 and runner.stats.passes == 2


def test_nothing_behind_the_mirror_shows_in_it(scene):
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.5, 5.0))
        ents["mirror"] = mirror_wall(world)
        # Green box straddling the plane far behind it, and one just behind the glass.
        ents["behind"] = world.spawn(Transform(position=(0.0, 1.5, -2.6)), MeshRef(box()),
                                     Material(color=(0.05, 0.9, 0.05)))
        ents["touching"] = world.spawn(Transform(position=(1.0, 1.0, -2.3), scale=(0.5, 0.5, 0.5)), MeshRef(box()),
                                       Material(color=(0.05, 0.9, 0.05)))

    runner = scene(build, SIZE)
    rgb = runner.frame()
    ids = runner.ids()
    surface = runner.engine.renderer.targets.read_surface_ids()
    in_mirror = surface == ents["mirror"]
    assert in_mirror.sum() > 2000
    assert not np.isin(ids[in_mirror], [ents["behind"], ents["touching"]]).any()
    pixels = rgb[in_mirror].astype(int)
    assert not ((pixels[:, 1] > pixels[:, 0] + 40) & (pixels[:, 1] > pixels[:, 2] + 40)).any()  # no green


def test_camera_close_to_the_mirror_uses_a_clip_plane_and_still_hides_what_is_behind(scene):
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.3, 1.5, -1.9), target=(0.3, 1.5, -3))  # 10 cm from the glass
        ents["mirror"] = mirror_wall(world)
        # A thin plate just behind the glass: between it and the reflected eye (10 cm behind).
        ents["behind"] = world.spawn(Transform(position=(0.3, 1.5, -2.02), scale=(1.0, 1.0, 0.01)),
                                     MeshRef(box()), Material(color=(0.05, 0.9, 0.05)))

    runner = scene(build, SIZE)
    runner.frame()
    view = runner.engine.reflection_system.views[1].view
    assert view.proj == runner.engine.main_view.proj  # oblique was not safe: plain + clip
    assert ents["behind"] not in runner.ids()
    assert (runner.engine.renderer.targets.read_surface_ids() == ents["mirror"]).mean() > 0.9  # all mirror


@pytest.mark.parametrize("visibility", ("exact", "predicted"))
def test_mirror_facing_away_offscreen_or_hidden_costs_no_pass(scene, visibility):
    """A mirror facing away or off screen is never a candidate.  One hidden behind a wall
    is: exact visibility finds it has no pixels and draws no view; predicted visibility
    draws it unseen (it might show this frame) and nothing below it."""
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.5, 5.0))
        ents["away"] = mirror_wall(world, position=(-2.5, 1.5, -2), size=(2, 2), rotation=FACING_BACK)
        ents["offscreen"] = mirror_wall(world, position=(30, 1.5, -2), size=(2, 2))
        ents["hidden"] = mirror_wall(world, position=(2.5, 1.5, -4), size=(2, 2))
        ents["wall"] = world.spawn(Transform(position=(2.5, 1.5, -2)), MeshRef(box((3, 3, 0.2))), Material())

    runner = scene(build, SIZE)
    runner.engine.reflection_system.visibility = visibility
    for _ in range(2):
        runner.frame()
    stats = runner.stats
    if visibility == "exact":
        assert stats.passes == 1 and stats.reflection_views == 0
    else:
        assert stats.passes == 2 and stats.reflection_views == 1 and stats.reflection_views_unseen == 1
        assert runner.engine.reflection_system.views[1].surface.entity == ents["hidden"]
        assert runner.engine.reflection_system.views[1].unseen
    # Uncover the hidden one: now exactly one reflection pass.
    runner.world.get(ents["wall"], Transform).position = (2.5, 10.0, -2)
    runner.frame()
    assert runner.stats.reflection_views == 1 and runner.stats.passes == 2
    assert runner.engine.reflection_system.views[1].surface.entity == ents["hidden"]
    runner.frame()
    assert runner.stats.reflection_views_unseen == 0
    assert not runner.engine.reflection_system.views[1].unseen


def test_reflection_work_is_limited_to_the_mirror_footprint(scene):
    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.5, 6.0))
        mirror_wall(world, position=(1.5, 1.5, -2), size=(1, 1))

    runner = scene(build, SIZE)
    runner.frame()
    x, y, w, h = runner.engine.reflection_system.views[1].rect
    assert w * h < 0.05 * SIZE[0] * SIZE[1]
    assert x > SIZE[0] // 2  # on the right, where the mirror is


def test_adjacent_mirrors_do_not_bleed(scene):
    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.5, 5.0))
        world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=8)), Material(texture=checker_texture(64, 8)))
        mirror_wall(world, position=(-1.0, 1.5, -2), size=(2, 3), color=(1.0, 0.0, 0.0))
        mirror_wall(world, position=(1.0, 1.5, -2), size=(2, 3), color=(0.0, 0.0, 1.0))

    runner = scene(build, SIZE)
    rgb = runner.frame()
    col, row = runner.project((0.0, 1.0, -2.0))
    left = rgb[row - 10:row + 10, col - 4:col - 1].reshape(-1, 3).astype(int)
    right = rgb[row - 10:row + 10, col + 2:col + 5].reshape(-1, 3).astype(int)
    assert (left[:, 0] > left[:, 2] + 30).all()
    assert (right[:, 2] > right[:, 0] + 30).all()
    assert runner.stats.reflection_views == 2


def test_higher_roughness_lowers_local_contrast(scene):
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.5, 4.0))
        # A self-lit checker wall behind the camera, facing the mirror.
        world.spawn(Transform(position=(0, 1.5, 5.5), rotation=glm.angleAxis(glm.radians(-90), glm.vec3(1, 0, 0))),
                    MeshRef(plane(12, 12, uv_repeat=6)), Material(texture=checker_texture(64, 8)), Emissive(1.0))
        ents["mirror"] = mirror_wall(world, roughness=0.0)

    runner = scene(build, SIZE)
    runner.frame()
    surface = runner.engine.renderer.targets.read_surface_ids()
    region = surface == ents["mirror"]

    def contrast(rgb):
        lum = srgb_to_linear(rgb).mean(axis=2)
        local = np.abs(np.diff(lum, axis=1))[region[:, 1:] & region[:, :-1]]
        return local.mean()

    sharp = contrast(runner.frame())
    runner.world.get(ents["mirror"], Mirror).roughness = 0.6
    blurred = contrast(runner.frame())
    assert sharp > 0.02  # the checker is visible in the sharp mirror
    assert blurred < 0.6 * sharp


def test_sky_shows_where_the_mirror_reflects_nothing(scene):
    sky = Skybox()

    def build(world):
        world.spawn(sky)
        look_from(world, (0.0, 1.0, 4.0), target=(0.0, 2.0, -2.0))
        mirror_wall(world, position=(0, 2.0, -2), size=(6, 6))

    runner = scene(build, SIZE)
    rgb = runner.frame()
    col, row = runner.project((0.5, 2.5, -2.0))
    view = runner.engine.main_view
    w, h = SIZE
    ndc = glm.vec4((col + 0.5) / w * 2 - 1, 1 - (row + 0.5) / h * 2, 1, 1)
    far = glm.inverse(view.view_proj) * ndc
    d = np.array(glm.normalize(glm.vec3(far) / far.w - view.eye))
    r = d * np.array([1, 1, -1])  # reflected in the z = -2 plane
    np.testing.assert_allclose(srgb_to_linear(rgb[row, col]), sky_radiance(sky, r), atol=0.03)
    assert runner.ids()[row, col] == 0  # the reflection ends in the sky


@pytest.mark.parametrize("rate", [0.0, 0.25, 0.5])
def test_reflect_rate_mixes_with_the_mirrors_own_shading(scene, rate):
    """A mirror shows (1 - rate) x its own shading + rate x the reflection.  Its own shading
    comes from a second scene where the same quad is no mirror at all, the full reflection
    from a third where the rate is 1: neither shares a frame with the one under test."""
    def build(mirror):
        def level(world):
            base_scene(world)
            look_from(world, (0.0, 1.5, 4.0))
            world.spawn(Transform(position=(0, 1.5, 6.0), scale=(8, 8, 0.1)), MeshRef(box()),
                        Material(color=(0.9, 0.9, 0.1)), Emissive(0.5))  # behind the camera: what the mirror shows
            extra = (mirror,) if mirror is not None else ()
            world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(quad(4, 3)), Material(color=(0.1, 0.1, 0.9)),
                        *extra)
        return level

    def pixel(mirror):
        runner = scene(build(mirror), SIZE)
        rgb = runner.frame()
        col, row = runner.project((0.3, 1.5, -2.0))
        return srgb_to_linear(rgb[row, col])

    own = pixel(None)
    full = pixel(Mirror(reflect_rate=1.0))
    mixed = pixel(Mirror(reflect_rate=rate))
    assert own[2] > own[0] + 0.05  # the quad's own blue
    assert full[0] > full[2] + 0.05  # the reflected yellow wall
    np.testing.assert_allclose(mixed, (1 - rate) * own + rate * full, atol=0.02)


def test_facing_mirrors_show_nested_images_of_decreasing_size(scene):
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (-1.5, 1.6, 3.5), target=(0.0, 1.5, -4.0), fov=50.0)
        mirror_wall(world, position=(0, 1.5, -4), size=(4, 3))
        mirror_wall(world, position=(0, 1.5, 4), size=(4, 3), rotation=FACING_BACK, color=(0.9, 0.95, 0.9))
        ents["ball"] = world.spawn(Transform(position=(1.2, 1.5, 1.5)), MeshRef(sphere(0.2)),
                                   Material(color=(0.9, 0.5, 0.1)))

    runner = scene(build, (240, 160))
    runner.frame()
    ids = runner.ids()
    assert runner.stats.reflection_views == 3  # the depth cap
    # Copies of the ball: the direct one, and one per reflection level that shows it.
    from scipy import ndimage

    labels, count = ndimage.label(ids == ents["ball"])
    sizes = sorted(np.bincount(labels.ravel())[1:], reverse=True)
    assert count >= 3, sizes
    assert all(a > b for a, b in zip(sizes, sizes[1:], strict=False))
    rects = [v.rect for v in runner.engine.reflection_system.views[1:]]
    areas = [w * h for _, _, w, h in rects]
    assert areas == sorted(areas, reverse=True) and areas[0] > areas[-1]


def test_facing_mirrors_keep_memory_bounded(scene):
    def build(world):
        base_scene(world)
        look_from(world, (0.4, 1.6, 3.5), target=(0.0, 1.5, -4.0))
        mirror_wall(world, position=(0, 1.5, -4), size=(4, 3), max_depth=8)
        mirror_wall(world, position=(0, 1.5, 4), size=(4, 3), rotation=FACING_BACK, max_depth=8)

    runner = scene(build, (96, 64))
    runner.engine.reflection_system.max_depth_cap = 6
    for _ in range(5):
        runner.frame()
    assert runner.stats.reflection_views == 6 and runner.stats.reflection_end_views == 1
    # One screen-sized set per level, reused: the root's, six levels', and the end image's
    # (the facing pair's recursion ends in last frame's image one level past the cap).
    assert len(runner.engine.renderer.levels) == 8


def test_a_mirror_on_a_mesh_that_is_not_flat_is_a_clear_error(scene):
    def build(world):
        look_from(world, (0, 1.5, 5))
        world.spawn(Transform(), MeshRef(box(name="crate")), Material(), Mirror())

    # Refused when the entity is made (the level's build), not on the first frame.
    with pytest.raises(ComponentValueError, match=r"Mirror on entity \d+: its MeshRef\.mesh 'crate' is not flat"):
        scene(build, (32, 32))


def test_explicit_plane_turns_any_mesh_into_a_mirror(scene):
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (1.5, 1.8, 5.0))
        world.spawn(Transform(position=(0, 1.5, -2.05)), MeshRef(box((4, 3, 0.1))), Material(),
                    Mirror(plane_point=(0, 0, 0.05), plane_normal=(0, 0, 1)))
        ents["box"] = world.spawn(Transform(position=(-1.0, 1.2, 0.0), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                                  Material(color=(0.9, 0.05, 0.05)))

    runner = scene(build, SIZE)
    runner.frame()
    col, row = reflected_pixel(runner, (-1.0, 1.2, 0.0))
    assert runner.ids()[row, col] == ents["box"]


def test_resolution_scale_renders_the_reflection_smaller_and_still_right(scene):
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (1.5, 1.8, 5.0))
        ents["mirror"] = mirror_wall(world, resolution_scale=0.5)
        ents["box"] = world.spawn(Transform(position=(-1.0, 1.2, 0.0), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                                  Material(color=(0.9, 0.05, 0.05)), Emissive(0.8))

    runner = scene(build, SIZE)
    half = runner.frame()
    assert runner.engine.renderer.levels[1].size == (SIZE[0] // 2, SIZE[1] // 2)
    col, row = reflected_pixel(runner, (-1.0, 1.2, 0.0))
    assert runner.ids()[row, col] == ents["box"]
    r, g, b = half[row, col].astype(int)
    assert r > 90 and r > 2 * g and r > 2 * b
    runner.world.get(ents["mirror"], Mirror).resolution_scale = 1.0
    full = runner.frame()
    assert runner.engine.renderer.levels[1].size == SIZE
    surface = runner.engine.renderer.targets.read_surface_ids() == ents["mirror"]
    diff = np.abs(full.astype(int) - half.astype(int))[surface]
    assert np.median(diff) <= 3 and diff.mean() < 10  # the same picture, a little softer


def test_reflection_filtering_changes_only_the_mirrors_pixels(scene):
    """reflection_anisotropy applies inside reflection views and nowhere else: a checker
    ground seen at a grazing angle in a mirror changes with it, the direct view does not."""
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.0, 6.0), target=(0.0, 1.0, 0.0))
        # A sampled texture (a generated checker is drawn from its cells, not filtered).
        ground = TextureData(checker_texture(64, 8).pixels.copy(), name="sampled checker")
        world.spawn(Transform(), MeshRef(plane(60, 60, uv_repeat=30)), Material(texture=ground))
        ents["mirror"] = mirror_wall(world, position=(0, 1.5, -2), size=(4, 3),
                                     rotation=glm.angleAxis(glm.radians(35.0), glm.vec3(0, 1, 0)))

    runner = scene(build, SIZE)
    renderer = runner.engine.renderer
    renderer.antialias = "off"  # FXAA would carry a change a pixel across the mirror's outline
    renderer.reflection_anisotropy = renderer.texture_anisotropy
    sharp = runner.frame().astype(int)
    renderer.reflection_anisotropy = 1.0
    trilinear = runner.frame().astype(int)
    mirror = runner.engine.renderer.targets.read_surface_ids() == ents["mirror"]
    changed = np.abs(sharp - trilinear).max(axis=2) > 0
    assert mirror.sum() > 2000 and (changed & mirror).sum() > 50
    assert not (changed & ~mirror).any()


def test_composite_covers_a_flat_mirrors_outline_and_a_solid_ones_rectangle(scene):
    """The composite of a flat mirror is its own quad (the mesh outline on its plane); a mirror
    plane given on a solid mesh has no such outline and composites over its rectangle. Either
    way the reflection lands on the mirror's pixels and nowhere else."""
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (1.5, 1.8, 5.0))
        ents["flat"] = mirror_wall(world, position=(-1.2, 1.5, -2), size=(2, 3),
                                   rotation=glm.angleAxis(glm.radians(20.0), glm.vec3(0, 1, 0)))
        ents["solid"] = world.spawn(Transform(position=(1.3, 1.5, -2.05)), MeshRef(box((2, 3, 0.1))),
                                    Material(color=(0.1, 0.1, 0.1)),
                                    Mirror(plane_point=(0, 0, 0.05), plane_normal=(0, 0, 1)))
        world.spawn(Transform(position=(0.0, 1.2, 0.5), scale=(0.8, 0.8, 0.8)), MeshRef(box()),
                    Material(color=(0.9, 0.05, 0.05)), Emissive(0.8))

    runner = scene(build, SIZE)
    runner.frame()
    mirrors = runner.world.resources[Surfaces].mirrors
    outline = mirrors[ents["flat"]].outline
    assert outline.shape == (4, 4)
    plane = np.array(tuple(mirrors[ents["flat"]].plane))
    assert np.abs(outline @ plane).max() < 1e-5  # all four corners on the mirror's plane
    assert mirrors[ents["solid"]].outline is None
    surface = runner.engine.renderer.targets.read_surface_ids()
    seen = runner.ids()
    for entity in (ents["flat"], ents["solid"]):
        changed = (surface == entity) & (seen != entity)
        assert changed.sum() > 300  # the reflection shows across the mirror
    # Outside the mirrors every pixel shows what is there.
    outside = (surface != ents["flat"]) & (surface != ents["solid"])
    assert (seen[outside] == surface[outside]).all()


def test_a_rough_mirror_does_not_blur_in_what_an_earlier_frame_left(scene):
    """A rough mirror reads wide mips of its level. Pixels of that level outside this frame's
    claimed rectangles hold whatever an earlier frame (or another mirror) left there. They
    must not leak in: garbage written there changes nothing in the next frame."""
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.5, 4.0))
        world.spawn(Transform(position=(0, 0, 0)), MeshRef(plane(12, 12, uv_repeat=6)),
                    Material(texture=checker_texture(64, 8)))
        ents["mirror"] = mirror_wall(world, size=(1.5, 1.2), roughness=0.7)

    runner = scene(build, SIZE)
    # The garbage is written behind the engine's back (nothing in it writes a level but its
    # tree): a still frame would keep the level as it is (ReflectionSystem.keep_still_views).
    runner.engine.reflection_system.keep_still_views = False
    runner.frame()
    clean = runner.frame().astype(int)
    level = runner.engine.renderer.levels[1]
    w, h = level.size
    garbage = np.zeros((h, w, 4), np.float16)
    garbage[..., 0] = 40.0  # bright red, fully "reflected"
    garbage[..., 3] = 1.0
    level.color.write(garbage.tobytes())
    polluted = runner.frame().astype(int)
    mirror = runner.engine.renderer.targets.read_surface_ids() == ents["mirror"]
    assert mirror.sum() > 300
    assert np.abs(polluted - clean)[mirror].max() <= 1


@pytest.mark.parametrize("roughness", [0.25, 0.6])
def test_a_rough_mirror_blurs_only_its_own_reflection(scene, roughness):
    """Two mirrors side by side; a red lamp is seen in the right one only. The left one, rough,
    blurs its own reflection (ground and sky): none of its neighbour's red gets in, however
    wide its blur (at 0.6 the bias reaches the coarsest mip of the reflection)."""
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.0, 1.5, 5.0))
        world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=8)), Material(texture=checker_texture(64, 8)))
        ents["rough"] = mirror_wall(world, position=(-1.0, 1.5, -2), size=(2, 3), roughness=0.0)
        ents["sharp"] = mirror_wall(world, position=(1.0, 1.5, -2), size=(2, 3))
        ents["lamp"] = world.spawn(Transform(position=(2.2, 1.5, 1.0), scale=(0.8, 2.5, 0.8)), MeshRef(box()),
                                   Material(color=(1.0, 0.0, 0.0)), Emissive(3.0))

    runner = scene(build, SIZE)
    runner.frame()
    surface = runner.engine.renderer.targets.read_surface_ids()
    left, right = surface == ents["rough"], surface == ents["sharp"]
    seen = runner.ids()
    assert not (seen[left] == ents["lamp"]).any() and (seen[right] == ents["lamp"]).sum() > 100
    runner.world.get(ents["rough"], Mirror).roughness = roughness
    with_lamp = runner.frame().astype(int)
    redness = with_lamp[..., 0] - (with_lamp[..., 1] + with_lamp[..., 2]) / 2
    assert redness[right].max() > 150  # the lamp, sharp in the right mirror
    runner.world.get(ents["lamp"], Transform).position = (2.2, -10.0, 1.0)  # under the ground
    without_lamp = runner.frame().astype(int)
    assert np.abs(with_lamp - without_lamp)[left].max() <= 2  # the lamp changes nothing on the left


def test_rough_views_blur_in_an_atlas_as_wide_as_their_level_needs(scene, monkeypatch):
    """Each rough view of a level is copied into its own tile of an atlas whose mips it is
    blurred from (``engine/render/rough_atlas.py``); the atlas holds as many columns of tiles
    as the level's rough views need (``glGenerateMipmap`` filters all of it): one mirror a
    tile's width, three four tiles', each size kept.  The frames equal those drawn with an
    atlas of eight columns whatever the count."""
    from engine.render import rough_atlas
    from engine.render.rough_atlas import TILE

    def build_with(count):
        def build(world):
            base_scene(world)
            look_from(world, (0.0, 1.5, 5.0))
            world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=8)), Material(texture=checker_texture(64, 8)))
            world.spawn(Transform(position=(0.0, 0.6, 1.0), scale=(0.6, 0.6, 0.6)), MeshRef(box()),
                        Material(color=(0.9, 0.3, 0.1)))
            for i in range(count):
                mirror_wall(world, position=(-2.2 + 2.2 * i, 1.5, -2), size=(2, 3), roughness=0.3)
        return build

    def frames(count):
        runner = scene(build_with(count), SIZE)
        runner.frame()
        atlas = runner.engine.reflection_system.tree.passes.rough_atlas
        return runner.frame().astype(int), atlas.texture.size, atlas.held()

    one, three = frames(1), frames(3)
    assert one[1:] == ((TILE, TILE), 1) and three[1:] == ((4 * TILE, TILE), 1)
    monkeypatch.setattr(rough_atlas, "atlas_grid", lambda count: (rough_atlas.COLUMNS, 1))
    for drawn, (wide, size, _) in ((one, frames(1)), (three, frames(3))):
        assert size == (8 * TILE, TILE) and np.array_equal(drawn[0], wide)
    assert one[0].std() > 5.0 and np.abs(one[0] - three[0]).max() > 50  # (two scenes, both drawn)


def test_pixels_a_mirror_owned_last_frame_are_not_reflected_into_once_something_hides_them(scene):
    """A level's node image and depth mask keep what the last frame's claims wrote. When a
    box moves in front of the mirror, the pixels it now covers must lose their reflection:
    the frame is the one a fresh engine draws with the box already there."""
    ents = {}

    def build_with(box_position):
        def build(world):
            base_scene(world)
            look_from(world, (0.0, 1.5, 4.0))
            world.spawn(Transform(position=(0, 0, 0)), MeshRef(plane(12, 12, uv_repeat=6)),
                        Material(texture=checker_texture(64, 8)))
            ents["mirror"] = mirror_wall(world, size=(2.0, 1.5))
            ents["box"] = world.spawn(Transform(position=box_position, scale=(0.4, 0.4, 0.4)), MeshRef(box()),
                                      Material(color=(0.1, 0.8, 0.1)))
        return build

    in_front = (-0.4, 1.4, 1.0)
    moving = scene(build_with((30.0, 1.5, 30.0)), SIZE)
    moving.frame()
    occluder = ents["box"]
    moving.world.get(occluder, Transform).position = glm.vec3(in_front)
    moved = moving.frame().astype(int)
    fresh = scene(build_with(in_front), SIZE).frame().astype(int)
    col, row = moving.project(in_front)
    assert moving.ids()[row, col] == occluder
    surface = moving.engine.renderer.targets.read_surface_ids()
    assert (surface == ents["mirror"]).sum() > 1000  # most of the mirror still shows, reflecting
    assert np.abs(moved - fresh).max() <= 1


def test_a_box_standing_on_a_floor_mirror_meets_its_reflection_without_a_crack(scene):
    """Seen at a grazing angle, the box's base and its reflection's base touch: below every
    column of the box, the first mirror pixel shows the box again (a clip offset in front of
    the mirror plane left a line of sky there)."""
    ents = {}

    def build(world):
        base_scene(world)
        look_from(world, (0.0, 0.02, 1.0), target=(0.0, 0.0, 0.0), fov=40.0)
        ents["mirror"] = world.spawn(Transform(rotation=glm.angleAxis(-glm.pi() / 2, glm.vec3(1, 0, 0))),
                                     MeshRef(quad(6, 6)), Material(color=(0.1, 0.1, 0.1)), Mirror())
        ents["box"] = world.spawn(Transform(position=(0, 0.25, 0)), MeshRef(box((1, 0.5, 1))),
                                  Material(color=(0.9, 0.2, 0.1)), Emissive(0.5))

    runner = scene(build, SIZE)
    runner.frame()
    surface = runner.engine.renderer.targets.read_surface_ids()
    seen = runner.ids()
    columns = np.flatnonzero((surface == ents["box"]).any(axis=0))
    assert len(columns) > 100
    cracked = []
    for col in columns:
        below = np.flatnonzero(surface[:, col] == ents["box"]).max() + 1
        assert surface[below, col] == ents["mirror"]
        if seen[below, col] != ents["box"]:
            cracked.append(int(col))
    assert not cracked, f"{len(cracked)} columns show a gap between the box and its reflection"


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_double_sided_mirror_mesh_does_not_show_its_own_glass(scene, path):
    """A quad drawn with both windings (as exported assets often are): from the reflected
    camera behind the mirror its back triangles face the camera and lie on the mirror plane.
    The view leaves its own surface out by entity (without that, every mirror pixel of this
    view showed the glass), so the reflection is there."""
    from engine.assets.mesh import Mesh

    ents = {}
    single = quad(4, 3)
    double = Mesh(single.positions, single.normals, single.uvs,
                  np.concatenate([single.indices, single.indices[:, ::-1]]), name="two-sided glass")

    def build(world):
        base_scene(world)
        look_from(world, (0.3, 1.6, 3.0), target=(0.0, 1.5, -2.0))
        ents["mirror"] = world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(double),
                                     Material(color=(0.1, 0.1, 0.1)), Mirror())

    runner = scene(build, SIZE)
    runner.engine.reflection_system.path = path
    runner.frame()
    glass = runner.engine.renderer.targets.read_surface_ids() == ents["mirror"]
    assert glass.mean() > 0.2 and runner.stats.reflection_views == 1 and runner.stats.reflection_path == path
    assert (runner.ids()[glass] == ents["mirror"]).mean() < 0.01  # no glass seen in the glass
