"""Animation layers (``AnimationLayer``): a second clip laid over a model's ``Animation``.
The door of tests/test_model_animation.py (a hinge node turned by "Open", the door node under
it moved by "Slide"): each layered pose against the matrices glm multiplies out from the two
clips' keys, mixed or added by hand (override: towards the layer's by its weight; additive:
its change from its first key added on); a mask (``root``) keeping the layer to a subtree;
a layer alone over the rest pose, moved on by its own speed, and taken away; a skinned arm's
joints and a sheet's morph weights layered; level files and refusals."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import Animation, AnimationLayer, ComponentValueError, FromModel, Morph, Skin
from engine.assets.models import spawn_model
from engine.core.errors import AssetError
from engine.core.world import World
from systems.model_system import ModelSystem
from tests.test_model_animation import QUARTER, close, door, door_matrix

HINGE, REST = glm.translate(glm.vec3(1, 0, 0)), glm.vec3(0.5, 0, 0)


def slide(s: float) -> glm.vec3:
    """The door's place in "Slide" at ``s`` s (its one cubic span, Hermite by hand)."""
    return (2 * s ** 3 - 3 * s ** 2 + 1) * glm.vec3(0.5, 0, 0) + (s ** 3 - 2 * s ** 2 + s) * glm.vec3(1, 0, 0) \
        + (-2 * s ** 3 + 3 * s ** 2) * glm.vec3(0.5, 1, 0) + (s ** 3 - s ** 2) * glm.vec3(1, 0, 0)


def opened(t: float) -> glm.quat:
    return glm.slerp(glm.quat(), QUARTER, t / 2.0)


def posed(tmp_path, animation: Animation | None, layer: AnimationLayer, steps=(0.0,)) -> tuple[World, list[glm.mat4]]:
    world = World("layered")
    root = spawn_model(world, door(tmp_path / "door.glb"))
    if animation is not None:
        world.add_component(root, animation)
    world.add_component(root, layer)
    stage = ModelSystem(world)
    placed = []
    for dt in steps:
        stage.process(dt)
        placed.append(door_matrix(world))
    return world, placed


def test_an_override_layer_moves_the_nodes_it_animates_towards_its_pose_by_its_weight(tmp_path):
    """"Slide" at 0.5 s over "Open" at 1 s, weight 0.4: the hinge as "Open" turns it (the layer
    animates only the door), the door 0.4 of the way from its rest place to Slide's."""
    _, (m,) = posed(tmp_path, Animation("Open", time=1.0, playing=False),
                    AnimationLayer("Slide", time=0.5, playing=False, weight=0.4))
    assert close(m, HINGE * glm.mat4_cast(opened(1.0)) * glm.translate(REST + 0.4 * (slide(0.5) - REST)))
    _, (whole,) = posed(tmp_path, Animation("Open", time=1.0, playing=False),
                        AnimationLayer("Slide", time=0.5, playing=False))
    assert close(whole, HINGE * glm.mat4_cast(opened(1.0)) * glm.translate(slide(0.5)))


def test_an_override_layer_on_the_same_node_turns_it_along_the_shorter_arc(tmp_path):
    """"Open" at 0.5 s laid at weight 0.5 over "Open" at 2 s: the hinge half way between the
    two turns (glm's slerp)."""
    _, (m,) = posed(tmp_path, Animation("Open", time=2.0, playing=False),
                    AnimationLayer("Open", time=0.5, playing=False, weight=0.5))
    assert close(m, HINGE * glm.mat4_cast(glm.slerp(opened(2.0), opened(0.5), 0.5)) * glm.translate(REST))


def test_an_additive_layer_adds_its_change_from_its_first_key(tmp_path):
    """Additive: "Open" at 2 s (a quarter turn from its first key's none) over "Open" at 1 s
    turns the hinge an eighth and then a quarter; at weight 0.5 an eighth and an eighth.
    "Slide" at 0.5 s over "Slide" at 1 s: Slide's place at 1 s plus its move from its first
    key at 0.5 s."""
    _, (m,) = posed(tmp_path, Animation("Open", time=1.0, playing=False),
                    AnimationLayer("Open", time=2.0, playing=False, blend="additive"))
    assert close(m, HINGE * glm.mat4_cast(opened(1.0) * QUARTER) * glm.translate(REST))
    _, (half,) = posed(tmp_path, Animation("Open", time=1.0, playing=False),
                       AnimationLayer("Open", time=2.0, playing=False, blend="additive", weight=0.5))
    assert close(half, HINGE * glm.mat4_cast(opened(1.0) * opened(1.0)) * glm.translate(REST))
    _, (moved,) = posed(tmp_path, Animation("Slide", time=1.0, playing=False),
                        AnimationLayer("Slide", time=0.5, playing=False, blend="additive"))
    assert close(moved, HINGE * glm.translate(slide(1.0) + slide(0.5) - slide(0.0)))


def test_a_layers_root_keeps_it_to_that_node_and_those_under_it(tmp_path):
    """"Open" as a layer rooted at "door" touches nothing (it animates the hinge, above the
    door): the base pose alone; rooted at "hinge" it turns it; a root the model lacks is
    refused naming its nodes."""
    base = HINGE * glm.translate(slide(0.5))
    _, (kept,) = posed(tmp_path, Animation("Slide", time=0.5, playing=False),
                       AnimationLayer("Open", time=2.0, playing=False, root="door"))
    assert close(kept, base)
    _, (turned,) = posed(tmp_path, Animation("Slide", time=0.5, playing=False),
                         AnimationLayer("Open", time=2.0, playing=False, root="hinge"))
    assert close(turned, HINGE * glm.mat4_cast(QUARTER) * glm.translate(slide(0.5)))
    with pytest.raises(AssetError, match=r"AnimationLayer: its model has no node 'spine' \(its nodes: 'hinge', "
                                         r"'door'\)"):
        posed(tmp_path, None, AnimationLayer("Open", root="spine"))
    with pytest.raises(AssetError, match=r"no clip 'Wave' \(its clips: 'Open', 'Slide', 'Blink'\)"):
        posed(tmp_path, None, AnimationLayer("Wave"))


def test_a_layer_alone_plays_over_the_rest_pose_by_its_own_speed_and_goes(tmp_path):
    """Without an Animation the layer lies over the rest pose; it moves on by its own speed
    (0.5: 1 s of frames is 0.5 s of clip); taken away, the parts go back to rest."""
    world, placed = posed(tmp_path, None, AnimationLayer("Open", speed=0.5), steps=(0.0, 1.0))
    assert close(placed[0], HINGE * glm.translate(REST))
    assert close(placed[1], HINGE * glm.mat4_cast(opened(0.5)) * glm.translate(REST))
    ((root, layer),) = list(world.query_one(AnimationLayer))
    assert layer.time == pytest.approx(0.5)
    world.remove_component(root, AnimationLayer)
    ModelSystem(world).process(0.1)
    assert close(door_matrix(world), HINGE * glm.translate(REST))


def test_a_layer_bends_a_skin_and_weighs_morph_targets(tmp_path):
    """The skinned arm's "Bend" as an additive layer at 1 s over "Bend" at 0.5 s: the elbow
    turned an eighth and then a quarter (its joint matrix); the sheet's "Breathe" as an
    override at weight 0.5 over its rest weights (0.25, 0): half way to (0.5, 0.25)."""
    from tests.test_morph_targets import sheet_glb
    from tests.test_skinning import arm_glb, elbow_matrix

    world = World("arm")
    root = spawn_model(world, arm_glb(tmp_path / "arm.glb"))
    world.add_component(root, Animation("Bend", time=0.5, playing=False))
    world.add_component(root, AnimationLayer("Bend", time=1.0, playing=False, blend="additive"))
    ModelSystem(world).process(0.0)
    ((entity, _),) = list(world.query_one(FromModel))
    turned = elbow_matrix(math.pi / 4 + math.pi / 2)   # (an eighth, then the quarter added)
    np.testing.assert_allclose(world.get(entity, Skin).joint_matrices[1], turned, atol=1e-5)

    world = World("sheet")
    root = spawn_model(world, sheet_glb(tmp_path / "sheet.glb"))
    world.add_component(root, AnimationLayer("Breathe", time=1.0, playing=False, weight=0.5))
    ModelSystem(world).process(0.0)
    ((entity, _),) = list(world.query_one(FromModel))
    np.testing.assert_allclose(world.get(entity, Morph).weights, [0.25 + 0.5 * (0.5 - 0.25), 0.5 * 0.25], atol=1e-6)


def test_bad_layer_values_are_refused_when_given():
    with pytest.raises(ComponentValueError, match=r"AnimationLayer.weight"):
        AnimationLayer("Open", weight=1.5)
    with pytest.raises(ComponentValueError, match=r"AnimationLayer.blend"):
        AnimationLayer("Open", blend="multiply")
    with pytest.raises(ComponentValueError, match=r"AnimationLayer.root must be a node's name"):
        AnimationLayer("Open", root=3)


def test_a_level_file_lays_a_layer_and_refuses_a_clip_or_root_the_model_lacks_by_its_line(tmp_path):
    """``[entity.AnimationLayer]`` in a level file plays over its Animation and is saved back;
    a clip or a root the file lacks fails the load, naming the line and those it has."""
    from engine.assets.level_file import LevelError, load_level
    from engine.assets.level_save import save_level

    door(tmp_path / "door.glb")
    text = ('[level]\nname = "hall"\n\n[[entity]]\nname = "door"\n[entity.Transform]\n[entity.Model]\n'
            'file = "door.glb"\n[entity.Animation]\nclip = "Open"\ntime = 1.0\nplaying = false\n'
            '[entity.AnimationLayer]\nclip = "CLIP"\ntime = 0.5\nplaying = false\nweight = 0.4\nroot = "ROOT"\n')
    (tmp_path / "hall.toml").write_text(text.replace("CLIP", "Slide").replace("ROOT", "door"))
    world = World("hall")
    names = load_level(tmp_path / "hall.toml").spawn(world)
    ModelSystem(world).process(0.0)
    layered = HINGE * glm.mat4_cast(opened(1.0)) * glm.translate(REST + 0.4 * (slide(0.5) - REST))
    assert close(door_matrix(world), layered)
    saved = save_level(world, tmp_path / "again.toml", names, name="hall").read_text()
    assert 'root = "door"' in saved and 'clip = "Slide"' in saved and "weight = 0.4" in saved
    (tmp_path / "hall.toml").write_text(text.replace("CLIP", "Wave").replace("ROOT", "door"))
    with pytest.raises(LevelError, match=r"no animation clip 'Wave' \(its clips: 'Open', 'Slide', 'Blink'") as caught:
        load_level(tmp_path / "hall.toml")
    assert (caught.value.field, caught.value.line) == ("AnimationLayer.clip", 14)
    (tmp_path / "hall.toml").write_text(text.replace("CLIP", "Slide").replace("ROOT", "spine"))
    with pytest.raises(LevelError, match=r"no node 'spine' \(its nodes: 'hinge', 'door'\)") as caught:
        load_level(tmp_path / "hall.toml")
    assert (caught.value.field, caught.value.line) == ("AnimationLayer.root", 18)


def turn_y(angle: float) -> glm.quat:
    return glm.angleAxis(angle, glm.vec3(0, 1, 0))


def flipped(tmp_path):
    """The door with a clip "Flip" turning the hinge from none to a quarter about +y, that
    quarter written as its negative quaternion (the same turn; dot with the first key < 0)."""
    from tests.test_model_animation import spun

    negated = [-QUARTER.x, -QUARTER.y, -QUARTER.z, -QUARTER.w]
    return spun(tmp_path / "flip.glb", {"Flip": ("LINEAR", [0.0, 2.0], np.array([[0, 0, 0, 1], negated]))})


def test_layers_and_fades_mix_a_negated_quaternion_along_the_shorter_arc(tmp_path):
    """"Flip" at 2 s (a quarter, as -q) over "Open" at 0 s (none), overriding at weight 0.5:
    an eighth turn (the long way round would be three eighths the other way); added at 0.5
    over "Open" at 1 s (an eighth): a quarter; a crossfade from "Flip" held at its end into
    "Open", half way (Open 0.5 s in: a quarter of its 90 degrees): the hinge half way between
    90 and 22.5 degrees; each angle worked out here."""
    from engine.assets.models import crossfade

    path = flipped(tmp_path)

    def hinge_after(animation, layer=None, fade=None):
        world = World("flip")
        root = spawn_model(world, path)
        world.add_component(root, animation)
        if layer is not None:
            world.add_component(root, layer)
        stage = ModelSystem(world)
        stage.process(0.0)
        if fade is not None:
            animation.playing = True
            crossfade(animation, fade, 1.0)
            stage.process(0.5)
        return door_matrix(world)

    over = hinge_after(Animation("Open", time=0.0, playing=False),
                       AnimationLayer("Flip", time=2.0, playing=False, weight=0.5))
    assert close(over, HINGE * glm.mat4_cast(turn_y(math.pi / 4)) * glm.translate(REST))
    added = hinge_after(Animation("Open", time=1.0, playing=False),
                        AnimationLayer("Flip", time=2.0, playing=False, weight=0.5, blend="additive"))
    assert close(added, HINGE * glm.mat4_cast(turn_y(math.pi / 2)) * glm.translate(REST))
    faded = hinge_after(Animation("Flip", time=2.0, playing=False, loop=False), fade="Open")
    open_at = 0.25 * math.pi / 2   # "Open" 0.5 s into its 2 s quarter turn
    assert close(faded, HINGE * glm.mat4_cast(turn_y(0.5 * (math.pi / 2 + open_at))) * glm.translate(REST))


def test_an_additive_layer_adds_its_change_in_scale(tmp_path):
    """"Blink" (the door's scale stepping 1, 2, 1 at 0, 1, 2 s) at 1.5 s (scale 2) over "Blink"
    at 1.5 s: its change from its first key (2 - 1) added on: 3 (as three.js adds an additive
    clip's scale change); at weight 0.5: 2.5; over the rest pose (1): 2."""
    for base, weight, expected in ((Animation("Blink", time=1.5, playing=False), 1.0, 3.0),
                                   (Animation("Blink", time=1.5, playing=False), 0.5, 2.5), (None, 1.0, 2.0)):
        _, (m,) = posed(tmp_path, base, AnimationLayer("Blink", time=1.5, playing=False, blend="additive",
                                                       weight=weight))
        assert close(m, HINGE * glm.translate(REST) * glm.scale(glm.vec3(expected))), (weight, expected)
