"""See-through things in front of a mirror blend over its reflection, at every level of a
view tree: the main view (level 0), a mirror seen in a mirror (level 1), and a probe face's
own tree.  The tree draws each level's transparent slot after compositing the level below
into it (``ScenePass.draw_transparent``), so the claims give the mirror the pixels behind
the glass and the glass blends over what the composite put there, never over the mirror's
own colour.

Checked by a second path, the blend rule applied in numpy: the same configuration drawn
three times, with the pane at alpha 0.5 (``a``), without it (what lies behind it: the
reflection) and with it opaque (its own shaded colour, the same shading at alpha 1), and
every pixel of the composited HDR image (level 0, linear, before present) must be
``a x opaque + (1 - a) x without``, the transparent slot's "over" blend
(``bindings.BLEND_OVER``).  Where the pane covers mirror B directly and where it is seen in
mirror A over B's reflection, the reflection behind it is bright green and each mirror's
own colour dark, so glass over the mirror's own colour misses by far more than the
tolerance."""
from __future__ import annotations

import shutil

import numpy as np
import pytest
from pyglm import glm

import engine.render.shader_library as shader_library
from components import Emissive, Material, MeshRef, Mirror, ReflectionProbe, Skybox, Transform
from engine.assets.mesh import quad
from engine.core.cube_faces import FACE_NAMES
from engine.render.frame_views import FrameViews
from tests.support import kept_frames_equal_drawn, look_from

SIZE = (240, 135)
ALPHA = 0.5
Y = glm.vec3(0.0, 1.0, 0.0)
PROBE_AT = (0.0, 1.5, 5.0)
# A float16 target (RGBA16F): each stored value within half an ulp (2^-11 relative), three
# images and a blend: a few thousandths of a value below 1.
RTOL, ATOL = 4e-3, 2e-3


def _room(ents: dict, alpha: float | None, probe: bool = False, see_through: bool = False):
    """Mirror B on the back wall (seen directly), mirror A on the left wall (B seen in it), a
    green emissive wall behind the camera (what both reflect) and, unless ``alpha`` is None,
    a 1 m pane of emissive red glass half a metre in front of B.  ``see_through``: B is a
    see-through mirror (alpha 0.6, as water is; reflect rate 0.7, so its own blend shows),
    drawn in the transparent slot before its claims, the pane after its composite, with a
    blue wall behind it (what shows through it)."""
    def build(world) -> None:
        world.spawn(Skybox())
        ents["camera"] = look_from(world, (0.0, 1.5, 4.0), target=(-1.0, 1.5, 0.0))
        ents["b"] = world.spawn(Transform(position=(1.2, 1.5, -3.0)), MeshRef(quad(3.0, 2.0)),
                                Material(color=(0.3, 0.3, 0.3, 0.6 if see_through else 1.0)),
                                Mirror(reflect_rate=0.7 if see_through else 1.0))
        ents["a"] = world.spawn(Transform(position=(-3.0, 1.5, 1.0), rotation=glm.angleAxis(glm.half_pi(), Y)),
                                MeshRef(quad(2.4, 2.0)), Material(color=(0.3, 0.3, 0.3)), Mirror())
        ents["wall"] = world.spawn(Transform(position=(0.0, 1.5, 9.0), rotation=glm.angleAxis(glm.pi(), Y)),
                                   MeshRef(quad(60.0, 20.0)), Material(color=(0.1, 0.8, 0.1)), Emissive(1.0))
        if see_through:
            world.spawn(Transform(position=(1.2, 1.5, -3.5)), MeshRef(quad(4.0, 3.0)), Material(color=(0.1, 0.2, 0.8)),
                        Emissive(0.5))
        if alpha is not None:
            ents["glass"] = world.spawn(Transform(position=(1.2, 1.5, -2.5)), MeshRef(quad(1.0, 1.0)),
                                        Material(color=(0.9, 0.15, 0.1, alpha)), Emissive(0.6))
        if probe:  # its -Z face sees B, the pane and A (B in A): a face that roots a view tree
            ents["probe"] = world.spawn(Transform(position=PROBE_AT), ReflectionProbe(resolution=128, depth=2))
    return build


def _render(scene, alpha: float | None, path: str = "per_mirror", visibility: str = "exact", probe: bool = False,
            see_through: bool = False):
    """The third frame of the room: level 0's linear colour (h, w, 3; row 0 at the top), its
    seen and surface ids, level 1's surface ids, the runner and the entities."""
    ents: dict = {}
    runner = scene(_room(ents, alpha, probe, see_through), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.engine.reflection_system.path = path
    runner.engine.reflection_system.visibility = visibility
    for _ in range(3):
        rgb = runner.frame()
    levels = runner.engine.renderer.levels
    w, h = SIZE
    colour = np.frombuffer(levels[0].color.read(), np.float16).reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
    return {"colour": colour, "rgb": rgb, "seen": runner.ids(), "surface": levels[0].read_surface_ids(),
            "level1": levels[1].read_surface_ids(), "runner": runner, "ents": ents}


def _blend_agrees(got: np.ndarray, opaque: np.ndarray, without: np.ndarray) -> None:
    want = ALPHA * opaque + (1.0 - ALPHA) * without
    bad = ~np.isclose(got, want, rtol=RTOL, atol=ATOL).all(axis=-1)
    assert not bad.any(), (f"{int(bad.sum())} pixels are not the pane blended over what is behind it; worst "
                           f"{np.abs(got - want).max():.4f}, e.g. got {got[bad][0]} want {want[bad][0]}")


@pytest.mark.parametrize("path,visibility,see_through", [
    ("per_mirror", "exact", False), ("batched", "exact", False), ("per_mirror", "predicted", False),
    ("batched", "predicted", False), ("per_mirror", "exact", True), ("batched", "predicted", True)])
def test_glass_blends_over_the_reflection_directly_and_in_a_mirror(scene, path, visibility, see_through):
    glass = _render(scene, ALPHA, path, visibility, see_through=see_through)
    without = _render(scene, None, path, visibility, see_through=see_through)
    opaque = _render(scene, 1.0, path, visibility, see_through=see_through)
    ents = glass["ents"]
    stats = glass["runner"].stats
    assert stats.reflection_path == path and stats.reflection_visibility == visibility
    assert len(glass["runner"].engine.renderer.transparent_batches()) == 1 + see_through
    pane = glass["seen"] == ents["glass"]
    direct = pane & (glass["surface"] == ents["glass"])   # the pane in front of B, in the main view
    in_a = pane & (glass["surface"] == ents["a"])         # the pane seen in A, in front of B's image
    assert direct.sum() > 200 and in_a.sum() > 40, (direct.sum(), in_a.sum())
    # Behind the pane: B's reflection of the green wall, directly and in A (B in A's level).
    assert (without["surface"][direct] == ents["b"]).all()
    assert (without["level1"][in_a] == ents["b"]).all()
    assert (without["seen"][direct | in_a] == ents["wall"]).all()
    behind = without["colour"][direct | in_a]
    # Green, not the dark mirror (a see-through B shows the sky through it too, under the green).
    assert (behind[:, 1] > 0.5).all() and (behind[:, 1] > (1.5 if see_through else 3.0) * behind[:, 0]).all()
    # Every pixel, the pane's and the rest: the "over" blend of the pane on what lies behind it.
    _blend_agrees(glass["colour"], opaque["colour"], without["colour"])
    # The ids are the pane's where it is seen (directly: its surface too), the rest as without it.
    assert np.array_equal(glass["seen"][~pane], without["seen"][~pane])
    assert np.array_equal(glass["surface"][~direct], without["surface"][~direct])
    assert glass["rgb"].max() > 100  # a picture, not a black frame


def test_the_blend_holds_where_the_filter_weighs_a_texels_neighbours_a_little(scene, monkeypatch, tmp_path):
    """A GPU filters with fixed-point weights: a bilinear read at a texel's centre weighs
    the texels beside it a little (the NVIDIA H200 showed the mirror's level under the
    pane's edge as a seam there).  The composite reads a level drawn at its parent's
    resolution texel for texel, so its lookups moved by 3% of a texel (shaders copied, the
    line changed) leave every pixel the pane's blend over what is behind it."""
    shaders = tmp_path / "shaders"
    shutil.copytree(shader_library.shader_dir(), shaders)
    composite = shaders / "mirror_composite.frag"
    line = "vec2 uv = gl_FragCoord.xy / parent_size;"
    assert line in composite.read_text()
    moved = "vec2 uv = (gl_FragCoord.xy + vec2(0.03, -0.03)) / parent_size;"
    composite.write_text(composite.read_text().replace(line, moved))
    monkeypatch.setattr(shader_library, "shader_dir", lambda: shaders)
    glass, without, opaque = (_render(scene, alpha) for alpha in (ALPHA, None, 1.0))
    assert (glass["seen"] == glass["ents"]["glass"]).sum() > 200
    _blend_agrees(glass["colour"], opaque["colour"], without["colour"])


def test_glass_in_front_of_a_mirror_in_a_probe_face(scene):
    """A probe whose faces see mirrors roots a view tree per face (depth 2): its -Z face,
    read back in linear float, is the pane blended over what is behind it, B's reflection
    directly and in A."""
    face = FACE_NAMES.index("-Z")
    faces = {}
    for name, alpha in (("glass", ALPHA), ("without", None), ("opaque", 1.0)):
        rendered = _render(scene, alpha, probe=True)
        faces[name] = rendered["runner"].engine.renderer.probes.read_face(rendered["ents"]["probe"], face)
        faces[name] = faces[name].astype(np.float64)
    glass, without, opaque = faces["glass"], faces["without"], faces["opaque"]
    covered = np.abs(opaque - without).max(axis=-1) > 0.05  # where the pane is in the face
    green_behind = covered & (without[..., 1] > 0.5) & (without[..., 1] > 3.0 * without[..., 0])
    # The pane over the green wall, which is behind the probe: only its reflections show it here.
    assert green_behind.sum() > 40, green_behind.sum()
    _blend_agrees(glass, opaque, without)


def test_mirrors_behind_glass_are_drawn_unlit_and_the_frame_is_the_all_lit_one(scene):
    """Glass no longer keeps the mirrors behind it shaded (unlit_mirrors.shading_replaced): it
    is drawn over their composited reflections, so the main view writes the unlit build's
    black under both mirrors, and the frame, pixel for pixel and id for id, is the one of an
    engine that shades every mirror (``MainViewSystem.depth_cap`` None, ``ViewTree.unlit``
    False)."""
    fast = _render(scene, ALPHA)
    shaded_ents: dict = {}
    shaded = scene(_room(shaded_ents, ALPHA), SIZE)
    shaded.engine.renderer.antialias = "off"
    shaded.engine.stages["main"].depth_cap = None
    shaded.engine.reflection_system.tree.unlit = False
    for _ in range(3):
        rgb = shaded.frame()
    assert np.array_equal(fast["rgb"], rgb) and np.array_equal(fast["seen"], shaded.ids())
    engine, ents = fast["runner"].engine, fast["ents"]
    assert engine.stages["main"]._root_options().unlit == {ents["a"], ents["b"]}
    engine.stages["main"].process(1.0 / 60.0)  # the main view alone, into level 0
    targets = engine.world.resources[FrameViews].levels[0]
    w, h = targets.size
    colour = np.frombuffer(targets.color.read(), np.float16).reshape(h, w, 4)
    surface = np.frombuffer(targets.surface.read(), np.uint32).reshape(h, w)
    under = np.isin(surface, [ents["a"], ents["b"]])
    assert under.sum() > 1000 and np.all(colour[under] == (0.0, 0.0, 0.0, 1.0))
    # The pane is not drawn yet: the reflect stage draws it over the reflections.
    assert not (surface == ents["glass"]).any()


def test_glass_with_only_the_sky_behind_it_in_a_mirror(scene):
    """A pane behind the camera, seen only in the mirror, with nothing but the sky behind
    it: a reflection level draws no sky (its composite adds it where the level's coverage,
    its alpha, is short of 1), so the pane's blend must add its own alpha to the coverage
    (``bindings.BLEND_OVER``); kept at 0, the sky came through it in full.  The pane over
    the sky is its blend rule, as in the main view: a x opaque + (1 - a) x without."""
    def room(alpha: float | None):
        def build(world) -> None:
            world.spawn(Skybox())
            look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -3.0))
            world.spawn(Transform(position=(0.0, 1.5, -3.0)), MeshRef(quad(4.0, 3.0)), Material(color=(0.3, 0.3, 0.3)),
                        Mirror())
            if alpha is not None:  # behind the camera, facing the mirror
                world.spawn(Transform(position=(0.0, 1.5, 6.0), rotation=glm.angleAxis(glm.pi(), Y)),
                            MeshRef(quad(2.0, 2.0)), Material(color=(0.9, 0.15, 0.1, alpha)), Emissive(0.6))
        return build

    colour = {}
    for alpha in (ALPHA, None, 1.0):
        runner = scene(room(alpha), SIZE)
        runner.engine.renderer.antialias = "off"
        for _ in range(2):
            runner.frame()
        w, h = SIZE
        colour[alpha] = np.frombuffer(runner.engine.renderer.levels[0].color.read(),
                                      np.float16).reshape(h, w, 4)[..., :3].astype(np.float64)
    pane = np.abs(colour[1.0] - colour[None]).max(axis=-1) > 0.05
    assert pane.sum() > 150  # the pane, in the mirror, over the sky
    _blend_agrees(colour[ALPHA], colour[1.0], colour[None])


def test_a_switched_off_see_through_mirror_keeps_its_fallback(scene):
    """A see-through mirror switched off (Mirror.enabled False: drawn as its plain material)
    is still a surface of the tree: its fallback (the sky's reflection, at its reflect rate
    w) is drawn over its pixels, so it is drawn with the opaque batches, not after the
    composites as glass is.  The fallback's colour F over whatever the pixel holds is
    w F + (1 - w) x under, so from the same quad opaque (switched off, and without the
    Mirror): w F = opaque_off - (1 - w) opaque_plain, and the see-through one switched off
    must be w F + (1 - w) see_through_plain."""
    rate = 0.6

    def room(ents: dict, alpha: float, mirror: bool):
        def build(world) -> None:
            world.spawn(Skybox())
            look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -3.0))
            world.spawn(Transform(position=(0.0, 1.5, -4.0)), MeshRef(quad(8.0, 6.0)),
                        Material(color=(0.1, 0.2, 0.8)), Emissive(0.5))  # behind it
            parts = [Transform(position=(0.0, 1.5, -3.0)), MeshRef(quad(3.0, 2.0)),
                     Material(color=(0.8, 0.3, 0.1, alpha))]
            if mirror:
                parts.append(Mirror(enabled=False, reflect_rate=rate))
            ents["quad"] = world.spawn(*parts)
        return build

    colour, on_quad = {}, None
    for alpha in (0.5, 1.0):
        for mirror in (True, False):
            ents: dict = {}
            runner = scene(room(ents, alpha, mirror), SIZE)
            runner.engine.renderer.antialias = "off"
            for _ in range(2):
                runner.frame()
            w, h = SIZE
            levels = runner.engine.renderer.levels
            colour[alpha, mirror] = np.frombuffer(levels[0].color.read(), np.float16).reshape(
                h, w, 4)[::-1, :, :3].astype(np.float64)
            if mirror:
                assert runner.stats.reflection_fallbacks >= 1
                if alpha == 0.5:
                    on_quad = levels[0].read_surface_ids() == ents["quad"]
    weighted_fallback = colour[1.0, True] - (1.0 - rate) * colour[1.0, False]
    want = weighted_fallback + (1.0 - rate) * colour[0.5, False]
    assert on_quad.sum() > 1000
    assert np.abs(colour[0.5, True] - colour[0.5, False])[on_quad].max() > 0.05  # the fallback shows
    bad = ~np.isclose(colour[0.5, True], want, rtol=RTOL, atol=ATOL).all(axis=-1)
    assert not bad.any(), f"{int(bad.sum())} pixels differ; worst {np.abs(colour[0.5, True] - want).max():.4f}"


def test_a_kept_tree_draws_the_roots_glass_over_its_composite(scene):
    """A still frame keeps the tree (``StillTree.keep``): levels 1 and below hold their own
    glass already, and the root, drawn anew without its transparent slot, gets its glass
    after level 1's composite, so a kept frame is the frame drawn whole (keeping off), bit
    for bit: colour, HDR image and ids."""
    ents: dict = {}
    keeping, drawing = scene(_room(ents, ALPHA), SIZE), scene(_room({}, ALPHA), SIZE)
    assert kept_frames_equal_drawn(keeping, drawing) >= 2
    assert (keeping.ids() == ents["glass"]).sum() > 300  # the pane, directly and in A
