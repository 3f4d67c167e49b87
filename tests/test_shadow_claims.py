"""Shadow claims of README.md and the lights' docstrings that no other test held to a frame:
``shadow_softness`` is the filtered edge's width in the map's texels (the "grid" filter);
the bias moves nothing along the light, so a thin wall's shadow starts at its foot (no
peter-panning), from a sun's map and a lamp's cube; a spot up to 45 degrees casts from a
map fitted to its cone, to the cone's very edge, and one a degree wider from its cube's lit
faces; a low sun's, a spot's and a lamp's (with a size or without) edge under grazing light
stays put whatever the softness, with no acne on the lit floor and a tilted panel.  Each against a second
computation: the edge's profile worked out from the filter's taps over a step, float64
shadow rays to the sun, the lamp and the spot, the frame with the light's shadows off."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm
from scipy import ndimage

from components import DirectionalLight, Material, MeshRef, PointLight, Skybox, Transform, look_rotation
from engine.assets.mesh import box, plane
from engine.render.shadows import _RINGS_END
from engine.render.views import MAX_DIRECTIONAL_LIGHTS
from tests.support import box_hits, look_from, pixel_rays, srgb_to_linear

BLACK_SKY = np.zeros((6, 4, 4, 3), np.float32)


def _floor_light(runner, floor: int, filter_: str = "grid") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``runner``'s second frame (FXAA off, ``filter_``) as linear green, each pixel's point on
    the floor (y = 0), and whether the pixel shows the floor (entity ``floor``)."""
    runner.engine.renderer.antialias = "off"
    runner.engine.renderer.shadows.filter = filter_
    runner.frame()
    shown = srgb_to_linear(runner.frame())[..., 1]
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = eye + rays * (-eye[1] / rays[..., 1])[..., None]
    return shown, points, runner.ids() == floor


# --- shadow_softness: the edge's width in texels ---------------------------------------------
def _edge_profile(t: np.ndarray, softness: float) -> np.ndarray:
    """The light left at ``t`` map texels from a straight shadow edge's middle: a bilinear
    comparison ramps over one texel (between the two texel centres astride the edge), and
    the grid's taps (2 a side, 3 past a softness of 1) spread ``softness`` texels apart
    average that ramp shifted to each: ``softness`` + 1 texels from dark to lit."""
    n = 3 if softness > 1.0 else 2
    offsets = (np.arange(n) - (n - 1) / 2.0) * (softness / (n - 1))
    return np.mean([np.clip(t - o + 0.5, 0.0, 1.0) for o in offsets], axis=0)


def _sun_edge(scene, softness: float, slab: bool, elevation: float = 90.0,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A sun ``elevation`` degrees up (from -x) on a white floor under a black sky, a slab over
    x < 0 half a metre up (its shadow's edge along z at x = 0.49 / tan(elevation): 0 straight
    down), the map 128 texels: the floor's light, its points, the floor's pixels, and the
    map's texel along x in metres (from its matrix)."""
    up = np.radians(elevation)
    edge = 0.49 / np.tan(up)

    def build(world):
        look_from(world, (1.5 + edge, 2.0, 2.0), (edge, 0.0, 0.0), fov=55.0)
        world.spawn(Skybox(faces=BLACK_SKY))
        world.resources["floor"] = world.spawn(Transform(), MeshRef(plane(12.0, 12.0)), Material(
            color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        if slab:
            world.spawn(Transform(position=(-2.0, 0.5, 0.0)), MeshRef(box((4.0, 0.02, 8.0))),
                        Material(color=(0.0, 0.0, 0.0)))
        world.spawn(DirectionalLight(direction=(float(np.cos(up)), -float(np.sin(up)), 0.0), intensity=2.0,
                                     shadow_resolution=128, shadow_softness=softness))

    runner = scene(build, (128, 96))
    light, points, floor = _floor_light(runner, runner.world.resources["floor"])
    block = runner.engine.renderer.shadows.block.astype(np.float64)
    to_map = block[:16].reshape(4, 4).T   # world -> atlas uv (rows u, v)
    atlas_texel = block[16 * MAX_DIRECTIONAL_LIGHTS + 2]
    return light, points, floor, float(atlas_texel / np.hypot(to_map[0, 0], to_map[1, 0]))


@pytest.mark.parametrize("softness", [0.0, 1.0, 4.0])
def test_shadow_softness_is_the_filtered_edges_width_in_the_maps_texels(scene, softness):
    """A sun's hard edge under the "grid" filter: each floor pixel's light across the slab's
    shadow edge is the profile its taps give a step, ``softness`` + 1 texels from dark to
    lit (1, 2 and 5 texels of 10 cm: a ramp, a ramp, a staircase of thirds), placed within
    half a texel of the ray-cast edge (x = 0: the map's texels quantise where it falls),
    within 0.04 everywhere (measured 0.006; widths 0.89, 1.8 and 4.71 texels from 5% to
    95% against 0.9, 1.8 and 4.7)."""
    lit, points, floor, texel = _sun_edge(scene, softness, slab=True)
    open_, _, _, _ = _sun_edge(scene, softness, slab=False)
    x = points[..., 0]
    near = floor & (np.abs(points[..., 2]) < 1.0) & (np.abs(x) < 0.8)
    assert near.sum() > 500 and 0.05 < texel < 0.2, (near.sum(), texel)
    share, x = lit[near] / open_[near], x[near]
    assert share.min() < 0.01 and share.max() > 0.99   # dark under the slab, lit past it
    shifts = np.linspace(-0.6, 0.6, 241) * texel
    errors = [np.abs(share - _edge_profile((x - s) / texel, softness)).max() for s in shifts]
    best = int(np.argmin(errors))
    assert errors[best] < 0.04, (errors[best], shifts[best] / texel)
    assert abs(shifts[best]) <= 0.5 * texel + 0.01, shifts[best] / texel
    # The width itself: 5% to 95% of the light over the profile's stretch (0.9 (s + 1) texels
    # for a ramp, (s + 1) - 0.3 for the staircase).
    order = np.argsort(x)
    xs, ss = x[order], share[order]
    width = (xs[np.argmax(ss > 0.95)] - xs[np.argmax(ss > 0.05)]) / texel
    expected = 0.9 * (softness + 1.0) if softness <= 1.0 else softness + 0.7
    assert abs(width - expected) < 0.4, (width, expected)


def test_a_low_suns_shadow_edge_stays_put_whatever_the_softness(scene):
    """The slab's shadow under a sun 25 degrees up (its edge 1.05 m out, the map's texels
    10 cm): where the floor's light crosses half, against the ray-cast edge, is the same at
    softness 0, 1 and 4 (within 0.3 texel) and within 2 texels of it, and under the slab the
    floor is dark: the sun's taps follow the receiver's plane, so the point is pushed off the
    floor by a texel, not by the filter's width (a push as wide as the filter moved the edge
    in by 1.6, 3.9 and 19 texels, the shadow all but gone at softness 4)."""
    edge = 0.49 / np.tan(np.radians(25.0))
    crossings = []
    for softness in (0.0, 1.0, 4.0):
        lit, points, floor, texel = _sun_edge(scene, softness, slab=True, elevation=25.0)
        open_, _, _, _ = _sun_edge(scene, softness, slab=False, elevation=25.0)
        x = points[..., 0]
        near = floor & (np.abs(points[..., 2]) < 1.0) & (np.abs(x - edge) < 1.0) & (open_ > 0.02)
        share, x = lit[near] / open_[near], x[near]
        bins = np.arange(edge - 0.9, edge + 0.9, 0.02)
        means = np.array([share[(x >= b) & (x < b + 0.02)].mean() for b in bins])
        under = means[bins + 0.02 < edge - 0.6]
        assert under.max() < 0.02, (softness, under.max())
        first = int(np.argmax(means > 0.5))
        crossing = bins[first] + 0.01 - 0.02 * (means[first] - 0.5) / (means[first] - means[first - 1])
        crossings.append((crossing - edge) / texel)
    assert max(crossings) - min(crossings) < 0.3 and max(abs(c) for c in crossings) < 2.0, crossings


# --- contact: no peter-panning --------------------------------------------------------------
WALL_HALF = np.array([0.002, 0.5, 0.6])   # a wall 4 mm thick, 1 m tall, 1.2 m long, standing on the floor at x = 0
LOW_SUN = np.array([-1.0, -0.35, 0.0]) / np.linalg.norm([-1.0, -0.35, 0.0])   # 19 degrees up, from +x
LAMP = np.array([1.0, 0.6, 0.0])


def _wall_light(scene, light: str, wall: bool, filter_: str):
    def build(world):
        look_from(world, (-0.9, 0.9, 0.9), (-0.15, 0.0, 0.0), fov=50.0)
        world.spawn(Skybox(faces=BLACK_SKY))
        world.resources["floor"] = world.spawn(Transform(), MeshRef(plane(12.0, 12.0)), Material(
            color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        if wall:
            world.spawn(Transform(position=(0.0, WALL_HALF[1], 0.0)), MeshRef(box(tuple(2.0 * WALL_HALF))),
                        Material(color=(0.0, 0.0, 0.0)))
        if light == "sun":
            world.spawn(DirectionalLight(direction=tuple(LOW_SUN), intensity=2.0))
        else:
            world.spawn(Transform(position=tuple(LAMP)), PointLight(intensity=6.0, range=10.0, shadows=True))

    runner = scene(build, (160, 120))
    shown = _floor_light(runner, runner.world.resources["floor"], filter_)
    return (*shown, float(runner.engine.renderer.shadows.block[16 * MAX_DIRECTIONAL_LIGHTS]))   # a sun's texel, metres


@pytest.mark.parametrize("filter_", ["single", "grid"])
@pytest.mark.parametrize("light", ["sun", "lamp"])
def test_a_thin_walls_shadow_starts_at_its_foot(scene, light, filter_):
    """Peter-panning: the bias is a normal offset and the caster pass's slope offset, nothing
    along the light, so the floor behind a 4 mm wall lit from 19 degrees up (the sun) or from
    a lamp 0.6 m up to its side is dark from its foot on, where a float64 shadow ray to the
    light meets the wall: from 2 mm behind its back face (a sun's grid filters its edge
    about the true one: from a texel, 6 mm, more; a depth bias along the light of a
    centimetre lights that strip), and the floor past its ends keeps all its light."""
    lit, points, floor, sun_texel = _wall_light(scene, light, True, filter_)
    open_, _, _, _ = _wall_light(scene, light, False, filter_)
    flat = points.reshape(-1, 3)
    towards = np.tile(-LOW_SUN, (len(flat), 1)) if light == "sun" else LAMP - flat
    limit = None if light == "sun" else np.ones(len(flat))
    centre = np.array([0.0, WALL_HALF[1], 0.0])

    def blocked(grow: float) -> np.ndarray:
        return box_hits(flat, towards, centre, WALL_HALF + grow, limit).reshape(floor.shape)

    x, z = points[..., 0], points[..., 2]
    share = lit / np.maximum(open_, 1e-6)
    texel = sun_texel if light == "sun" and filter_ == "grid" else 0.0   # (the grid's edge is centred on the true one)
    behind = floor & blocked(0.0) & (np.abs(z) < 0.4) & (x < -WALL_HALF[0] - 0.002 - texel) & (x > -0.3)
    foot = behind & (x > -WALL_HALF[0] - 0.02)   # the first 2 cm behind it
    beside = floor & ~blocked(0.05) & (np.abs(x) < 0.5)   # past its ends' shadow, well clear of the edge
    assert foot.sum() > 20 and behind.sum() > 300 and beside.sum() > 300, (foot.sum(), behind.sum(), beside.sum())
    assert share[behind].max() < 0.05, (share[foot].max(), np.sort(x[behind][share[behind] >= 0.05])[-5:])
    assert share[beside].min() > 0.97, share[beside].min()


# --- a spot's map to 45 degrees, its cube past them ----------------------------------------
SPOT_LAMP = np.array([0.0, 3.0, 0.0])
CRATE, CRATE_HALF = np.array([2.25, 0.5, 0.4]), np.array([0.15, 0.15, 0.15])   # its shadow runs out of the cone


def _spot_frame(scene, spot_angle: float, crate: bool):
    def build(world):
        look_from(world, (1.2, 3.2, 2.6), (2.5, 0.0, 0.3), fov=50.0)
        world.resources["floor"] = world.spawn(Transform(), MeshRef(plane(16.0, 16.0)),
                                               Material(color=(0.8, 0.8, 0.8), roughness=1.0))
        if crate:
            world.spawn(Transform(position=tuple(CRATE)), MeshRef(box(tuple(2.0 * CRATE_HALF))),
                        Material(color=(0.6, 0.5, 0.4)))
        world.spawn(Transform(position=tuple(SPOT_LAMP), rotation=look_rotation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))),
                    PointLight(intensity=12.0, range=15.0, spot_angle=spot_angle, spot_blend=0.0, shadows=True,
                               shadow_resolution=256))

    runner = scene(build, (160, 120))
    runner.engine.renderer.antialias = "off"
    return runner, runner.frame()


@pytest.mark.parametrize("spot_angle, path", [(45.0, "spot_map"), (46.0, "cube")])
def test_a_spot_to_45_degrees_casts_from_its_map_to_the_cones_edge_and_a_wider_one_from_its_cube(
        scene, spot_angle, path):
    """A hard-edged spot straight down from 3 m, a crate near its cone's edge whose shadow
    runs out of the cone: at 45 degrees it casts from its map (no cube face drawn), at 46
    from its cube's five faces the cone lights (not the one looking up); either way every
    floor pixel in the cone shows the crate's shadow where a float64 ray from its point to
    the lamp meets the crate, out to a third of a degree from the cone's edge (pixels within
    two of the cast edge left out: the normal offset, a texel or two at a grazing 45 degrees;
    measured: none wrong of 8339 and 8757, 35 and 31 of them in shadow within 2 degrees of
    the edge)."""
    runner, frame = _spot_frame(scene, spot_angle, crate=True)
    _, bare = _spot_frame(scene, spot_angle, crate=False)
    if path == "spot_map":
        assert runner.stats.shadow_path == "spot_map" and runner.stats.shadow_faces_drawn == 0
    else:
        assert runner.stats.shadow_path != "spot_map" and runner.stats.shadow_faces_drawn == 5
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = (eye + rays * (-eye[1] / rays[..., 1])[..., None]).reshape(-1, 3)
    to = points - SPOT_LAMP
    angle = np.degrees(np.arccos(-to[:, 1] / np.linalg.norm(to, axis=1))).reshape(runner.size[::-1])
    cast = box_hits(points, SPOT_LAMP - points, CRATE, CRATE_HALF, limit=np.ones(len(points))).reshape(angle.shape)
    floor = ndimage.binary_erosion(runner.ids() == runner.world.resources["floor"])
    near_edge = ndimage.binary_dilation(cast, iterations=2) & ~ndimage.binary_erosion(cast, iterations=2)
    judged = floor & ~near_edge & (angle < spot_angle - 0.3)
    dark = srgb_to_linear(frame).mean(-1) < 0.5 * srgb_to_linear(bare).mean(-1)
    rim = judged & cast & (angle > spot_angle - 2.0)
    assert judged.sum() > 4000 and (judged & cast).sum() > 80 and rim.sum() > 10, (judged.sum(), rim.sum())
    assert srgb_to_linear(bare)[rim].mean() > 0.05   # the cone lights its rim
    wrong = judged & (dark != cast)
    assert wrong.sum() <= 2, (wrong.sum(), angle[wrong])


# --- a spot's and a lamp's edge under grazing light: put, whatever the softness --------------
GRAZING_LAMP = np.array([-1.5, 1.0, 0.0])   # 1 m up, 1.5 m beside the slab's edge
SLAB, SLAB_HALF = np.array([-2.0, 0.5, 0.0]), np.array([2.0, 0.01, 4.0])   # _sun_edge's slab, over x < 0
PANEL, PANEL_TILT = np.array([2.0, 0.6, -1.1]), 40.0   # a panel off the edge's way, tilted towards the lamp
SPHERE_RADIUS = 0.05   # a lamp with a size: its penumbra on the floor at the edge about 0.16 m across


def _grazing_frames(scene, kind: str) -> dict:
    """A spot (30 degrees, its map 128 texels), a lamp (its cube 128 texels a face) or a lamp
    with a size (a sphere SPHERE_RADIUS across: percentage-closer soft shadows) 1 m up
    and 1.5 m to the side of _sun_edge's slab (white floor, black sky), aimed at the slab's
    shadow edge, which its light meets 18 degrees up, and a panel to the side tilted 40
    degrees to face it (n.l 0.27 at its middle), clear of the floor: the light (linear
    green) with the light's shadows off, then on under the "grid" filter at softness 0, 1 and
    4 and under "single" (keys "off", 0.0, 1.0, 4.0, "single"), the floor's points, the
    floor's and the panel's pixels (less two at their rims), and the map's texel on the floor
    along x at the ray-cast edge (metres: from the spot's matrix, or the cube's face
    coordinates, 128 / 2 texels a unit), with that edge (float64 rays to the light)."""
    xs = np.linspace(0.5, 3.0, 25001)
    line = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=1)
    edge = float(xs[np.argmin(box_hits(line, GRAZING_LAMP - line, SLAB, SLAB_HALF, np.ones(len(xs))))])

    def build(world):
        look_from(world, (1.5 + edge, 2.0, 2.0), (edge, 0.0, 0.0), fov=55.0)
        world.spawn(Skybox(faces=BLACK_SKY))
        world.resources["floor"] = world.spawn(Transform(), MeshRef(plane(12.0, 12.0)), Material(
            color=(1.0, 1.0, 1.0), roughness=1.0, environment_reflection=0.0))
        world.spawn(Transform(position=tuple(SLAB)), MeshRef(box(tuple(2.0 * SLAB_HALF))),
                    Material(color=(0.0, 0.0, 0.0)))
        world.resources["panel"] = world.spawn(
            Transform(position=tuple(PANEL), rotation=glm.angleAxis(np.radians(PANEL_TILT), glm.vec3(1, 0, 0))),
            MeshRef(box((1.0, 0.02, 1.0))), Material(color=(1.0, 1.0, 1.0), roughness=1.0,
                                                     environment_reflection=0.0))
        shape = {"spot": {"spot_angle": 30.0, "spot_blend": 0.0}, "sphere": {"radius": SPHERE_RADIUS}}.get(kind, {})
        world.resources["light"] = world.spawn(
            Transform(position=tuple(GRAZING_LAMP), rotation=look_rotation(tuple((edge, 0.0, 0.0) - GRAZING_LAMP))),
            PointLight(intensity=6.0, range=10.0, shadows=False, shadow_resolution=128, **shape))

    runner = scene(build, (128, 96))
    runner.engine.renderer.antialias = "off"
    light = runner.world.get(runner.world.resources["light"], PointLight)
    frames, paths = {}, set()
    for key in ("off", 0.0, 1.0, 4.0, "single"):
        light.shadows = key != "off"
        light.shadow_softness = 1.0 if isinstance(key, str) else key
        runner.engine.renderer.shadows.filter = "single" if key == "single" else "grid"
        runner.frame()
        paths.add(runner.stats.shadow_path)
        frames[key] = srgb_to_linear(runner.frame())[..., 1]
    assert ("spot_map" in paths) == (kind == "spot"), paths
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    points = eye + rays * (-eye[1] / rays[..., 1])[..., None]
    ids = runner.ids()

    def map_texels(x: float) -> np.ndarray:   # the floor point (x, 0, 0) in the map's texels
        if kind == "spot":
            block = runner.engine.renderer.shadows.block.astype(np.float64)
            to_map = block[_RINGS_END // 4:_RINGS_END // 4 + 16].reshape(4, 4).T
            q = to_map @ np.array([x, 0.0, 0.0, 1.0])
            return q[:2] / q[3] * np.array(runner.engine.renderer.shadows.spot_atlas.size)
        way = np.array([x, 0.0, 0.0]) - GRAZING_LAMP
        major = int(np.argmax(np.abs(way)))
        return np.delete(way, major) / abs(way[major]) * 128 / 2.0

    texel = 1e-4 / float(np.linalg.norm(map_texels(edge + 1e-4) - map_texels(edge)))
    return {"frames": frames, "points": points, "floor": ids == runner.world.resources["floor"],
            "panel": ndimage.binary_erosion(ids == runner.world.resources["panel"], iterations=2),
            "texel": texel, "edge": edge}


@pytest.mark.parametrize("kind", ["spot", "lamp", "sphere"])
def test_a_grazing_spots_and_lamps_shadow_edge_stays_put_whatever_the_softness(scene, kind):
    """A spot's map and a lamp's cube under light 18 degrees up (the texels on the floor 10
    and 15 cm): the slab's shadow edge (the place an ideal step with the floor's light there
    would have, against the float64 ray-cast edge) is the same at softness 0, 1 and 4 (within
    0.3 texel) and within 2 texels of it, and the floor under the slab is dark: the taps
    follow the receiver's plane (a spot's through its perspective map, a lamp's along each
    tap's way), so the point is pushed off the floor by a texel, not by the filter's width
    (that push moved the edge in by 1.1, 2.1, 4.7 texels for the spot, 0.9, 1.7, 3.5 for the
    lamp, the floor under the slab 0.4 m in half lit at softness 4; now 1.1 and 0.9 at each).
    And no acne: the lit floor past the edge and the tilted panel keep 0.97 of their light
    with the shadows off, at each softness and under the "single" filter (the taps compared
    with a flat plane left the spot's 0.91 and 0.86 at softness 4, the lamp's panel 0.73 at
    1; a spot's plane found without the divide's term, 0.48).  A lamp with a size filters
    over its penumbra, the softness unused but for the push it took (soft_cube_shadow's was
    still (1 + softness) texels: the floor 0.4 m under the slab 0.2 lit at softness 4); its
    taps compare with the receiver's plane along their ways too (receiver_at)."""
    shot = _grazing_frames(scene, kind)
    frames, points, floor, texel, edge = shot["frames"], shot["points"], shot["floor"], shot["texel"], shot["edge"]
    off = frames["off"]
    x, z = points[..., 0], points[..., 2]
    assert 0.08 < texel < 0.2 and shot["panel"].sum() > 100, (texel, shot["panel"].sum())
    past = floor & (np.abs(z) < 0.5) & (x > edge + 0.6) & (x < edge + 2.0) & (off > 0.02)
    near = floor & (np.abs(z) < 0.6) & (np.abs(x - edge) < 0.9) & (off > 0.02)
    assert past.sum() > 300 and near.sum() > 1000, (past.sum(), near.sum())
    for key in (0.0, 1.0, 4.0, "single"):
        share = frames[key] / np.maximum(off, 1e-6)
        assert share[past].min() > 0.97 and share[shot["panel"]].min() > 0.97, \
            (key, share[past].min(), share[shot["panel"]].min())
    places = []
    for softness in (0.0, 1.0, 4.0):
        share, xs = frames[softness][near] / off[near], x[near]
        bins = np.arange(edge - 0.9, edge + 0.9, 0.02)
        means = np.array([share[(xs >= b) & (xs < b + 0.02)].mean() for b in bins])
        under = means[bins + 0.02 < edge - 0.6]
        assert under.max() < 0.02, (softness, under.max())
        # Where a step holding the same light would stand (a 2-tap grid's edge is a staircase
        # whose half-light crossing is a plateau's end).
        places.append((bins[0] + 0.02 * float(np.sum(1.0 - means)) - edge) / texel)
    assert max(places) - min(places) < 0.3 and max(abs(p) for p in places) < 2.0, places
