"""Probe blending: where reflection probes' influence boxes overlap, an object blends the
probes by weight (a linear falloff ``blend_distance`` wide inside each box's walls, the
weights normalised), so it crosses from one probe's room to the next without a pop."""
from __future__ import annotations

import re

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    Emissive,
    Material,
    MeshRef,
    ReflectionProbe,
    Reflective,
    Skybox,
    Transform,
)
from engine.assets.mesh import quad
from engine.core.world import World
from engine.rules.probe_rules import LookChanges, probe_blend, probe_for, probe_weight
from systems.transform_system import TransformSystem
from tests.support import look_from, srgb_to_linear

# Two rooms along x: A's box spans x in [-7, 1], B's x in [-1, 7]; they overlap in [-1, 1].
CENTRES = {"a": (-3.0, 0.0, 0.0), "b": (3.0, 0.0, 0.0)}
INFLUENCE = (8.0, 4.0, 4.0)
BLEND = 1.0


def expected_weights(x: float, blend: float = BLEND) -> tuple[float, float, float]:
    """The weights' formula, written out here on its own: each box's weight is its position's
    distance inside the box's nearest wall over the blend distance, at most 1 (0 outside);
    the two are divided by their sum where it passes 1; the sky has what is left."""
    weights = []
    for centre in CENTRES.values():
        inside = min(INFLUENCE[axis] / 2 - abs((x, 0.0, 0.0)[axis] - centre[axis]) for axis in range(3))
        weights.append(0.0 if inside < 0 else 1.0 if blend == 0 else min(1.0, inside / blend))
    total = max(1.0, sum(weights))
    a, b = weights[0] / total, weights[1] / total
    return a, b, 1.0 - a - b


def two_rooms(ents, blend=BLEND):
    """Probe A sees a red wall where an object's reflection looks (+z), probe B a blue one: the
    walls meet at x = 0, 6 in front of the probes, behind the camera.  A white chrome quad
    (flat: it samples the influence boxes, not a probe of its own) faces +z."""
    def build(world):
        world.spawn(Skybox(zenith=(0.05, 0.4, 0.05), horizon=(0.05, 0.4, 0.05), ground=(0.05, 0.4, 0.05)))
        ents["camera"] = look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=30.0)
        for name, centre in CENTRES.items():
            ents[name] = world.spawn(Transform(position=centre),
                                     ReflectionProbe(resolution=32, refresh="once", influence=INFLUENCE,
                                                     blend_distance=blend))
        facing_back = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
        for x, colour in ((-6.0, (0.6, 0.05, 0.05)), (6.0, (0.05, 0.05, 0.6))):
            world.spawn(Transform(position=(x, 0.0, 6.0), rotation=facing_back), MeshRef(quad(12, 12)),
                        Material(color=colour), Emissive(1.0))
        ents["quad"] = world.spawn(Transform(), MeshRef(quad(1.0, 1.0)),
                                   Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"))
    return build


def place(runner, ents, x: float) -> np.ndarray:
    """Move the quad (and the camera with it, so each pixel's ray is the same) to ``x``;
    the linear colour of the quad's middle."""
    world = runner.world
    world.get(ents["quad"], Transform).position = glm.vec3(x, 0.0, 0.0)
    world.get(ents["camera"], Transform).position = glm.vec3(x, 0.0, 3.0)
    rgb = runner.frame()
    h, w = rgb.shape[:2]
    return srgb_to_linear(rgb[h // 2 - 3:h // 2 + 3, w // 2 - 3:w // 2 + 3]).reshape(-1, 3).mean(axis=0)


@pytest.fixture
def world():
    """A world that steps the transform stage only: the rules read world matrices, no GL."""
    w = World("probe-blending")
    w.add_system(TransformSystem(w), priority=1)
    yield w
    w.close()


def test_the_rules_weigh_the_boxes_by_their_falloff(world):
    """probe_blend's probes and weights at known positions (in one box, in the overlap, in a
    lone box's falloff, outside both) against the formula; probe_for names the strongest."""
    ents = {}
    two_rooms(ents)(world)
    tile = ents["quad"]
    for x in (-8.0, -6.6, -3.0, -1.0, -0.5, 0.0, 0.3, 0.95, 1.0, 4.0, 6.5, 7.5):
        world.get(tile, Transform).position = glm.vec3(x, 0.0, 0.0)
        world.step(1 / 60)
        blend = probe_blend(world, tile)
        a, b, sky = expected_weights(x)
        got = dict(zip(blend.probes, blend.weights, strict=True))
        assert got.get(ents["a"], 0.0) == pytest.approx(a, abs=1e-6), x
        assert got.get(ents["b"], 0.0) == pytest.approx(b, abs=1e-6), x
        assert blend.sky == pytest.approx(sky, abs=1e-6), x
        assert set(blend.probes) == {ents[k] for k, w in (("a", a), ("b", b)) if w > 0}, x
        assert probe_for(world, tile) == (0 if a == b == 0 else ents["a"] if a >= b else ents["b"]), x
    # The object's own probe is sampled alone, whatever boxes hold it.
    world.add_component(tile, ReflectionProbe())
    world.step(1 / 60)
    assert probe_blend(world, tile).probes == (tile,) and probe_blend(world, tile).weights == (1.0,)


def test_the_boxes_blends_at_once_are_each_ones_blend(world):
    """box_blends (numpy, every plain mesh at once: a moving box asks again of all of them)
    against box_blend (one position, the rule written out there) at 400 random places among
    four overlapping boxes, with and without falloffs, and two boxes at one centre (a tie:
    the lower owner first); and a plain mesh's probe_blend is its box_blend."""
    from engine.rules.probe_rules import box_blend, box_blends
    rng = np.random.default_rng(5)
    for centre, size, blend in (((0.0, 0.0, 0.0), (6.0, 4.0, 6.0), 1.0), ((3.0, 0.5, 1.0), (5.0, 5.0, 5.0), 0.0),
                                ((-2.0, 0.0, 2.0), (4.0, 3.0, 4.0), 1.5), ((-2.0, 0.0, 2.0), (4.0, 3.0, 4.0), 0.5)):
        world.spawn(Transform(position=centre), ReflectionProbe(influence=size, blend_distance=blend))
    meshes = [world.spawn(Transform(position=tuple(rng.uniform(-5.0, 5.0, 3))), MeshRef(quad(0.2, 0.2)), Material())
              for _ in range(400)]
    world.step(1 / 60)
    at_once = box_blends(world, meshes)
    held = 0
    for entity in meshes:
        one = box_blend(world, world.get(entity, Transform).world[3].xyz)
        assert at_once[entity].probes == one.probes, entity
        np.testing.assert_allclose(at_once[entity].weights, one.weights, rtol=1e-9, atol=1e-12)
        assert probe_blend(world, entity) == one  # (a plain mesh samples the boxes that hold it)
        held += bool(one.probes)
    assert 50 < held < 400  # (places in boxes, in their overlaps and outside all of them)


def test_a_move_inside_the_falloff_changes_the_look_and_one_inside_full_weight_does_not(world):
    """``LookChanges`` (what the extract stage rewrites rows for and the probes scheduler
    recaptures for) has an object whose weights changed: a step within the overlap, or a
    probe's blend distance written; a step where one probe holds it at full weight is no
    change of look."""
    ents = {}
    two_rooms(ents)(world)
    tile = ents["quad"]
    looks = LookChanges()

    def step_to(x: float) -> set[int]:
        world.get(tile, Transform).position = glm.vec3(x, 0.0, 0.0)
        world.step(1 / 60)
        return looks.entities(world)

    assert tile in step_to(-3.0)
    assert tile not in step_to(-3.5)  # A alone at full weight: the same look
    assert tile in step_to(0.2)
    assert tile in step_to(0.3)       # the weights moved on
    world.get(ents["a"], ReflectionProbe).blend_distance = 0.5  # A at x = 0.3: 0.7 / 0.5, full weight
    world.step(1 / 60)
    assert tile in looks.entities(world)


def test_blend_distance_is_checked_against_the_box():
    assert ReflectionProbe(influence=(4, 2, 6), blend_distance=1.0).blend_distance == 1.0
    with pytest.raises(ComponentValueError, match=r"ReflectionProbe\.blend_distance.*half the influence"):
        ReflectionProbe(influence=(4, 2, 6), blend_distance=1.5)
    with pytest.raises(ComponentValueError, match=r"ReflectionProbe\.blend_distance"):
        ReflectionProbe(blend_distance=-0.1)
    with pytest.raises(ComponentValueError, match=r"ReflectionProbe\.blend_distance"):
        ReflectionProbe(blend_distance=float("nan"))
    probe = ReflectionProbe(influence=(4, 4, 4), blend_distance=2.0)
    with pytest.raises(ComponentValueError, match=r"ReflectionProbe\.influence.*half the influence"):
        probe.influence = (2, 4, 4)
    assert probe.influence == glm.vec3(4, 4, 4)


def test_a_level_file_carries_blend_distance(tmp_path):
    """Loaded, spawned and saved back; a blend distance wider than half the box is refused
    when the level loads, naming the field."""
    from engine.assets.level_file import LevelError, load_level, save_level

    path = tmp_path / "rooms.toml"
    text = """
[level]
name = "rooms"

[[entity]]
name = "room_a"
[entity.Transform]
position = [-3.0, 0.0, 0.0]
[entity.ReflectionProbe]
influence = [8.0, 4.0, 4.0]
blend_distance = 1.5
"""
    path.write_text(text, encoding="utf-8")
    world = World("rooms-level")
    try:
        names = load_level(path).spawn(world)
        assert world.get(names["room_a"], ReflectionProbe).blend_distance == 1.5
        saved = save_level(world, tmp_path / "again.toml", names)
        assert "blend_distance = 1.5" in saved.read_text(encoding="utf-8")
    finally:
        world.close()
    path.write_text(text.replace("1.5", "2.5"), encoding="utf-8")
    with pytest.raises(LevelError, match=r"blend_distance"):
        load_level(path)


def test_an_object_in_the_overlap_shows_the_probes_mixed_by_their_weights(scene):
    """A white chrome quad at known positions: where one probe holds it at full weight it
    shows that room's colour (A red, B blue), outside both boxes the sky (green); in the
    overlap and in a lone box's falloff its colour is the weights' formula (worked out in
    this test) applied to those three colours; and crossing from A to B in steps of 0.1
    changes it by small steps (no pop: a hard switch of probes would jump by the whole
    difference)."""
    ents = {}
    runner = scene(two_rooms(ents), (64, 48))
    runner.engine.renderer.antialias = "off"
    pure = {"a": place(runner, ents, -3.0), "b": place(runner, ents, 3.0), "sky": place(runner, ents, -8.0)}
    # The three sources are far apart (red, blue, green), and none is black.
    assert pure["a"][0] > 3 * pure["a"][2] and pure["b"][2] > 3 * pure["b"][0] and pure["a"][0] > 0.05
    assert pure["sky"][1] > 3 * max(pure["sky"][0], pure["sky"][2]) and pure["sky"][1] > 0.05
    spread = np.abs(pure["a"] - pure["b"]).max()
    for x in (-6.5, -6.8, -0.7, 0.0, 0.4, 0.8, 6.6):
        a, b, sky = expected_weights(x)
        expect = a * pure["a"] + b * pure["b"] + sky * pure["sky"]
        seen = place(runner, ents, x)
        assert np.abs(seen - expect).max() < 0.02 * spread + 0.004, (x, (a, b, sky), seen, expect)
    previous = place(runner, ents, -1.3)
    steps = []
    for x in np.arange(-1.2, 1.31, 0.1):
        colour = place(runner, ents, float(x))
        steps.append(np.abs(colour - previous).max())
        previous = colour
    assert np.abs(previous - pure["b"]).max() < 0.01 * spread  # it has crossed into B
    assert max(steps) < 0.15 * spread, steps
    assert sum(steps) > 0.9 * spread  # ...by many small steps that add up to the whole change


def test_probe_blending_is_defined_in_the_probe_rules_only():
    """The weights' rule has one owner (the extract stage, the scheduler's LookChanges and
    the scene export all read it from engine/rules/probe_rules.py)."""
    from tests.test_probe_schedule import ROOT, top_level_names

    pattern = re.compile(r"probe_blend|probe_weight|ProbeBlend|MAX_BLENDED_PROBES|NO_PROBE")
    defined = {}
    for package in ("components", "engine", "systems", "shell", "games", "benchmarks"):
        for path in sorted((ROOT / package).rglob("*.py")):
            hits = sorted(n for n in top_level_names(path) if pattern.fullmatch(n))
            if hits:
                defined[path.relative_to(ROOT).as_posix()] = hits
    assert set(defined) == {"engine/rules/probe_rules.py"}, defined


def test_the_editors_outline_of_a_probe_is_where_its_weight_falls(world):
    """``reach_outline`` of a selected probe (shell/handles.py): the twelve edges of its
    influence box and twelve of the box ``blend_distance`` inside it, and the rule agrees:
    just outside each outer corner the probe weighs nothing and just inside something; just
    inside each inner corner it weighs 1 and just outside less.  A probe with no influence
    box (it serves its own entity) has no outline."""
    from shell.handles import reach_outline

    ents = {}
    two_rooms(ents)(world)
    world.step(1 / 60)
    view_proj = glm.perspective(glm.radians(60.0), 1.0, 0.1, 100.0) * glm.lookAt(glm.vec3(-3.0, 6.0, 14.0),
                                                                                 glm.vec3(-3.0, 0.0, 0.0),
                                                                                 glm.vec3(0.0, 1.0, 0.0))
    outline = reach_outline(world, ents["a"], view_proj, (640, 480))
    assert len(outline.world) == 24 and len(outline.lines) == 24
    centre = np.array(CENTRES["a"])

    def weight(point) -> float:
        return probe_weight(point, centre, INFLUENCE, BLEND)

    outer = {tuple(map(float, p)) for edge in outline.world[:12] for p in edge}
    inner = {tuple(map(float, p)) for edge in outline.world[12:] for p in edge}
    assert len(outer) == len(inner) == 8
    for corner in outer:
        towards = (centre - np.array(corner)) * 1e-3
        assert weight(np.array(corner) - towards) == 0.0 and weight(np.array(corner) + towards) > 0.0
    for corner in inner:
        towards = (centre - np.array(corner)) * 1e-3
        assert weight(np.array(corner) + towards) == pytest.approx(1.0) and weight(np.array(corner) - towards) < 1.0
    world.add_component(ents["quad"], ReflectionProbe())
    assert reach_outline(world, ents["quad"], view_proj, (640, 480)) is None
