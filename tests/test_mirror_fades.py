"""Mirror fades (issue 27 item 2): a distance and an angle fade, off by default.  The weight
is checked against its formula (linear from start to end, the product of the two, from each
view's own eye), the image against a second path (a mirror without fades whose reflect rate
is the faded weight), and a fully faded mirror against the counters of no mirror at all."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from benchmarks.mirrors import MirrorRing
from components import ComponentValueError, DirectionalLight, Emissive, Material, MeshRef, Mirror, Transform
from engine.assets.level_file import LevelError, load_level
from engine.assets.mesh import box, quad
from engine.core.world import World
from tests.support import SceneRunner, linear_to_srgb8, look_from, srgb_to_linear

MIRROR_AT = glm.vec3(0.0, 1.5, -2.0)
HALF = 0.6  # the mirror is 1.2 x 1.2


def _room(mirror: Mirror, eye):
    """A mirror on a wall facing the camera at ``eye``, and a red glowing panel behind the
    camera for it to reflect; the mirror's own material is dark blue."""
    def build(world: World) -> None:
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        look_from(world, eye, target=MIRROR_AT, fov=50.0)
        world.spawn(Transform(position=MIRROR_AT), MeshRef(quad(2 * HALF, 2 * HALF)),
                    Material(color=(0.05, 0.1, 0.6)), mirror)
        world.spawn(Transform(position=(0.0, 1.5, 14.0), scale=(60, 30, 0.1)), MeshRef(box()),
                    Material(color=(0.9, 0.1, 0.1)), Emissive(1.0))
    return build


def _expected_weight(eye, distance=None, angle=None) -> float:
    """The fades' formula, worked out here from the mirror's geometry: distance to the
    mirror's bounding sphere, angle between its normal (+Z) and the direction to the eye."""
    eye = glm.vec3(eye)
    to_eye = eye - MIRROR_AT
    weight = 1.0
    if distance is not None:
        d = max(glm.length(to_eye) - math.sqrt(2.0) * HALF, 0.0)
        weight *= min(max((distance[1] - d) / (distance[1] - distance[0]), 0.0), 1.0)
    if angle is not None:
        a = math.degrees(math.acos(glm.dot(glm.normalize(to_eye), glm.vec3(0, 0, 1))))
        weight *= min(max((angle[1] - a) / (angle[1] - angle[0]), 0.0), 1.0)
    return weight


def _mirror_pixels(ctx, mirror: Mirror, eye) -> tuple[np.ndarray, SceneRunner]:
    runner = SceneRunner(ctx, _room(mirror, eye), (160, 120))
    image = runner.frame()
    x, y = runner.project(MIRROR_AT)
    return image[y - 6:y + 6, x - 6:x + 6].reshape(-1, 3).astype(float), runner


@pytest.mark.parametrize("eye, fades", [
    ((0.0, 1.5, 4.0), {"fade_distance": (3.0, 8.0)}),                      # halfway down the distance fade
    ((3.2, 1.5, 1.2), {"fade_angle": (20.0, 60.0)}),                       # seen at ~48 degrees
    ((2.0, 1.5, 3.0), {"fade_distance": (2.0, 9.0), "fade_angle": (10.0, 70.0)}),  # both at once
])
def test_a_partly_faded_mirror_shows_its_reflection_at_the_faded_weight(ctx, eye, fades):
    weight = _expected_weight(eye, fades.get("fade_distance"), fades.get("fade_angle"))
    assert 0.15 < weight < 0.85, f"the case should sit inside its fade, got weight {weight}"
    faded, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.9, **fades), eye)
    (view,) = runner.engine.reflection_system.views[1:]
    assert view.fade == pytest.approx(weight, abs=1e-6)
    runner.close()
    # The second path: the mirror unfaded and switched off (its fallback, the sky's
    # reflection: issue 36), mixed by the weight in linear light: the faded share of the
    # reflection is the fallback's, not the mirror's own shading.
    off, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.9, enabled=False), eye)
    runner.close()
    unfaded, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.9), eye)
    runner.close()
    second = linear_to_srgb8(weight * srgb_to_linear(unfaded) + (1.0 - weight) * srgb_to_linear(off))
    assert np.abs(faded - second).max() <= 2.0
    assert faded[:, 0].mean() < unfaded[:, 0].mean() - 20.0  # less of the red panel than unfaded


def test_a_mirror_past_its_fades_costs_no_view_and_shows_its_fallback(ctx):
    """Past its fades a mirror costs no view and shows its fallback (the sky's reflection,
    issue 36), as a mirror switched off does, not its own dark blue."""
    eye = (0.0, 1.5, 4.0)
    faded, runner = _mirror_pixels(ctx, Mirror(fade_distance=(1.0, 3.0)), eye)  # 6 m away, past 3
    stats = runner.engine.renderer.stats
    assert stats.reflection_views == 0 and stats.reflection_views_faded == 1
    assert stats.reflection_fallbacks == 1
    passes, draws = stats.passes, stats.draw_calls
    runner.close()
    plain, runner = _mirror_pixels(ctx, Mirror(enabled=False), eye)
    assert (runner.stats.passes, runner.stats.draw_calls) == (passes, draws)
    runner.close()
    assert np.abs(faded - plain).max() <= 1.0
    material, runner = _mirror_pixels(ctx, Mirror(reflect_rate=0.0), eye)  # the mirror's own shading
    runner.close()
    assert np.abs(faded - material).max(axis=1).mean() > 20.0


def test_every_mirror_faded_out_costs_what_no_mirror_costs(ctx):
    """The 8-mirror benchmark ring with every mirror faded: no view, and the passes and draws
    of the same ring with its mirrors switched off (the frame's cost is the benchmark's,
    ``python -m benchmarks mirrors --faded``)."""
    counts = {}
    for case in ("faded", "off"):
        game = MirrorRing(8)
        runner = SceneRunner(ctx, game.build, (160, 90))
        runner.engine.game = game
        for _, mirror in runner.world.query_one(Mirror):
            if case == "faded":
                mirror.fade_distance = (0.0, 0.5)
            else:
                mirror.enabled = False
        runner.frame()
        stats = runner.stats
        counts[case] = (stats.reflection_views, stats.passes, stats.draw_calls)
        if case == "faded":
            assert stats.reflection_views_faded >= 4
        runner.close()
    assert counts["faded"] == counts["off"] and counts["faded"][0] == 0


def test_a_mirror_seen_in_a_mirror_fades_by_the_reflected_eye(ctx):
    """Two mirrors side by side facing a third, all with a distance fade: each view's weight
    is the formula from its own parent's eye (a reflected eye from the second level on, one
    per mirror it was seen in), not the camera's."""
    def build(world: World) -> None:
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=1.0))
        look_from(world, (0.5, 1.5, 0.5), target=(0.0, 1.5, -3.0), fov=80.0)
        for x, z, turn in ((-1.3, -3.0, 0.0), (1.3, -4.0, 0.0), (0.0, 3.0, math.pi)):
            world.spawn(Transform(position=(x, 1.5, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                        MeshRef(quad(2.4, 2.0)), Material(color=(0.2, 0.2, 0.2)),
                        Mirror(fade_distance=(2.0, 16.0), max_depth=3))
    runner = SceneRunner(ctx, build, (160, 120))
    runner.frame()
    views = runner.engine.reflection_system.views[1:]
    assert len({v.parent.index for v in views if v.level == 2}) >= 2  # several reflected eyes on one level
    for v in views:
        corners = v.surface.corners[:, :3]
        centre = corners.mean(axis=0)
        radius = np.linalg.norm(corners - centre, axis=1).max()
        eye = np.array(v.parent.view.eye)
        d = max(np.linalg.norm(eye - centre) - radius, 0.0)
        assert v.fade == pytest.approx(min(max((16.0 - d) / 14.0, 0.0), 1.0), abs=1e-5)
    assert len({round(v.fade, 4) for v in views}) >= 2  # deeper views are farther: they fade more
    runner.close()


@pytest.mark.parametrize("field, value", [
    ("fade_distance", (5.0, 2.0)), ("fade_distance", (-1.0, 2.0)), ("fade_distance", (1.0, float("inf"))),
    ("fade_angle", (10.0, 95.0)), ("fade_angle", (30.0, 30.0)), ("fade_angle", "far"),
])
def test_bad_fades_are_refused_naming_the_field(field, value):
    with pytest.raises(ComponentValueError, match=f"Mirror.{field}"):
        Mirror(**{field: value})


def test_level_files_carry_fades(tmp_path):
    text = """
[level]
name = "fades"

[[entity]]
name = "glass"
[entity.Transform]
[entity.MeshRef]
mesh = { quad = [1.0, 1.0] }
[entity.Mirror]
fade_distance = [4.0, 12.0]
fade_angle = [30.0, 75.0]
"""
    path = tmp_path / "fades.toml"
    path.write_text(text)
    world = World()
    load_level(path).spawn(world)
    ((_, mirror),) = world.query_one(Mirror)
    assert mirror.fade_distance == (4.0, 12.0) and mirror.fade_angle == (30.0, 75.0)
    path.write_text(text.replace("75.0", "120.0"))
    with pytest.raises(LevelError, match="fade_angle"):
        load_level(path)
