"""What a see-through material's alpha fades (``Material.blend``): "fade" all of its light,
"transparent" only its diffuse light, its highlights and its reflection of the sky lying
whole over what shows through.  Checked against frames drawn without the pane and with it
opaque: a black pane's light is all highlight and reflection, so over a blue wall the pane
at alpha a shows that light (fade: a x it) plus (1 - a) x the wall, channel by channel."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Emissive,
    Fog,
    Material,
    MeshRef,
    Reflective,
    Skybox,
    Transform,
)
from engine.assets.mesh import quad
from engine.assets.texture_data import TextureData
from tests.support import look_from, srgb_to_linear

SIZE = (120, 90)
ALPHA = 0.3


def scene_with(pane: Material | tuple | None, fog: bool = False):
    def build(world):
        camera = look_from(world, (0.0, 0.0, 6.0), (0.0, 0.0, 0.0), fov=40.0)
        if fog:
            world.add_component(camera, Fog(color=(0.6, 0.3, 0.1), density=0.12))
        world.spawn(Skybox(faces=np.full((6, 4, 4, 3), 0.5, np.float32)))
        if not fog:
            world.spawn(DirectionalLight(direction=(0.0, -0.15, -1.0), intensity=0.6, shadows=False))
        world.spawn(Transform(position=(0.0, 0.0, -2.0)), MeshRef(quad(12.0, 9.0)),
                    Material(color=(0.0, 0.0, 0.4, 1.0), environment_reflection=0.0), Emissive(power=1.0))  # blue
        if pane is not None:
            world.spawn(Transform(), MeshRef(quad(3.0, 3.0)), *(pane if isinstance(pane, tuple) else (pane,)))
    return build


def linear(scene, pane: Material | tuple | None, fog: bool = False) -> np.ndarray:
    runner = scene(scene_with(pane, fog), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame())


def test_transparent_keeps_the_highlights_and_reflections_whole_and_fade_fades_them(scene):
    wall = linear(scene, None)
    opaque = linear(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3))
    kept = linear(scene, Material(color=(0.0, 0.0, 0.0, ALPHA), roughness=0.3, blend="transparent"))
    faded = linear(scene, Material(color=(0.0, 0.0, 0.0, ALPHA), roughness=0.3))
    # The pane's middle (it covers 3 m of the 4.4 m the view spans at its distance).
    h, w = SIZE[1], SIZE[0]
    middle = (slice(h // 2 - 25, h // 2 + 25), slice(w // 2 - 30, w // 2 + 30))
    light = opaque[middle]
    assert light[..., 0].max() > 0.15 and light[..., 0].min() > 0.015   # a highlight over the sky's reflection
    assert wall[middle][..., 2].min() > 0.4
    step = 0.012   # about 1.5 sRGB levels where these values lie
    np.testing.assert_allclose(kept[middle], light + (1.0 - ALPHA) * wall[middle], atol=step, rtol=0.02)
    np.testing.assert_allclose(faded[middle], ALPHA * light + (1.0 - ALPHA) * wall[middle], atol=step, rtol=0.02)
    # (and the two differ where the highlight is: by (1 - alpha) of it)
    assert (kept[middle][..., 0] - faded[middle][..., 0]).max() > 0.1


def test_a_see_through_reflective_keeps_its_slots_reflection_whole(scene):
    """A black pane with Reflective("skybox", mix=0.6): its light is the slot's reflection of
    the sky (and what the mix leaves of the sun's highlight), all of it kept whole by
    "transparent" over (1 - alpha) x the wall, faded to alpha x it by "fade"."""
    def pane(alpha: float, blend: str = "fade") -> tuple:
        return (Material(color=(0.0, 0.0, 0.0, alpha), roughness=0.3, blend=blend), Reflective(mode="skybox", mix=0.6))

    wall = linear(scene, None)
    opaque, kept, faded = linear(scene, pane(1.0)), linear(scene, pane(ALPHA, "transparent")), \
        linear(scene, pane(ALPHA))
    h, w = SIZE[1], SIZE[0]
    middle = (slice(h // 2 - 25, h // 2 + 25), slice(w // 2 - 30, w // 2 + 30))
    light = opaque[middle]
    assert light[..., 0].min() > 0.2   # the sky's reflection: 0.6 x 0.5
    np.testing.assert_allclose(kept[middle], light + (1.0 - ALPHA) * wall[middle], atol=0.012, rtol=0.02)
    np.testing.assert_allclose(faded[middle], ALPHA * light + (1.0 - ALPHA) * wall[middle], atol=0.012, rtol=0.02)


def test_in_fog_a_see_through_pane_gives_its_alphas_share_of_the_fogs_light(scene):
    """Fog between the eye and a grey metal pane: the fog's own light F (the frame of a pane
    that sends nothing, black and reflecting nothing) is added once over the pane's pixels whatever
    shows through.  A fading pane is then alpha x the opaque pane's fogged frame O plus
    (1 - alpha) x the fogged wall W; a transparent one O - (1 - alpha) F + (1 - alpha) W (its
    reflection whole, the fog in front of it once)."""
    wall = linear(scene, None, fog=True)
    grey = (0.5, 0.5, 0.5)   # a grey metal: its light is all reflection, half the sky's
    opaque = linear(scene, Material(color=(*grey, 1.0), metallic=1.0, roughness=0.2), fog=True)
    fog_light = linear(scene, Material(color=(0.0, 0.0, 0.0, 1.0), environment_reflection=0.0), fog=True)
    kept = linear(scene, Material(color=(*grey, ALPHA), metallic=1.0, roughness=0.2, blend="transparent"), fog=True)
    faded = linear(scene, Material(color=(*grey, ALPHA), metallic=1.0, roughness=0.2), fog=True)
    h, w = SIZE[1], SIZE[0]
    middle = (slice(h // 2 - 25, h // 2 + 25), slice(w // 2 - 30, w // 2 + 30))
    o, f, b = opaque[middle], fog_light[middle], wall[middle]
    assert f[..., 0].min() > 0.2 and (o - f)[..., 0].min() > 0.01   # fog, and a reflection through it
    np.testing.assert_allclose(faded[middle], ALPHA * o + (1.0 - ALPHA) * b, atol=0.012, rtol=0.02)
    np.testing.assert_allclose(kept[middle], o - (1.0 - ALPHA) * f + (1.0 - ALPHA) * b, atol=0.012, rtol=0.02)


def test_blend_is_checked_and_written_in_level_files(tmp_path):
    with pytest.raises(ComponentValueError, match=r"Material.blend must be one of \('fade', 'transparent'\)"):
        Material(blend="glass")
    from engine.assets.level_file import load_level, save_level
    from engine.core.world import World

    world = World("pane")
    pane = world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Material(color=(1, 1, 1, 0.2), blend="transparent"))
    saved = save_level(world, tmp_path / "pane.toml", {"pane": pane}, name="pane")
    assert 'blend = "transparent"' in saved.read_text()
    again = World("again")
    names = load_level(saved).spawn(again)
    assert again.get(names["pane"], Material).blend == "transparent"


def test_transparent_keeps_an_emissive_panes_light_whole(scene):
    """A black, unreflecting pane that glows (Emissive power 0.5 times an orange emissive
    map): "transparent" keeps the glow whole over (1 - alpha) x the wall, as a lit sign on
    glass is; "fade" fades it with the rest.  The glow alone is the opaque pane's frame (its
    highlight is under a level: black, roughness 1)."""
    orange = TextureData(np.full((4, 4, 3), (240, 150, 20), np.uint8), name="orange")

    def pane(alpha: float, blend: str = "fade") -> tuple:
        return (Material(color=(0.0, 0.0, 0.0, alpha), roughness=1.0, environment_reflection=0.0, blend=blend,
                         emissive_map=orange), Emissive(power=0.5))

    wall = linear(scene, None)
    glow, kept, faded = linear(scene, pane(1.0)), linear(scene, pane(ALPHA, "transparent")), \
        linear(scene, pane(ALPHA))
    h, w = SIZE[1], SIZE[0]
    middle = (slice(h // 2 - 25, h // 2 + 25), slice(w // 2 - 30, w // 2 + 30))
    light = glow[middle]
    assert light[..., 0].min() > 0.3 and light[..., 1].min() > 0.08   # the glow
    np.testing.assert_allclose(kept[middle], light + (1.0 - ALPHA) * wall[middle], atol=0.012, rtol=0.02)
    np.testing.assert_allclose(faded[middle], ALPHA * light + (1.0 - ALPHA) * wall[middle], atol=0.012, rtol=0.02)


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_through_a_portal_the_slot_is_cut_about_tinted_glass_as_its_things_lie_before_and_behind_it(scene, path):
    """Beyond portal B, seen through A (``tests.test_particles``'s pair): a refracting pane of
    index 1 that reflects nothing and lets through half the light behind it (a tint of 0.5),
    a see-through green square behind it and a yellow one in front of it, over part of it on
    screen (both unlit, at alpha 0.5, fading all their light).  The portal's level cuts its
    slot about the glass (``ScenePass._slot_and_glass``): the green is drawn before the glass,
    into what it marches, so through the pane it is tinted with the rest, the frame half the
    frame without the pane; the yellow after, over it, untinted: its own light (the frame
    without the pane, less half what lies behind it there) over the tinted frame without the
    yellow, let through by half.  Drawn all after the glass, the green would lie over the
    tint; all before, the yellow under it.  Level 0's linear colour, pixel by pixel where
    the rays (the camera's, straight through A) meet each square and the pane."""
    from components import Refractive
    from engine.assets.portals import spawn_portal_pair
    from tests.support import pixel_rays
    from tests.test_particles import EYE, FOV, PORTAL_A, PORTAL_B, PORTAL_SIZE, PORTAL_TURN, beyond_b, pair_carry
    from tests.test_screen_refraction import CLEAR, on_quad

    size, carry = (96, 72), pair_carry()
    turn = glm.quat_cast(carry)
    pane_at, green_at, yellow_at = (0.0, 0.0, -4.0), (-0.3, 0.1, -4.8), (0.35, -0.15, -3.4)

    def frame(pane: bool, yellow: bool) -> tuple[np.ndarray, object]:
        def build(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            spawn_portal_pair(world, PORTAL_A, None, PORTAL_B, PORTAL_TURN, size=PORTAL_SIZE)
            world.spawn(Skybox())
            world.spawn(Transform(position=beyond_b(carry, 0.0, 0.0, -7.0), rotation=turn), MeshRef(quad(20.0, 20.0)),
                        Material(color=(0.5, 0.3, 0.6, 1.0), unlit=True))
            world.spawn(Transform(position=beyond_b(carry, *green_at), rotation=turn), MeshRef(quad(0.8, 0.8)),
                        Material(color=(0.1, 0.9, 0.1, 0.5), unlit=True, double_sided=True))
            if yellow:
                world.spawn(Transform(position=beyond_b(carry, *yellow_at), rotation=turn), MeshRef(quad(0.5, 0.5)),
                            Material(color=(0.9, 0.9, 0.1, 0.5), unlit=True, double_sided=True))
            if pane:
                world.spawn(Transform(position=beyond_b(carry, *pane_at), rotation=turn), MeshRef(quad(1.2, 1.2)),
                            Material(color=(0.5, 0.5, 0.5, 0.0), double_sided=True, **CLEAR),
                            Refractive(ior=1.0, solid=False))
        runner = scene(build, size)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        runner.engine.reflection_system.keep_still_views = False   # (the portal's level drawn each frame)
        for _ in range(2):
            runner.frame()
        w, h = size
        colour = runner.engine.renderer.levels[0].color.read()
        return np.frombuffer(colour, np.float16).reshape(h, w, 4)[::-1, :, :3].astype(np.float64), runner

    seen, runner = frame(True, True)
    stats = runner.stats
    assert stats.reflection_views == 1 and stats.reflection_path == path
    unpaned, _ = frame(False, True)
    bare, _ = frame(False, False)
    tinted, _ = frame(True, False)
    eye, rays = pixel_rays(runner.engine.main_view, size)
    inside = on_quad(eye, rays, np.array(PORTAL_A), 0.9)   # (A's opening, 2.5 x 2, less a margin)
    pane = inside & on_quad(eye, rays, np.array(pane_at), 0.57)
    yellow = on_quad(eye, rays, np.array(yellow_at), 0.23)
    green = pane & on_quad(eye, rays, np.array(green_at), 0.37) & ~on_quad(eye, rays, np.array(yellow_at), 0.27)
    yellow &= pane
    assert green.sum() > 40 and yellow.sum() > 20, (green.sum(), yellow.sum())
    assert (unpaned[green][:, 1] > 1.3 * unpaned[green][:, [0, 2]].max(axis=1)).all()   # (the green square there)
    assert np.abs(unpaned[yellow] - bare[yellow]).max(axis=-1).min() > 0.1               # (the yellow one there)
    np.testing.assert_allclose(seen[green], 0.5 * unpaned[green], rtol=6e-3, atol=3e-3)
    own = unpaned - 0.5 * bare
    np.testing.assert_allclose(seen[yellow], own[yellow] + 0.5 * tinted[yellow], rtol=6e-3, atol=3e-3)
    assert stats.slot_after_glass >= 1   # (the cut made in the portal's level: the yellow after the glass)
