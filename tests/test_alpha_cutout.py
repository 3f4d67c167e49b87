"""Cutout materials (``Material.alpha_cutoff``, glTF's ``alphaMode: MASK``): nothing is drawn
where the alpha (the colour's times the texture's) falls below the cutoff, in the view, in a
mirror, and in every kind of shadow map (the sun's atlas, a point light's cube drawn a face
at a time or in one layered pass, a spot's perspective map).

A grate of eight slats (a 2.4 m square at 1.2 m over a floor; its texture opaque on the
even eighths of u, clear on the odd) is judged against float64 rays cast here: which slat a
pixel's ray meets, which a floor point's ray to the light crosses, which a ray reflected by
the mirror meets.  Pixels near a slat's edge (a fifth to a quarter of its width either side)
are left out: the texture's filtering and the shadow filter's reach."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Portal,
    Transform,
    look_rotation,
)
from engine.assets.level_file import LevelError, load_level, save_level
from engine.assets.mesh import load_model, plane, quad
from engine.assets.models import spawn_model
from engine.assets.texture_data import TextureData
from engine.core.errors import AssetError
from engine.core.world import World
from tests.support import look_from, pixel_rays, six_pass_only, skip_unless_layered, srgb_to_linear
from tests.test_materials_from_files import write_glb, write_obj

GRATE_Y, GRATE_HALF, SLATS = 1.2, 1.2, 8
SUN = np.array([-1.0, -1.0, -0.2]) / np.linalg.norm([-1.0, -1.0, -0.2])
LAMP = np.array([1.5, 3.0, 0.3])
SPOT_AXIS = np.array([-2.5, -3.0, -0.5])   # at the grate's centre, to the shadow's middle
SPOT_ANGLE = 44.0
SIZE = (240, 180)


def slat_pixels(size: int = 64, colour=(200, 160, 90)) -> np.ndarray:
    """RGBA: ``colour`` everywhere, alpha 255 on the even eighths of the columns, 0 on the odd."""
    pixels = np.zeros((size, size, 4), np.uint8)
    pixels[..., :3] = colour
    pixels[:, (np.arange(size) * SLATS // size) % 2 == 0, 3] = 255
    return pixels


SLAT_TEXTURE = TextureData(slat_pixels(), name="slats")


def _grate(world, light: str = "sun", cutoff: float | None = 0.5, alpha: float = 1.0, grate: bool = True,
           mirror: bool = False) -> dict:
    eye, target = ((0.0, 5.0, 6.0), (0.0, 0.5, 0.0)) if mirror else ((-0.5, 4.0, 2.2), (-0.5, 0.0, -0.1))
    ids = {"camera": look_from(world, eye, target)}
    if light == "sun":
        world.spawn(DirectionalLight(direction=glm.vec3(*SUN), intensity=2.5))
    elif light == "spot":
        world.spawn(Transform(position=LAMP.tolist(), rotation=look_rotation(SPOT_AXIS.tolist())),
                    PointLight(intensity=20.0, range=10.0, shadows=True, spot_angle=SPOT_ANGLE, spot_blend=0.1))
    else:
        world.spawn(Transform(position=LAMP.tolist()), PointLight(intensity=20.0, range=10.0, shadows=True))
    ids["floor"] = world.spawn(Transform(), MeshRef(plane(12, 12)), Material(color=(0.8, 0.8, 0.8), roughness=1.0))
    if grate:
        ids["grate"] = world.spawn(Transform(position=(0.0, GRATE_Y, 0.0)),
                                   MeshRef(plane(2 * GRATE_HALF, 2 * GRATE_HALF)),
                                   Material(color=(1.0, 1.0, 1.0, alpha), texture=SLAT_TEXTURE, alpha_cutoff=cutoff))
    if mirror:
        ids["mirror"] = world.spawn(Transform(position=(0.0, 1.5, -3.0)), MeshRef(quad(6.0, 3.0)), Material(),
                                    Mirror())
    world.resources["ids"] = ids
    return ids


def _slats(points: np.ndarray, margin: float, edge: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """(on a slat, in a gap) for points on the grate's plane, each at least ``margin`` of a
    slat's width from a slat's edge and ``edge`` metres inside the grate's outline."""
    u = (points[..., 0] + GRATE_HALF) / (2 * GRATE_HALF)
    inside = (np.abs(points[..., 0]) < GRATE_HALF - edge) & (np.abs(points[..., 2]) < GRATE_HALF - edge)
    cell = u * SLATS
    clear = inside & (np.abs(cell - np.floor(cell) - 0.5) < 0.5 - margin)
    even = np.floor(cell) % 2 == 0
    return clear & even, clear & ~even


def _meets_grate(origin: np.ndarray, direction: np.ndarray, grow: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Where rays meet the grate's plane (NaN: never ahead of them), and whether within its
    outline grown by ``grow``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (GRATE_Y - origin[..., 1]) / direction[..., 1]
    points = origin + direction * np.where(t > 0, t, np.nan)[..., None]
    near = (np.abs(points[..., 0]) < GRATE_HALF + grow) & (np.abs(points[..., 2]) < GRATE_HALF + grow)
    return points, near


def _floor_points(runner) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's floor point, and whether the floor is seen there for sure: not through
    the grate's outline, except clearly through a gap."""
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = -eye[1] / rays[..., 1]
    points = eye + rays * t[..., None]
    at_grate, near = _meets_grate(np.broadcast_to(eye, rays.shape), rays)
    _, gap = _slats(at_grate, 0.2)
    return points, (t > 0) & (~near | gap)


def test_a_cutout_is_drawn_only_where_its_alpha_reaches_the_cutoff(scene):
    """Looking down at the grate: the ids say the grate is seen where a pixel's ray meets a
    slat and the floor where it passes a gap; the same grate without a cutoff is seen
    everywhere (its texture's alpha is not a blend: its colour's alpha is 1)."""
    cut = scene(_grate, SIZE)
    whole = scene(lambda w: _grate(w, cutoff=None), SIZE)
    cut.frame(), whole.frame()
    ids = cut.world.resources["ids"]
    eye, rays = pixel_rays(cut.engine.main_view, cut.size)
    at_grate, _ = _meets_grate(np.broadcast_to(eye, rays.shape), rays)
    slat, gap = _slats(at_grate, 0.2)
    assert slat.sum() > 1500 and gap.sum() > 1500, (slat.sum(), gap.sum())
    seen = cut.ids()
    assert (seen[slat] == ids["grate"]).all()
    assert (seen[gap] == ids["floor"]).all()
    assert (whole.ids()[slat | gap] == whole.world.resources["ids"]["grate"]).all()


@pytest.mark.parametrize("alpha, cutoff, drawn", [(0.4, 0.5, False), (0.4, 0.3, True), (0.6, 0.5, True)])
def test_the_colours_alpha_multiplies_the_textures_and_a_cutout_is_never_blended(scene, alpha, cutoff, drawn):
    """The alpha cut is the colour's times the texture's: a colour alpha of 0.4 leaves the
    slats (texture alpha 1) under a cutoff of 0.5 and over one of 0.3.  Where it is drawn it
    is opaque: on the slats the frame equals the colour-alpha-1 grate's (their edges move a
    little: the filtered alpha between a slat's texels and a gap's crosses the cutoff
    elsewhere once scaled), and no batch is transparent."""
    runner = scene(lambda w: _grate(w, alpha=alpha, cutoff=cutoff), SIZE)
    opaque = scene(lambda w: _grate(w, cutoff=cutoff), SIZE)
    frame, opaque_frame = runner.frame(), opaque.frame()
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    slat, _ = _slats(_meets_grate(np.broadcast_to(eye, rays.shape), rays)[0], 0.2)
    grate = runner.world.resources["ids"]["grate"]
    assert (runner.ids()[slat] == grate).all() == drawn
    assert not (runner.ids()[slat] == grate).any() or drawn
    assert not runner.engine.renderer.transparent_batches()
    if drawn:
        np.testing.assert_array_equal(frame[slat], opaque_frame[slat])


def _light_rays(points: np.ndarray, light: str) -> tuple[np.ndarray, np.ndarray]:
    """Where each floor point's way to the light crosses the grate's plane, and whether it
    crosses within the grate's grown outline."""
    if light == "sun":
        return _meets_grate(points, np.broadcast_to(-SUN, points.shape))
    return _meets_grate(points, LAMP - points)


@pytest.mark.parametrize("light, path", [("sun", ""), ("point", "layered"), ("point", "six_pass"),
                                         ("spot", "spot_map")])
def test_a_cutouts_shadow_falls_only_under_its_slats(scene, monkeypatch, light, path):
    """Each floor point whose way to the light crosses a slat is darker than with no grate
    there; one whose way crosses a gap, or misses the grate, is as lit as with no grate.  The
    grate drawn whole shadows the gaps' points too: the shadow maps read the cutout."""
    if path == "six_pass":
        six_pass_only(monkeypatch)
    cut = scene(lambda w: _grate(w, light), SIZE)
    bare = scene(lambda w: _grate(w, light, grate=False), SIZE)
    whole = scene(lambda w: _grate(w, light, cutoff=None), SIZE)
    cut_rgb, bare_rgb, whole_rgb = cut.frame(), bare.frame(), whole.frame()
    if path == "layered":  # (a driver refusing both layered targets draws six passes)
        skip_unless_layered(cut.engine.renderer)
    if path:
        assert cut.stats.shadow_path == path
    points, floor = _floor_points(cut)
    floor &= cut.ids() == cut.world.resources["ids"]["floor"]
    crossing, near = _light_rays(points, light)
    under, between = _slats(crossing, 0.25)
    if light == "spot":   # inside the cone's full light only
        to = points - LAMP
        cosine = to @ SPOT_AXIS / np.linalg.norm(to, axis=-1) / np.linalg.norm(SPOT_AXIS)
        floor &= np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))) < SPOT_ANGLE * 0.9 - 3.0
    shadowed, lit, missed = floor & under, floor & between, floor & ~near
    assert shadowed.sum() > 500 and lit.sum() > 500 and missed.sum() > 5000, \
        (shadowed.sum(), lit.sum(), missed.sum())
    luminance = {name: srgb_to_linear(rgb).mean(-1) for name, rgb in
                 (("cut", cut_rgb), ("bare", bare_rgb), ("whole", whole_rgb))}
    assert (luminance["cut"][shadowed] < 0.7 * luminance["bare"][shadowed]).all()
    for where in (lit, missed):
        assert np.abs(cut_rgb[where].astype(int) - bare_rgb[where]).max() <= 2
    # Drawn whole, the grate shadows the gaps' points as well (where it does not hide them).
    behind = lit & (whole.ids() == whole.world.resources["ids"]["floor"])
    assert behind.sum() > 300
    assert (luminance["whole"][behind] < 0.7 * luminance["bare"][behind]).all()


def test_a_mirror_shows_the_cutout_with_its_gaps(scene):
    """Pixels of the mirror whose reflected ray meets a slat see the grate (its id); those
    whose reflected ray passes a gap see past it."""
    runner = scene(lambda w: _grate(w, mirror=True), (320, 240))
    runner.frame()
    ids = runner.world.resources["ids"]
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    t = (-3.0 - eye[2]) / rays[..., 2]
    on = eye + rays * t[..., None]
    mirror = (t > 0) & (np.abs(on[..., 0]) < 2.9) & (on[..., 1] > 0.1) & (on[..., 1] < 2.9)
    _, before = _meets_grate(np.broadcast_to(eye, rays.shape), rays, grow=0.1)
    at_grate, _ = _meets_grate(np.broadcast_to(eye, rays.shape), rays)
    mirror &= ~(before & (np.linalg.norm(at_grate - eye, axis=-1) < t))   # the grate itself in front
    reflected = rays * np.array([1.0, 1.0, -1.0])
    slat, gap = _slats(_meets_grate(on, reflected)[0], 0.25)
    slat, gap = slat & mirror, gap & mirror
    assert slat.sum() > 100 and gap.sum() > 100, (slat.sum(), gap.sum())
    seen = runner.ids()
    assert (seen[slat] == ids["grate"]).all()
    assert not (seen[gap] == ids["grate"]).any()


@pytest.mark.parametrize("change", ["alpha", "cutoff"])
def test_changing_a_cutout_draws_the_kept_shadow_maps_again(scene, change):
    """The sun's map is kept while nothing changes.  Lowering the colour's alpha under the
    cutoff (the slats go) or changing the cutoff (a batch of its own) draws it again: the
    frame equals a fresh engine's made with the new values."""
    runner = scene(_grate, SIZE)
    runner.frame(), runner.frame()
    assert runner.stats.shadow_maps_drawn == 0
    material = runner.world.get(runner.world.resources["ids"]["grate"], Material)
    if change == "alpha":
        material.color = glm.vec4(1.0, 1.0, 1.0, 0.3)
        fresh = scene(lambda w: _grate(w, alpha=0.3), SIZE)
    else:
        material.color = glm.vec4(1.0, 1.0, 1.0, 0.3)
        runner.frame()
        material.alpha_cutoff = 0.2
        fresh = scene(lambda w: _grate(w, alpha=0.3, cutoff=0.2), SIZE)
    frame = runner.frame()
    assert runner.stats.shadow_maps_drawn >= 1
    np.testing.assert_array_equal(frame, fresh.frame())


def test_a_new_cutoff_draws_with_the_programs_already_built(scene):
    """The cutoff is a uniform of the cutout builds, not compiled in: a grate dragged from
    one cutoff to another in the editor compiles nothing (a batch of its own, the same
    programs), and draws as a fresh engine made with the new cutoff."""
    runner = scene(lambda w: _grate(w, alpha=0.4, cutoff=0.3), SIZE)
    runner.frame(), runner.frame()
    shaders = runner.engine.renderer.shaders
    built = len(shaders._programs)
    material = runner.world.get(runner.world.resources["ids"]["grate"], Material)
    for cutoff in (0.35, 0.38, 0.39):   # still under the colour's 0.4: the slats stay
        material.alpha_cutoff = cutoff
        frame = runner.frame()
    assert len(shaders._programs) == built
    np.testing.assert_array_equal(frame, scene(lambda w: _grate(w, alpha=0.4, cutoff=0.39), SIZE).frame())
    material.alpha_cutoff = 0.41   # over it: the slats go, in the view and the sun's map
    np.testing.assert_array_equal(runner.frame(), scene(lambda w: _grate(w, grate=False), SIZE).frame())


# --- values ----------------------------------------------------------------------------------

@pytest.mark.parametrize("value, reason", [(1.5, "<= 1.0"), (-0.1, ">= 0.0"), (float("nan"), "finite"),
                                           ("half", "number"), (True, "number")])
def test_a_bad_cutoff_is_refused_naming_the_field(value, reason):
    with pytest.raises(ComponentValueError, match=rf"Material\.alpha_cutoff.*{reason}"):
        Material(alpha_cutoff=value)
    material = Material()
    with pytest.raises(ComponentValueError, match=r"Material\.alpha_cutoff"):
        material.alpha_cutoff = value
    assert material.alpha_cutoff is None


@pytest.mark.parametrize("surface", ["Mirror", "Portal"])
def test_a_mirror_or_portal_is_never_a_cutout(surface):
    """Refused when spawned, when the surface joins a cutout and when the cutoff is set."""
    world = World()
    kind = Mirror if surface == "Mirror" else Portal
    with pytest.raises(ComponentValueError, match=f"alpha_cutoff 0.5 on a {surface}"):
        world.spawn(Transform(), MeshRef(quad()), Material(alpha_cutoff=0.5), kind())
    cutout = world.spawn(Transform(), MeshRef(quad()), Material(alpha_cutoff=0.5))
    with pytest.raises(ComponentValueError, match=f"on a {surface}"):
        world.add_component(cutout, kind())
    held = world.spawn(Transform(), MeshRef(quad()), Material(), kind())
    with pytest.raises(ComponentValueError, match=f"on a {surface}"):
        world.get(held, Material).alpha_cutoff = 0.25
    assert world.get(held, Material).alpha_cutoff is None


def test_a_level_file_keeps_a_cutout(tmp_path):
    from PIL import Image

    Image.fromarray(slat_pixels()).save(tmp_path / "slats.png")
    text = """[level]
name = "grate"

[[entity]]
name = "grate"
Transform = { position = [0.0, 1.2, 0.0] }
MeshRef = { mesh = { plane = [2.4, 2.4] } }
Material = { texture = { file = "slats.png" }, alpha_cutoff = 0.35 }
"""
    (tmp_path / "grate.toml").write_text(text)
    world = World()
    names = load_level(tmp_path / "grate.toml").spawn(world)
    material = world.get(names["grate"], Material)
    assert material.alpha_cutoff == pytest.approx(0.35)
    saved = save_level(world, tmp_path / "again.toml", names, name="grate")
    again = World()
    names = load_level(saved).spawn(again)
    assert again.get(names["grate"], Material).alpha_cutoff == pytest.approx(0.35)
    (tmp_path / "bad.toml").write_text(text.replace("0.35", "2.0"))
    with pytest.raises(LevelError, match=r"alpha_cutoff.*<= 1.0"):
        load_level(tmp_path / "bad.toml").spawn(World())


# --- glTF ------------------------------------------------------------------------------------

def _glb(tmp_path, mode: str | None, cutoff: float | None = None, factor_alpha: float = 1.0,
         metallic: float = 0.0, name: str = "m.glb"):
    material = {"name": "slats", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, factor_alpha],
                                                           "baseColorTexture": {"index": 0},
                                                           "metallicFactor": metallic}}
    if mode is not None:
        material["alphaMode"] = mode
    if cutoff is not None:
        material["alphaCutoff"] = cutoff
    return write_glb(tmp_path / name, plane(2.4, 2.4), material, [slat_pixels()])


@pytest.mark.parametrize("mode, cutoff, expected_cutoff, expected_alpha", [
    ("MASK", None, 0.5, 1.0), ("MASK", 0.3, 0.3, 1.0), (None, None, None, 1.0), ("OPAQUE", None, None, 1.0),
    ("BLEND", None, None, 0.999)])
def test_gltf_alpha_modes_reach_the_material(tmp_path, mode, cutoff, expected_cutoff, expected_alpha):
    """MASK: the file's cutoff (0.5 when it gives none); OPAQUE (the default): the alpha is
    ignored, even the factor's 0.5; BLEND with a see-through texture: the transparent slot."""
    path = _glb(tmp_path, mode, cutoff, factor_alpha=0.5 if mode in (None, "OPAQUE") else 1.0)
    world = World()
    root = spawn_model(world, path)
    (part,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
    material = world.get(part, Material)
    assert material.alpha_cutoff == (pytest.approx(expected_cutoff) if expected_cutoff is not None else None)
    assert material.color.w == pytest.approx(expected_alpha)


def test_gltf_bad_alpha_values_are_refused_naming_the_material(tmp_path):
    with pytest.raises(AssetError, match=r"slats.*alphaCutoff must be a number in \[0, 1\]"):
        load_model(_glb(tmp_path, "MASK", 1.5))
    with pytest.raises(AssetError, match=r"clip\.glb.*alphaMode.*CLIP"):   # (trimesh's own check)
        load_model(_glb(tmp_path, "CLIP", name="clip.glb"))


def test_a_flat_metal_cutout_from_a_file_reflects_without_becoming_a_mirror(tmp_path):
    """A flat metallic part is a planar mirror, but a flat metal grate (MASK) cannot be one
    (a mirror is drawn whole): it reflects as a curved part does, through a probe."""
    world = World()
    root = spawn_model(world, _glb(tmp_path, "MASK", metallic=1.0))
    (part,) = [e for e, (t,) in world.query(Transform) if t.parent == root]
    assert not world.has(part, Mirror)
    assert world.get(part, Material).alpha_cutoff == 0.5
    from components import Reflective
    assert world.get(part, Reflective).mode == "cube"
    plain = World()
    root = spawn_model(plain, _glb(tmp_path, None, metallic=1.0, name="plain.glb"))
    (part,) = [e for e, (t,) in plain.query(Transform) if t.parent == root]
    assert plain.has(part, Mirror)
    assert math.isclose(plain.get(part, Material).color.w, 1.0)


def test_an_obj_dissolve_map_makes_an_opaque_material_a_cutout(scene, tmp_path):
    """An MTL with ``map_Kd`` (the slats' colour, opaque) and ``map_d`` (a grey image: the
    slats white, the gaps black) is the slatted texture's cutout at 0.5: the model draws the
    frame the grate made in code draws; ``d`` below 1 keeps it blended instead."""
    colour = slat_pixels()
    grey = colour[..., 3].copy()
    colour[..., 3] = 255
    path = write_obj(tmp_path, plane(2 * GRATE_HALF, 2 * GRATE_HALF), "Kd 1 1 1\nmap_Kd colour.png\nmap_d mask.png",
                     {"colour.png": colour[..., :3].copy(), "mask.png": grey})
    (part,) = load_model(path)
    assert part.alpha_cutoff == 0.5
    np.testing.assert_array_equal(part.texture.pixels, slat_pixels())

    def build(world):
        _grate(world, grate=False)
        world.resources["ids"]["grate"] = spawn_model(world, path, position=(0.0, GRATE_Y, 0.0))
    from_file = scene(build, SIZE)
    in_code = scene(_grate, SIZE)
    assert np.abs(from_file.frame().astype(int) - in_code.frame()).max() <= 1
    (tmp_path / "model.mtl").write_text("newmtl m\nKd 1 1 1\nd 0.8\nmap_Kd colour.png\nmap_d mask.png\n")
    (part,) = load_model(path)
    assert part.alpha_cutoff is None and part.color[3] == pytest.approx(0.8)


# --- far away: mip levels that keep the coverage -----------------------------------------------

def dots_pixels(size: int = 128, share: float = 0.3, seed: int = 5) -> np.ndarray:
    """RGBA: a leafy pattern, ``share`` of the texels opaque, at random (seeded), the rest clear."""
    pixels = np.zeros((size, size, 4), np.uint8)
    pixels[..., :3] = (60, 140, 50)
    pixels[..., 3] = np.where(np.random.default_rng(seed).random((size, size)) < share, 255, 0)
    return pixels


def test_every_mip_level_of_a_cutouts_texture_keeps_its_coverage(scene):
    """Averaged down the mip chain, 30% scattered opaque texels fall under a 0.5 cutoff by
    level 3 (the driver's own chain, uploaded for an ordinary texture); a cutout's texture
    has each level's alpha rescaled so as much of it stays over the cutoff as of level 0,
    measured as the sampler blends it (engine/render/cutout_mips.py)."""
    from engine.render.cutout_mips import alpha_share

    runner = scene(lambda w: look_from(w, (0.0, 1.0, 3.0)), (32, 32))
    runner.frame()
    renderer = runner.engine.renderer
    texture = TextureData(dots_pixels(), name="dots")
    plain, kept = renderer._upload_texture(texture), renderer._upload_cutout_texture(texture, 0.5)
    target = alpha_share(texture.pixels[..., 3], 0.5, filtered=True)   # as the sampler sees level 0
    assert 0.15 < target < 0.32
    try:
        for level, side in enumerate((128, 64, 32, 16, 8)):
            kept_alpha, plain_alpha = (np.frombuffer(t.read(level=level), np.uint8).reshape(side, side, 4)[..., 3]
                                       for t in (kept, plain))
            assert abs(alpha_share(kept_alpha, 0.5, filtered=True) - target) <= 0.05, level
            if level >= 3:
                assert alpha_share(plain_alpha, 0.5, filtered=True) < 0.05, level
    finally:
        plain.release()
        kept.release()


def test_a_far_cutout_keeps_its_leaves(scene, monkeypatch):
    """A 30%-opaque leafy cutout 30 m away (its texture 1.5 mip levels down) still covers
    more than a tenth of the pixels it spans (14% here, 25% on an H200); with the driver's
    plain mip chain it all but vanishes (1% here, 3% on the H200, whose anisotropic
    filtering reads finer levels)."""
    from engine.render import renderer as renderer_module

    leaves = TextureData(dots_pixels(), name="leaves")

    def build(world):
        look_from(world, (0.0, 1.0, 0.0), (0.0, 1.0, -1.0), fov=40.0)
        world.resources["ids"] = {"leaves": world.spawn(
            Transform(position=(0.0, 1.0, -30.0)), MeshRef(quad(4.0, 4.0)),
            Material(texture=leaves, alpha_cutoff=0.5, roughness=1.0))}

    def share(runner) -> float:
        runner.frame()
        eye, rays = pixel_rays(runner.engine.main_view, runner.size)
        t = (-30.0 - eye[2]) / rays[..., 2]
        points = eye + rays * t[..., None]
        inside = (np.abs(points[..., 0]) < 1.9) & (np.abs(points[..., 1] - 1.0) < 1.9)
        assert inside.sum() > 400
        return float((runner.ids()[inside] == runner.world.resources["ids"]["leaves"]).mean())

    kept = share(scene(build, (320, 240)))
    monkeypatch.setattr(renderer_module, "keep_alpha_share", lambda alpha, cutoff, target: alpha)
    plain = share(scene(build, (320, 240)))
    # Level 0, as the sampler sees it, covers 28%; a far pixel reads two small levels blended
    # (trilinear), which thins any pattern, so the far share is under that, but not gone.
    assert kept > 0.1 and plain < 0.05 and kept > 4 * plain, (kept, plain)
