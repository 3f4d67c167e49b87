"""Show and hide in reflections (components.visibility): real frames, facts about the id
image (what is drawn at each pixel after the mirrors and portals are composited) and the
probes' cube faces.  Where a thing should land is worked out from the reflection's math,
and each hidden case is set against the same scene without the component."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    Camera,
    ComponentValueError,
    DirectionalLight,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Portal,
    ReflectionProbe,
    Skybox,
    Transform,
    Visibility,
)
from components.limits import ALL_LAYERS, REFLECTION_LAYERS, VIEW_KINDS, VIEW_MIRROR, VIEW_PROBE
from engine.assets.mesh import box, quad
from engine.assets.portals import spawn_portal_pair
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix
from engine.render.sky import face_directions
from tests.support import box_hits, look_from, pixel_rays, skip_unless_trusted, srgb_to_linear

SIZE = (200, 150)
VAMPIRE = (-1.0, 1.2, 0.0)
EYE = (1.5, 1.8, 5.0)
BLUE_BACKDROP = (0.05, 0.05, 0.9)


def hall(ents, visibility=None, **mirror):
    """A mirror at z = -2 facing the camera, a red box (the vampire) between them, and a blue
    backdrop behind the camera: what the mirror shows behind the vampire (the reflected ray
    through the vampire goes on to the backdrop at z = 8)."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        look_from(world, EYE)
        ents["mirror"] = world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(quad(4, 3)),
                                     Material(color=(0.1, 0.1, 0.1)), Mirror(**mirror))
        ents["backdrop"] = world.spawn(Transform(position=(0, 2, 8)), MeshRef(box((16, 8, 0.2))),
                                       Material(color=BLUE_BACKDROP), Emissive(1.0))
        parts = [Transform(position=VAMPIRE, scale=(0.6, 0.6, 0.6)), MeshRef(box()), Material(color=(0.9, 0.05, 0.05)),
                 Emissive(0.8)]
        if visibility is not None:
            parts.append(visibility)
        ents["vampire"] = world.spawn(*parts)
    return build


def reflected_pixel(runner, point, mirror_point=(0, 1.5, -2), normal=(0, 0, 1)):
    """Where the mirror image of ``point`` lands on screen (the reflection matrix, no renderer)."""
    m = reflection_matrix(plane_from_point_normal(mirror_point, normal))
    return runner.project(glm.vec3(m * glm.vec4(glm.vec3(point), 1.0)))


def in_surface(runner, entity) -> np.ndarray:
    """The main view's pixels of surface ``entity`` (a mirror or portal drawn at level 0)."""
    return runner.engine.renderer.targets.read_surface_ids() == entity


def test_a_vampire_is_seen_directly_and_not_in_the_mirror_which_shows_what_is_behind_it(scene):
    shown, hidden = {}, {}
    runs = {}
    for key, ents, visibility in (("shown", shown, None), ("hidden", hidden, Visibility(in_mirrors=False))):
        runner = runs[key] = scene(hall(ents, visibility), SIZE)
        rgb = runner.frame()
        col, row = reflected_pixel(runner, VAMPIRE)
        direct_col, direct_row = runner.project(VAMPIRE)
        ids = runner.ids()
        assert in_surface(runner, ents["mirror"])[row, col]  # the image point lies on the glass
        assert ids[direct_row, direct_col] == ents["vampire"]  # seen directly either way
        mirror_ids = ids[in_surface(runner, ents["mirror"])]
        if key == "shown":
            assert ids[row, col] == ents["vampire"]
            assert (mirror_ids == ents["vampire"]).sum() > 50
        else:
            # The mirror shows what lies behind the vampire along the reflected ray: the backdrop.
            assert ids[row, col] == ents["backdrop"]
            assert not (mirror_ids == ents["vampire"]).any()
            r, g, b = srgb_to_linear(rgb[row, col])
            assert b > 0.3 and b > 4 * r, rgb[row, col]
        runs[key + "_rgb"] = rgb


def test_a_ghost_is_seen_only_in_the_mirror(scene):
    ents = {}
    runner = scene(hall(ents, Visibility(direct=False)), SIZE)
    runner.frame()
    col, row = reflected_pixel(runner, VAMPIRE)
    ids = runner.ids()
    mirror = in_surface(runner, ents["mirror"])
    assert ids[row, col] == ents["vampire"]
    assert (ids[mirror] == ents["vampire"]).sum() > 50
    assert not (ids[~mirror] == ents["vampire"]).any()  # nowhere outside the mirror's own pixels
    direct_col, direct_row = runner.project(VAMPIRE)
    assert ids[direct_row, direct_col] != ents["vampire"]  # not where it stands


def two_mirrors(ents, layer3=None):
    """Two mirrors side by side, the left one hiding layer 3; a box on layer 3 (or with
    ``layer3``'s Visibility) and one on layer 0 stand in front of both."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        look_from(world, (0.0, 2.5, 6.0), target=(0.0, 0.8, -2.0))
        ents["left"] = world.spawn(Transform(position=(-2.1, 1.5, -2)), MeshRef(quad(4, 3)),
                                   Material(color=(0.1, 0.1, 0.1)), Mirror(hides_layers=[3]))
        ents["right"] = world.spawn(Transform(position=(2.1, 1.5, -2)), MeshRef(quad(4, 3)),
                                    Material(color=(0.1, 0.1, 0.1)), Mirror())
        # Each box is wide and in front of the seam: its image lands on both mirrors (at y 1.1
        # and 1.5 on the glass), while the camera sees the boxes themselves below the glass.
        ents["layer3"] = world.spawn(Transform(position=(0.0, 0.4, 2.0), scale=(3.0, 0.3, 0.3)), MeshRef(box()),
                                     Material(color=(0.9, 0.05, 0.05)), Emissive(0.8),
                                     layer3 if layer3 is not None else Visibility(layers=[3]))
        ents["layer0"] = world.spawn(Transform(position=(0.0, 1.0, 2.0), scale=(3.0, 0.3, 0.3)), MeshRef(box()),
                                     Material(color=(0.05, 0.9, 0.05)), Emissive(0.8))
    return build


def test_a_mirror_that_hides_a_layer_leaves_out_what_is_on_it_while_another_mirror_shows_it(scene):
    """Two mirrors side by side, the left one hiding layer 3; a box on layer 3 and one on layer
    0 stand in front of both: the layer-3 box is in the right mirror only, the layer-0 box in
    both, and both are seen directly (the camera's view shows every layer)."""
    ents = {}
    runner = scene(two_mirrors(ents), SIZE)
    runner.frame()
    ids = runner.ids()
    left, right = in_surface(runner, ents["left"]), in_surface(runner, ents["right"])
    assert (ids[right] == ents["layer3"]).sum() > 30
    assert not (ids[left] == ents["layer3"]).any()
    assert (ids[left] == ents["layer0"]).sum() > 30 and (ids[right] == ents["layer0"]).sum() > 30
    outside = ~(left | right)
    assert (ids[outside] == ents["layer3"]).sum() > 30 and (ids[outside] == ents["layer0"]).sum() > 30


def portal_room(ents, visibility=None, mirror_beyond=False):
    """A portal A at (0, 1.5, 0) facing the camera (z = 4) and its partner B at (20, 1.5, 0):
    the camera sees through A what lies in front of B, as from (20, 1.5, -4) looking +z.
    Without ``mirror_beyond`` a red box (the vampire) stands 2 m in front of B, a blue
    backdrop behind it; with it, the box stands 3 m to B's side, outside what A's window
    shows, and a mirror 6 m in front of B faces back: the box is seen only in that mirror,
    through the portal (a mirror view below a portal view)."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, 0.0))
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 0), None, (20, 1.5, 0), None)
        ents["backdrop"] = world.spawn(Transform(position=(20, 2, 12)), MeshRef(box((16, 8, 0.2))),
                                       Material(color=BLUE_BACKDROP), Emissive(1.0))
        if mirror_beyond:
            facing_b = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
            ents["mirror"] = world.spawn(Transform(position=(20, 1.5, 6), rotation=facing_b), MeshRef(quad(8, 5)),
                                         Material(color=(0.1, 0.1, 0.1)), Mirror())
        position = (23.0, 1.5, 1.0) if mirror_beyond else (20.0, 1.2, 2.0)
        size = 1.0 if mirror_beyond else 0.6
        parts = [Transform(position=position, scale=(size, size, size)), MeshRef(box()),
                 Material(color=(0.9, 0.05, 0.05)), Emissive(0.8)]
        ents["vampire"] = world.spawn(*parts, *([visibility] if visibility is not None else []))
    return build


@pytest.mark.parametrize("visibility, seen", [(None, True), (Visibility(in_portals=False), False),
                                              (Visibility(in_mirrors=False), True), (Visibility(in_probes=False), True),
                                              (Visibility(direct=False), True)])
def test_hidden_in_portals_is_hidden_through_a_portal_and_only_there(scene, visibility, seen):
    ents = {}
    runner = scene(portal_room(ents, visibility), SIZE)
    rgb = runner.frame()
    ids = runner.ids()
    through = in_surface(runner, ents["a"])
    assert through.sum() > 2000 and runner.stats.reflection_views >= 1
    assert ((ids[through] == ents["vampire"]).sum() > 100) == seen
    # Where it is not, the backdrop behind it is: the carried point lands on A's pixels.
    col, row = runner.project((0.0, 1.2, -2.0))  # (20, 1.2, 2) carried back to A's side
    assert through[row, col]
    assert ids[row, col] == (ents["vampire"] if seen else ents["backdrop"])
    if not seen:
        r, g, b = srgb_to_linear(rgb[row, col])
        assert b > 0.3 and b > 4 * r, rgb[row, col]


@pytest.mark.parametrize("visibility, seen", [(None, True), (Visibility(in_mirrors=False), False),
                                              (Visibility(in_portals=False), False),
                                              (Visibility(direct=False), True)])
def test_kinds_accumulate_a_mirror_seen_through_a_portal_is_both(scene, visibility, seen):
    """The box is seen only in the mirror beyond the portal: a view that is a portal's and a
    mirror's at once.  Hidden in mirrors, or in portals, it is not drawn there."""
    ents = {}
    runner = scene(portal_room(ents, visibility, mirror_beyond=True), SIZE)
    runner.frame()
    ids = runner.ids()
    through = in_surface(runner, ents["a"])
    assert runner.stats.reflection_views >= 2  # the portal's view and the mirror's below it
    assert ((ids[through] == ents["vampire"]).sum() > 30) == seen
    assert not (ids[~through] == ents["vampire"]).any()


def probe_room(ents, visibility=None, probe_hides=(), mirror_behind=False):
    """A probe at the origin (32 texels a face), a red box 2 m down -Z and a green one 2 m
    down +X, both glowing: each in the centre of its face.  With ``mirror_behind`` the red
    box is behind the probe (+Z) and a mirror 2 m down -Z shows it to the -Z face (the face's
    view tree: a mirror view below a probe view)."""
    def build(world):
        world.spawn(Skybox())
        look_from(world, (3.0, 0.5, 3.0), target=(0.0, 0.0, 0.0))
        ents["probe"] = world.spawn(Transform(), ReflectionProbe(resolution=32, refresh="once", depth=1,
                                                                 hides_layers=list(probe_hides)))
        if mirror_behind:
            ents["mirror"] = world.spawn(Transform(position=(0, 0, -2)), MeshRef(quad(6, 6)),
                                         Material(color=(0.05, 0.05, 0.05)), Mirror())
        parts = [Transform(position=(0, 0, 2) if mirror_behind else (0, 0, -2)), MeshRef(box((0.8, 0.8, 0.8))),
                 Material(color=(0.9, 0.05, 0.05)), Emissive(2.0)]
        ents["red"] = world.spawn(*parts, *([visibility] if visibility is not None else []))
        ents["green"] = world.spawn(Transform(position=(2, 0, 0)), MeshRef(box((0.8, 0.8, 0.8))),
                                    Material(color=(0.05, 0.9, 0.05)), Emissive(2.0))
    return build


def face_centre(runner, probe: int, face: int) -> np.ndarray:
    image = runner.engine.renderer.probes.read_face(probe, face)
    n = image.shape[0]
    return image[n // 2 - 1: n // 2 + 1, n // 2 - 1: n // 2 + 1].mean(axis=(0, 1))


def is_red(rgb) -> bool:
    return rgb[0] > 1.0 and rgb[0] > 4 * max(rgb[1], rgb[2])


@pytest.mark.parametrize("path", ["six_pass", "layered"])
@pytest.mark.parametrize("visibility, probe_hides, seen", [
    (None, (), True), (Visibility(in_probes=False), (), False), (Visibility(in_mirrors=False), (), True),
    (Visibility(in_portals=False), (), True), (Visibility(direct=False), (), True),
    (Visibility(layers=[3]), (3,), False), (Visibility(layers=[3, 5]), (3,), True), (None, (3,), True)])
def test_a_probe_capture_leaves_out_what_is_hidden_in_probes_or_on_a_layer_it_hides(scene, path, visibility,
                                                                                     probe_hides, seen):
    """The -Z face read back: red where the box is drawn, the sky where it is hidden; the
    green box on the +X face is drawn either way."""
    ents = {}
    runner = scene(probe_room(ents, visibility, probe_hides), (32, 32))
    if path == "layered":
        skip_unless_trusted(runner.engine.renderer, "layered_capture")
    runner.engine.stages["probes"].path = path
    runner.frame()
    assert runner.stats.probe_captures == 1 and runner.engine.stages["probes"].path_used == path
    red, green = face_centre(runner, ents["probe"], 5), face_centre(runner, ents["probe"], 0)
    assert is_red(red) == seen, red
    if not seen:
        assert red[2] > red[0] and red.sum() > 0.3, red  # the sky behind it, not black
    assert green[1] > 1.0 and green[1] > 4 * max(green[0], green[2]), green


@pytest.mark.parametrize("visibility, seen", [(None, True), (Visibility(in_mirrors=False), False),
                                              (Visibility(in_probes=False), False),
                                              (Visibility(direct=False), True)])
def test_a_mirror_seen_by_a_probe_face_is_a_probe_view_and_a_mirror_view(scene, visibility, seen):
    ents = {}
    runner = scene(probe_room(ents, visibility, mirror_behind=True), (32, 32))
    runner.frame()
    face = runner.engine.renderer.probes.read_face(ents["probe"], 5)  # -Z: the mirror, the box's image in it
    target = np.array([0.0, 0.0, -6.0]) / 6.0  # the image of (0, 0, 2) in the mirror at z = -2
    row, col = np.unravel_index(np.argmax(face_directions(5, 32) @ target), (32, 32))
    assert is_red(face[row, col]) == seen, face[row, col]


@pytest.mark.parametrize("case", ["vampire", "ghost", "layers", "hidden_layer_box"])
def test_the_batched_path_draws_the_same_ids_as_the_per_mirror_path(scene, case):
    """One draw per mesh for a whole level (each instance once a view) leaves out the same
    instances as a draw per view (the vertex shader's clip distance, in both)."""
    results = {}
    for path in ("per_mirror", "batched"):
        ents = {}
        if case in ("vampire", "ghost"):
            build = hall(ents, Visibility(in_mirrors=False) if case == "vampire" else Visibility(direct=False))
        else:
            build = two_mirrors(ents, None if case == "layers" else Visibility(in_mirrors=False, layers=[3]))
        runner = scene(build, SIZE)
        runner.engine.reflection_system.path = path
        runner.frame()
        assert runner.stats.reflection_path == path
        results[path] = runner.ids()
    assert results["per_mirror"].any()
    np.testing.assert_array_equal(results["batched"], results["per_mirror"])


def test_a_changed_added_or_removed_visibility_is_drawn_the_next_frame(scene):
    """The instance row is written again when the component is added, changed or removed."""
    ents = {}
    runner = scene(hall(ents), SIZE)
    world = runner.world

    def in_mirror() -> int:
        runner.frame()
        return int((runner.ids()[in_surface(runner, ents["mirror"])] == ents["vampire"]).sum())

    shown = in_mirror()
    assert shown > 50
    world.add_component(ents["vampire"], Visibility(in_mirrors=False))
    assert in_mirror() == 0
    world.get(ents["vampire"], Visibility).in_mirrors = True
    assert in_mirror() == shown
    world.get(ents["vampire"], Visibility).layers = [2]
    assert in_mirror() == shown  # the mirror shows every layer
    world.get(ents["mirror"], Mirror).shows_layers = [0, 1]
    assert in_mirror() == 0
    world.get(ents["mirror"], Mirror).shows_layers = None
    world.get(ents["vampire"], Visibility).in_mirrors = False
    assert in_mirror() == 0
    world.remove_component(ents["vampire"], Visibility)
    assert in_mirror() == shown


LEVEL = """
[level]
name = "vampires"

[[entity]]
name = "mirror"
[entity.Transform]
position = [0.0, 1.5, -2.0]
[entity.MeshRef]
mesh = { quad = [4.0, 3.0] }
[entity.Mirror]
hides_layers = [3]

[[entity]]
name = "door"
[entity.Transform]
position = [5.0, 1.5, -2.0]
[entity.MeshRef]
mesh = { quad = [2.0, 3.0] }
[entity.Portal]
shows_layers = [0, 2]

[[entity]]
name = "probe"
[entity.Transform]
[entity.ReflectionProbe]
hides_layers = [1, 3]

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 1.7, 5.0]
[entity.Camera]
shows_layers = [0, 1, 3]
hides_layers = [1]

[[entity]]
name = "vampire"
[entity.Transform]
position = [0.0, 1.0, 0.0]
[entity.MeshRef]
mesh = { box = [0.5, 1.8, 0.5] }
[entity.Visibility]
in_mirrors = false
in_probes = false
layers = [0, 3]
"""


def test_a_level_file_carries_visibility_and_the_surfaces_layers_and_saves_them_back(tmp_path):
    from engine.assets.level_file import load_level, save_level
    from engine.core.world import World

    path = tmp_path / "level.toml"
    path.write_text(LEVEL)
    world = World("visibility-level")
    try:
        names = load_level(path).spawn(world)
        vampire = world.get(names["vampire"], Visibility)
        assert (vampire.direct, vampire.in_mirrors, vampire.in_portals, vampire.in_probes) == (True, False, True, False)
        assert vampire.layers == (0, 3) and vampire.layer_mask == 0b1001
        assert vampire.hidden_kinds == VIEW_MIRROR | VIEW_PROBE
        assert world.get(names["mirror"], Mirror).layer_mask == ALL_LAYERS & ~(1 << 3)
        assert world.get(names["door"], Portal).layer_mask == 0b101
        assert world.get(names["probe"], ReflectionProbe).layer_mask == ALL_LAYERS & ~0b1010
        assert world.get(names["camera"], Camera).layer_mask == 0b1001
        saved = tmp_path / "saved.toml"
        save_level(world, saved, names)
        again = World("visibility-level-again")
        try:
            names2 = load_level(saved).spawn(again)
            assert again.get(names2["vampire"], Visibility).hidden_kinds == VIEW_MIRROR | VIEW_PROBE
            assert again.get(names2["vampire"], Visibility).layers == (0, 3)
            assert again.get(names2["mirror"], Mirror).hides_layers == (3,)
            assert again.get(names2["door"], Portal).shows_layers == (0, 2)
            assert again.get(names2["camera"], Camera).layer_mask == 0b1001
        finally:
            again.close()
    finally:
        world.close()


@pytest.mark.parametrize("old, new, field, reason", [
    ("layers = [0, 3]", "layers = [0, 16]", "Visibility.layers", r"layer numbers in \[0, 15\].*16"),
    ("layers = [0, 3]", "layers = 3", "Visibility.layers", r"must be a list of layer numbers"),
    ("layers = [0, 3]", "layers = []", "Visibility.layers", r"at least one layer"),
    ("layers = [0, 3]", "layers = [1.5]", "Visibility.layers", r"layer numbers"),
    ("in_mirrors = false", "in_mirrors = 0", "Visibility.in_mirrors", r"must be True or False"),
    ("in_mirrors = false", "in_mirror = false", "Visibility.in_mirror", r"Visibility has no field 'in_mirror'"),
    ("hides_layers = [3]", "hides_layers = [-1]", "Mirror.hides_layers", r"layer numbers in \[0, 15\]"),
    ("shows_layers = [0, 2]", "shows_layers = [\"all\"]", "Portal.shows_layers", r"layer numbers"),
    ("hides_layers = [1, 3]", "hides_layers = [99]", "ReflectionProbe.hides_layers", r"\[0, 15\]"),
    ("shows_layers = [0, 1, 3]", "shows_layers = 0", "Camera.shows_layers", r"list of layer numbers"),
])
def test_a_bad_value_in_a_level_file_is_refused_naming_the_field_and_line(tmp_path, old, new, field, reason):
    from engine.assets.level_file import LevelError, load_level

    assert old in LEVEL
    path = tmp_path / "level.toml"
    path.write_text(LEVEL.replace(old, new, 1))
    with pytest.raises(LevelError, match=reason) as caught:
        load_level(path)
    assert caught.value.field == field
    assert caught.value.line == path.read_text().splitlines().index(new) + 1


@pytest.mark.parametrize("make", [
    lambda: Visibility(layers=[REFLECTION_LAYERS]), lambda: Visibility(layers=3), lambda: Visibility(layers=[]),
    lambda: Visibility(layers=[True]), lambda: Visibility(in_portals="no"), lambda: Mirror(shows_layers=[16]),
    lambda: Portal(hides_layers=5), lambda: ReflectionProbe(shows_layers=[-2])])
def test_bad_values_are_refused_when_given_naming_the_field(make):
    with pytest.raises(ComponentValueError, match=r"^(Visibility|Mirror|Portal|ReflectionProbe)\.\w+ "):
        make()
    visibility = Visibility()
    with pytest.raises(ComponentValueError, match=r"Visibility\.layers .*\[0, 15\]"):
        visibility.layers = [2, 40]
    assert visibility.layers == (0,)  # the refused write changed nothing


def test_the_shaders_read_the_masks_as_the_python_side_packs_them():
    """The GLSL's kind-bit count is the one of components/limits.py (a define the shader
    library makes from it), and the instance code is exact in the float it rides in (all 16
    layers and 4 kinds set)."""
    from components.visibility import DRAWN_EVERYWHERE, visibility_code
    from engine.render.shader_library import engine_defines

    assert engine_defines()["VIEW_KIND_BITS"] == f"{VIEW_KINDS}u"
    full = visibility_code((1 << VIEW_KINDS) - 1, ALL_LAYERS)
    assert int(np.float32(full)) == (1 << (VIEW_KINDS + REFLECTION_LAYERS)) - 1 < 2 ** 24
    assert DRAWN_EVERYWHERE == 1 << VIEW_KINDS


@pytest.mark.parametrize("hider, seen", [(None, True), ("a", False), ("b", True)])
def test_a_portal_that_hides_a_layer_leaves_it_out_of_its_view(scene, hider, seen):
    """The box is on layer 2.  Portal A (the one looked into) hiding layer 2 leaves it out of
    the view through A; its partner B hiding it does not (B's layers are for looking into B)."""
    ents = {}
    runner = scene(portal_room(ents, Visibility(layers=[2])), SIZE)
    if hider is not None:
        runner.world.get(ents[hider], Portal).hides_layers = [2]
    runner.frame()
    ids = runner.ids()
    through = in_surface(runner, ents["a"])
    assert ((ids[through] == ents["vampire"]).sum() > 100) == seen


def test_a_portal_clone_is_drawn_where_its_source_is_and_follows_its_changes(scene):
    """A bar halfway through portal A comes out of B as a clone (the slice stage's stand-in):
    seen directly at both portals.  Given Visibility(direct=False) after the first frame, the
    clone is hidden with its source (it stands in for it): neither half is seen directly."""
    from tests.test_portal_slice import SIZE as SLICE_SIZE
    from tests.test_portal_slice import build_pair

    ents = {}
    runner = scene(lambda world: build_pair(world, ents, (0, 3.0, 7.0), (0, 1.5, 0)), SLICE_SIZE)
    runner.frame()
    halves = [runner.project((-2.8, 1.7, 0.6)), runner.project((2.8, 1.7, 0.6))]  # in front of A; out of B
    assert [runner.ids()[row, col] for col, row in halves] == [ents["bar"]] * 2
    runner.world.add_component(ents["bar"], Visibility(direct=False))
    runner.frame()
    assert ents["bar"] not in [runner.ids()[row, col] for col, row in halves]
    runner.world.get(ents["bar"], Visibility).direct = True
    runner.frame()
    assert [runner.ids()[row, col] for col, row in halves] == [ents["bar"]] * 2


def test_the_sample_level_has_a_vampire_no_mirror_shows_and_a_ghost_only_the_mirrors_show(ctx):
    """The hall (games/hall_of_mirrors/hall.toml) from its mirror-wall pose: the vampire and
    its head are seen directly and in none of the mirrors' pixels; the ghost is seen in the
    mirrors' pixels only."""
    from engine.core.frame_io import Output
    from engine.render.targets import CaptureTarget
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.app import Engine

    game = HallOfMirrors()
    engine = Engine(game, ctx)
    size = (320, 180)
    capture = CaptureTarget(ctx, size)
    try:
        engine.place_camera(-1.5, 1.6, -1.0, 10.0, 0.0)
        engine.frame(1.0 / 60.0, Output(capture.framebuffer, size))
        assert capture.read_rgb().max() > 0
        ids = engine.renderer.targets.read_ids()
        surfaces = engine.renderer.targets.read_surface_ids()
        names = game.names
        mirrors = np.isin(surfaces, [names[f"mirror_{i}"] for i in range(1, 6)])
        assert mirrors.mean() > 0.2
        vampire = np.isin(ids, [names["vampire"], names["vampire_head"]])
        assert vampire[~mirrors].sum() > 500 and not vampire[mirrors].any()
        ghost = ids == names["ghost"]
        assert ghost[mirrors].sum() > 100 and not ghost[~mirrors].any()
    finally:
        capture.release()
        engine.close()


@pytest.mark.parametrize("camera_layers", [{}, {"hides_layers": [3]}])
def test_the_camera_shows_its_layers_directly_and_in_what_it_sees_through_surfaces(scene, camera_layers):
    """A camera's culling mask: the two-mirror scene seen by a camera hiding layer 3.  The
    right mirror shows every layer, so what it shows is the camera's: the layer-3 box is
    nowhere, the layer-0 box directly and in both mirrors."""

    ents = {}
    runner = scene(two_mirrors(ents), SIZE)
    for _, camera in runner.world.query_one(Camera):
        for field, value in camera_layers.items():
            setattr(camera, field, value)
    runner.frame()
    ids = runner.ids()
    left, right = in_surface(runner, ents["left"]), in_surface(runner, ents["right"])
    outside = ~(left | right)
    shown = not camera_layers
    assert ((ids[outside] == ents["layer3"]).sum() > 30) == shown
    assert ((ids[right] == ents["layer3"]).sum() > 30) == shown
    assert (ids == ents["layer3"]).any() == shown
    for where in (outside, left, right):
        assert (ids[where] == ents["layer0"]).sum() > 30


@pytest.mark.parametrize("visibility", ("exact", "predicted"))
def test_a_camera_showing_only_a_layer_sees_nothing_else_not_even_the_mirrors(scene, visibility):
    """Everything without a Visibility is on layer 0: a camera showing only layer 3 draws the
    layer-3 box alone; the mirrors are not drawn, so they reflect nothing, and the planner
    knows it without a claim: no view, not even one drawn on last frame's word."""

    ents = {}
    runner = scene(two_mirrors(ents), SIZE)
    runner.engine.reflection_system.visibility = visibility
    for _, camera in runner.world.query_one(Camera):
        camera.shows_layers = [3]
    for _ in range(2):
        runner.frame()
    ids = runner.ids()
    assert set(np.unique(ids).tolist()) == {0, ents["layer3"]}
    assert (ids == ents["layer3"]).sum() > 200
    assert runner.stats.reflection_views == 0 and runner.stats.passes == 1


@pytest.mark.parametrize("visibility", ("exact", "predicted"))
def test_a_mirror_drawn_nowhere_the_view_looks_is_no_candidate(scene, visibility):
    """A mirror's own Visibility decides where it is drawn, and so whether a view can look
    into it: moved to a layer the camera does not show, or its mesh made invisible, it makes
    no view from the next frame on (the surfaces' table follows the change); a mirror hidden
    in mirrors is seen directly but not in the other mirror."""
    ents = {}
    runner = scene(two_mirrors(ents), SIZE)
    runner.engine.reflection_system.visibility = visibility
    for _, camera in runner.world.query_one(Camera):
        camera.shows_layers = [0, 3]
    runner.frame()
    runner.frame()
    views = lambda: sorted(v.surface.entity for v in runner.engine.reflection_system.views[1:])  # noqa: E731
    assert views() == sorted((ents["left"], ents["right"]))
    runner.world.add_component(ents["left"], Visibility(layers=[5]))
    runner.frame()
    assert views() == [ents["right"]]
    assert not in_surface(runner, ents["left"]).any()
    runner.world.get(ents["left"], Visibility).layers = [0]
    runner.world.get(ents["right"], MeshRef).visible = False
    runner.frame()
    assert views() == [ents["left"]]
    runner.world.get(ents["right"], MeshRef).visible = True
    runner.frame()
    assert views() == sorted((ents["left"], ents["right"]))
    runner.world.get(ents["left"], Visibility).layers = [5]
    runner.frame()
    assert views() == [ents["right"]]
    runner.world.remove_component(ents["left"], Visibility)  # back on layer 0
    runner.frame()
    assert views() == sorted((ents["left"], ents["right"]))


@pytest.mark.parametrize("visibility", ("exact", "predicted"))
def test_a_mirror_hidden_in_mirrors_is_not_looked_into_from_a_mirror(scene, visibility):
    """Two facing mirrors, the back one hidden in mirrors: the camera sees the front one, whose
    view does not draw the back one, so no view looks into the back mirror from it (not even
    one drawn on last frame's word: it is no candidate)."""
    ents = {}

    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -2.0))
        ents["front"] = world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(quad(4, 3)),
                                    Material(color=(0.1, 0.1, 0.1)), Mirror(max_depth=4, end_image=False))
        ents["back"] = world.spawn(Transform(position=(0, 1.5, 6), rotation=glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))),
                                   MeshRef(quad(4, 3)), Material(color=(0.1, 0.1, 0.1)),
                                   Mirror(max_depth=4, end_image=False))
    runner = scene(build, SIZE)
    runner.engine.reflection_system.visibility = visibility
    runner.frame()
    seen = [v.surface.entity for v in runner.engine.reflection_system.views[1:]]
    assert ents["back"] in seen and len(seen) >= 2  # the front mirror shows the back one, and so on
    runner.world.add_component(ents["back"], Visibility(in_mirrors=False))
    runner.frame()
    runner.frame()
    seen = [v.surface.entity for v in runner.engine.reflection_system.views[1:]]
    assert seen == [ents["front"]]


HALF_TURN = glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))
CHAIN_SIZE = (128, 96)
CHAIN_BOX = (np.array([20.0, 1.3, 2.0]), np.full(3, 0.5))  # the box in front of B: centre, half sizes


def mirror_then_portal(ents, visibility=None):
    """A mirror at z = -1.5 facing the camera (z = 1) and, behind the camera, portal A at
    z = 2.5 facing the mirror; its partner B stands at (20, 1.5, 0) facing +Z with a red box
    (the vampire) 2 m in front of it and a blue backdrop behind that.  The box is seen only
    in the mirror, through A: a portal's view below a mirror's."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        look_from(world, (0.0, 1.5, 1.0), target=(0.0, 1.5, -1.5))
        ents["mirror"] = world.spawn(Transform(position=(0, 1.5, -1.5)), MeshRef(quad(4, 3)),
                                     Material(color=(0.1, 0.1, 0.1)), Mirror())
        ents["a"], ents["b"] = spawn_portal_pair(world, (0, 1.5, 2.5), HALF_TURN, (20, 1.5, 0), None, size=(3.0, 2.4))
        ents["backdrop"] = world.spawn(Transform(position=(20, 2, 10)), MeshRef(box((16, 8, 0.2))),
                                       Material(color=BLUE_BACKDROP), Emissive(1.0))
        parts = [Transform(position=tuple(CHAIN_BOX[0])), MeshRef(box()), Material(color=(0.9, 0.05, 0.05)),
                 Emissive(0.8)]
        ents["vampire"] = world.spawn(*parts, *([visibility] if visibility is not None else []))
    return build


def mirror_then_portal_rays(runner, ents, grow, chain_box=CHAIN_BOX):
    """Which pixels see the box along the chain, in float64 (no renderer): each pixel's ray
    reflected in the mirror's plane (z = -1.5), through A's rectangle (z = 2.5, 3 x 2.4 m),
    carried to B's side by the pair's transform and cast at the box (``chain_box``: centre,
    half sizes) grown by ``grow``."""
    eye, rays = pixel_rays(runner.engine.main_view, CHAIN_SIZE)
    rays = rays.reshape(-1, 3)
    t = (-1.5 - eye[2]) / rays[:, 2]
    on_mirror = (t > 0) & (np.abs(eye[0] + t * rays[:, 0]) < 2.0) & (np.abs(eye[1] + t * rays[:, 1] - 1.5) < 1.5)
    flip = np.array([1.0, 1.0, -1.0])
    origin, directions = eye * flip + (0.0, 0.0, -3.0), rays * flip  # reflected in z = -1.5
    t = (2.5 - origin[2]) / directions[:, 2]
    at_a = origin + t[:, None] * directions
    through_a = on_mirror & (t > 0) & (np.abs(at_a[:, 0]) < 1.5) & (np.abs(at_a[:, 1] - 1.5) < 1.2)
    a_world, b_world = (np.array(glm.dmat4(runner.world.get(ents[e], Transform).world).to_list()).T for e in "ab")
    turn = np.array(glm.dmat4(glm.rotate(glm.pi(), glm.vec3(0, 1, 0))).to_list()).T
    carry = b_world @ turn @ np.linalg.inv(a_world)
    carried_origin = carry[:3, :3] @ origin + carry[:3, 3]
    hits = box_hits(np.broadcast_to(carried_origin, at_a.shape), directions @ carry[:3, :3].T, chain_box[0],
                    chain_box[1] + grow)
    return (through_a & hits).reshape(CHAIN_SIZE[1], CHAIN_SIZE[0])


@pytest.mark.parametrize("visibility, hides, seen", [
    (None, {}, True), (Visibility(in_mirrors=False), {}, False), (Visibility(in_portals=False), {}, False),
    (Visibility(direct=False), {}, True), (Visibility(in_probes=False), {}, True),
    (Visibility(layers=[2]), {"mirror": [2]}, False), (Visibility(layers=[2]), {"a": [2]}, False),
    (Visibility(layers=[2]), {"b": [2]}, True), (Visibility(layers=[2]), {"camera": [2]}, False),
    (Visibility(layers=[2, 5]), {"mirror": [5]}, True), (Visibility(layers=[2, 5]), {"a": [2]}, True),
    (Visibility(layers=[2, 5]), {"mirror": [5], "a": [2]}, False)],
    ids=["shown", "in_mirrors", "in_portals", "direct", "in_probes", "mirror_hides", "a_hides", "b_hides",
         "camera_hides", "mirror_hides_one_of_two", "a_hides_one_of_two", "each_hides_one_of_two"])
def test_a_portal_seen_in_a_mirror_is_both_kinds_and_shows_the_layers_both_show(scene, visibility, hides, seen):
    """The other way round from the test above: a portal's view below a mirror's.  Kinds
    accumulate (hidden in mirrors or in portals, the box is not drawn there) and the view
    shows the layers the camera, the mirror and A all show (B's are for looking into B): a
    box on layers 2 and 5 is seen through a mirror hiding 5 or a portal hiding 2, not through
    both at once.  Where the box should be is cast along the chain in float64: the box's
    pixels (a margin in) are the box, or the backdrop behind it where it is hidden; none
    outside them (a margin out) is the box."""
    ents = {}
    runner = scene(mirror_then_portal(ents, visibility), CHAIN_SIZE)
    for name, layers in hides.items():
        if name == "camera":
            for _, camera in runner.world.query_one(Camera):
                camera.hides_layers = layers
        else:
            runner.world.get(ents[name], Mirror if name == "mirror" else Portal).hides_layers = layers
    rgb = runner.frame()
    ids = runner.ids()
    levels = [(v.level, v.surface.entity) for v in runner.engine.reflection_system.views[1:]]
    assert levels == [(1, ents["mirror"]), (2, ents["a"])]
    inside, outside = mirror_then_portal_rays(runner, ents, -0.05), ~mirror_then_portal_rays(runner, ents, 0.05)
    assert inside.sum() > 60
    assert not (ids[outside] == ents["vampire"]).any()
    if seen:
        assert (ids[inside] == ents["vampire"]).all(), int((ids[inside] != ents["vampire"]).sum())
        red = srgb_to_linear(rgb[inside])
        assert (red[:, 0] > 2 * red[:, 2]).all()  # (antialiasing softens the edge pixels)
    else:
        assert (ids[inside] == ents["backdrop"]).all(), np.unique(ids[inside])
        blue = srgb_to_linear(rgb[inside])
        assert (blue[:, 2] > 2 * blue[:, 0]).all()


@pytest.mark.parametrize("case", ["portal_hidden", "portal_layer", "portal_shows", "in_mirror_shown",
                                  "in_mirror_hidden_in_portals", "in_mirror_hidden_in_mirrors", "in_mirror_layers"])
def test_the_batched_path_hides_through_portals_and_by_their_layers_as_the_per_mirror_path(scene, case):
    """The batched path (one draw per mesh for a level, each view's mask in its row of the
    Views table) leaves out what is hidden in portals, or on a layer the portal hides, as the
    per-mirror path does, for a portal looked into directly and for one seen in a mirror (a
    mirrored portal view, level 2): the same ids, the same colours, and the box drawn or not
    as the chain says (its carried centre is the box, or the backdrop)."""
    results = {}
    for path in ("per_mirror", "batched"):
        ents = {}
        if case.startswith("portal"):
            visibility = {"portal_hidden": Visibility(in_portals=False), "portal_layer": Visibility(layers=[2]),
                          "portal_shows": Visibility(in_mirrors=False, layers=[2, 5])}[case]
            runner = scene(portal_room(ents, visibility), SIZE)
            if case != "portal_hidden":
                runner.world.get(ents["a"], Portal).hides_layers = [2]
            point, seen = (0.0, 1.2, -2.0), case == "portal_shows"  # the box's centre carried back to A's side
        else:
            visibility = {"in_mirror_shown": None, "in_mirror_hidden_in_portals": Visibility(in_portals=False),
                          "in_mirror_hidden_in_mirrors": Visibility(in_mirrors=False),
                          "in_mirror_layers": Visibility(layers=[2, 5])}[case]
            runner = scene(mirror_then_portal(ents, visibility), CHAIN_SIZE)
            if case == "in_mirror_layers":
                runner.world.get(ents["mirror"], Mirror).hides_layers = [5]
                runner.world.get(ents["a"], Portal).hides_layers = [2]
            point, seen = None, case == "in_mirror_shown"
        runner.engine.reflection_system.path = path
        runner.engine.reflection_system.visibility = "exact"
        rgb = runner.frame()
        assert runner.stats.reflection_path == path
        ids = runner.ids()
        if point is None:
            expected = mirror_then_portal_rays(runner, ents, -0.05)
            assert expected.sum() > 60
            shown = ids[expected]
        else:
            col, row = runner.project(point)
            shown = ids[row, col]
        assert (shown == ents["vampire"] if seen else shown == ents["backdrop"]).all(), (path, np.unique(shown))
        results[path] = (ids, rgb.astype(int), [(v.level, v.surface.entity, v.view.mirrored)
                                                for v in runner.engine.reflection_system.views[1:]])
    (ids, rgb, views), (batched_ids, batched_rgb, batched_views) = results["per_mirror"], results["batched"]
    assert views == batched_views and len(views) >= 1
    np.testing.assert_array_equal(batched_ids, ids)
    assert np.abs(batched_rgb - rgb).max() <= 2


FRONT_Z, BACK_Z = -1.5, 1.5   # two facing mirrors, 4 x 3 m, centred at y = 1.5
CORRIDOR_SIZE = (160, 120)
CORRIDOR_BOX = (np.array([-0.6, 1.2, 0.0]), np.full(3, 0.35))


def corridor(ents, visibility=None, front=None, back=None):
    """Two facing mirrors (the front one at z = -1.5 facing +Z, the back one at z = 1.5
    facing it), each to depth 3 without end images, and a red glowing box between them: the
    camera, near the back mirror, sees the box directly and in the front mirror at levels 1
    (front), 2 (back seen in front) and 3 (front seen in back seen in front)."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        look_from(world, (0.7, 1.6, 1.2), target=(-0.3, 1.4, FRONT_Z), fov=55.0)
        for name, z, turn, layers in (("front", FRONT_Z, glm.quat(), front), ("back", BACK_Z, HALF_TURN, back)):
            ents[name] = world.spawn(Transform(position=(0, 1.5, z), rotation=turn), MeshRef(quad(4, 3)),
                                     Material(color=(0.1, 0.1, 0.1)),
                                     Mirror(max_depth=3, end_image=False, hides_layers=layers or ()))
        parts = [Transform(position=tuple(CORRIDOR_BOX[0]), scale=tuple(2.0 * CORRIDOR_BOX[1])), MeshRef(box()),
                 Material(color=(0.9, 0.05, 0.05)), Emissive(0.8)]
        ents["box"] = world.spawn(*parts, *([visibility] if visibility is not None else []))
    return build


def corridor_levels(runner, drawn, grow) -> np.ndarray:
    """The level (0 to 3) at which each pixel's ray meets the box grown by ``grow``, -1 where
    it never does, in float64 (no renderer): each ray bounced between the two mirrors'
    rectangles (z flipped at each), at most three times, meeting the box at level n only where
    ``drawn(n)`` says it is drawn there and it lies before the next mirror."""
    eye, rays = pixel_rays(runner.engine.main_view, CORRIDOR_SIZE)
    direction = rays.reshape(-1, 3).copy()
    origin = np.broadcast_to(eye, direction.shape).copy()
    found = np.full(len(direction), -1)
    alive = np.ones(len(direction), bool)
    centre, half = CORRIDOR_BOX
    for level in range(4):
        t = (np.where(direction[:, 2] < 0, FRONT_Z, BACK_Z) - origin[:, 2]) / direction[:, 2]
        at = origin + t[:, None] * direction
        on_glass = (t > 1e-6) & (np.abs(at[:, 0]) < 2.0) & (np.abs(at[:, 1] - 1.5) < 1.5)
        if drawn(level):
            hit = box_hits(origin, direction, centre, half + grow, np.where(on_glass, t, np.inf))
            found[alive & hit] = level
            alive &= ~hit
        alive &= on_glass & (level < 3)  # past level 3 the front mirror shows its fallback
        origin = np.where(alive[:, None], at, origin)
        direction = np.where(alive[:, None], direction * (1.0, 1.0, -1.0), direction)
    return found.reshape(CORRIDOR_SIZE[1], CORRIDOR_SIZE[0])


@pytest.mark.parametrize("visibility, front, back, levels", [
    (None, None, None, {0, 1, 2, 3}), (Visibility(in_mirrors=False), None, None, {0}),
    (Visibility(direct=False), None, None, {1, 2, 3}), (Visibility(in_portals=False), None, None, {0, 1, 2, 3}),
    (Visibility(layers=[3]), None, [3], {0, 1}), (Visibility(layers=[3]), [3], None, {0}),
    (Visibility(layers=[3, 5]), [5], [3], {0, 1})],
    ids=["shown", "in_mirrors", "ghost", "in_portals", "back_hides", "front_hides", "each_hides_one_of_two"])
def test_hide_rules_hold_three_mirrors_deep_on_both_paths(scene, visibility, front, back, levels):
    """A mirror in a mirror in a mirror: the box's pixels at each level are cast in float64
    (rays bounced between the two mirrors), and at the levels the rule draws it (kinds: a
    mirror view from level 1 on; layers: those every mirror of the chain shows, so the back
    mirror hiding a layer takes the box out of levels 2 and 3, not 1) each of them is the box,
    on the per-mirror path and the batched one alike; no pixel outside them (a margin out)
    is.  The two paths draw the same ids, and colours within 2."""
    results = {}
    for path in ("per_mirror", "batched"):
        ents = {}
        runner = scene(corridor(ents, visibility, front, back), CORRIDOR_SIZE)
        runner.engine.reflection_system.path = path
        runner.engine.reflection_system.visibility = "exact"
        rgb = runner.frame()
        assert runner.stats.reflection_path == path
        views = [(v.level, v.surface.entity) for v in runner.engine.reflection_system.views[1:]]
        assert views == [(1, ents["front"]), (2, ents["back"]), (3, ents["front"])]
        ids = runner.ids()
        inside = corridor_levels(runner, lambda level: level in levels, -0.03)
        outside = corridor_levels(runner, lambda level: level in levels, 0.03) < 0
        everywhere = corridor_levels(runner, lambda level: True, -0.03)
        for level in range(4):
            assert (everywhere == level).sum() > 30  # the box is there to be seen at every level
            if level in levels:
                assert (inside == level).sum() > 30
                assert (ids[inside == level] == ents["box"]).all(), (path, level)
                red = srgb_to_linear(rgb[inside == level])
                assert (red[:, 0] > 3 * red[:, 2]).all(), (path, level)
        assert not (ids[outside] == ents["box"]).any(), (path, np.unique(everywhere[outside & (ids == ents["box"])]))
        results[path] = ids, rgb.astype(int)
    (ids, rgb), (batched_ids, batched_rgb) = results["per_mirror"], results["batched"]
    np.testing.assert_array_equal(batched_ids, ids)
    assert np.abs(batched_rgb - rgb).max() <= 2


# Four boxes before B, each seen only in the mirror through A (level 2: a mirror's and a
# portal's view at once), and one behind the camera seen in the mirror alone (level 1).
CROWD_HALF = np.full(3, 0.25)
CROWD = {"plain": ((19.4, 1.0, 2.0), None), "in_mirrors": ((20.6, 1.0, 2.0), Visibility(in_mirrors=False)),
         "in_portals": ((19.4, 1.9, 2.0), Visibility(in_portals=False)),
         "ghost": ((20.6, 1.9, 2.0), Visibility(direct=False)),
         "near": ((-2.0, 1.0, 1.8), Visibility(in_portals=False))}


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_one_level_two_view_leaves_out_both_what_is_hidden_in_mirrors_and_what_is_hidden_in_portals(scene, path):
    """The mirror-then-portal chain with five boxes at once: through the portal seen in the
    mirror (level 2) the box hidden in mirrors and the box hidden in portals are both left out
    (the backdrop behind each is there instead), while a plain box and one hidden only
    directly are drawn; a box hidden in portals standing behind the camera is drawn in the
    mirror (level 1, a mirror view only).  Each box's pixels are cast in float64 (rays
    reflected in the mirror, and for the four, carried through the pair: a margin in), on
    either path; no pixel outside them (a margin out) is a box."""
    ents = {}

    def build(world):
        mirror_then_portal(ents)(world)
        world.delete_entity(ents["vampire"])  # the chain's own box: the crowd stands in its place
        for name, (centre, visibility) in CROWD.items():
            ents[name] = world.spawn(Transform(position=centre, scale=tuple(2.0 * CROWD_HALF)), MeshRef(box()),
                                     Material(color=(0.9, 0.05, 0.05)), Emissive(0.8),
                                     *([visibility] if visibility is not None else []))
    runner = scene(build, CHAIN_SIZE)
    runner.engine.reflection_system.path = path
    runner.engine.reflection_system.visibility = "exact"
    rgb = runner.frame()
    assert runner.stats.reflection_path == path
    assert [(v.level, v.surface.entity) for v in runner.engine.reflection_system.views[1:]] == \
        [(1, ents["mirror"]), (2, ents["a"])]
    ids = runner.ids()
    assert not (ids == ents["vampire"]).any()
    eye, rays = pixel_rays(runner.engine.main_view, CHAIN_SIZE)
    flip = np.array([1.0, 1.0, -1.0])
    t = (-1.5 - eye[2]) / rays[..., 2]
    at = eye + t[..., None] * rays
    on_mirror = (t > 0) & (np.abs(at[..., 0]) < 2.0) & (np.abs(at[..., 1] - 1.5) < 1.5)

    def near_hits(grow):  # reflected in z = -1.5, cast at the box behind the camera
        hits = box_hits(np.broadcast_to(eye * flip + (0.0, 0.0, -3.0), (rays.size // 3, 3)),
                        (rays * flip).reshape(-1, 3), np.array(CROWD["near"][0]), CROWD_HALF + grow)
        return on_mirror & hits.reshape(on_mirror.shape)

    any_box = np.zeros_like(on_mirror)
    for name, (centre, _) in CROWD.items():
        if name == "near":
            inside, grown = near_hits(-0.03), near_hits(0.03)
        else:
            inside, grown = (mirror_then_portal_rays(runner, ents, grow, (np.array(centre), CROWD_HALF))
                             for grow in (-0.03, 0.03))
        any_box |= grown
        assert inside.sum() > 15, name
        if name in ("in_mirrors", "in_portals"):
            assert (ids[inside] == ents["backdrop"]).all(), (name, np.unique(ids[inside]))
            blue = srgb_to_linear(rgb[inside])
            assert (blue[:, 2] > 2 * blue[:, 0]).all(), name
        else:
            assert (ids[inside] == ents[name]).all(), (name, np.unique(ids[inside]))
            red = srgb_to_linear(rgb[inside])
            assert (red[:, 0] > 2 * red[:, 2]).all(), name
    assert not np.isin(ids[~any_box], [ents[name] for name in CROWD]).any()
