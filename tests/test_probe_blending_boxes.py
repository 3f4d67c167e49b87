"""Probe blending where three influence boxes hold an object: it blends the two that weigh
most (ties: the nearer centre first), never the third, by the rules and in the frame.

Three probes on the x axis (A at 0, B at 2.5, C at 3.5), boxes 8 m a side with a 2 m
falloff, so at x = 0 the three weigh 1, 0.75 and 0.25: a rule that took the third box
instead of the second would blend A with C.  Each probe sees only a wall of its own colour
(its own reflection layer): A red, B green, C blue, so the frame says which probes were
mixed and by how much."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import Emissive, Material, MeshRef, ReflectionProbe, Reflective, Skybox, Transform, Visibility
from engine.assets.mesh import quad
from engine.core.world import World
from engine.rules.probe_rules import MAX_BLENDED_PROBES, probe_blend
from systems.transform_system import TransformSystem
from tests.support import look_from, pixel_rays, srgb_to_linear

CENTRES = {"a": 0.0, "b": 2.5, "c": 3.5}
COLOURS = {"a": (0.6, 0.05, 0.05), "b": (0.05, 0.6, 0.05), "c": (0.05, 0.05, 0.6)}
LAYERS = {"a": 1, "b": 2, "c": 3}
SIDE = 8.0
BLEND = 2.0
# Where all three boxes hold the quad: x = 0 (A 1, B 0.75, C 0.25), -0.2 (1, 0.65, 0.15),
# 1.7 (all at full weight: the nearer centres B, then A), 3.2 (C and B full, A 0.4).
POSITIONS = (0.0, -0.2, 1.7, 3.2)


def expected_blend(x: float, picks: tuple[int, int] = (0, 1)) -> dict[str, float]:
    """The rule written out on its own: each box's weight is the distance inside its nearest
    wall over the blend distance, at most 1; the two largest are kept (equal ones: the
    nearer centre first) and divided by their sum where it passes 1.  ``picks``: which of the
    ranked boxes are kept ((0, 2): the wrong rule, the third for the second)."""
    weights = {}
    for name, centre in CENTRES.items():
        inside = min(SIDE / 2 - abs(x - centre), SIDE / 2, SIDE / 2)
        weights[name] = 0.0 if inside < 0 else min(1.0, inside / BLEND)
    ranked = sorted((name for name in weights if weights[name] > 0),
                    key=lambda name: (-weights[name], abs(x - CENTRES[name])))
    kept = [ranked[i] for i in picks]
    total = max(1.0, sum(weights[name] for name in kept))
    return {name: weights[name] / total for name in kept}


def three_rooms(ents):
    """The three probes (captured once), each showing only its layer; a wall of each layer's
    colour behind the camera (+z), where the quad's reflection looks; a white chrome quad
    facing +z (flat: it samples the influence boxes, no probe of its own)."""
    def build(world):
        world.spawn(Skybox(zenith=(0.3, 0.3, 0.3), horizon=(0.3, 0.3, 0.3), ground=(0.3, 0.3, 0.3)))
        ents["camera"] = look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=30.0)
        facing_back = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        for name, centre in CENTRES.items():
            ents[name] = world.spawn(Transform(position=(centre, 0.0, 0.0)),
                                     ReflectionProbe(resolution=32, refresh="once", influence=(SIDE, SIDE, SIDE),
                                                     blend_distance=BLEND, shows_layers=[LAYERS[name]]))
            world.spawn(Transform(position=(0.0, 0.0, 6.0), rotation=facing_back), MeshRef(quad(200, 200)),
                        Material(color=COLOURS[name]), Emissive(1.0), Visibility(layers=[LAYERS[name]]))
        ents["quad"] = world.spawn(Transform(), MeshRef(quad(1.0, 1.0)),
                                   Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"))
    return build


def test_the_rules_blend_the_two_boxes_that_weigh_most_of_three():
    world = World("three-rooms")
    world.add_system(TransformSystem(world), priority=1)
    try:
        ents = {}
        three_rooms(ents)(world)
        assert MAX_BLENDED_PROBES == 2
        for x in POSITIONS:
            world.get(ents["quad"], Transform).position = glm.vec3(x, 0.0, 0.0)
            world.step(1 / 60)
            blend = probe_blend(world, ents["quad"])
            expect = expected_blend(x)
            assert blend.probes == tuple(ents[name] for name in expect), (x, blend, expect)
            assert blend.weights == pytest.approx(tuple(expect.values()), abs=1e-6), x
            assert blend.sky == pytest.approx(0.0, abs=1e-6), x  # two full boxes, or more than 1 between them
        # Each of the three is left out somewhere: no box is dropped for being what it is.
        assert {name for x in POSITIONS for name in CENTRES if name not in expected_blend(x)} == {"a", "c"}
    finally:
        world.close()


def _middle(runner, ents, x: float) -> np.ndarray:
    """The quad and the camera moved to ``x`` (so each pixel's ray is the same); the linear
    colour of the frame's middle."""
    runner.world.get(ents["quad"], Transform).position = glm.vec3(x, 0.0, 0.0)
    runner.world.get(ents["camera"], Transform).position = glm.vec3(x, 0.0, 3.0)
    rgb = runner.frame()
    h, w = rgb.shape[:2]
    return srgb_to_linear(rgb[h // 2 - 3:h // 2 + 3, w // 2 - 3:w // 2 + 3]).reshape(-1, 3).mean(axis=0)


def test_an_object_in_three_boxes_shows_the_two_strongest_probes_mixed_by_their_weights(scene):
    """Each probe's own colour is measured alone (the other two boxes taken away: that probe
    at full weight at its centre); where three boxes hold the quad its colour is the rule's two probes
    mixed by their weights, and far from the mix with the third probe instead."""
    ents = {}
    runner = scene(three_rooms(ents), (64, 48))
    runner.engine.renderer.antialias = "off"
    runner.frame()  # every probe captured (once)
    pure = {}
    for name in CENTRES:
        for other in CENTRES:
            runner.world.get(ents[other], ReflectionProbe).influence = (SIDE, SIDE, SIDE) if other == name else None
        pure[name] = _middle(runner, ents, CENTRES[name])
        assert probe_blend(runner.world, ents["quad"]).probes == (ents[name],)
    for other in CENTRES:
        runner.world.get(ents[other], ReflectionProbe).influence = (SIDE, SIDE, SIDE)
    # Each probe shows its own wall: red, green, blue, none black.
    for name, channel in (("a", 0), ("b", 1), ("c", 2)):
        colour = pure[name]
        assert colour[channel] > 0.05 and colour[channel] > 3 * np.delete(colour, channel).max(), (name, colour)
    spread = min(np.abs(pure[p] - pure[q]).max() for p in CENTRES for q in CENTRES if p < q)
    for x in POSITIONS:
        expect_weights = expected_blend(x)
        expect = sum(weight * pure[name] for name, weight in expect_weights.items())
        seen = _middle(runner, ents, x)
        assert np.abs(seen - expect).max() < 0.02 * spread + 0.004, (x, expect_weights, seen, expect)
        # The mix with the third probe in the second's place is far from what is seen.
        wrong = sum(weight * pure[name] for name, weight in expected_blend(x, picks=(0, 2)).items())
        assert np.abs(seen - wrong).max() > 0.2 * spread, (x, seen, wrong)


# Two box-projected probes whose boxes share their +X wall (x = 4), their y and z walls, and hold
# a plain smooth metal tile (no Reflective) at full weight each: A about (0, 1, 0), 8 m wide,
# B about (1, 1, 0), 6 m wide.  A red panel of light on the shared wall.
PROJECTED = {"a": ((0.0, 1.0, 0.0), (8.0, 4.0, 8.0)), "b": ((1.0, 1.0, 0.0), (6.0, 4.0, 8.0))}
TILE_AT = np.array([2.0, 0.0, 0.0])


def _on_panel(points: np.ndarray) -> np.ndarray:
    """Whether points on the plane x = 4 lie on the panel (2 x 2.4 about (4, 1.2, 0))."""
    return (np.abs(points[:, 1] - 1.2) < 1.2) & (np.abs(points[:, 2]) < 1.0)


def _seen_from(centre: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Whether a lookup of ``rays`` (rows, unprojected) from ``centre`` shows the panel."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (4.0 - centre[0]) / rays[:, 0]
        hit = centre + rays * t[:, None]
    return (rays[:, 0] > 1e-6) & _on_panel(hit)


def test_a_plain_metal_in_two_box_projected_boxes_shows_each_probe_projected_by_its_own_box(scene):
    """A smooth white metal tile with no Reflective (it samples the probes whose boxes hold it:
    a blend of A and B, half each) on the floor.  Each pixel's reflected ray, followed in numpy
    from the tile to the boxes' shared wall (ray-box intersection), meets the red panel or not;
    both probes, each box-projected by its own box, then say the same.  Where a lookup without
    the correction, from A's centre or from B's, would say otherwise, the pixel is red as a
    pixel all lookups agree is red (both probes show the panel) or not red at all: a probe looked
    up along the bare ray would leave half the red, or half of it where none belongs."""
    ents = {}
    size = (128, 96)

    def build(world):
        world.spawn(Skybox())
        look_from(world, (0.5, 0.4, 1.0), target=(4.0, 0.3, -0.3), fov=50.0)
        for name, (centre, box_size) in PROJECTED.items():
            ents[name] = world.spawn(Transform(position=centre), ReflectionProbe(
                resolution=128, refresh="once", influence=box_size, box_projection=True))
        ents["tile"] = world.spawn(Transform(position=tuple(TILE_AT),
                                             rotation=glm.angleAxis(-glm.pi() / 2, glm.vec3(1, 0, 0))),
                                   MeshRef(quad(3, 3)), Material(color=(1, 1, 1), metallic=1.0, roughness=0.0),
                                   Visibility(in_probes=False))
        world.spawn(Transform(position=(4.0, 1.2, 0.0), rotation=glm.angleAxis(-glm.pi() / 2, glm.vec3(0, 1, 0))),
                    MeshRef(quad(2.0, 2.4)), Material(color=(0.9, 0.05, 0.05)), Emissive(1.5))

    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    shown = srgb_to_linear(runner.frame()).reshape(-1, 3)
    blend = probe_blend(runner.world, ents["tile"])
    assert set(blend.probes) == {ents["a"], ents["b"]} and blend.weights == pytest.approx((0.5, 0.5))
    eye, rays = pixel_rays(runner.engine.main_view, size)
    rays = rays.reshape(-1, 3)
    on_tile = runner.ids().reshape(-1) == ents["tile"]
    points = eye + rays * (-eye[1] / rays[:, 1])[:, None]
    reflected = rays * np.array([1.0, -1.0, 1.0])

    def corrected(r: np.ndarray) -> np.ndarray:
        """The panel along ``r`` from the tile's points: each ray to the first wall of the box
        (y in [-1, 3], z in [-4, 4], x = 4: both boxes' walls for a ray going +x)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.minimum((np.where(r[:, 1] > 0, 3.0, -1.0) - points[:, 1]) / r[:, 1],
                           (np.where(r[:, 2] > 0, 4.0, -4.0) - points[:, 2]) / r[:, 2])
            tx = (4.0 - points[:, 0]) / r[:, 0]
        hit = points + r * tx[:, None]
        return (r[:, 0] > 1e-6) & (tx <= t) & _on_panel(hit)

    truth = corrected(reflected)
    plain = [_seen_from(np.array(centre), reflected) for centre, _ in PROJECTED.values()]
    # Clear of the panel's edges, where a texel's blur decides: the answers the same for rays
    # turned a little each way.
    steady = on_tile.copy()
    for turn in ((0, 0.06, 0), (0, -0.06, 0), (0, 0, 0.06), (0, 0, -0.06)):
        steady &= corrected(reflected + np.array(turn)) == truth
        for centre, _ in PROJECTED.values():
            steady &= _seen_from(np.array(centre), reflected + np.array(turn)) == _seen_from(np.array(centre),
                                                                                             reflected)
    differ = steady & ((truth != plain[0]) | (truth != plain[1]))
    assert (differ & truth).sum() > 20 and (differ & ~truth).sum() > 20, ((differ & truth).sum(),
                                                                           (differ & ~truth).sum())

    def redness(linear: np.ndarray) -> np.ndarray:
        return linear[:, 0] - np.maximum(linear[:, 1], linear[:, 2])

    # The panel's red at full weight: A's box alone holding the tile (B's taken away).
    runner.world.get(ents["b"], ReflectionProbe).influence = None
    runner.frame()
    alone = redness(srgb_to_linear(runner.frame()).reshape(-1, 3))
    assert probe_blend(runner.world, ents["tile"]).probes == (ents["a"],)
    full = np.median(alone[differ & truth])
    assert full > 0.3, full
    for red in (alone, redness(shown)):
        assert np.mean(np.abs(red[differ & truth] - full) < 0.15 * full) > 0.95, np.percentile(red[differ & truth], 5)
        assert np.mean(red[differ & ~truth] < 0.1 * full) > 0.95, np.percentile(red[differ & ~truth], 95)
