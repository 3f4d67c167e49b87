"""Picking by pixel from a real frame's id images: a box seen directly, the same box seen in a
mirror, and (with the surface modifier) the mirror it was seen in; where each lands on the
screen is worked out by projection and reflection math, not read from the renderer."""
from __future__ import annotations

import numpy as np

from shell.editor import Editor, pick
from tests.test_level_edit import edit_scene
from tests.test_mirrors import reflected_pixel

BOX = (-1.0, 1.2, 0.0)


def test_pick_a_box_directly_in_a_mirror_and_the_mirror_itself(scene):
    ents = {}
    runner = scene(lambda world: edit_scene(world, ents), (160, 120))
    rgb = runner.frame()
    assert rgb.std() > 10
    ids, surfaces = runner.ids(), runner.engine.renderer.targets.read_surface_ids()
    editor = Editor(runner.world)
    direct = runner.project(BOX)
    mirrored = reflected_pixel(runner, BOX)
    assert direct != mirrored

    assert editor.pick(ids, surfaces, *direct) == ents["box"] == editor.selected
    assert editor.pick(ids, surfaces, *mirrored) == ents["box"]  # the box, though the pixel is the mirror's
    assert editor.pick(ids, surfaces, *mirrored, surface=True) == ents["mirror"]
    assert editor.pick(ids, surfaces, *direct, surface=True) == ents["box"]  # nothing between: the box itself
    # The mirror's glass where the box is not seen in it: the modifier picks the mirror, a
    # plain click what the mirror shows there (the sky or the floor, not the box).
    beside = (mirrored[0] + 25, mirrored[1])
    assert surfaces[beside[1], beside[0]] == ents["mirror"]
    assert pick(ids, surfaces, *beside, surface=True) == ents["mirror"]
    assert pick(ids, surfaces, *beside) != ents["box"]
    # The sky above everything is nothing; a pixel off the image is nothing.
    assert editor.pick(ids, surfaces, 80, 2) is None and editor.selected is None
    assert pick(ids, surfaces, -1, 5) is None and pick(ids, surfaces, 160, 5) is None
    # Every pixel the box covers, directly or in the mirror, picks the box.
    rows, cols = np.nonzero(ids == ents["box"])
    assert len(rows) > 20 and all(pick(ids, surfaces, c, r) == ents["box"] for r, c in zip(rows, cols, strict=True))
