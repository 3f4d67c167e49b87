"""Shadow atlases outlive their engine on its context (``engine/render/free_depth_images.py``):
an engine closed hands its atlases on, the next that needs one of the same size takes it
instead of making one, and draws the frame a new atlas gives, whatever the last owner drew
in it; the list keeps no more than it is told, and none once released."""
from __future__ import annotations

import moderngl
import numpy as np
import pytest

from components import DirectionalLight, Material, MeshRef, PointLight, Transform, look_rotation
from engine.assets.mesh import box, plane
from engine.render.free_depth_images import KEEP, FreeDepthImages
from tests.support import SceneRunner, look_from

SIZE = (96, 64)


@pytest.fixture
def free(monkeypatch) -> FreeDepthImages:
    """A list of this test's own (its images released after)."""
    own = FreeDepthImages()
    monkeypatch.setattr(FreeDepthImages, "of", classmethod(lambda cls, ctx: own))
    yield own
    own.release()


def _boxes(places, spot: bool = False):
    """A floor under a shadow-casting sun (and, with ``spot``, a spot casting from the spot
    atlas), with boxes at ``places``."""
    def build(world):
        look_from(world, (0.0, 4.0, 7.0), (0.0, 0.0, 0.0))
        world.spawn(DirectionalLight(direction=(0.4, -1.0, -0.3), intensity=2.0, shadows=True,
                                     shadow_resolution=1024))
        if spot:
            world.spawn(Transform(position=(1.0, 4.0, 1.0),
                                  rotation=look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))),
                        PointLight(intensity=30.0, range=12.0, shadows=True, spot_angle=40.0))
        world.spawn(Transform(), MeshRef(plane(12.0, 12.0)), Material(color=(0.7, 0.7, 0.7)))
        for x, z in places:
            world.spawn(Transform(position=(x, 0.75, z)), MeshRef(box((1.0, 1.5, 1.0))),
                        Material(color=(0.8, 0.3, 0.2)))
    return build


def _frames(ctx, build, frames: int = 2) -> list[np.ndarray]:
    runner = SceneRunner(ctx, build, SIZE)
    try:
        return [runner.frame() for _ in range(frames)]
    finally:
        runner.close()


def test_a_closed_engines_atlas_is_taken_by_the_next_which_draws_what_a_new_atlas_draws(ctx, free, monkeypatch):
    # The first engine's atlases: boxes on the right, their shadows in the sun's tiles.
    _frames(ctx, _boxes([(2.0, 0.0), (2.5, -2.0)], spot=True))
    assert free.count == 2   # the sun's atlas and the spots' (1 x 1 stand-ins are not kept)
    made = []
    original = moderngl.Context.depth_texture

    def depth_texture(self, size, *args, **kwargs):
        made.append(tuple(size))
        return original(self, size, *args, **kwargs)

    monkeypatch.setattr(moderngl.Context, "depth_texture", depth_texture)
    # The next: boxes on the left; it takes both atlases, holding the first one's depths.
    taken = _frames(ctx, _boxes([(-2.0, 1.0)], spot=True))
    assert free.taken == 2 and all(size[0] <= 1 or size == SIZE for size in made), made
    # The same world with new atlases (none handed out).
    free.released = True
    fresh = _frames(ctx, _boxes([(-2.0, 1.0)], spot=True))
    assert any(size[0] >= 2048 for size in made), made   # (made this time)
    for a, b in zip(taken, fresh, strict=True):
        assert a.max() > 0.1
        assert np.array_equal(a, b), f"{int((a != b).any(-1).sum())} pixels differ"


def test_the_list_keeps_at_most_keep_the_longest_unused_going_first(ctx, free):
    images = [ctx.depth_texture((8 + i, 8)) for i in range(KEEP + 2)]
    for image in images:
        free.give(image)
    assert free.count == KEEP
    assert free.take((8, 8)) is None and free.take((9, 8)) is None   # released: the first two
    assert free.take((10, 8)) is images[2] and free.count == KEEP - 1 and free.taken == 1
    images[2].release()
    stand_in = ctx.depth_texture((1, 1))
    free.give(stand_in)   # nothing to save: released at once
    assert free.count == KEEP - 1 and free.take((1, 1)) is None


def test_a_released_list_hands_out_nothing_and_releases_what_it_is_given(ctx, free):
    kept = ctx.depth_texture((16, 16))
    free.give(kept)
    free.release()
    assert free.count == 0 and free.take((16, 16)) is None
    late = ctx.depth_texture((16, 16))
    free.give(late)
    assert free.count == 0 and free.take((16, 16)) is None
