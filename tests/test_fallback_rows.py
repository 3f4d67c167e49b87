"""The fallbacks' rows built from columns (``MirrorPasses.prepare_fallbacks``: a level's
fallbacks gathered as the planner's (parent, surface) pairs and packed a column at a time)
are, byte for byte, the rows packed one fallback at a time through ``composite_rows`` and
``struct`` (how they were packed before, each a Composite of its parent view and surface):
the same draws, in the same groups and order, so the same pixels.  Checked in every frame of
scenes that between them have every kind of row: the 16-mirror ring in exact and predicted
visibility (fallbacks at several levels, past the depth limits and below views drawn
unseen, more than one draw's worth), a mirror inside a probe's box (the probes' build and
weights), cut water (its waves where the tile goes), a portal (its carry and offset), a
partly faded mirror (a share below 1), the end views' holes of a normal-mapped pair (an
end view's node, a normal map's draw).  And drawn 16 rows a draw, the ring's frames are those
drawn with every row of a build in one draw (the FallbackRows block's 256)."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from pyglm import glm

from components import Material, Mirror, Transform
from engine.assets.texture_data import ripple_normal_map
from engine.core.frame_io import Output
from engine.render.mirror_passes import Composite, MirrorPasses, composite_rows, surface_look
from engine.render.targets import CaptureTarget
from engine.resources import ViewBudget
from shell.app import Engine
from tests.support import SceneRunner


def _packed_one_at_a_time(fallbacks, size, probes, chunk: int) -> dict:
    """Each fallback's row as a Composite of its parent view over the parent's rectangle
    (``composite_rows``, glm's matrices) and its extras packed with ``struct``, grouped by
    (build, normal map, probes) in the order of each group's first row, in chunks of
    ``chunk`` (a draw's rows)."""
    count = len(fallbacks)
    groups: dict[tuple, list] = {}
    for p, s, fallback_share, end_view in zip(fallbacks.at, fallbacks.surface, fallbacks.share or [1.0] * count,
                                              fallbacks.end or [-1] * count, strict=True):
        parent, look = fallbacks.parents[p], surface_look(fallbacks.states[s])
        view = parent.view
        rect = view.scissor if parent.level and view.scissor is not None else (0, 0, *view.size)
        blend = probes.get(look.entity)
        owners = (*blend.probes, 0, 0)[:2] if blend is not None else (0, 0)
        variant = look.fallback_variant
        if owners != (0, 0):
            variant = variant.replace("fallback", "fallback_probes", 1)
        w1, w2 = (*(blend.weights if blend is not None else ()), 0.0, 0.0)[:2]
        groups.setdefault((variant, look.normal_map, *owners), []).append((
            Composite(parent.index, rect, rect, view, look),
            struct.pack("<4I", look.entity & 0xFFFFFFFF, end_view + 1, 0, 0),
            struct.pack("<8f", w1, w2, fallback_share, 0.0, look.plane_w, *look.offset)))
    return {key: [(composite_rows([row[0] for row in group[at:at + chunk]], size),
                   b"".join(row[1] for row in group[at:at + chunk]), b"".join(row[2] for row in group[at:at + chunk]))
                  for at in range(0, len(group), chunk)] for key, group in groups.items()}


@pytest.fixture
def compared(monkeypatch):
    """Every prepare_fallbacks call from now on is checked against ``_packed_one_at_a_time``
    (at the call: a water surface's waves move between frames); yields what each compared:
    (fallbacks, chunks, group keys, any share below 1, any end view)."""
    seen = []
    prepare = MirrorPasses.prepare_fallbacks

    def checked(self, fallbacks, size, probes):
        prepared = prepare(self, fallbacks, size, probes)
        expected = _packed_one_at_a_time(fallbacks, size, probes, self.fallback_chunk)
        assert list(prepared.groups) == list(expected)
        for key, chunks in expected.items():
            assert len(prepared.groups[key]) == len(chunks)
            for got, want in zip(prepared.groups[key], chunks, strict=True):
                for name, a, b in zip(("rows", "ids", "weights"), got, want, strict=True):
                    assert a == b, f"{key}: the {name} differ"
        assert prepared.count == len(fallbacks)
        seen.append((len(fallbacks), sum(len(chunks) for chunks in expected.values()), set(expected),
                     any(share < 1.0 for share in fallbacks.share or ()), any(end >= 0 for end in fallbacks.end or ())))
        return prepared

    monkeypatch.setattr(MirrorPasses, "prepare_fallbacks", checked)
    return seen


def _ring_frames(ctx, visibility: str, chunk: int | None = None, frames: int = 6) -> list[np.ndarray]:
    """The 16-mirror ring's first ``frames`` frames at 320 x 180 (100 fallbacks and more each),
    its fallbacks drawn ``chunk`` rows a draw (None: as many as a draw takes)."""
    from benchmarks.mirrors import MirrorRing

    engine = Engine(MirrorRing(16), ctx)
    engine.reflection_system.visibility = visibility
    if chunk is not None:
        engine.reflection_system.tree.passes.fallback_chunk = chunk
    size = (320, 180)
    capture = CaptureTarget(ctx, size)
    images = []
    try:
        for _ in range(frames):
            engine.frame(1.0 / 60.0, Output(capture.framebuffer, size))
            assert engine.renderer.stats.reflection_fallbacks >= 100
            images.append(capture.read_rgb())
    finally:
        capture.release()
        engine.close()
    return images


@pytest.mark.parametrize("visibility", ["exact", "predicted"])
def test_the_ring_of_16_mirrors_rows_are_those_packed_one_at_a_time(ctx, compared, visibility):
    """In chunks of 16 rows (several draws a build), and the frames are those drawn with a
    draw a build (FALLBACK_ROWS: a level's fallbacks of one build in one draw)."""
    whole = _ring_frames(ctx, visibility)
    assert max(entry[1] for entry in compared) == max(len(entry[2]) for entry in compared)  # a draw a build
    compared.clear()
    chunked = _ring_frames(ctx, visibility, chunk=16)
    assert len(compared) >= 6 and max(entry[1] for entry in compared) >= 4  # several draws of one build
    assert sum(entry[0] for entry in compared) >= 600
    for a, b in zip(whole, chunked, strict=True):
        assert a.std() > 10 and np.array_equal(a, b)


def test_a_probes_water_portal_and_faded_rows_are_those_packed_one_at_a_time(scene, compared):
    from components import Water
    from tests.test_reflection_fallback import EYE, TINT, _floor_mirror

    runner = scene(_floor_mirror({}, Mirror(color=TINT, max_depth=0), probe=True))
    for _ in range(3):
        runner.frame()
    distance = math.dist(EYE, (0.0, 0.0, 0.0)) - math.sqrt(2.0) * 1.5  # to the mirror's bounding sphere
    faded = scene(_floor_mirror({}, Mirror(color=TINT, reflect_rate=0.8, fade_distance=(distance - 1.0,
                                                                                         distance + 1.0))))
    faded.frame()
    ents: dict = {}
    water = scene(_floor_mirror(ents, Mirror(color=TINT), ViewBudget(views=0)))
    water.world.get(ents["mirror"], Material).normal_map = ripple_normal_map(64, 4, 0.5)  # waves that move
    water.world.add_component(ents["mirror"], Water(ior=1.33, speed=1.0))
    for _ in range(2):
        water.frame()
    portal = scene(_portal_build())
    portal.frame()
    keys = set().union(*(entry[2] for entry in compared))
    variants = {key[0] for key in keys}
    assert {"fallback_probes", "fallback", "fallback_portal"} <= variants and any("water" in v for v in variants)
    assert runner.stats.reflection_fallbacks == 1 and faded.stats.reflection_fallbacks == 1
    assert any(entry[3] for entry in compared)  # the faded mirror's share


def _portal_build():
    from components import DirectionalLight, Skybox
    from engine.assets.portals import spawn_portal_pair
    from tests.support import look_from

    def build(world) -> None:
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.4), intensity=1.5))
        look_from(world, (0.3, 1.4, 3.0), target=(0.0, 1.8, 0.0), fov=50.0)
        spawn_portal_pair(world, (0.0, 1.5, 0.0), None, (10.0, 1.5, 0.0),
                          glm.angleAxis(glm.radians(90), glm.vec3(0, 1, 0)), size=(2.0, 2.5))
        world.resources[ViewBudget] = ViewBudget(views=0)
    return build


def test_the_end_views_holes_rows_are_those_packed_one_at_a_time(ctx, compared):
    from engine.rules.frame_rules import active_camera
    from tests.test_end_images import _facing_pair

    runner = SceneRunner(ctx, _facing_pair(3, normal_map=ripple_normal_map(64, 4, 0.5)), (240, 160))
    runner.engine.reflection_system.max_depth_cap = 8
    ends = []
    try:
        for frame in range(4):
            yaw = math.pi if frame < 3 else 0.0  # turned round in one frame: the end views' images miss
            runner.world.get(active_camera(runner.world), Transform).rotation = glm.quat(
                glm.angleAxis(-yaw, glm.vec3(0, 1, 0)))
            runner.frame(0.0)
            ends.append(runner.stats.reflection_end_views)
    finally:
        runner.close()
    assert ends[3] >= 1
    assert any(key[1] is not None for entry in compared for key in entry[2])  # a normal map's draw
    assert any(entry[4] for entry in compared)  # an end view's holes
