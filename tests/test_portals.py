"""Portals: component rules, pair math, scene export."""
from __future__ import annotations

import json

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, Portal, Transform
from engine.assets.portals import spawn_portal_pair
from engine.core.portal_math import pair_transform, portal_plane
from engine.core.world import World
from shell.capture import export_scene

TURN_Y_90 = glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0))


@pytest.fixture
def world():
    w = World("portal-test")
    yield w
    w.close()


def test_pair_transform_carries_the_front_of_one_portal_to_the_back_of_the_other():
    a = glm.translate(glm.vec3(0, 1, 0))
    b = glm.translate(glm.vec3(10, 1, 0)) * glm.mat4_cast(TURN_Y_90)
    carry = pair_transform(a, b)
    # A point 1 m in front of A (+Z) comes out 1 m behind B: B's back is -Z turned by 90 deg about Y = -X.
    np.testing.assert_allclose(glm.vec3(carry * glm.vec4(0, 1, 1, 1)), (9, 1, 0), atol=1e-5)
    # Walking into A (direction -Z) means walking out of B's front (+Z of B = +X).
    np.testing.assert_allclose(glm.vec3(carry * glm.vec4(0, 0, -1, 0)), (1, 0, 0), atol=1e-5)
    # The centre maps to the centre, and the pair undone is the identity.
    np.testing.assert_allclose(glm.vec3(carry * glm.vec4(0, 1, 0, 1)), (10, 1, 0), atol=1e-5)
    back = pair_transform(b, a) * carry
    np.testing.assert_allclose(np.array(back.to_list()), np.eye(4), atol=1e-5)
    plane = portal_plane(b)
    np.testing.assert_allclose(glm.vec3(plane), (1, 0, 0), atol=1e-5)


def test_a_portal_paired_with_itself_is_an_error(world):
    e = world.spawn(Transform())
    with pytest.raises(ComponentValueError, match="paired with itself"):
        world.add_component(e, Portal(partner=e))
    a, b = spawn_portal_pair(world, (0, 1, 0), None, (5, 1, 0), None)
    with pytest.raises(ComponentValueError, match="paired with itself"):
        world.get(a, Portal).partner = a
    assert world.get(a, Portal).partner == b


@pytest.mark.parametrize("field, value", [("size", (0, 2)), ("size", (1, float("nan"))), ("size", 3),
                                          ("max_depth", -1), ("max_depth", 2.5), ("partner", -4), ("enabled", 1)])
def test_portal_values_are_checked(field, value):
    with pytest.raises(ComponentValueError, match=f"Portal.{field}"):
        Portal(**{field: value})


def test_scene_export_lists_each_portal_partner_and_carry_transform(world, tmp_path):
    from components import Camera

    a, b = spawn_portal_pair(world, (0, 1, 0), None, (10, 1, 0), TURN_Y_90)
    cam = world.spawn(Transform(position=(0, 1.6, 5)), Camera())
    from systems import TransformSystem

    world.add_system(TransformSystem(world), 50)
    world.step(1 / 60)
    export_scene(world, tmp_path / "s.glb", cam, (64, 36))
    info = json.loads((tmp_path / "s.json").read_text())
    assert info["portals"][str(a)]["partner"] == b and info["portals"][str(b)]["partner"] == a
    carry = np.array(info["portals"][str(a)]["to_partner"], np.float64).reshape(4, 4).T  # column-major
    np.testing.assert_allclose(carry @ [0, 1, 1, 1], [9, 1, 0, 1], atol=1e-5)
    world.delete_entity(b)
    world.step(1 / 60)
    export_scene(world, tmp_path / "s.glb", cam, (64, 36))
    info = json.loads((tmp_path / "s.json").read_text())
    assert info["portals"][str(a)] == {"partner": None, "to_partner": None}
