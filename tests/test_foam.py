"""Shore foam (``Water.foam``): white water where a pond is shallow, drawn over the water's
reflection and what is seen through it, lit as any surface is.  Measured in rendered frames
against where the water's depth puts it (each pixel's ray to the surface and on to the pool's
floor, worked out here) and against a plain surface of the foam's colour lit by the same
lights."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    Skybox,
    Transform,
    Water,
    look_rotation,
)
from engine.assets.mesh import box, quad
from engine.assets.texture_data import wave_normal_map
from engine.core.errors import WaterLimitWarning
from tests.support import pixel_rays, srgb_to_linear

FLAT = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))
RISE, RUN = 1.2, 4.0                 # the pool's floor rises 1.2 m over 4 m along +x ...
SLOPE = math.atan2(RISE, RUN)
FLOOR_AT = (0.0, -0.4, 0.0)           # ... through this point: it meets the surface at x = 1.33
FOAM_DEPTH = 0.3
FOAM_COLOR = (0.8, 0.85, 0.9)
POST = (1.7, 0.0, 0.9)               # a post on the shore, whose shadow falls across the foam


def floor_height(x: np.ndarray) -> np.ndarray:
    """The pool's floor under x (the ramp's plane)."""
    return FLOOR_AT[1] + (x - FLOOR_AT[0]) * math.tan(SLOPE)


def pool(foam: float, *, water: bool = True, offset=(0.0, 0.0), post: bool = False, waves: bool = False,
         halves=None):
    """A still pond 4 m square over a floor that rises out of it along +x, lit by a sun and a
    grey sky, seen from above; ``water`` False: an opaque quad of the foam's colour in its
    place (what the foam's light is measured against); ``halves``: the pond as two waters,
    its far half (z < 0) and its near one, each with its (foam, colour)."""
    def build(world):
        eye = glm.vec3(0.6, 2.2, 1.6)
        world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0.8, 0.0, 0.0) - eye)), Camera(fov_y=55.0))
        world.spawn(Skybox(faces=[np.full((8, 8, 3), 0.25, np.float32) for _ in range(6)]))
        world.spawn(DirectionalLight(direction=(-0.8, -1.0, -0.2), intensity=1.5))
        world.spawn(Transform(position=FLOOR_AT, rotation=glm.angleAxis(SLOPE, glm.vec3(0, 0, 1)) * FLAT),
                    MeshRef(quad(RUN / math.cos(SLOPE) + 0.4, 4.0)),
                    Material(color=(0.5, 0.4, 0.3, 1.0), roughness=1.0))
        if post:
            world.spawn(Transform(position=POST), MeshRef(box((0.2, 2.4, 0.2))),
                        Material(color=(0.6, 0.6, 0.6, 1.0), roughness=1.0))
        if halves is not None:   # (one mesh and material: one batch of two waters)
            mesh, look = quad(4.0, 2.0), Material(color=(0.05, 0.2, 0.25, 0.3), roughness=0.2)
            for z, (strength, colour) in zip((-1.0, 1.0), halves, strict=True):
                world.spawn(Transform(position=(0.0, 0.0, z), rotation=FLAT), MeshRef(mesh), look, Mirror(),
                            Water(foam=strength, foam_depth=FOAM_DEPTH, foam_scale=0.1, foam_color=colour))
        elif water:
            world.spawn(Transform(rotation=FLAT), MeshRef(quad(4.0, 4.0)),
                        Material(color=(0.05, 0.2, 0.25, 0.3), roughness=0.2,
                                 normal_map=wave_normal_map() if waves else None, normal_scale=0.2), Mirror(),
                        Water(foam=foam, foam_depth=FOAM_DEPTH, foam_scale=0.1, foam_color=FOAM_COLOR, offset=offset))
        else:
            world.spawn(Transform(rotation=FLAT), MeshRef(quad(4.0, 4.0)),
                        Material(color=(*FOAM_COLOR, 1.0), roughness=1.0, environment_reflection=0.0))
    return build


def render(scene, build, size=(160, 120)):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (a still water: no waves, said)
        runner = scene(build, size)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        rgb = runner.frame()
    return runner, srgb_to_linear(rgb)


def water_under(runner) -> np.ndarray:
    """Each pixel's metres of water between the surface and the floor along its ray (NaN: the
    ray does not meet the pond's surface, or meets the floor first)."""
    eye, directions = pixel_rays(runner.engine.main_view, runner.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -eye[1] / directions[..., 1]
    at = eye + directions * t[..., None]
    on = (t > 0) & (np.abs(at[..., 0]) < 2.0) & (np.abs(at[..., 2]) < 2.0)
    # The floor along the ray: eye.y + d.y s = floor_height(eye.x + d.x s).
    k = math.tan(SLOPE)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (FLOOR_AT[1] + (eye[0] - FLOOR_AT[0]) * k - eye[1]) / (directions[..., 1] - directions[..., 0] * k)
    floor = eye + directions * s[..., None]
    depth = at[..., 1] - floor[..., 1]
    return np.where(on & (s > t), depth, np.nan)


def test_foam_lies_where_the_water_is_shallow_and_thins_out_with_its_depth(scene):
    """Along the shore where the floor rises out of the pond: where a pixel's ray finds more
    than ``foam_depth`` of water under the surface the frame is the one without foam, bit for
    bit; near the water's edge almost all of the surface is foam (brighter); in between, the
    share of the surface the foam covers falls as the water deepens."""
    runner, foamy = render(scene, pool(1.0))
    _, plain = render(scene, pool(0.0))
    under = water_under(runner)
    deep = under > FOAM_DEPTH * 1.05
    assert deep.sum() > 2000
    np.testing.assert_array_equal(foamy[deep], plain[deep])
    changed = np.abs(foamy - plain).max(axis=-1) > 0.02
    shares = []
    for low, high in ((0.0, 0.05), (0.05, 0.12), (0.12, 0.2), (0.2, 0.28)):
        band = (under >= low * FOAM_DEPTH / 0.3) & (under < high * FOAM_DEPTH / 0.3)
        assert band.sum() > 40, (low, band.sum())
        shares.append(changed[band].mean())
    assert shares[0] > 0.9, shares
    assert all(a > b for a, b in zip(shares, shares[1:], strict=False)), shares   # thinning out with the depth
    assert shares[-1] < 0.5, shares
    assert (foamy[changed & (under < 0.05)] > plain[changed & (under < 0.05)]).all(axis=-1).mean() > 0.95
    # The Foam block as the GLSL lays it out (std140) is the size the engine packs.
    from engine.render.foam import FOAM_BLOCK_BYTES

    built = [program for program in runner.engine.renderer.scene_pass.programs.built.values() if "Foam" in program]
    assert built and {program["Foam"].size for program in built} == {FOAM_BLOCK_BYTES}
    # The foam reads the depth the water's composite copied: no copy of its own a frame (nor in
    # the water's own reflection, which shows none of its foam).
    copy = runner.engine.renderer.scene_pass.refraction_copy
    before = copy.copies
    runner.frame()
    assert copy.copies - before == 1


def test_foam_is_lit_as_a_surface_of_its_colour_with_its_shadows(scene):
    """At the water's edge, where the foam covers the surface whole, a foam pixel is the pixel
    of an opaque quad of the foam's colour in the water's place, lit by the same sun and sky:
    in the sun, and in the post's shadow across the shallows, as dark as the quad is there."""
    runner, foamy = render(scene, pool(1.0, post=True))
    _, quad_frame = render(scene, pool(1.0, water=False, post=True))
    under = water_under(runner)
    edge = under < 0.02
    ratio = foamy[..., 1] / np.maximum(quad_frame[..., 1], 1e-4)
    whole = edge & (np.abs(ratio - 1.0) < 0.25)   # (those the pattern covers whole: most at the edge)
    assert whole.sum() > 0.6 * edge.sum() > 30, (whole.sum(), edge.sum())
    assert abs(np.median(ratio[whole]) - 1.0) < 0.02, np.median(ratio[whole])
    lit_level = np.median(quad_frame[..., 1][edge])
    shaded = whole & (quad_frame[..., 1] < 0.6 * lit_level)   # the post's shadow on the foam
    assert shaded.sum() > 5, shaded.sum()
    assert np.median(foamy[..., 1][shaded]) < 0.6 * np.median(foamy[..., 1][whole & ~shaded])


def test_the_foam_drifts_with_the_waves_offset(scene):
    """The pattern is carried with the waves (``Water.offset``): a quarter tile on, the foam
    lies elsewhere along the shore; back at the start, exactly where it was."""
    _, first = render(scene, pool(1.0, offset=(0.0, 0.0), waves=True))
    runner, moved = render(scene, pool(1.0, offset=(0.25, 0.1), waves=True))
    _, again = render(scene, pool(1.0, offset=(0.0, 0.0), waves=True))
    shallow = water_under(runner) < FOAM_DEPTH * 0.8
    assert (np.abs(moved - first).max(axis=-1)[shallow] > 0.05).mean() > 0.1
    np.testing.assert_array_equal(first, again)


def test_a_mirror_shows_the_ponds_foam(scene):
    """A mirror standing over the pond, facing the shallows, shows the foam in its reflection
    (the foam is drawn in every view the view tree draws): its pixels with foam differ from
    those without."""
    def with_mirror(foam):
        def build(world):
            pool(foam)(world)
            world.spawn(Transform(position=(0.8, 0.8, -1.9)), MeshRef(quad(2.4, 1.6)), Material(), Mirror())
        return build

    runner, foamy = render(scene, with_mirror(1.0))
    _, plain = render(scene, with_mirror(0.0))
    assert runner.stats.views_spent >= 2   # (the mirror's view and the pond's)
    eye, directions = pixel_rays(runner.engine.main_view, runner.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-1.9 - eye[2]) / directions[..., 2]
    at = eye + directions * t[..., None]
    on_mirror = (t > 0) & (np.abs(at[..., 0] - 0.8) < 1.2) & (np.abs(at[..., 1] - 0.8) < 0.8)
    under = water_under(runner)
    in_front = ~(under < np.inf)   # (pixels the pond does not cover: the mirror's own)
    changed = np.abs(foamy - plain).max(axis=-1) > 0.05
    assert (changed & on_mirror & in_front).sum() > 20, (changed & on_mirror & in_front).sum()


def test_a_second_water_shows_its_own_foam_as_it_does_alone(scene):
    """Two waters side by side, each with foam of its own colour: each half of the frame is
    the frame with that water's foam alone (the other's off), the far one held in the block's
    first slot and the near one in its second, where alone it had the first; and the near
    one's foam is there (its half differs from the frame with the far one's alone)."""
    far, near = (1.0, (0.9, 0.45, 0.3)), (0.8, (0.3, 0.55, 0.95))
    runner, both = render(scene, pool(1.0, halves=(far, near)))
    slots = [water.entity for water in runner.engine.renderer.foam.waters]
    _, far_alone = render(scene, pool(1.0, halves=(far, (0.0, near[1]))))
    _, near_alone = render(scene, pool(1.0, halves=((0.0, far[1]), near)))
    eye, directions = pixel_rays(runner.engine.main_view, runner.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -eye[1] / directions[..., 1]
    z = (eye + directions * t[..., None])[..., 2]
    under = water_under(runner)
    on_far, on_near = (under < np.inf) & (z < -0.05), (under < np.inf) & (z > 0.05)
    (first, _), (second, _) = sorted(runner.world.query(Water), key=lambda pair: pair[0])
    assert slots == [first, second]
    shallow = under < FOAM_DEPTH
    assert (on_far & shallow).sum() > 100 and (on_near & shallow).sum() > 100
    near_foam = np.abs(near_alone - far_alone).max(axis=-1) > 0.05
    assert near_foam[on_near & shallow].mean() > 0.3
    np.testing.assert_allclose(both[on_far], far_alone[on_far], atol=1.5 / 255)
    np.testing.assert_allclose(both[on_near], near_alone[on_near], atol=1.5 / 255)


def test_foam_values_are_checked_and_waters_past_the_limit_are_said(scene):
    for field, value in (("foam", 1.5), ("foam", -0.1), ("foam_depth", 0.0), ("foam_scale", -1.0),
                         ("foam_color", (2.0, 0.0))):
        with pytest.raises(ComponentValueError, match=rf"Water\.{field}"):
            Water(**{field: value})

    def five(world):
        pool(1.0)(world)
        for k in range(4):
            world.spawn(Transform(position=(6.0 + 3.0 * k, 0.0, 0.0), rotation=FLAT), MeshRef(quad(2.0, 2.0)),
                        Material(color=(0.1, 0.2, 0.2, 0.3)), Mirror(), Water(foam=0.5))

    with pytest.warns(WaterLimitWarning, match=r"5 waters have foam: 4 are drawn"):
        runner = scene(five, (32, 24))
        runner.frame()
    assert runner.stats.foam_waters_cut == 1
    assert len(runner.engine.renderer.foam.waters) == 4


def test_a_context_with_too_few_texture_units_draws_no_foam_and_says_so(scene, ctx):
    """On a context with 16 fragment texture units (macOS's OpenGL 4.1) the water has no foam:
    the frame is the one without it, and a GLLimitWarning names the water and the limit, once."""
    from engine.core.errors import GLLimitWarning
    from engine.render.foam import FOAM_SAMPLERS, FoamBlock

    _, plain = render(scene, pool(0.0))
    runner = scene(pool(1.0), (160, 120))
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.foam.release()
    runner.engine.renderer.foam = FoamBlock(ctx, texture_units=16)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(2):
            image = runner.frame()
    said = [w for w in caught if issubclass(w.category, GLLimitWarning)]
    assert len(said) == 1 and f"foam needs {FOAM_SAMPLERS} texture units" in str(said[0].message)
    assert runner.engine.renderer.foam.waters == ()
    np.testing.assert_array_equal(srgb_to_linear(image), plain)


@pytest.mark.parametrize("depth", [0, 1])
def test_a_monitors_picture_shows_the_foam_the_cameras_view_does(scene, depth):
    """A monitor's camera where the active camera stands (its ``depth`` 0: no view tree, the
    root finished as the main view's is; 1: the pond's reflection view too): the foam changes
    the picture where it changes the camera's own frame, nearly all the surface at the water's
    edge and none where the water is deep."""
    from components import Camera, Monitor

    size = (160, 120)

    def watched(foam):
        def build(world):
            pool(foam)(world)
            (camera, (_, transform)), = [(e, c) for e, c in world.query(Camera, Transform)]
            lens = world.spawn(Transform(position=transform.position, rotation=transform.rotation),
                               Camera(fov_y=55.0, active=False))
            world.spawn(Transform(position=(0.6, 2.2, 9.0)), MeshRef(quad(1.6, 0.9)), Material(color=(0.0, 0.0, 0.0)),
                        Monitor(camera=lens, size=size, depth=depth))
        return build

    pictures, frames = [], []
    for foam in (1.0, 0.0):
        runner, frame = render(scene, watched(foam), size)
        (screen, _), = runner.world.query_one(Monitor)
        pictures.append(runner.engine.renderer.monitors.read(screen)[..., :3])
        frames.append(frame)
    in_picture = np.abs(pictures[0] - pictures[1]).max(axis=-1) > 0.02
    in_frame = np.abs(frames[0] - frames[1]).max(axis=-1) > 0.02
    under = water_under(runner)
    edge, deep = under < 0.05 * FOAM_DEPTH / 0.3, under > FOAM_DEPTH * 1.05
    assert edge.sum() > 40 and deep.sum() > 2000
    assert in_picture[edge].mean() > 0.9 and not in_picture[deep].any()
    assert (in_picture & in_frame).sum() > 0.9 * max(in_picture.sum(), in_frame.sum())


@pytest.mark.parametrize("depth", [0, 1])
def test_a_probe_shows_the_foam_where_the_water_is_shallow_at_any_depth(scene, depth):
    """A probe over the shore (its ``depth`` 0: no mirror or portal views in its faces, each
    finished as a root is; 1: the pond's reflection view too): in every face that sees the
    pond (looking down, and the -X, +Z and -Z faces' lower halves; +X looks past the shore),
    where a texel's ray from the probe finds more than ``foam_depth`` of water under the
    surface the foam changes nothing, and at the water's edge (seen looking down and along
    the shore, +Z and -Z) nearly all of the surface is foam.  Before the faces of a probe
    with no view tree were finished as a root, one at depth 0 showed none (drawn whole: no
    copy of the depth under the water)."""
    from components import ReflectionProbe
    from engine.core.cube_faces import face_directions

    probe_at, size = np.array([1.0, 0.8, 0.0]), 64
    seen = {1: "-X", 3: "-Y", 4: "+Z", 5: "-Z"}   # the faces that see the pond; the last three its edge

    def probed(foam):
        def build(world):
            pool(foam)(world)
            world.resources["probe"] = world.spawn(Transform(position=tuple(probe_at)),
                                                   ReflectionProbe(resolution=size, depth=depth, refresh="once"))
        return build

    faces = []
    for foam in (1.0, 0.0):
        runner, _ = render(scene, probed(foam))
        faces.append({face: runner.engine.renderer.probes.read_face(runner.world.resources["probe"], face)
                      for face in seen})
    k = math.tan(SLOPE)
    rise = FLOOR_AT[1] + (probe_at[0] - FLOOR_AT[0]) * k - probe_at[1]   # the floor's plane along a ray from the probe
    for face, name in seen.items():
        directions = face_directions(face, size)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -probe_at[1] / directions[..., 1]
            s = rise / (directions[..., 1] - directions[..., 0] * k)
        at = probe_at + directions * t[..., None]
        on = (t > 0) & (np.abs(at[..., 0]) < 1.95) & (np.abs(at[..., 2]) < 1.95)
        under = np.where(on & (s > t), at[..., 1] - (probe_at + directions * s[..., None])[..., 1], np.nan)
        changed = np.abs(faces[0][face] - faces[1][face]).max(axis=-1) > 0.02
        edge, deep = under < 0.05 * FOAM_DEPTH / 0.3, under > FOAM_DEPTH * 1.05
        assert deep.sum() > 200 and (edge.sum() > 20) == (name != "-X"), (name, edge.sum(), deep.sum())
        if name != "-X":
            assert changed[edge].mean() > 0.9, (name, changed[edge].mean())
        assert not changed[deep].any(), name


def test_a_probe_capture_asks_once_whether_its_faces_are_finished_as_a_root(scene, monkeypatch):
    """Whether a probe's faces with no view tree are finished as a root (``_finished``: a
    look over the transparent batches for foam, screen-refracting glass and see-through
    surfaces) is asked once a capture: ``capture_probe`` passes its answer to the six-pass
    ``capture`` (it asked twice, the same question a capture, before).  The capture still
    shows the foam (the test above), so the answer passed down is the one that counts."""
    from components import ReflectionProbe
    from engine.render.probes import ProbeCaptures

    asked, captured = [], []
    finished, capture_probe = ProbeCaptures._finished, ProbeCaptures.capture_probe
    monkeypatch.setattr(ProbeCaptures, "_finished", lambda self: asked.append(1) or finished(self))
    monkeypatch.setattr(ProbeCaptures, "capture_probe",
                        lambda self, *a, **k: captured.append(1) or capture_probe(self, *a, **k))

    def build(world):
        pool(1.0)(world)
        world.spawn(Transform(position=(1.0, 0.8, 0.0)), ReflectionProbe(resolution=32, depth=0, refresh="every_frame"))

    render(scene, build, size=(32, 24))
    assert len(captured) >= 2 and len(asked) == len(captured), (len(asked), len(captured))


def carried_pool(foam: float, place: glm.mat4):
    """``pool``'s floor, sky, sun and pond (with ``foam``), each placed by ``place`` (rigid)
    after its own transform: for a test that spawns it beyond a portal."""
    turn = glm.quat_cast(place)

    def build(world):
        world.spawn(Skybox(faces=[np.full((8, 8, 3), 0.25, np.float32) for _ in range(6)]))
        world.spawn(DirectionalLight(direction=(-0.8, -1.0, -0.2), intensity=1.5))
        world.spawn(Transform(position=glm.vec3(place * glm.vec4(*FLOOR_AT, 1.0)),
                              rotation=turn * glm.angleAxis(SLOPE, glm.vec3(0, 0, 1)) * FLAT),
                    MeshRef(quad(RUN / math.cos(SLOPE) + 0.4, 4.0)),
                    Material(color=(0.5, 0.4, 0.3, 1.0), roughness=1.0))
        world.spawn(Transform(position=glm.vec3(place[3]), rotation=turn * FLAT), MeshRef(quad(4.0, 4.0)),
                    Material(color=(0.05, 0.2, 0.25, 0.3), roughness=0.2), Mirror(),
                    Water(foam=foam, foam_depth=FOAM_DEPTH, foam_scale=0.1, foam_color=FOAM_COLOR))
    return build


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_portal_shows_the_foam_as_the_eye_it_carries_sees_it(scene, path):
    """The pond with its shore beyond portal B, seen down through portal A (the pond's
    reflection a level below the portal's view), and the same world without portals rendered
    directly from the eye the pair carries the camera's to: inside A's opening the two are the
    same pixels (the portal's level draws the foam with its own camera: its depth read back
    through the portal view's projection, its oblique near plane and all), and the foam is
    there (the opening differs from the pond's without foam).  (A batched level drew its
    water writing depth, so the foam drawn over it failed its depth test: none showed.)"""
    from tests.test_particles import through_a_portal_and_from_its_eye

    def content(foam):
        def make(world, carry):
            carried_pool(foam, carry * glm.translate(glm.vec3(-1.0, -1.3, -4.7)))(world)
        return make

    shot = dict(path=path, eye=glm.vec3(0.0, 0.6, 0.0), target=(0.3, -1.3, -4.7), fov=55.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # (a still water: no waves, said)
        foamy, direct, opening, runners = through_a_portal_and_from_its_eye(scene, content(1.0), **shot)
        plain, _, _, _ = through_a_portal_and_from_its_eye(scene, content(0.0), **shot)
    assert runners[True].stats.reflection_views >= 2   # (the portal's view and the pond's below it)
    shown = np.abs(foamy - plain).max(axis=-1)[opening]
    assert (shown > 0.05).sum() > 60, (shown > 0.05).sum()   # (the foam is there)
    apart = np.abs(foamy - direct).max(axis=-1)[opening]
    assert np.quantile(apart, 0.99) <= 0.01 and apart.max() <= 0.04, (np.quantile(apart, 0.99), apart.max())
