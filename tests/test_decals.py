"""Decals drawn (``Decal``; ``systems/decal_system.py``): a decal on a wall against a second
path (a quad of the same look laid on the wall: the same pixels, lit alike), its image the
right way up, in a mirror's view as a quad there is, over a wall seen far off and at a
grazing angle, cut again when a surface moves into its box (and not when decal and wall
move together), a surface on another layer, turned away, or a mirror left bare, its
Visibility honoured, emission, and its part and GPU mesh gone with it.  Against rays: a
turned, tilted box covers the floor pixels whose point lies in it, and one held by a sliding
crate where it is now; against quads of computed alphas, the angle and depth fades; a
normal map leans the light as a turned wall does; same-order overlaps by the view's eye
(a mirror's its own); a monitor's picture, a shadow, a region; posed meshes take none."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentWarning,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Skybox,
    Transform,
    Visibility,
    look_rotation,
)
from components.decal import Decal, FromDecal
from engine.assets.mesh import box, quad
from engine.assets.texture_data import TextureData
from engine.render.gl_context import GLCapabilities
from tests.support import look_from

SIZE = (96, 72)
GREY = (0.5, 0.5, 0.5, 1.0)
LOOK = (0.8, 0.25, 0.1, 0.7)


def lit(world) -> None:
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(-0.3, -0.4, -1.0), intensity=2.0))


def wall(world, position=(0.0, 0.0, 0.0), size=4.0) -> int:
    """A grey wall facing +z."""
    return world.spawn(Transform(position=glm.vec3(position)), MeshRef(quad(size, size)), Material(color=GREY))


def render(scene, build, frames: int = 2, size=SIZE):
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    for _ in range(frames):
        image = runner.frame()
    return runner, image.astype(np.int64)


def decals(runner):
    return runner.engine.stages["decals"]


def looks():
    """(Decal fields, the same look as Material fields) of the second-path test's cases."""
    from engine.assets.texture_data import checker_texture, ripple_normal_map

    bumps, paint = ripple_normal_map(64, 4, 0.6), checker_texture(32, 4, (220, 60, 40), (240, 230, 200))
    cutout = TextureData(np.concatenate([np.asarray(paint.pixels)[..., :3],
                                         np.where(np.indices((32, 32)).sum(axis=0) % 16 < 8, 255, 0)
                                         .astype(np.uint8)[..., None]], axis=2), name="stripes")
    return {
        "faded": ({"color": LOOK}, {"color": LOOK}),
        "mapped": ({"texture": paint, "color": (1.0, 1.0, 1.0, 0.8), "normal_map": bumps, "normal_scale": 0.8,
                    "roughness": 0.2, "metallic": 0.3},
                   {"texture": paint, "color": (1.0, 1.0, 1.0, 0.8), "normal_map": bumps, "normal_scale": 0.8,
                    "roughness": 0.2, "metallic": 0.3}),
        "cutout": ({"texture": cutout, "alpha_cutoff": 0.5},
                   {"texture": cutout, "alpha_cutoff": 0.5, "color": (1.0, 1.0, 1.0, 1.0)}),  # (a Decal's is white)
    }


@pytest.mark.parametrize("look", ["faded", "mapped", "cutout"])
def test_a_decal_on_a_wall_is_the_pixels_a_quad_of_its_look_laid_there_draws(scene, look):
    """A plain see-through one, one with an image, a normal map, roughness and metal, and a
    cutout (drawn solid with the opaque batches, cut where its image's alpha is below its
    cutoff): each the pixels of a quad of the same look laid on the wall."""
    decal_look, material_look = looks()[look]

    def build(kind):
        def make(world):
            look_from(world, (0.4, 0.3, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
            lit(world)
            wall(world)
            if kind == "decal":
                world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(**decal_look))
            elif kind == "quad":  # the second path: the same look on a quad just in front (casting
                # no shadow, as a decal's cut casts none)
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 1e-3)), MeshRef(quad(1.0, 1.0), casts_shadows=False),
                            Material(**material_look))
        return make

    runner, with_decal = render(scene, build("decal"))
    _, with_quad = render(scene, build("quad"))
    _, bare = render(scene, build("none"))
    x0, y0 = runner.project((-0.4, 0.4, 0.0))
    x1, y1 = runner.project((0.4, -0.4, 0.0))
    inside = (slice(y0, y1), slice(x0, x1))
    # (a normal map's tangent frame and a cutout's mip level come from the UVs' screen
    # derivatives, which the cut's triangles, not the quad's two, carry: a few levels here and
    # there, on bumps and on the cut's edges)
    assert np.abs(with_decal[inside] - with_quad[inside]).max() <= (2 if look == "faded" else 6)
    assert np.abs(with_decal[inside] - with_quad[inside]).mean() <= 0.5
    changed = np.abs(with_decal[inside] - bare[inside]).max(axis=2) > 20  # it is there: not the bare wall
    assert changed.mean() > {"faded": 0.99, "mapped": 0.6, "cutout": 0.3}[look]
    outside = np.ones(with_decal.shape[:2], bool)
    ox0, oy0 = runner.project((-0.55, 0.55, 0.0))
    ox1, oy1 = runner.project((0.55, -0.55, 0.0))
    outside[oy0:oy1, ox0:ox1] = False
    assert np.abs(with_decal[outside] - bare[outside]).max() <= 1  # nothing beyond its box
    part = [e for e, _ in runner.world.query_one(FromDecal)]
    assert len(part) == 1 and runner.world.get(part[0], MeshRef).casts_shadows is False


def corners_texture() -> TextureData:
    """2 x 2: red top left, green top right, blue bottom left, white bottom right (row 0 at the top)."""
    pixels = np.array([[[255, 0, 0, 255], [0, 255, 0, 255]], [[0, 0, 255, 255], [255, 255, 255, 255]]], np.uint8)
    return TextureData(np.repeat(np.repeat(pixels, 8, axis=0), 8, axis=1), name="corners")


@pytest.mark.parametrize("where", ["wall", "floor"])
def test_the_image_is_the_right_way_up_seen_from_where_it_is_thrown(scene, where):
    def build(world):
        lit(world)
        if where == "wall":
            look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
            wall(world)
            world.spawn(Transform(scale=glm.vec3(1.2, 1.2, 0.5)), Decal(texture=corners_texture()))
        else:  # a floor decal looking down, its up (+y) towards -z: seen from above with -z up the screen
            look_from(world, (0.0, 3.0, 0.01), target=(0.0, 0.0, 0.0), fov=40.0)
            world.spawn(Transform(rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(1, 0, 0))),
                        MeshRef(quad(4.0, 4.0)), Material(color=GREY))
            world.spawn(Transform(rotation=look_rotation(glm.vec3(0, -1, 0), glm.vec3(0, 0, -1)),
                                  scale=glm.vec3(1.2, 1.2, 0.5)), Decal(texture=corners_texture()))

    runner, image = render(scene, build)
    # Each quarter's middle: on the wall (x, y), on the floor (x, -z) as the screen shows them.
    corners = {"red": (-0.3, 0.3), "green": (0.3, 0.3), "blue": (-0.3, -0.3), "white": (0.3, -0.3)}
    points = {name: (x, y, 0.0) if where == "wall" else (x, 0.0, -y) for name, (x, y) in corners.items()}
    for name, point in points.items():
        x, y = runner.project(point)
        r, g, b = image[y, x]
        if name == "red":
            assert r > 2 * g and r > 2 * b, (name, image[y, x])
        elif name == "green":
            assert g > 2 * r and g > 2 * b, (name, image[y, x])
        elif name == "blue":
            assert b > 2 * r and b > 2 * g, (name, image[y, x])
        else:
            assert min(r, g, b) > 0.7 * max(r, g, b), (name, image[y, x])


def mirror_scene(kind: str, hidden: bool = False):
    """The camera looks into a mirror that faces the wall with the decal (or a quad of its look)."""
    def make(world):
        lit(world)
        look_from(world, (0.0, 0.0, 2.0), target=(0.0, 0.0, 5.0), fov=40.0)  # facing away from the wall
        wall(world)
        world.spawn(Transform(position=glm.vec3(0.0, 0.0, 5.0), rotation=look_rotation(glm.vec3(0, 0, 1))),
                    MeshRef(quad(4.0, 4.0)), Mirror())  # (its face, +z, turned to -z: towards the wall)
        shown = [Visibility(in_mirrors=False)] if hidden else []
        if kind == "decal":
            world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(color=LOOK), *shown)
        elif kind == "quad":
            world.spawn(Transform(position=glm.vec3(0.0, 0.0, 1e-3)), MeshRef(quad(1.0, 1.0)), Material(color=LOOK),
                        *shown)
    return make


def test_a_mirror_shows_the_decal_as_it_shows_a_quad_of_its_look(scene):
    runner, with_decal = render(scene, mirror_scene("decal"))
    _, with_quad = render(scene, mirror_scene("quad"))
    _, bare = render(scene, mirror_scene("none"))
    differs = np.abs(with_quad - bare).sum(axis=2) > 30  # where the quad shows in the mirror
    assert differs.sum() > 100
    assert np.abs(with_decal - with_quad).max() <= 3


def test_a_decal_hidden_in_mirrors_is_not_in_the_mirror(scene):
    runner, hidden = render(scene, mirror_scene("decal", hidden=True))
    _, bare = render(scene, mirror_scene("none"))
    assert np.abs(hidden - bare).max() <= 1
    part = [e for e, _ in runner.world.query_one(FromDecal)][0]
    assert runner.world.get(part, Visibility).in_mirrors is False


@pytest.mark.parametrize("eye", [(0.0, 0.0, 40.0), (6.0, 0.0, 1.2)])
def test_the_decal_wins_over_its_wall_far_off_and_at_a_grazing_angle(scene, eye):
    """Every pixel inside the decal's square shows it (the depth offset), not the wall under it."""
    colour = (0.0, 0.9, 0.0, 1.0)

    def build(world):
        world.spawn(Skybox())
        look_from(world, eye, target=(0.0, 0.0, 0.0), fov=8.0 if eye[2] > 10 else 40.0)
        world.spawn(Transform(), MeshRef(quad(4.0, 4.0)), Material(color=(0.9, 0.0, 0.0, 1.0), unlit=True))
        world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(color=colour))

    runner, image = render(scene, build, size=(128, 96))
    xs, ys = zip(*(runner.project(p) for p in [(-0.45, 0.45, 0), (0.45, 0.45, 0), (-0.45, -0.45, 0),
                                                (0.45, -0.45, 0)]), strict=True)
    window = image[min(ys) + 1:max(ys) - 1, min(xs) + 1:max(xs) - 1]
    assert window.size > 0
    red = window[..., 0] > window[..., 1]
    assert red.sum() == 0, f"{red.sum()} of {red.size} pixels show the wall through the decal"


def floor_world(world, crate_x: float):
    """A floor, a crate and a decal over the middle of the floor looking down."""
    lit(world)
    look_from(world, (0.0, 4.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
    world.spawn(Transform(rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(1, 0, 0))), MeshRef(quad(8.0, 8.0)),
                Material(color=GREY))
    crate = world.spawn(Transform(position=glm.vec3(crate_x, 0.25, 0.0)), MeshRef(box((0.5, 0.5, 0.5))),
                        Material(color=GREY))
    decal = world.spawn(Transform(rotation=look_rotation(glm.vec3(0, -1, 0), glm.vec3(0, 0, -1)),
                                  scale=glm.vec3(1.5, 1.5, 1.4)), Decal(color=(0.9, 0.0, 0.0, 1.0)))
    return crate, decal


def test_a_surface_moving_into_the_box_is_cut_again_and_painted(scene):
    made = {}

    def build(world):
        made["crate"], made["decal"] = floor_world(world, crate_x=3.0)

    runner, _ = render(scene, build)
    stage = decals(runner)
    state = stage.states[made["decal"]]
    assert made["crate"] not in state.pieces
    cuts = stage.cuts
    x, y = runner.project((0.0, 0.5, 0.0))  # where the crate's top will be
    runner.world.get(made["crate"], Transform).position = glm.vec3(0.0, 0.25, 0.0)
    image = runner.frame().astype(np.int64)
    assert stage.cuts == cuts + 1 and made["crate"] in state.pieces
    r, g, b = image[y, x]
    assert r > 3 * g, image[y, x]  # the crate's top is painted
    # Its sides, turned 90 degrees from the decal (past the angle fade's end), are not.
    part = [e for e, c in runner.world.query_one(FromDecal) if c.decal == made["decal"]][0]
    mesh = runner.world.get(part, MeshRef).mesh
    world_normals = mesh.normals @ np.array(glm.mat3(runner.world.get(part, Transform).world), np.float64).T
    up = world_normals[:, 1] / np.linalg.norm(world_normals, axis=1)
    assert up.min() >= np.cos(np.radians(80.0)) - 1e-6
    # Each frame it slides through the box it is cut again; the cuts it leaves behind let
    # their GPU meshes go (as many held after twenty as after one).
    held = runner.engine.renderer.resource_counts()
    pieces = stage.pieces_cut
    for step in range(1, 21):
        runner.world.get(made["crate"], Transform).position = glm.vec3(0.01 * step, 0.25, 0.0)
        runner.frame()
    assert stage.cuts == cuts + 21
    assert stage.pieces_cut == pieces + 20  # the crate's piece alone each frame: the floor's is kept
    assert runner.engine.renderer.resource_counts()["meshes"] == held["meshes"]
    assert runner.engine.renderer.resource_counts()["batches"] == held["batches"]
    # And moving out again takes it away.
    runner.world.get(made["crate"], Transform).position = glm.vec3(3.0, 0.25, 0.0)
    runner.frame()
    assert made["crate"] not in state.pieces and stage.cuts == cuts + 22


def test_a_decal_moved_with_its_wall_is_not_cut_again_and_follows_it(scene):
    made = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 4.0), target=(0.0, 0.0, 0.0), fov=50.0)
        made["mover"] = mover = world.spawn(Transform())
        world.spawn(Transform(parent=mover), MeshRef(quad(2.0, 2.0)), Material(color=GREY))
        world.spawn(Transform(parent=mover, scale=glm.vec3(0.6, 0.6, 0.4)), Decal(color=(0.0, 0.0, 0.9, 1.0)))

    runner, _ = render(scene, build)
    stage = decals(runner)
    cuts = stage.cuts
    runner.world.get(made["mover"], Transform).position = glm.vec3(0.8, 0.3, 0.0)
    image = runner.frame().astype(np.int64)
    assert stage.cuts == cuts
    x, y = runner.project((0.8, 0.3, 0.0))
    r, g, b = image[y, x]
    assert b > 3 * r and b > 3 * g, image[y, x]
    x, y = runner.project((0.0, 0.0, 0.0))  # where it was: the wall now (grey)
    r, g, b = image[y, x]
    assert b < 1.3 * r, image[y, x]


def test_surfaces_on_other_layers_mirrors_and_glass_take_no_decal(scene):
    made = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 4.0), target=(0.0, 0.0, 0.0), fov=50.0)
        made["wall"] = wall(world)
        made["other"] = world.spawn(Transform(position=glm.vec3(0.0, 0.0, 0.1)), MeshRef(quad(0.3, 0.3)),
                                    Material(color=GREY), Visibility(layers=[1]))
        made["mirror"] = world.spawn(Transform(position=glm.vec3(0.5, 0.0, 0.05)), MeshRef(quad(0.3, 0.3)), Mirror())
        made["decal"] = world.spawn(Transform(scale=glm.vec3(1.5, 1.5, 0.5)), Decal(layers=[0]))

        made["pane"] = world.spawn(Transform(position=glm.vec3(-0.5, 0.0, 0.1)), MeshRef(quad(0.3, 0.3)),
                                   Material(color=(0.2, 0.4, 0.9, 0.5)))  # see-through: glass

    runner, _ = render(scene, build)
    assert set(decals(runner).states[made["decal"]].pieces) == {made["wall"]}
    decal = runner.world.get(made["decal"], Decal)
    decal.layers = None  # every layer: the other one too, the mirror and the glass still not
    runner.frame()
    assert set(decals(runner).states[made["decal"]].pieces) == {made["wall"], made["other"]}
    runner.world.get(made["pane"], Material).color = glm.vec4(0.2, 0.4, 0.9, 1.0)  # opaque now: it takes it
    runner.frame()
    assert set(decals(runner).states[made["decal"]].pieces) == {made["wall"], made["other"], made["pane"]}


def test_emission_makes_a_decal_glow_as_an_emissive_quad_does(scene):
    def build(kind):
        def make(world):
            world.spawn(Skybox(zenith=(0, 0, 0, 1), horizon=(0, 0, 0, 1), ground=(0, 0, 0, 1)))
            look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
            wall(world)
            if kind == "decal":
                world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(color=(0.6, 0.3, 0.1, 1.0), emissive=2.0))
            else:
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 1e-3)), MeshRef(quad(1.0, 1.0)),
                            Material(color=(0.6, 0.3, 0.1, 1.0)), Emissive(2.0))
        return make

    runner, with_decal = render(scene, build("decal"))
    _, with_quad = render(scene, build("quad"))
    x, y = runner.project((0.0, 0.0, 0.0))
    assert with_decal[y, x].max() > 100
    assert np.abs(with_decal[y - 5:y + 5, x - 5:x + 5] - with_quad[y - 5:y + 5, x - 5:x + 5]).max() <= 2


def test_its_part_and_gpu_mesh_go_with_the_decal_and_with_what_it_lay_on(scene):
    made = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
        made["wall"] = wall(world)

    def held(runner):  # GL objects by kind, less the program builds (a cache, kept for the next decal)
        counts = runner.engine.renderer.resource_counts()
        counts.pop("programs")
        return counts

    runner, _ = render(scene, build)
    before = held(runner)
    world = runner.world
    decal = world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(color=LOOK))
    runner.frame()
    assert len(world.query_one(FromDecal)) == 1
    assert runner.engine.renderer.resource_counts()["meshes"] == before["meshes"] + 1
    world.delete_entity(decal)
    runner.frame()
    assert world.query_one(FromDecal) == [] and held(runner) == before
    # Its component removed, likewise; and the wall going leaves a decal nothing to lie on.
    decal = world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(color=LOOK))
    runner.frame()
    world.remove_component(decal, Decal)
    runner.frame()
    assert world.query_one(FromDecal) == [] and held(runner) == before
    world.add_component(decal, Decal(color=LOOK))
    runner.frame()
    assert len(world.query_one(FromDecal)) == 1
    world.delete_entity(made["wall"])
    runner.frame()
    assert world.query_one(FromDecal) == [] and decals(runner).states[decal].part is None


LEVEL = """
[level]
name = "stained"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 3.0, 0.01]
rotation = { pitch = -89.0 }
[entity.Camera]

[[entity]]
name = "sky"
[entity.Skybox]

[[entity]]
name = "floor"
[entity.Transform]
rotation = { pitch = -90.0 }
[entity.MeshRef]
mesh = { quad = [4.0, 4.0] }
[entity.Material]
color = [0.5, 0.5, 0.5, 1.0]

[[entity]]
name = "stain"
[entity.Transform]
position = [0.3, 0.0, 0.2]
rotation = { pitch = -90.0 }
scale = [1.6, 1.6, 0.4]
[entity.Decal]
texture = { puff = [64, 3] }
color = [0.05, 0.03, 0.02, 0.9]
region = [0.0, 0.0, 1.0, 1.0]
angle_fade = [50.0, 70.0]
layers = [0]
"""


def test_a_decal_loads_saves_without_its_part_and_loads_again_to_the_same_picture(tmp_path, scene):
    from engine.assets.level_file import LevelError, load_level, save_level

    path = tmp_path / "stained.toml"
    path.write_text(LEVEL)
    made = {}

    def build(level_path):
        def make(world):
            made.update(load_level(level_path).spawn(world))
        return make

    runner, first = render(scene, build(path))
    decal = runner.world.get(made["stain"], Decal)
    assert decal.angle_fade == (50.0, 70.0) and decal.layers == (0,) and decal.texture is not None
    assert len(runner.world.query_one(FromDecal)) == 1
    saved = save_level(runner.world, tmp_path / "saved.toml", made, name="stained")
    text = saved.read_text()
    assert text.count("[[entity]]") == 4 and "FromDecal" not in text and "[entity.Decal]" in text
    _, again = render(scene, build(saved))
    assert np.abs(again - first).max() == 0
    x, y = runner.project((0.3, 0.0, 0.2))  # the stain's middle darkens the floor there
    bx, by = runner.project((-1.0, 0.0, -0.9))  # bare floor
    assert first[y, x].sum() < 0.75 * first[by, bx].sum(), (first[y, x], first[by, bx])
    path.write_text(LEVEL.replace("angle_fade = [50.0, 70.0]", "angle_fade = [70.0, 50.0]"))
    with pytest.raises(LevelError, match=r"stained\.toml:\d+: entity 'stain': Decal\.angle_fade.*end >= start"):
        load_level(path)


def test_the_editor_picks_the_decal_refuses_edits_of_its_cut_and_outlines_its_box(scene):
    """A click on a decal's pixels selects the decal (its cut mesh is the engine's); the cut
    is not in the entity list and refuses edits; deleting the decal is not refused for that
    child and takes the cut with it; the decal's outline is its box's twelve edges and the way
    it throws; its layers switch on at [0] and off again."""
    from shell.editor import EditError, Editor
    from shell.handles import reach_outline

    made = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
        made["wall"] = wall(world)
        made["decal"] = world.spawn(Transform(position=glm.vec3(0.2, 0.1, 0.0), scale=glm.vec3(1.0, 0.8, 0.5)),
                                    Decal(color=LOOK))

    runner, _ = render(scene, build)
    world = runner.world
    editor = Editor(world, names={"wall": made["wall"], "stain": made["decal"]})
    part = [e for e, _ in world.query_one(FromDecal)][0]
    x, y = runner.project((0.2, 0.1, 0.0))
    ids = runner.ids()
    assert ids[y, x] == part  # the cut's own id is drawn there ...
    assert editor.pick(ids, None, x, y) == made["decal"]  # ... and the click selects the decal
    bx, by = runner.project((-0.8, -0.7, 0.0))
    assert editor.pick(ids, None, bx, by) == made["wall"]
    assert part not in [e for e, _ in editor.listed()[0]]
    with pytest.raises(EditError, match="cut mesh of the decal stain"):
        editor.set_field(part, "Material", "roughness", 0.9)
    matrix = world.get(made["decal"], Transform).world
    outline = reach_outline(world, made["decal"], runner.engine.main_view.view_proj, SIZE)
    corners = {tuple(round(c, 5) for c in glm.vec3(matrix * glm.vec4(sx, sy, sz, 1.0)))
               for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (-0.5, 0.5)}
    edges = outline.world[:12]
    assert {tuple(round(c, 5) for c in p) for edge in edges for p in edge} == corners
    assert sorted(round(glm.length(a - b), 4) for a, b in edges) == [0.5] * 4 + [0.8] * 4 + [1.0] * 4
    start, tip = outline.world[12]
    assert tuple(tip) == pytest.approx((0.2, 0.1, -0.25)) and tuple(start) == pytest.approx((0.2, 0.1, 0.25))
    assert editor.switched_on(made["decal"], "Decal", "layers") == (0,)
    editor.set_field(made["decal"], "Decal", "layers", (0,))
    assert world.get(made["decal"], Decal).layers == (0,)
    editor.delete(made["decal"])
    runner.frame()
    assert not world.exists(part) and world.query_one(FromDecal) == []


def test_a_probe_captures_the_decal_as_it_captures_a_quad_of_its_look(scene):
    """A reflection probe in front of the wall sees the decal on its -z face as it sees a
    quad of the same look laid there (a capture draws every batch the way a view does)."""
    from components import ReflectionProbe

    def build(kind):
        def make(world):
            lit(world)
            look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
            wall(world)
            world.probe = world.spawn(Transform(position=glm.vec3(0.0, 0.0, 1.5)), ReflectionProbe(resolution=32))
            if kind == "decal":
                world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(color=LOOK))
            elif kind == "quad":
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 1e-3)), MeshRef(quad(1.0, 1.0)), Material(color=LOOK))
        return make

    faces = {}
    for kind in ("decal", "quad", "none"):
        runner, _ = render(scene, build(kind))
        faces[kind] = runner.engine.renderer.probes.read_face(runner.world.probe, 5).astype(np.float64)  # -z
    assert np.abs(faces["quad"] - faces["none"]).max() > 0.1  # the look is on that face
    np.testing.assert_allclose(faces["decal"], faces["quad"], atol=0.01)


def test_where_its_image_is_clear_a_decal_writes_no_id_and_a_click_goes_through(scene):
    """A round image's clear corners leave the wall's id (a click there selects the wall);
    its middle has the decal's cut's."""
    from engine.assets.texture_data import puff_texture

    made = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
        made["wall"] = wall(world)
        world.spawn(Transform(scale=glm.vec3(1.2, 1.2, 0.5)), Decal(texture=puff_texture(32, 1)))

    runner, _ = render(scene, build)
    part = [e for e, _ in runner.world.query_one(FromDecal)][0]
    ids = runner.ids()
    cx, cy = runner.project((0.0, 0.0, 0.0))
    kx, ky = runner.project((0.55, 0.55, 0.0))  # inside the box, outside the puff's disc
    assert ids[cy, cx] == part and ids[ky, kx] == made["wall"]


def test_a_gpus_builds_drop_a_clear_part_last_and_draw_the_same_frame_and_ids(scene):
    """A GPU's scene builds (``Gpu.discards_last``: scene.frag's DISCARDS_LAST) leave a
    decal's clear part out with the other dropped pixels, after the derivatives the rest of
    its quad takes, not at once; llvmpipe keeps a quad's pixels running either way, so the
    two builds draw the same colours and ids here (the clear corners the wall's)."""
    from engine.assets.texture_data import puff_texture

    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
        wall(world)
        world.spawn(Transform(scale=glm.vec3(1.2, 1.2, 0.5)), Decal(texture=puff_texture(32, 1)))

    seen = []
    for last in (False, True):
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.renderer.discards_last = last
        for _ in range(2):
            image = runner.frame()
        builds = [dict(key[3]) for key in runner.engine.renderer.shaders._programs if key[1] == "scene.frag"]
        assert builds and all(("DISCARDS_LAST" in defines) is last for defines in builds)
        ids = runner.ids()
        part = [e for e, _ in runner.world.query_one(FromDecal)][0]
        (cx, cy), (kx, ky) = runner.project((0.0, 0.0, 0.0)), runner.project((0.55, 0.55, 0.0))
        assert ids[cy, cx] == part and ids[ky, kx] != part  # its middle the cut's, a clear corner the wall's
        seen.append((image, ids))
    (plain, plain_ids), (deferred, deferred_ids) = seen
    assert np.array_equal(plain_ids, deferred_ids)
    # The same colours where the early discard's derivatives are defined too (llvmpipe); on a
    # GPU the early build's rim beside the clear part may take other texture levels (what
    # DISCARDS_LAST is for): at most 1% of the cut's pixels there.
    apart = int((np.abs(plain.astype(np.int64) - deferred).max(axis=2) > 0).sum())
    software = GLCapabilities.read(runner.engine.ctx).software
    assert apart == 0 if software else apart <= 0.01 * int((plain_ids == part).sum()), apart


def test_glass_in_front_of_a_decal_blends_over_it_wherever_their_boxes_centres_are(scene):
    """A pane standing on a floor's big decal, farther from the eye by its centre than the
    decal's is: the decal (on an opaque surface) is blended first, so the pane tints it as
    it tints an opaque quad of the decal's look (a second path, drawn with the opaque
    batches)."""
    colour = (0.9, 0.2, 0.1, 1.0)

    def build(kind):
        def make(world):
            lit(world)
            look_from(world, (0.0, 1.2, 4.0), target=(0.0, 0.3, 0.0), fov=40.0)
            world.spawn(Transform(rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(1, 0, 0))),
                        MeshRef(quad(8.0, 8.0)), Material(color=GREY))
            world.spawn(Transform(position=glm.vec3(0.0, 0.5, 0.6)), MeshRef(quad(1.5, 1.0)),
                        Material(color=(0.1, 0.3, 0.9, 0.5)))  # the pane, its centre 3.4 m off
            if kind == "decal":  # its centre 2.9 m off, reaching under and behind the pane
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 2.0),
                                      rotation=look_rotation(glm.vec3(0, -1, 0), glm.vec3(0, 0, -1)),
                                      scale=glm.vec3(3.0, 4.0, 0.5)), Decal(color=colour))
            else:
                world.spawn(Transform(position=glm.vec3(0.0, 1e-3, 2.0),
                                      rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(1, 0, 0))),
                            MeshRef(quad(3.0, 4.0)), Material(color=colour))
        return make

    runner, with_decal = render(scene, build("decal"))
    _, with_quad = render(scene, build("quad"))
    x, y = runner.project((0.0, 0.0, 0.3))  # the floor behind the pane, under the decal
    px, py = runner.project((0.0, 0.5, 0.6))
    assert abs(y - py) < 20  # (the pane covers it on screen)
    assert np.abs(with_decal - with_quad).max() <= 3


def test_an_image_past_the_gl_limit_is_refused_naming_the_decal(scene):
    from engine.core.errors import GLLimitError

    made = {}

    def build(world):
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0))
        wall(world)
        made["decal"] = world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)),
                                    Decal(texture=TextureData(np.zeros((1, 40000, 4), np.uint8), name="banner")))

    runner = scene(build, (32, 32))
    decal = made["decal"]
    with pytest.raises(GLLimitError, match=rf"the cut of the Decal on entity {decal}\).*'banner' is 40000x1.*"
                                           r"GL_MAX_TEXTURE_SIZE"):
        runner.frame()


@pytest.mark.parametrize("order", [0, 1])
def test_of_two_overlapping_decals_the_higher_order_is_blended_over(scene, order):
    """A small green decal inside a big red one, its box's middle farther from the eye: of the
    same order the farther is blended first (the red covers it); given a higher order it is
    blended over the red."""
    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
        wall(world)
        world.spawn(Transform(scale=glm.vec3(1.2, 1.2, 0.4)), Decal(color=(0.9, 0.05, 0.05, 1.0)))
        world.spawn(Transform(position=glm.vec3(0.0, 0.0, -0.2), scale=glm.vec3(0.4, 0.4, 0.8)),
                    Decal(color=(0.05, 0.9, 0.05, 1.0), order=order))

    runner, image = render(scene, build)
    x, y = runner.project((0.0, 0.0, 0.0))
    r, g, b = image[y, x]
    assert (g > 2 * r) if order else (r > 2 * g), image[y, x]


def test_on_a_dense_mesh_the_cut_is_the_whole_soups_cut(scene):
    """The stage hands the cut only the triangles whose bounds meet the box (a small decal on
    a big mesh); the pieces are those of cutting every triangle (a second path, here)."""
    from engine.assets.mesh import sphere
    from engine.core.decal_clip import decal_geometry, soup

    ball = sphere(1.0, 96, 48)
    made = {}

    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 4.0), target=(0.0, 0.0, 0.0), fov=40.0)
        world.spawn(Transform(), MeshRef(ball), Material(color=GREY))
        made["decal"] = world.spawn(Transform(position=glm.vec3(0.2, 0.1, 1.0), scale=glm.vec3(0.6, 0.5, 0.8)),
                                    Decal(angle_fade=(40.0, 70.0)))

    runner, _ = render(scene, build)
    part = [e for e, _ in runner.world.query_one(FromDecal)][0]
    cut = runner.world.get(part, MeshRef).mesh
    box_world = np.array(runner.world.get(made["decal"], Transform).world, np.float64)
    to_box = np.linalg.inv(box_world)
    positions = ball.positions @ to_box[:3, :3].T + to_box[:3, 3]
    facing = ball.normals @ np.array([0.0, 0.0, 1.0])  # (the ball unturned, unscaled: its normals are the world's)
    whole = decal_geometry(soup(positions, ball.normals @ box_world[:3, :3], facing, ball.indices), (40.0, 70.0),
                           0.1, (0.0, 0.0, 1.0, 1.0))

    def area(p):
        t = p.reshape(-1, 3, 3)
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()

    assert len(cut.positions) == len(whole.positions) > 100
    assert area(cut.positions) == pytest.approx(area(whole.positions), rel=1e-5)
    np.testing.assert_allclose(np.sort(cut.colors[:, 3]), np.sort(whole.alphas), atol=1e-6)


def _sticker(behind: bool, portal: bool = False):
    """A decal thrown onto a mirror (or a portal's opening), with a wall just behind the
    glass inside its box (``behind``) or none."""
    def make(world):
        lit(world)
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=50.0)
        if portal:
            from engine.assets.portals import spawn_portal_pair
            world.resources["surface"] = spawn_portal_pair(world, (0.0, 0.0, 0.0), None, (8.0, 0.0, 0.0), None,
                                                           size=(2.0, 2.0))[0]
        else:
            world.resources["surface"] = world.spawn(Transform(), MeshRef(quad(2.0, 2.0)), Material(), Mirror())
        if behind:
            wall(world, position=(0.0, 0.0, -0.1))
        world.resources["decal"] = world.spawn(Transform(scale=glm.vec3(0.5, 0.5, 0.5)), Decal(color=LOOK))
    return make


@pytest.mark.parametrize("portal", [False, True])
def test_a_decal_on_a_mirror_alone_is_said_to_show_nowhere_once(scene, portal):
    """Mirrors and portals take no decal (their picture is the view beyond them): a sticker
    put on one alone makes no part, and a ComponentWarning names the decal and the surface,
    once (not again when it is moved and cut again)."""
    runner = scene(_sticker(behind=False, portal=portal), SIZE)
    decal, surface = runner.world.resources["decal"], runner.world.resources["surface"]
    kind = "Portal" if portal else "Mirror"
    with pytest.warns(ComponentWarning, match=f"Decal on entity {decal}: its box meets the {kind} of entity "
                                              f"{surface} .* shows nowhere"):
        runner.frame()
    assert not runner.world.query_one(FromDecal)
    runner.world.get(decal, Decal).color = (0.2, 0.8, 0.1, 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ComponentWarning)
        runner.frame()


def test_no_word_where_a_surface_in_the_box_takes_the_decal(scene):
    """The same sticker with a wall behind the mirror inside its box: the wall takes it (a
    part is made), and nothing is said."""
    runner = scene(_sticker(behind=True), SIZE)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ComponentWarning)
        runner.frame()
    assert len(runner.world.query_one(FromDecal)) == 1


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_portal_shows_the_decal_as_the_eye_it_carries_sees_it(scene, path):
    """A wall beyond portal B with a decal of the mapped look (a normal map, metallic, rough:
    lit by a lamp and the sky as its view's eye sees them) rendered through portal A, and the
    same world without portals rendered directly from the eye the pair carries the camera's
    to: inside A's opening the two are the same pixels, and the decal is there (the opening
    differs from the bare wall's)."""
    from components import HemisphereLight, PointLight
    from tests.test_particles import beyond_b, through_a_portal_and_from_its_eye

    decal = looks()["mapped"][0]

    def content(with_decal):
        def make(world, carry):
            turn = glm.quat_cast(carry)
            world.spawn(Skybox())
            world.spawn(HemisphereLight(sky=(0.3, 0.35, 0.5), ground=(0.2, 0.15, 0.1), intensity=1.0))
            world.spawn(Transform(position=beyond_b(carry, 0.6, 0.5, -3.0)), PointLight(intensity=10.0, range=20.0))
            world.spawn(Transform(position=beyond_b(carry, 0.0, 0.0, -4.0), rotation=turn), MeshRef(quad(8.0, 8.0)),
                        Material(color=GREY))
            if with_decal:
                world.spawn(Transform(position=beyond_b(carry, -0.1, 0.1, -4.0), rotation=turn,
                                      scale=glm.vec3(1.2, 0.9, 0.5)), Decal(**decal))
        return make

    through, direct, opening, _ = through_a_portal_and_from_its_eye(scene, content(True), path=path)
    bare, _, _, _ = through_a_portal_and_from_its_eye(scene, content(False), path=path)
    shown = np.abs(through - bare).max(axis=-1)[opening]
    assert (shown > 0.05).sum() > 150, (shown > 0.05).sum()   # (the decal is there)
    apart = np.abs(through - direct).max(axis=-1)[opening]
    assert np.quantile(apart, 0.99) <= 0.01 and apart.max() <= 0.04, (np.quantile(apart, 0.99), apart.max())


def test_a_decal_running_under_refracting_glass_shows_through_it_as_without_the_glass(scene):
    """A floor's decal running from in front of a standing refracting pane (index 1, reflecting
    nothing) to well behind it: the decal lies on an opaque surface, so the transparent slot
    draws it before the glass (``ScenePass._slot_before``), into the copy the glass marches,
    though its box reaches nearer the eye than the pane: where the pane covers the decal's far
    part it shows as the frame drawn without the pane does (the floor's rays, as a second
    path), decal and all; drawn after the glass it would be hidden there."""
    from components import Refractive
    from tests.support import pixel_rays

    colour = (0.9, 0.2, 0.1, 1.0)

    def build(glass, decal=True):
        def make(world):
            lit(world)
            look_from(world, (0.0, 1.2, 4.0), target=(0.0, 0.3, 0.0), fov=40.0)
            world.spawn(Transform(rotation=glm.angleAxis(glm.radians(-90.0), glm.vec3(1, 0, 0))),
                        MeshRef(quad(8.0, 8.0)), Material(color=GREY))
            if decal:
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 0.5),
                                      rotation=look_rotation(glm.vec3(0, -1, 0), glm.vec3(0, 0, -1)),
                                      scale=glm.vec3(1.2, 3.0, 0.5)), Decal(color=colour))
            if glass:
                world.spawn(Transform(position=glm.vec3(0.0, 0.8, 0.6)), MeshRef(quad(2.0, 1.6)),
                            Material(color=(1.0, 1.0, 1.0, 0.0), double_sided=True, roughness=0.0, reflectance=0.0,
                                     environment_reflection=0.0), Refractive(ior=1.0))
        return make

    runner, seen = render(scene, build(True))
    _, drawn = render(scene, build(False))
    _, bare = render(scene, build(False, decal=False))
    assert runner.engine.renderer.refracting_batches()
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    floor = eye + (-eye[1] / rays[..., 1])[..., None] * rays          # (where each ray meets the floor)
    pane = eye + ((0.6 - eye[2]) / rays[..., 2])[..., None] * rays     # (and the pane's plane)
    behind = (rays[..., 1] < 0) & (np.abs(floor[..., 0]) < 0.5) & (floor[..., 2] > -0.9) & (floor[..., 2] < 0.45) \
        & (np.abs(pane[..., 0]) < 0.95) & (pane[..., 1] > 0.05) & (pane[..., 1] < 1.55)
    assert behind.sum() > 100, behind.sum()
    assert (np.abs(drawn - bare).max(axis=-1)[behind] > 40).all()   # (the decal is there)
    assert np.abs(seen - drawn).max(axis=-1)[behind].max() <= 3


FLOOR_TURN = glm.angleAxis(glm.radians(-90.0), glm.vec3(1, 0, 0))  # a quad facing +y


def settled(mask: np.ndarray) -> np.ndarray:
    """Pixels of ``mask`` whose eight neighbours are in it too (none on its edge)."""
    kept = mask.copy()
    kept[0, :] = kept[-1, :] = kept[:, 0] = kept[:, -1] = False
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            kept &= np.roll(np.roll(mask, dy, axis=0), dx, axis=1)
    return kept


def test_a_turned_tilted_decal_covers_the_floor_pixels_whose_ray_point_lies_in_its_box(scene):
    """A decal thrown 20 degrees off straight down, its box turned about the vertical and
    reaching below the floor at one corner (depth fade 0: a hard cut): each pixel's ray is
    followed to the floor and its point taken into the box's own space (numpy, float64): the
    pixels whose point lies inside the unit cube (with their neighbours) show the decal (its
    id, its green), those outside (with their neighbours) the bare floor to the level."""
    from tests.support import pixel_rays

    turn = look_rotation(glm.vec3(0.3, -1.0, 0.2), glm.vec3(0.5, 0.0, -1.0))
    where, scale = glm.vec3(0.1, 0.15, -0.1), glm.vec3(1.4, 0.9, 0.8)

    def build(decal):
        def make(world):
            lit(world)
            look_from(world, (0.3, 3.0, 2.5), target=(0.0, 0.0, 0.0), fov=45.0)
            world.spawn(Transform(rotation=FLOOR_TURN), MeshRef(quad(8.0, 8.0)), Material(color=GREY))
            if decal:
                world.spawn(Transform(position=where, rotation=turn, scale=scale),
                            Decal(color=(0.1, 0.9, 0.1, 1.0), depth_fade=0.0))
        return make

    runner, image = render(scene, build(True))
    _, bare = render(scene, build(False))
    part = [e for e, _ in runner.world.query_one(FromDecal)][0]
    ids = runner.ids()
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    assert (rays[..., 1] < 0).all()
    point = eye + (-eye[1] / rays[..., 1])[..., None] * rays  # where each ray meets the floor
    to_box = np.linalg.inv(np.array(glm.mat4(glm.translate(where) * glm.mat4_cast(turn) * glm.scale(scale)),
                                    np.float64))
    local = point @ to_box[:3, :3].T + to_box[:3, 3]
    inside = (np.abs(local) <= 0.5).all(axis=-1)
    assert (local[..., 2][inside] < -0.49).any() and (np.abs(local[..., 2]) > 0.5).any()  # (the depth cuts it too)
    shown, clear = settled(inside), settled(~inside)
    assert shown.sum() > 300 and clear.sum() > 2000
    assert (ids[shown] == part).all() and not (ids[clear] == part).any()
    green = image[shown]
    assert (green[:, 1] > 2 * green[:, 0]).all() and (np.abs(image - bare).max(axis=-1)[shown] > 40).all()
    assert np.abs(image - bare).max(axis=-1)[clear].max() <= 1


@pytest.mark.parametrize("case", ["turned 70 of 60-80", "turned 30 of 20-40", "turned 10 of 0-0", "deep 0.45 of 0.1",
                                  "deep 0.2 of 0.4"])
def test_a_surface_turned_from_the_decal_or_near_its_boxs_end_takes_it_faded_by_the_stated_share(scene, case):
    """A wall turned about y by ``turn`` degrees from facing the decal (or standing
    ``deep`` of the box's depth from its middle, towards its far end) through a decal of
    opacity 0.7: it takes the decal as it takes a quad of the same look laid on it whose
    alpha is 0.7 times the share worked out here from the README's words (angle: 1 up to
    the fade's start, 0 past its end, linear in degrees between; depth: linear over
    ``depth_fade`` of the box's depth at each end); the share is neither 0 nor 1, so the
    wall and the full decal both differ from it."""
    words = case.split()
    turn, deep = (float(words[1]), 0.0) if words[0] == "turned" else (0.0, float(words[1]))
    if words[0] == "turned":
        start, end = (float(v) for v in words[3].split("-"))
        share = 1.0 if turn <= start else 0.0 if turn >= end else (end - turn) / (end - start)
        fields = {"angle_fade": (start, end), "depth_fade": 0.0}
        if end == 0.0:  # (a hard angle: 0 degrees of fade, a surface turned 10 takes none)
            share = 0.0
    else:
        fade = float(words[3])
        share = (0.5 - deep) / fade
        fields = {"depth_fade": fade}
    rotation = glm.angleAxis(glm.radians(turn), glm.vec3(0, 1, 0))
    normal = rotation * glm.vec3(0, 0, 1)
    across = 0.5 / np.cos(np.radians(turn))  # half the width the box's sides cut out of the turned wall

    def build(kind, alpha=LOOK[3]):
        def make(world):
            lit(world)
            look_from(world, 3.0 * normal + glm.vec3(0.0, 0.3, 0.0), target=(0.0, 0.0, 0.0), fov=40.0)
            world.spawn(Transform(rotation=rotation), MeshRef(quad(6.0, 6.0)), Material(color=GREY))
            if kind == "decal":
                depth = 1.0 if deep else 4.0
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, deep), scale=glm.vec3(1.0, 1.0, depth)),
                            Decal(color=LOOK, **fields))
            elif kind == "quad":
                world.spawn(Transform(position=1e-3 * normal, rotation=rotation),
                            MeshRef(quad(2.0 * across, 1.0), casts_shadows=False), Material(color=(*LOOK[:3], alpha)))
        return make

    runner, with_decal = render(scene, build("decal"))
    _, bare = render(scene, build("none"))
    _, full = render(scene, build("quad"))
    middle = [runner.project(rotation * glm.vec3(sx * 0.8 * across, sy * 0.4, 0.0)) for sx in (-1, 1) for sy in (-1, 1)]
    xs, ys = zip(*middle, strict=True)
    window = (slice(min(ys), max(ys)), slice(min(xs), max(xs)))
    assert with_decal[window].size > 300
    if share == 0.0:
        assert not runner.world.query_one(FromDecal)
        assert np.abs(with_decal - bare).max() == 0
        return
    _, faded = render(scene, build("quad", LOOK[3] * share))
    assert np.abs(with_decal[window] - faded[window]).max() <= 2
    assert np.abs(full[window] - faded[window]).max() > 12 and np.abs(bare[window] - faded[window]).max() > 12


@pytest.mark.parametrize("towards, scale", [("u", 1.0), ("v", 1.0), ("u", 0.5)])
def test_a_normal_mapped_decal_is_lit_as_a_wall_turned_as_its_map_says(scene, towards, scale):
    """A decal turned a quarter turn on a flat wall (its image's +U along the world's +y, +V
    along -x) whose normal map leans every normal 35 degrees towards +U (or +V), times
    ``normal_scale``: the middle of it is lit as a plain decal of the same look on a wall
    turned by the angle worked out here from the map's bytes (atan of scale x lean over
    out, OpenGL's convention: red towards +U, green towards +V) towards +y (or -x), and
    not as on the flat wall."""
    lean = np.radians(35.0)
    texel = np.array([np.sin(lean), 0.0, np.cos(lean)] if towards == "u" else [0.0, np.sin(lean), np.cos(lean)])
    stored = np.round((texel * 0.5 + 0.5) * 255.0).astype(np.uint8)
    bytes_read = stored / 255.0 * 2.0 - 1.0
    along = bytes_read[0] if towards == "u" else bytes_read[1]
    angle = np.degrees(np.arctan2(scale * along, bytes_read[2]))
    # Leaning towards +U (world +y) is the wall turned about x by -angle; towards +V (world -x), about y by -angle.
    wall_turn = glm.angleAxis(glm.radians(-angle), glm.vec3(1, 0, 0) if towards == "u" else glm.vec3(0, 1, 0))
    flat_map = TextureData(np.tile(np.append(stored, 255).astype(np.uint8), (8, 8, 1)), name="leaning")
    decal_turn = glm.angleAxis(glm.radians(90.0), glm.vec3(0, 0, 1))
    look = {"color": (0.4, 0.4, 0.4, 1.0), "roughness": 0.6}

    def build(mapped, turned):
        def make(world):
            world.spawn(Skybox())
            world.spawn(DirectionalLight(direction=(0.0, -0.8, -0.6) if towards == "u" else (0.8, 0.0, -0.6),
                                         intensity=1.5))  # (grazing from where the normals lean)
            look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=30.0)
            world.spawn(Transform(rotation=wall_turn if turned else glm.quat()), MeshRef(quad(4.0, 4.0)),
                        Material(color=GREY))
            extra = {"normal_map": flat_map, "normal_scale": scale} if mapped else {}
            world.spawn(Transform(rotation=decal_turn, scale=glm.vec3(1.0, 1.0, 2.0)), Decal(**look, **extra))
        return make

    runner, mapped = render(scene, build(True, False))
    _, turned = render(scene, build(False, True))
    _, flat = render(scene, build(False, False))
    (x0, y0), (x1, y1) = runner.project((-0.15, 0.15, 0.0)), runner.project((0.15, -0.15, 0.0))
    window = (slice(y0, y1), slice(x0, x1))
    assert mapped[window].size > 300
    assert np.abs(turned[window] - flat[window]).max(axis=-1).min() > 12   # (the lean shows)
    assert np.abs(mapped[window] - turned[window]).max() <= 2, np.abs(mapped[window] - turned[window]).max()


def two_decals(world, eye, target=(0.0, 0.0, 0.0)) -> None:
    """A red decal's box middle at x = -0.3, a green one's at +0.3, the same order, both
    on a wall facing +z and overlapping over -0.3 < x < 0.3; the camera at ``eye``."""
    lit(world)
    look_from(world, eye, target=target, fov=40.0)
    wall(world, size=6.0)
    world.spawn(Transform(position=glm.vec3(-0.3, 0.0, 0.0), scale=glm.vec3(1.2, 1.0, 0.5)),
                Decal(color=(0.9, 0.05, 0.05, 1.0)))
    world.spawn(Transform(position=glm.vec3(0.3, 0.0, 0.0), scale=glm.vec3(1.2, 1.0, 0.5)),
                Decal(color=(0.05, 0.9, 0.05, 1.0)))


def red_or_green(rgb) -> str:
    r, g, _ = (int(v) for v in rgb)
    assert max(r, g) > 2 * min(r, g), rgb
    return "red" if r > g else "green"


def test_of_two_decals_of_one_order_the_one_nearer_the_views_eye_is_over_a_mirrors_eye_its_own(scene):
    """Same order, overlapping: from an eye on the left the red (its box's middle nearer)
    covers the overlap, from the right the green, as the eye moves (no order kept from an
    earlier frame).  A mirror standing at x = 3 facing -x, seen from the left (x = -0.5),
    shows the overlap as a camera at the eye's image behind it (x = 6.5) sees it: its
    view's eye, not the camera's, orders the two (the green, nearer that eye)."""
    runner, image = render(scene, lambda world: two_decals(world, (-1.5, 0.0, 3.0)))
    assert red_or_green(image[runner.project((0.0, 0.0, 0.0))[::-1]]) == "red"
    camera = [e for e, c in runner.world.query_one(Camera)][0]
    runner.world.get(camera, Transform).position = glm.vec3(1.5, 0.0, 3.0)
    runner.world.get(camera, Transform).rotation = look_rotation(glm.vec3(-1.5, 0.0, -3.0))
    runner.frame()
    image = runner.frame()
    assert red_or_green(image[runner.project((0.0, 0.0, 0.0))[::-1]]) == "green"
    _, behind = render(scene, lambda world: two_decals(world, (6.5, 0.0, 3.0)))
    assert red_or_green(behind[runner.project((0.0, 0.0, 0.0))[::-1]]) == "green"

    def mirrored(world):
        two_decals(world, (-0.5, 0.0, 3.0), target=(3.0, 0.0, 1.4))
        world.spawn(Transform(position=glm.vec3(3.0, 0.0, 1.4), rotation=look_rotation(glm.vec3(1, 0, 0))),
                    MeshRef(quad(2.4, 2.0)), Mirror())  # (its face, +z, turned to -x)

    runner, image = render(scene, mirrored)
    x, y = runner.project((6.0, 0.0, 0.0))  # the overlap's middle's image behind the mirror
    assert red_or_green(image[y, x]) == "green"


def picture_look(decal: bool) -> dict:
    """The mapped look less its normal map (whose bumps, read at a few texels a pixel, turn
    highlights on the least difference of UVs between the cut's triangles and a quad's)."""
    look = dict(looks()["mapped"][0 if decal else 1])
    look.pop("normal_map"), look.pop("normal_scale")
    return look


def test_a_monitors_picture_shows_the_decal_as_it_shows_a_quad_of_its_look(scene):
    """A camera (not active) looking at the wall feeds a monitor's screen: its picture (read
    back) of the decal is its picture of a quad of the same look laid there, and the look is
    in it (it differs from the bare wall's)."""
    from components import Monitor

    def build(kind):
        def make(world):
            lit(world)
            look_from(world, (0.0, 0.0, -3.0), target=(0.0, 0.0, -6.0), fov=40.0)  # (the frame sees the screen)
            wall(world)
            lens = world.spawn(Transform(position=glm.vec3(0.5, 0.3, 3.0),
                                         rotation=look_rotation(glm.vec3(-0.5, -0.3, -3.0))),
                               Camera(fov_y=40.0, active=False))
            world.screen = world.spawn(Transform(position=glm.vec3(0.0, 0.0, -6.0)), MeshRef(quad(1.6, 1.2)),
                                       Material(color=(0.0, 0.0, 0.0, 1.0)), Monitor(camera=lens, size=(48, 36)))
            if kind == "decal":
                world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(**picture_look(True)))
            elif kind == "quad":
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 1e-3)), MeshRef(quad(1.0, 1.0), casts_shadows=False),
                            Material(**picture_look(False)))
        return make

    pictures = {}
    for kind in ("decal", "quad", "none"):
        runner, _ = render(scene, build(kind))
        pictures[kind] = runner.engine.renderer.monitors.read(runner.world.screen)[..., :3].astype(np.float64)
    assert (np.abs(pictures["decal"] - pictures["none"]).max(axis=-1) > 0.05).sum() > 150
    apart = np.abs(pictures["decal"] - pictures["quad"]).max(axis=-1)
    assert np.quantile(apart, 0.99) <= 0.01 and apart.max() <= 0.03, (np.quantile(apart, 0.99), apart.max())


def test_a_decal_parented_to_a_sliding_crate_recuts_the_floor_alone_and_lies_where_rays_say(scene):
    """A decal held by a crate (its child), looking down over the crate's top and the floor
    beside it: the crate slides 0.7 m, the decal with it.  The floor's piece is cut again,
    the crate's kept (they moved together); each pixel's first hit (numpy rays against the
    crate's box and the floor) shows the decal's id exactly where that point lies in the
    decal's new box on a surface facing up (the crate's top, the floor), not on the crate's
    sides nor where the box was."""
    from tests.support import pixel_rays

    made = {}
    down = look_rotation(glm.vec3(0, -1, 0), glm.vec3(0, 0, -1))

    def build(world):
        lit(world)
        look_from(world, (0.6, 3.2, 3.0), target=(0.6, 0.0, 0.0), fov=50.0)
        made["floor"] = world.spawn(Transform(rotation=FLOOR_TURN), MeshRef(quad(8.0, 8.0)), Material(color=GREY))
        made["crate"] = world.spawn(Transform(position=glm.vec3(-0.4, 0.5, 0.0)), MeshRef(box((1.0, 1.0, 1.0))),
                                    Material(color=GREY))
        made["decal"] = world.spawn(Transform(parent=made["crate"], position=glm.vec3(0.7, 0.0, 0.0), rotation=down,
                                              scale=glm.vec3(1.6, 1.2, 2.4)), Decal(color=(0.1, 0.1, 0.9, 1.0)))

    runner, _ = render(scene, build)
    stage = decals(runner)
    assert set(stage.states[made["decal"]].pieces) == {made["floor"], made["crate"]}
    cuts, pieces = stage.cuts, stage.pieces_cut
    runner.world.get(made["crate"], Transform).position = glm.vec3(0.3, 0.5, 0.0)
    runner.frame()
    assert stage.cuts == cuts + 1 and stage.pieces_cut == pieces + 1  # (the floor's piece alone)
    ids = runner.ids()
    part = stage.states[made["decal"]].part
    eye, rays = pixel_rays(runner.engine.main_view, SIZE)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (np.array([-0.2, 0.0, -0.5]) - eye) / rays
        t2 = (np.array([0.8, 1.0, 0.5]) - eye) / rays
    near, far = np.minimum(t1, t2), np.maximum(t1, t2)
    on_crate = (near.max(axis=-1) <= far.min(axis=-1)) & (far.min(axis=-1) > 0)
    t = np.where(on_crate, near.max(axis=-1), -eye[1] / rays[..., 1])
    facing_up = ~on_crate | (near.argmax(axis=-1) == 1)  # the floor, or the crate's top
    point = eye + t[..., None] * rays
    box_world = np.array(runner.world.get(made["decal"], Transform).world, np.float64)
    assert box_world[:3, 3] == pytest.approx([1.0, 0.5, 0.0])
    local = (point - box_world[:3, 3]) @ np.linalg.inv(box_world[:3, :3]).T
    painted = (np.abs(local) <= 0.5).all(axis=-1) & facing_up
    shown, clear = settled(painted), settled(~painted)
    assert settled(painted & on_crate).sum() > 40 and settled(painted & ~on_crate).sum() > 100
    assert (ids[shown] == part).all() and not (ids[clear] == part).any()


def test_skinned_and_morphed_surfaces_take_no_decal_and_the_same_meshes_unposed_do(scene):
    """A quad posed by a Morph and one posed by a Skin (both left where they are modelled)
    in a decal's box take none of it (the GPU poses them): no piece, no part, the frame the
    bare one; the same quads as plain meshes take it."""
    from components import Morph, Skin
    from engine.assets.mesh import Mesh

    made = {}

    def build(posed, decal=True):
        def make(world):
            lit(world)
            look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
            flat = quad(0.6, 0.6)
            positions, triangles = np.asarray(flat.positions, np.float32), np.asarray(flat.indices).reshape(-1, 3)
            n = len(positions)
            still = np.zeros((1, n, 3), np.float32)
            if posed:
                morphed = Mesh(positions, flat.normals, flat.uvs, triangles, name="morphed",
                               morph_positions=still, morph_normals=still)
                skinned = Mesh(positions, flat.normals, flat.uvs, triangles, name="skinned",
                               joints=np.zeros((n, 2), np.uint16), weights=np.tile([1.0, 0.0], (n, 1)))
                extra = ([Morph((1.0,))], [Skin(np.eye(4)[None].copy())])
            else:
                morphed = skinned = flat
                extra = ([], [])
            made["morphed"] = world.spawn(Transform(position=glm.vec3(-0.35, 0.0, 0.0)), MeshRef(morphed),
                                          Material(color=GREY), *extra[0])
            made["skinned"] = world.spawn(Transform(position=glm.vec3(0.35, 0.0, 0.0)), MeshRef(skinned),
                                          Material(color=GREY), *extra[1])
            if decal:
                made["decal"] = world.spawn(Transform(scale=glm.vec3(1.6, 1.0, 0.5)), Decal(color=LOOK))
        return make

    runner, posed = render(scene, build(True))
    assert decals(runner).states[made["decal"]].pieces == {} and not runner.world.query_one(FromDecal)
    ids = runner.ids()
    assert all(ids[runner.project((x, 0.0, 0.0))[::-1]] == made[name]
               for x, name in ((-0.35, "morphed"), (0.35, "skinned")))  # (they are drawn)
    _, bare = render(scene, build(True, decal=False))
    assert np.abs(posed - bare).max() == 0
    runner, plain = render(scene, build(False))
    assert set(decals(runner).states[made["decal"]].pieces) == {made["morphed"], made["skinned"]}
    for x in (-0.35, 0.35):
        column, row = runner.project((x, 0.0, 0.0))
        assert np.abs(plain[row, column] - posed[row, column]).max() > 40


def test_a_decal_in_a_shadow_is_shadowed_as_a_quad_of_its_look_there(scene):
    """A post between the sun and the wall throws its shadow across the decal's middle: the
    decal is lit as a quad of its look laid there (casting none) is, shadow and all, and the
    shadow is on it (darker than the same decal with no post)."""
    def build(kind, post=True):
        def make(world):
            world.spawn(Skybox())
            world.spawn(DirectionalLight(direction=(-0.6, -0.3, -1.0), intensity=2.0))
            look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
            wall(world)
            if post:
                world.spawn(Transform(position=glm.vec3(0.6, 0.3, 1.0)), MeshRef(box((0.2, 2.6, 0.2))),
                            Material(color=GREY))
            if kind == "decal":
                world.spawn(Transform(scale=glm.vec3(1.0, 1.0, 0.5)), Decal(color=(0.8, 0.6, 0.2, 1.0)))
            else:
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 1e-3)), MeshRef(quad(1.0, 1.0), casts_shadows=False),
                            Material(color=(0.8, 0.6, 0.2, 1.0)))
        return make

    runner, shaded = render(scene, build("decal"))
    _, quad_shaded = render(scene, build("quad"))
    _, sunlit = render(scene, build("decal", post=False))
    # The post (x = 0.6, 1 m out from the wall) casts along the sun onto x = 0 +- 0.16 of the wall,
    # out of the eye's way to it; x = 0.38 is lit.
    shade_x, shade_y = runner.project((0.0, -0.3, 0.0))
    lit_x, _ = runner.project((0.38, -0.3, 0.0))
    ids = runner.ids()
    part = [e for e, _ in runner.world.query_one(FromDecal)][0]
    assert ids[shade_y, shade_x] == part and ids[shade_y, lit_x] == part
    assert shaded[shade_y, shade_x].sum() < 0.7 * sunlit[shade_y, shade_x].sum()   # (in the shadow)
    assert np.abs(shaded[shade_y, lit_x] - sunlit[shade_y, lit_x]).max() <= 3       # (beside it, lit)
    (x0, y0), (x1, y1) = runner.project((-0.4, 0.4, 0.0)), runner.project((0.4, -0.4, 0.0))
    assert np.abs(shaded[y0:y1, x0:x1] - quad_shaded[y0:y1, x0:x1]).max() <= 3


@pytest.mark.parametrize("region, colour", [((0.0, 0.5, 0.5, 1.0), "red"), ((0.5, 0.5, 1.0, 1.0), "green"),
                                            ((0.0, 0.0, 0.5, 0.5), "blue")])
def test_a_region_throws_that_part_of_the_image_over_the_whole_box(scene, region, colour):
    """``region`` (u0, v0, u1, v1), v up the image (row 0 its top): of the 2 x 2 corners image
    the quarter named, stretched over the whole box, all of its pixels that colour."""
    def build(world):
        lit(world)
        look_from(world, (0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), fov=40.0)
        wall(world)
        world.spawn(Transform(scale=glm.vec3(1.2, 1.2, 0.5)), Decal(texture=corners_texture(), region=region))

    runner, image = render(scene, build)
    (x0, y0), (x1, y1) = runner.project((-0.5, 0.5, 0.0)), runner.project((0.5, -0.5, 0.0))
    rgb = image[y0:y1, x0:x1].reshape(-1, 3)
    assert len(rgb) > 500
    channel = {"red": 0, "green": 1, "blue": 2}[colour]
    others = [c for c in range(3) if c != channel]
    assert (rgb[:, channel] > 2 * rgb[:, others].max(axis=1)).all()
