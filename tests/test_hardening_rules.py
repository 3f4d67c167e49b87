"""Hardening, round 3 (issue 41): rules checked when the value is given, not frames later
(item 2), and what a game maker reads when something is wrong (item 6).  Each refusal is
one ``speculum: error:`` line (exit 2) from the command line, or an error at the line of
code that makes the mistake; each silent mistake is one warning."""
from __future__ import annotations

import dataclasses
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from components import (
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    Portal,
    Skybox,
    Transform,
    Water,
)
from components.tracking import TrackedComponent
from engine.assets.level_file import LevelError, LevelGame, load_level
from engine.assets.mesh import plane, quad
from engine.core.game import Game, GameSystem, ScheduleError
from engine.core.world import World
from engine.resources import ViewBudget
from shell.runner import main
from tests.support import look_from

HEADLESS = ["--headless", "--frames", "1", "--size", "8x8"]


@pytest.fixture
def world():
    made = World("hardening rules")
    try:
        yield made
    finally:
        made.close()


def _pond(**mirror) -> tuple:
    return Transform(), MeshRef(quad(2.0, 2.0)), Material(color=(0.1, 0.2, 0.3, 0.5)), Mirror(**mirror)


# --- item 2: Water's rules at spawn and at every write --------------------------------------

def test_water_without_a_mirror_is_refused_at_spawn_in_any_order_and_nothing_is_made(world):
    before = set(world.entities())
    with pytest.raises(ComponentValueError, match=r"Water on entity \d+: a Water needs a Mirror"):
        world.spawn(Transform(), MeshRef(quad()), Material(), Water())
    assert not list(world.query_one(Water)) and set(world.entities()) == before
    # The Mirror may come before or after the Water in the spawn's list.
    world.spawn(Water(), *_pond())
    world.spawn(*_pond(), Water())
    assert len(list(world.query_one(Water))) == 2


def test_water_added_to_an_entity_without_a_mirror_is_refused_at_that_call(world):
    entity = world.spawn(Transform(), MeshRef(quad()), Material())
    with pytest.raises(ComponentValueError, match="a Water needs a Mirror"):
        world.add_component(entity, Water())
    assert not world.has(entity, Water)
    world.add_component(entity, Mirror())
    world.add_component(entity, Water())
    assert world.has(entity, Water)


def test_a_mirror_and_a_portal_on_one_entity_are_refused_in_either_order_and_nothing_is_made(world):
    """Each makes the surface's pixels show a view of its own: which one showed was left to
    the order the systems met them in."""
    before = set(world.entities())
    for parts in ((Mirror(), Portal()), (Portal(), Mirror())):
        joining = type(parts[1]).__name__
        with pytest.raises(ComponentValueError, match=rf"entity \d+: a {joining} on an entity with a "
                                                      f"{type(parts[0]).__name__}: its pixels show one view"):
            world.spawn(Transform(), MeshRef(quad()), Material(), *parts)
        assert set(world.entities()) == before
    mirror = world.spawn(Transform(), MeshRef(quad()), Material(), Mirror())
    with pytest.raises(ComponentValueError, match="a Portal on an entity with a Mirror"):
        world.add_component(mirror, Portal())
    assert not world.has(mirror, Portal)
    world.remove_component(mirror, Mirror)
    world.add_component(mirror, Portal())   # (a surface may change from one to the other)
    assert world.has(mirror, Portal)


def test_a_second_skybox_is_refused_naming_the_first_and_after_it_goes_one_is_taken(world):
    first = world.spawn(Skybox())
    before = set(world.entities())
    with pytest.raises(ComponentValueError, match=rf"Skybox on entity \d+: entity {first} holds the world's Skybox "
                                                  "already, and a world has one sky"):
        world.spawn(Skybox(face_size=16))
    assert set(world.entities()) == before
    other = world.spawn(Transform())
    with pytest.raises(ComponentValueError, match=f"entity {first} holds the world's Skybox"):
        world.add_component(other, Skybox())
    world.add_component(first, Skybox(face_size=16))   # (its own sky replaced: still one)
    world.delete_entity(first)
    world.step(0.0)
    world.add_component(other, Skybox())
    assert [entity for entity, _ in world.query_one(Skybox)] == [other]


def test_a_rough_mirror_and_water_are_refused_together_at_spawn_join_and_write(world):
    with pytest.raises(ComponentValueError, match=r"Mirror.roughness on entity \d+ must be 0 with a Water"):
        world.spawn(*_pond(roughness=0.2), Water())
    with pytest.raises(ComponentValueError, match="must be 0 with a Water"):
        world.spawn(Water(), *_pond(roughness=0.2))
    rough = world.spawn(*_pond(roughness=0.3))
    with pytest.raises(ComponentValueError, match="must be 0 with a Water"):
        world.add_component(rough, Water())
    pond = world.spawn(*_pond(), Water())
    mirror = world.get(pond, Mirror)
    with pytest.raises(ComponentValueError, match=f"Mirror.roughness on entity {pond} must be 0 with a Water"):
        mirror.roughness = 0.1  # the write itself, not a MirrorError every frame after
    assert mirror.roughness == 0.0
    with pytest.raises(ComponentValueError, match="must be 0 with a Water"):
        world.add_component(pond, Mirror(roughness=0.5))  # a replacement Mirror, too
    # A mirror without water may be rough; a shared Mirror is checked for every holder.
    world.get(rough, Mirror).roughness = 0.6
    shared = Mirror()
    world.spawn(*_pond()[:3], shared)
    world.spawn(*_pond()[:3], shared, Water())
    with pytest.raises(ComponentValueError, match="must be 0 with a Water"):
        shared.roughness = 0.2


def test_water_whose_mirror_is_taken_off_waits_with_a_warning_and_never_stops_a_frame(scene):
    ents = {}

    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.3)))
        look_from(world, (0.0, 2.0, 3.0), target=(0.0, 0.0, 0.0))
        world.spawn(Transform(position=(0.0, -0.2, 0.0)), MeshRef(plane(6, 6)), Material(color=(0.8, 0.6, 0.2)))
        ents["pond"] = world.spawn(Transform(rotation=_flat()), MeshRef(quad(2.0, 2.0)),
                                   Material(color=(0.1, 0.2, 0.3, 0.5)), Mirror(), Water())
    runner = scene(build, (32, 24))
    runner.frame()
    world = runner.world
    world.remove_component(ents["pond"], Mirror)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        world.get(ents["pond"], Water).speed = 0.2
        runner.frame()
        world.get(ents["pond"], Water).speed = 0.3
        rgb = runner.frame()
    said = [str(w.message) for w in caught if "Water has no Mirror" in str(w.message)]
    assert len(said) == 1 and f"entity {ents['pond']}" in said[0], said
    assert rgb.mean() > 3  # the lit floor, not a black frame


def _flat():
    from pyglm import glm
    return glm.angleAxis(-np.pi / 2, glm.vec3(1, 0, 0))


# --- item 2: Mirror fades refuse strings and booleans ---------------------------------------

@pytest.mark.parametrize("value", ["ab", "8", ("8", "14"), (True, 14.0), (0.0, False), 5, (1.0,), (1.0, 2.0, 3.0),
                                   {"start": 1, "end": 2}])
@pytest.mark.parametrize("name", ["fade_distance", "fade_angle"])
def test_fades_refuse_text_booleans_and_wrong_lengths_naming_the_field(name, value):
    with pytest.raises(ComponentValueError, match=f"Mirror.{name} must be None or two numbers"):
        Mirror(**{name: value})
    mirror = Mirror()
    with pytest.raises(ComponentValueError, match=f"Mirror.{name}"):
        setattr(mirror, name, value)
    assert getattr(mirror, name) is None


def test_fades_still_take_numbers_of_either_kind():
    mirror = Mirror(fade_distance=(8, 14.5), fade_angle=np.array([60.0, 85.0]))
    assert mirror.fade_distance == (8.0, 14.5) and mirror.fade_angle == (60.0, 85.0)


# --- item 2: game systems checked when the schedule is built --------------------------------

def _bounce(world, dt):
    pass


def _one_arg(world):
    pass


class _NoDt:
    def process(self):
        pass


class _SystemsGame(Game):
    title = "systems check"

    def __init__(self, systems):
        self._systems = systems

    def build(self, world: World) -> None:
        look_from(world, (0.0, 1.0, 3.0), target=(0.0, 0.0, 0.0))

    def systems(self):
        return self._systems() if callable(self._systems) else self._systems


@pytest.mark.parametrize("make, expected", [
    (lambda: [GameSystem(_bounce, after=3)], "GameSystem '_bounce': after must be a stage or game system name"),
    (lambda: [GameSystem(_bounce, before=("extract", None))], "GameSystem '_bounce': before must be"),
    (lambda: None, "returned None; return a list of GameSystem"),
    (lambda: GameSystem(_bounce), "return a list of GameSystem"),
    (lambda: [GameSystem(_one_arg)], "game system '_one_arg' cannot be called as function(world, dt)"),
    (lambda: [GameSystem(_NoDt())], "game system '_NoDt' cannot be called as process(dt)"),
], ids=["after-int", "before-none", "systems-none", "not-a-list", "one-argument", "process-without-dt"])
def test_game_systems_that_cannot_be_scheduled_or_called_are_one_error_line(make, expected, capsys, tmp_path):
    """Each was a TypeError traceback (at the Engine, or in the first frame that called the
    system); now a ScheduleError naming the system, before anything is made."""
    with pytest.raises(ScheduleError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        from engine.core.game import schedule_order
        schedule_order(["game", "extract"], make())
    assert main(_SystemsGame(make), [*HEADLESS, "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("speculum: error: ") and expected in lines[0], lines


def test_systems_that_take_more_optional_arguments_or_any_still_run(tmp_path):
    calls = []

    def optional(world, dt, scale=1.0):
        calls.append("optional")

    def anything(*args):
        calls.append("anything")

    game = _SystemsGame([GameSystem(optional), GameSystem(anything)])
    assert main(game, [*HEADLESS, "--out", str(tmp_path / "out")]) == 0
    assert calls == ["optional", "anything"]


# --- item 2: a game's own components in a level file, by their annotations ------------------

@dataclasses.dataclass(eq=False)
class Bounce(TrackedComponent):
    """A game's own component, as games write them: annotated plain data, no checks."""

    height: float = 1.0
    times: int = 0
    loud: bool = False
    label: str = ""
    span: tuple[float, float] = (0.0, 1.0)
    steps: list[int] = dataclasses.field(default_factory=list)


def _level(tmp_path: Path, body: str, name: str = "level.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body))
    return path


@pytest.mark.parametrize("field, value, kind", [
    ("height", '"high"', "a number"), ("height", "true", "a number"), ("times", "1.5", "an integer"),
    ("loud", "1", "true or false"), ("label", "3", "a string"), ("span", "[1.0, 2.0, 3.0]", "tuple[float, float]"),
    ("span", '[1.0, "x"]', "tuple[float, float]"), ("steps", "[1, 2.5]", "list[int]"), ("steps", "4", "list[int]")])
def test_a_games_own_component_field_of_the_wrong_kind_is_refused_naming_file_line_and_field(tmp_path, field, value,
                                                                                            kind):
    path = _level(tmp_path, f"""\
        [level]
        name = "bouncy"

        [[entity]]
        name = "ball"
        [entity.Bounce]
        {field} = {value}
        """)
    with pytest.raises(LevelError) as caught:
        load_level(path, {"Bounce": Bounce})
    text = str(caught.value)
    assert str(path) in text and ":7:" in text and f"Bounce.{field}" in text and kind in text, text


def test_a_games_own_component_of_the_right_kinds_loads(tmp_path):
    path = _level(tmp_path, """\
        [level]
        name = "bouncy"

        [[entity]]
        name = "ball"
        [entity.Bounce]
        height = 2
        times = 3
        loud = true
        label = "hop"
        span = [0.5, 1]
        steps = [1, 2]
        """)
    level = load_level(path, {"Bounce": Bounce})
    with World("bounce") as world:
        names = level.spawn(world)
        bounce = world.get(names["ball"], Bounce)
        assert (bounce.height, bounce.times, bounce.loud, bounce.label) == (2, 3, True, "hop")


class _BounceGame(LevelGame):
    title = "bouncy"
    game = "bouncy"
    components = {"Bounce": Bounce}
    makes_camera = True


def test_a_level_for_another_game_is_refused_as_such_before_its_components_are_read(tmp_path, capsys):
    """Its components are the other game's: before, the first one unknown here was the error."""
    path = _level(tmp_path, """\
        [level]
        name = "someone else's"
        game = "portal_run"

        [[entity]]
        name = "door"
        [entity.Doorway]
        width = "wide"
        """)
    with pytest.raises(LevelError, match="the level is for portal_run, not for bouncy") as caught:
        _BounceGame(path).load()
    assert ":3:" in str(caught.value)
    assert main(_BounceGame(path), [*HEADLESS, "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "not for bouncy" in lines[0] and "Doorway" not in lines[0], lines


# --- item 2: a wrong ViewBudget is one error line -------------------------------------------

class _BudgetGame(Game):
    title = "budget"

    def __init__(self, budget):
        self.budget = budget

    def build(self, world: World) -> None:
        look_from(world, (0.0, 1.0, 3.0), target=(0.0, 0.0, 0.0))
        world.resources[ViewBudget] = self.budget() if callable(self.budget) and self.budget is not ViewBudget \
            else self.budget


@pytest.mark.parametrize("budget, expected", [
    (ViewBudget, "holds the class ViewBudget, not a budget: make one, e.g. ViewBudget(views=24)"),
    ({"views": 4}, "must be a ViewBudget(views=..., pixels=..., probe_ms=..., min_pixels=..., frame_ms=...), got dict"),
    (lambda: ViewBudget(views=-2), "ViewBudget.views must be None or an int >= 0, got -2"),
    (lambda: ViewBudget(probe_ms="2"), "ViewBudget.probe_ms must be None or a finite number > 0, got '2'"),
], ids=["class", "dict", "negative-views", "text-probe-ms"])
def test_a_wrong_view_budget_is_one_error_line(budget, expected, tmp_path, capsys):
    assert main(_BudgetGame(budget), [*HEADLESS, "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("speculum: error: ") and expected in lines[0], lines


# --- item 6: silent mistakes get a warning ---------------------------------------------------

def _warned(make) -> list[str]:
    from components import ComponentWarning
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        make()
    return [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]


def test_glass_on_an_opaque_material_is_said_as_either_joins_and_see_through_glass_is_not():
    """A Refractive whose Material has alpha 1 (the default) shows the material's colour over
    all of it (the bent light is blended by the alpha): said, naming the entity, when the
    Refractive joins the Material's entity, when the Material joins the Refractive's, and at
    spawn; glass of alpha under 1, an albedo texture (its alpha may open it) or a cutout is not."""
    from components import Refractive
    from engine.assets.texture_data import TextureData

    world = World()
    said = _warned(lambda: world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Material(), Refractive()))
    assert len(said) == 1 and "Refractive on entity" in said[0] and "alpha is 1" in said[0], said
    plain = world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Material(color=(1.0, 1.0, 1.0, 1.0)))
    said = _warned(lambda: world.add_component(plain, Refractive(ior=1.3)))
    assert len(said) == 1 and f"entity {plain}:" in said[0], said
    glass = world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Refractive())
    said = _warned(lambda: world.add_component(glass, Material(color=(0.9, 0.9, 0.9))))
    assert len(said) == 1 and f"entity {glass}:" in said[0], said
    texels = TextureData(np.full((2, 2, 4), 255, np.uint8), name="white")
    for material in (Material(color=(1.0, 1.0, 1.0, 0.0)), Material(color=(0.2, 0.9, 0.3, 0.5)),
                     Material(texture=texels), Material(alpha_cutoff=0.5)):
        assert _warned(lambda material=material: world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), material,
                                                             Refractive())) == []
    world.close()


def test_a_cameras_component_on_an_entity_without_a_camera_is_said_once_and_on_a_camera_is_not():
    """Every component a camera reads from its own entity (``CAMERA_COMPONENTS``: the screen
    passes, fog, the post chain) spawned on an entity without a Camera is said once, naming
    them all and the entity; one joining such an entity later is said; on a camera's entity,
    spawned beside the Camera or joining it, nothing is said."""
    from components import AmbientOcclusion, Bloom, Camera, Fog
    from engine.rules.camera_rules import CAMERA_COMPONENTS

    world = World()
    for kind in CAMERA_COMPONENTS:
        said = _warned(lambda kind=kind: world.spawn(Transform(), kind()))
        assert len(said) == 1 and f"{kind.__name__} on entity" in said[0] and "has no Camera" in said[0], said
    said = _warned(lambda: world.spawn(Transform(), Bloom(), AmbientOcclusion()))
    assert len(said) == 1 and "AmbientOcclusion, Bloom on entity" in said[0], said
    crate = world.spawn(Transform(), MeshRef(quad(1.0, 1.0)))
    assert _warned(lambda: world.add_component(crate, Fog())) == [f"Fog on entity {crate}, which has no Camera: a "
                                                                   "camera reads it from its own entity, so here it "
                                                                   "does nothing; put it on the camera's entity"]
    camera = None

    def on_a_camera():
        nonlocal camera
        camera = world.spawn(Bloom(), Transform(), Camera(), AmbientOcclusion())   # (the Camera after one)
        world.add_component(camera, Fog())
    assert _warned(on_a_camera) == []
    world.close()


def test_colours_written_0_to_255_are_warned_and_colours_in_0_to_1_or_bright_floats_are_not():
    from components import PointLight
    said = _warned(lambda: Material(color=(255, 128, 0)))
    assert len(said) == 1 and "Material.color = (255, 128, 0) looks like 0-255" in said[0]
    assert "(1, 0.502, 0)" in said[0]
    assert len(_warned(lambda: PointLight(color=[200, 200, 200]))) == 1
    for fine in ((1, 1, 1), (0, 0, 1), (0.5, 0.2, 0.1), (3.0, 3.0, 3.0), (255.0, 0.0, 0.0)):
        assert _warned(lambda fine=fine: Material(color=fine)) == [], fine


def test_an_entity_hidden_in_every_kind_of_view_is_warned_at_the_line_that_hides_it():
    from components import Visibility
    said = _warned(lambda: Visibility(direct=False, in_mirrors=False, in_portals=False, in_probes=False))
    assert len(said) == 1 and "drawn nowhere" in said[0]
    ghost = Visibility(direct=False, in_portals=False, in_probes=False)  # seen only in mirrors: fine
    assert _warned(lambda: setattr(ghost, "in_probes", False)) == []
    said = _warned(lambda: setattr(ghost, "in_mirrors", False))
    assert len(said) == 1 and "drawn nowhere" in said[0]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        Visibility(direct=False, in_mirrors=False, in_portals=False, in_probes=False)
    assert caught[0].filename == __file__  # the warning points at the game's line, not the component's


def test_a_view_that_shows_no_layer_is_warned():
    from components import Camera, Portal
    for make in (lambda: Camera(shows_layers=[]), lambda: Mirror(shows_layers=()), lambda: Portal(shows_layers=[])):
        said = _warned(make)
        assert len(said) == 1 and "shows no layer" in said[0], said
    assert _warned(lambda: Camera(shows_layers=None)) == _warned(lambda: Camera(shows_layers=[0])) == []


def test_a_view_whose_hidden_layers_cover_every_layer_it_shows_is_warned_as_either_is_given():
    """shows_layers less hides_layers empty draws nothing, as shows_layers=[] does: said once
    when the second of the two is given, at construction or written later, naming both; a
    hidden layer among others shown, or hides_layers alone, is not said."""
    from components import Camera, Portal
    for make in (lambda: Camera(shows_layers=[1], hides_layers=[1]), lambda: Mirror(shows_layers=(2, 3),
                 hides_layers=[3, 2]), lambda: Portal(shows_layers=[5], hides_layers=[4, 5])):
        said = _warned(make)
        assert len(said) == 1 and "hides every layer" in said[0] and "view draws nothing" in said[0], said
    camera = Camera(shows_layers=[1])
    said = _warned(lambda: setattr(camera, "hides_layers", [1]))
    assert len(said) == 1 and "Camera.hides_layers = [1]" in said[0] and "shows_layers = [1]" in said[0], said
    mirror = Mirror(hides_layers=[1])
    said = _warned(lambda: setattr(mirror, "shows_layers", [1]))
    assert len(said) == 1 and "Mirror.hides_layers = [1]" in said[0], said
    assert _warned(lambda: Camera(shows_layers=[1, 2], hides_layers=[1])) == []
    assert _warned(lambda: Mirror(hides_layers=[0, 3])) == []
    assert _warned(lambda: Camera(shows_layers=[], hides_layers=[1])) == [w for w in _warned(
        lambda: Camera(shows_layers=[])) if "shows no layer" in w]   # (said once, as shows_layers=[])


def test_water_with_no_normal_map_is_warned_once_at_spawn(world):
    from engine.assets.texture_data import ripple_normal_map
    said = _warned(lambda: world.spawn(*_pond(), Water()))
    assert len(said) == 1 and "no normal_map, so the water has no waves" in said[0]
    waves = Material(color=(0.1, 0.2, 0.3, 0.5), normal_map=ripple_normal_map(32))
    assert _warned(lambda: world.spawn(Transform(), MeshRef(quad(2.0, 2.0)), waves, Mirror(), Water())) == []


def test_a_blend_distance_without_an_influence_box_is_warned_when_the_probe_comes(scene):
    from components import ReflectionProbe, Reflective
    from engine.assets.mesh import sphere

    def build(world):
        look_from(world, (0.0, 1.0, 3.0), target=(0.0, 0.0, 0.0))
        world.spawn(Transform(), MeshRef(sphere(0.5)), Material(metallic=1.0), Reflective("cube"),
                    ReflectionProbe(resolution=16, blend_distance=0.5))
        world.spawn(Transform(position=(2.0, 0.0, 0.0)), MeshRef(sphere(0.5)), Material(metallic=1.0),
                    Reflective("cube"), ReflectionProbe(resolution=16, influence=(4, 4, 4), blend_distance=0.5))
    runner = scene(build, (16, 16))
    said = _warned(runner.frame)
    assert len(said) == 1 and "blend_distance = 0.5 does nothing without an influence box" in said[0], said
    assert _warned(runner.frame) == []  # said when it comes (or changes), not every frame


# --- item 6: the command line and the window ------------------------------------------------

def test_camera_takes_a_negative_first_value_without_an_equals_sign(tmp_path):
    from games.hall_of_mirrors.level import HallOfMirrors
    from shell.runner import parse_args
    args = parse_args(HallOfMirrors(), ["--headless", "--camera", "-4.5,1.6,3,-90,-5"])
    assert args.camera == (-4.5, 1.6, 3.0, -90.0, -5.0)
    assert parse_args(HallOfMirrors(), ["--camera", "-.5,1,2,0,0"]).camera == (-0.5, 1.0, 2.0, 0.0, 0.0)
    assert parse_args(HallOfMirrors(), ["--camera=-1,1,2,0,0"]).camera[0] == -1.0


TITLE_SCRIPT = r'''
import moderngl_window as mglw
from engine import Game
from shell.window import make_window_config
from tests.support import look_from

class Renamed(Game):
    title = "first level"
    frames = 0
    def build(self, world):
        look_from(world, (0, 1, 3), target=(0, 0, 0))
    def update(self, world, dt):
        self.frames += 1
        if self.frames == 2:
            self.title = "second level"

config = mglw.create_window_config_instance(make_window_config(Renamed()),
                                            args=["--window", "headless", "--backend", "egl", "--size", "16x16"])
titles = [config.wnd.title]
for _ in range(3):
    config.on_render(0.0, 1 / 60)
    titles.append(config.wnd.title)
print(titles)
config.on_close()
config.wnd.destroy()
'''


def test_the_window_title_follows_the_games_title_when_it_changes_level():
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, "-c", TITLE_SCRIPT], cwd=root, capture_output=True, text=True, timeout=120,
                          env={**__import__("os").environ, "PYTHONPATH": str(root)})
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == str(["first level", "first level", "second level",
                                                       "second level"])


def test_mirror_beams_title_names_the_level_it_plays_after_n(world):
    from games.mirror_beam import MirrorBeam
    game = MirrorBeam()
    game.build(world)
    first = game.level.name
    assert game.title == f"Speculum: mirror beam: {first}"
    game.play_level(world, game.next_level())
    assert game.level.name != first and game.title == f"Speculum: mirror beam: {game.level.name}"


# --- item 6: save_level writes spawn_model's model, or says plainly why not ------------------

def _two_part_glb(path: Path, textured: bool = False) -> Path:
    import trimesh
    from PIL import Image
    first, second = trimesh.creation.box(), trimesh.creation.icosphere(subdivisions=1)
    if textured:
        image = Image.fromarray(np.full((4, 4, 3), (200, 30, 30), np.uint8))
        first.visual = trimesh.visual.TextureVisuals(uv=np.zeros((len(first.vertices), 2)), image=image)
    scene = trimesh.Scene()
    scene.add_geometry(first, node_name="crate")
    scene.add_geometry(second, node_name="ball", transform=trimesh.transformations.translation_matrix([2, 0, 0]))
    scene.export(path)
    return path


def test_a_spawned_model_is_saved_as_its_file_and_loads_back_the_same(tmp_path):
    """spawn_model's root holds the file's Model: a level file writes it (not its parts) and
    makes the same parts, placed the same, when it loads."""
    from engine.assets.level_file import save_level
    from engine.assets.models import spawn_model
    model = _two_part_glb(tmp_path / "two.glb")
    with World("model") as first:
        root = spawn_model(first, model, position=(1.0, 0.0, -2.0))
        saved = save_level(first, tmp_path / "saved.toml", {"model": root})
        text = saved.read_text()
        assert 'file = "two.glb"' in text and "part = " not in text and text.count("[[entity]]") == 1, text
        before = sorted((len(mesh_ref.mesh.positions), tuple(np.round(transform.position, 5)))
                        for _, (mesh_ref, transform) in first.query(MeshRef, Transform))
    with World("again") as second:
        names = load_level(saved).spawn(second)
        assert second.get(names["model"], Transform).position == first_position()
        after = sorted((len(mesh_ref.mesh.positions), tuple(np.round(transform.position, 5)))
                       for _, (mesh_ref, transform) in second.query(MeshRef, Transform))
    assert after == before and len(after) == 2


def first_position():
    from pyglm import glm
    return glm.vec3(1.0, 0.0, -2.0)


def test_a_models_embedded_image_given_to_another_entity_is_refused_plainly_by_save_level(tmp_path):
    """A model's parts are saved as its file; an image decoded from inside the file, given to
    an entity of the level's own, has no file a level could name: refused, saying so."""
    from engine.assets.level_file import save_level
    from engine.assets.mesh import box
    from engine.assets.models import spawn_model
    model = _two_part_glb(tmp_path / "painted.glb", textured=True)
    with World("painted") as world:
        root = spawn_model(world, model)
        painted = next(m.texture for _, m in world.query_one(Material) if m.texture is not None)
        save_level(world, tmp_path / "model_only.toml", {"model": root})   # the model alone: its file
        world.spawn(Transform(), MeshRef(box()), Material(texture=painted))
        with pytest.raises(LevelError, match=r"Material.texture.*is an image inside the model file .*painted.glb"):
            save_level(world, tmp_path / "painted.toml")


# --- item 6: benchmark help and reports ------------------------------------------------------

def test_benchmark_help_names_targets_without_issue_numbers_and_gpu_report_says_it_runs_the_suite():
    import re
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[1]
    for args in (["--help"], ["cpu", "--help"], ["lighting", "--help"], ["gpu-report", "--help"]):
        done = subprocess.run([sys.executable, "-m", "benchmarks", *args], cwd=root, capture_output=True, text=True,
                              timeout=120)
        assert done.returncode == 0, done.stderr
        assert not re.search(r"issue \d", done.stdout.lower()), done.stdout
    from benchmarks import SUITES
    assert "whole test suite" in SUITES["gpu-report"][1] and "minutes" in SUITES["gpu-report"][1]
    for module in ("benchmarks.cpu", "benchmarks.lighting", "benchmarks.gpu_report"):
        text = __import__(module, fromlist=["x"]).__doc__
        assert not re.search(r"issue \d", text.lower()), module


def test_gpu_report_fails_when_a_target_that_applies_here_is_not_met():
    from benchmarks.gpu_report import FIXED, failed
    rows = [{"target": "ecs_cpu_ms", "value": 12.5, "limit": 10.0, "unit": "ms", "met": False, "applies": True,
             "set_for": "this machine"},
            {"target": "frame_0_mirrors", "value": 3.0, "limit": 0.85, "unit": "ms", "met": False, "applies": False,
             "set_for": "gpu"},
            {"target": "plan_us_per_view", "value": 4.0, "limit": 10.0, "unit": "us", "met": True, "applies": True,
             "set_for": "this machine"}]
    report = {"benchmarks": {"cpu": {FIXED: {"status": "ok", "rows": rows}}}}
    assert failed(report) == ["target ecs_cpu_ms not met: 12.5 ms over 10.0"]
    rows[0]["met"] = True
    assert failed(report) == []


# --- item 7: the in-place edit trap ----------------------------------------------------------

def _crate_room(ents, x=0.0):
    from engine.assets.mesh import box

    def build(world):
        world.spawn(DirectionalLight(direction=(0.3, -1.0, -0.5), intensity=2.0))
        look_from(world, (0.0, 1.0, 5.0), target=(0.0, 1.0, 0.0), fov=50.0)
        ents["crate"] = world.spawn(Transform(position=(x, 0.5, 0.0)), MeshRef(box()),
                                    Material(color=(0.9, 0.2, 0.1)))
    return build


def _runner(ctx, build, update=None, size=(64, 48)):
    from tests.support import SceneRunner
    return SceneRunner(ctx, build, size, update)


def test_a_position_edited_in_place_in_update_is_drawn_that_frame_as_an_assigned_one_is(ctx):
    """``t.position.y += 1`` in the game's update: no field write, but the transform stage
    sees it (the in-place watch), so the frame shows the crate where an assignment would
    have put it: the same pixels and ids as a second world whose crate was assigned there."""
    ents, other = {}, {}

    def lift(world, dt):
        world.get(ents["crate"], Transform).position.y += 0.5

    def assign(world, dt):
        transform = world.get(other["crate"], Transform)
        transform.position = transform.position + glm_vec3(0.0, 0.5, 0.0)

    edited, assigned = _runner(ctx, _crate_room(ents), lift), _runner(ctx, _crate_room(other), assign)
    try:
        for frame in range(3):
            seen, expected = edited.frame(), assigned.frame()
            crate = edited.world.get(ents["crate"], Transform)
            assert crate.position.y == 0.5 + 0.5 * (frame + 1)
            assert crate.world[3].y == crate.position.y  # the world matrix followed the edit
            np.testing.assert_array_equal(seen, expected, err_msg=f"frame {frame}")
            np.testing.assert_array_equal(edited.ids() == ents["crate"], assigned.ids() == other["crate"])
        assert (edited.ids() == ents["crate"]).sum() > 20  # on screen: the crate, not an empty frame
    finally:
        edited.close()
        assigned.close()


def glm_vec3(*values):
    from pyglm import glm
    return glm.vec3(*values)


def test_a_colour_edited_in_place_between_frames_is_drawn_the_next_frame(ctx):
    ents = {}
    runner = _runner(ctx, _crate_room(ents))
    try:
        runner.frame()
        at = runner.ids() == ents["crate"]
        red = runner.frame()[at].mean(axis=0)
        assert red[0] > 2 * red[2]
        runner.world.get(ents["crate"], Material).color.b = 0.9  # in place, after the frame
        runner.world.get(ents["crate"], Material).color.x = 0.1
        blue = runner.frame()[at].mean(axis=0)
        assert blue[2] > 2 * blue[0], (red, blue)
    finally:
        runner.close()


@pytest.mark.parametrize("mend", ["replace", "delete"])
def test_a_bad_in_place_edit_is_refused_until_what_held_it_is_replaced_or_deleted(ctx, mend):
    """A NaN put in ``material.color.x`` is refused at the next frame's transform stage,
    naming the field, and at every frame after while the world holds it; a game that then
    replaces the Material (or deletes the crate) has mended its world: the next frame renders
    (the new colour on the crate, or no crate), not the same refusal again for a component
    the world no longer holds (found by ``benchmarks/still_fuzz.py``: a light edited in place
    with a NaN, then replaced, failed every frame after)."""
    from components import ComponentValueError

    ents = {}
    runner = _runner(ctx, _crate_room(ents))
    try:
        runner.frame()
        bad = runner.world.get(ents["crate"], Material)
        bad.color.x = float("nan")
        for _ in range(2):
            with pytest.raises(ComponentValueError, match=r"in-place edit of Material\.color"):
                runner.frame()
        if mend == "replace":
            runner.world.add_component(ents["crate"], Material(color=(0.1, 0.2, 0.9)))
        else:
            runner.world.delete_entity(ents["crate"])
        rgb = runner.frame()
        assert runner.ctx.error == "GL_NO_ERROR"
        assert np.isfinite(np.frombuffer(runner.engine.renderer.targets.color.read(), np.float16)).all()
        at = runner.ids() == ents["crate"]
        if mend == "replace":
            blue = rgb[at].mean(axis=0)
            assert at.sum() > 20 and blue[2] > 2 * blue[0], blue
        else:
            assert not at.any()
        assert all(watched[0] is not bad for watched in runner.world._handed.values())  # let go
    finally:
        runner.close()


def test_a_vector_a_game_keeps_is_watched_while_it_keeps_it_and_dropped_after(ctx):
    """A game that keeps ``p = t.position`` and edits ``p.x`` every frame without reading the
    field again: still seen (the value is held elsewhere, so the watch keeps it); vectors
    read once and not kept leave the watch after the frame (it does not grow with reads)."""
    ents, kept = {}, {}

    def build(world):
        _crate_room(ents)(world)
        for index in range(50):
            world.spawn(Transform(position=(index, -5.0, 0.0)))

    def update(world, dt):
        if "done" in kept:
            return
        if "p" not in kept:
            kept["p"] = world.get(ents["crate"], Transform).position
        kept["p"].x += 0.25
        for _, transform in world.query_one(Transform):
            _ = transform.position  # read, not kept

    runner = _runner(ctx, build, update)
    try:
        for frame in range(3):
            runner.frame()
            assert runner.world.get(ents["crate"], Transform).world[3].x == 0.25 * (frame + 1)
        watched = runner.world._handed
        assert len(watched) == 1 and next(iter(watched.values()))[2] is kept["p"]
        kept.clear()
        kept["done"] = True
        runner.frame()
        assert not runner.world._handed
    finally:
        runner.close()


class _NanEdit(Game):
    title = "nan in place"

    def build(self, world: World) -> None:
        look_from(world, (0.0, 1.0, 3.0), target=(0.0, 0.0, 0.0))
        self.crate = world.spawn(Transform(), MeshRef(quad()), Material())

    def update(self, world: World, dt: float) -> None:
        world.get(self.crate, Transform).position.x = float("nan")


def test_a_value_edited_in_place_that_the_field_cannot_hold_is_one_error_line(tmp_path, capsys):
    assert main(_NanEdit(), [*HEADLESS, "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "Transform.position must be finite" in lines[0], lines
    assert "in-place edit of Transform.position" in lines[0], lines


# --- item 3: a level file sets the view budget -----------------------------------------------

def test_a_level_file_sets_the_view_budget_and_save_level_writes_it_back(tmp_path):
    from engine.assets.level_file import save_level
    path = _level(tmp_path, """\
        [level]
        name = "budgeted"
        view_budget = { views = 12, probe_ms = 2.5, min_pixels = 64, frame_ms = 8.0 }

        [[entity]]
        name = "floor"
        [entity.Transform]
        """)
    level = load_level(path)
    expected = ViewBudget(views=12, probe_ms=2.5, min_pixels=64, frame_ms=8.0)
    with World("budget") as world:
        names = level.spawn(world)
        assert world.resources[ViewBudget] == expected
        saved = save_level(world, tmp_path / "again.toml", names, name="budgeted")
    assert load_level(saved).view_budget == expected
    assert "min_render_scale" not in saved.read_text()   # (a default is left out)


@pytest.mark.parametrize("value, expected", [
    ("{ views = -1 }", "ViewBudget.views must be None or an int >= 0, got -1"),
    ("{ views = 2.5 }", "ViewBudget.views must be None or an int >= 0"),
    ("{ probe_ms = 0 }", "ViewBudget.probe_ms must be None or a finite number > 0"),
    ("{ min_pixels = 0 }", "ViewBudget.min_pixels must be None or an int >= 1, got 0"),
    ("{ view = 3 }", "view_budget has unknown keys ['view']"),
    ("12", "view_budget must be a table such as { views = 24 }"),
])
def test_a_bad_view_budget_in_a_level_is_refused_naming_file_and_line(tmp_path, value, expected):
    path = _level(tmp_path, f"""\
        [level]
        name = "budgeted"
        view_budget = {value}
        """)
    with pytest.raises(LevelError) as caught:
        load_level(path)
    assert f"{path}:3:" in str(caught.value) and expected in str(caught.value), str(caught.value)


# --- item 5: mirrored geometry ---------------------------------------------------------------

def _mirror_scene(ents, scale=(1.0, 1.0, 1.0), parent_scale=None, camera_parent=None):
    from engine.assets.mesh import box
    from engine.assets.texture_data import checker_texture

    def build(world):
        world.spawn(DirectionalLight(direction=(0.4, -1.0, -0.6), intensity=2.0))
        if camera_parent is None:
            look_from(world, (0.6, 1.6, 4.0), target=(0.0, 0.6, 0.0), fov=60.0)
        else:
            holder = world.spawn(Transform(scale=camera_parent))
            camera = look_from(world, (0.6, 1.6, 4.0), target=(0.0, 0.6, 0.0), fov=60.0)
            transform = world.get(camera, Transform)
            transform.position = transform.position * glm_vec3(*(1.0 / s for s in camera_parent))
            flip = glm_vec3(*camera_parent)
            transform.rotation = _mirrored_rotation(transform.rotation, flip)
            transform.parent = holder
        world.spawn(Transform(), MeshRef(plane(8, 8)), Material(texture=checker_texture(64, 8)))
        world.spawn(Transform(position=(0.0, 1.2, -2.5)), MeshRef(quad(3.0, 2.0)), Material(), Mirror())
        if parent_scale is None:
            ents["crate"] = world.spawn(Transform(position=(-0.8, 0.5, 0.0), scale=scale), MeshRef(box()),
                                        Material(color=(0.9, 0.3, 0.1)))
        else:
            holder = world.spawn(Transform(position=(-0.8, 0.5, 0.0), scale=parent_scale))
            ents["crate"] = world.spawn(Transform(scale=scale, parent=holder), MeshRef(box()),
                                        Material(color=(0.9, 0.3, 0.1)))
    return build


def _mirrored_rotation(rotation, flip):
    """The local rotation that, under a parent scaled by ``flip`` (+-1 each), points the
    camera's -Z and +Y where ``rotation`` alone does (the mirrored axes mapped back)."""
    from pyglm import glm
    forward, up = rotation * glm.vec3(0, 0, -1) * flip, rotation * glm.vec3(0, 1, 0) * flip
    right = glm.cross(forward, up)
    return glm.quat_cast(glm.mat3(right, up, -forward))


@pytest.mark.parametrize("scale, parent_scale", [((-1.0, 1.0, 1.0), None), ((1.0, -1.0, 1.0), None),
                                                  ((-1.0, -1.0, -1.0), None), ((1.0, 1.0, 1.0), (-1.0, 1.0, 1.0))],
                         ids=["x", "y", "xyz", "parent-x"])
def test_a_mirrored_box_is_drawn_as_the_same_box_unmirrored(scene, scale, parent_scale):
    """A box is its own mirror image: scaled by -1 along an axis (or under a parent that
    is) it must look exactly like the plain box, in the frame and in the mirror; culled
    with the wrong winding it showed its inside faces (or nothing)."""
    plain_ents, mirrored_ents = {}, {}
    plain = scene(_mirror_scene(plain_ents), (96, 72))
    mirrored = scene(_mirror_scene(mirrored_ents, scale, parent_scale), (96, 72))
    expected, shown = plain.frame(), mirrored.frame()
    crate = mirrored.ids() == mirrored_ents["crate"]
    assert crate.sum() > 100 and (plain.ids() == plain_ents["crate"]).sum() == crate.sum()
    np.testing.assert_allclose(shown.astype(int), expected.astype(int), atol=2)
    assert mirrored.stats.reflection_views >= 1


def test_a_box_that_turns_mirrored_by_moving_changes_batch_and_is_drawn_right(scene):
    ents, plain_ents = {}, {}
    runner = scene(_mirror_scene(ents), (96, 72))
    expected = scene(_mirror_scene(plain_ents), (96, 72)).frame()
    runner.frame()
    runner.world.get(ents["crate"], Transform).scale = (-1.0, 1.0, 1.0)
    np.testing.assert_allclose(runner.frame().astype(int), expected.astype(int), atol=2)
    runner.world.get(ents["crate"], Transform).scale = (1.0, 1.0, 1.0)
    np.testing.assert_allclose(runner.frame().astype(int), expected.astype(int), atol=2)


def test_a_camera_under_a_mirrored_parent_sees_the_floor_and_the_mirror(scene):
    """The camera's parent has scale (-1, 1, 1); its local pose is set so that it looks
    from the same point the same way as the plain camera: the frame is the plain one (the
    view does not mirror, so no face is culled as a back face)."""
    plain_ents, parented_ents = {}, {}
    plain = scene(_mirror_scene(plain_ents), (96, 72))
    parented = scene(_mirror_scene(parented_ents, camera_parent=(-1.0, 1.0, 1.0)), (96, 72))
    expected, shown = plain.frame(), parented.frame()
    assert shown.mean() > 20
    np.testing.assert_allclose(shown.astype(int), expected.astype(int), atol=2)
    assert parented.stats.reflection_views >= 1


def test_a_portal_on_a_mesh_not_flat_in_its_plane_is_said_once_per_join(world):
    """A Portal's rectangle lies in its local XY plane; a mesh with depth along local Z (a
    box: the editor's first mesh; a plane lying flat) shows the view on every pixel, its sides
    too: a ComponentWarning names the entity and the mesh when the Portal or the MeshRef
    joins or the mesh is replaced; a quad says nothing."""
    from components import ComponentWarning
    from engine.assets.mesh import box

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        door = world.spawn(Transform(), MeshRef(quad(2.0, 3.0)), Material(), Portal())
        assert not [w for w in caught if issubclass(w.category, ComponentWarning)]
        crate = world.spawn(Transform(), Portal(), MeshRef(box(name="crate")), Material())  # (either order)
        lying = world.spawn(Transform(), MeshRef(plane(2.0, 3.0)), Material(), Portal())
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]
        assert len(said) == 2, said
        assert said[0].startswith(f"Portal on entity {crate}: its MeshRef.mesh 'crate' is not flat in its local XY")
        assert said[1].startswith(f"Portal on entity {lying}: ")
        world.get(door, MeshRef).mesh = box(name="deep")
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]
        assert len(said) == 3 and said[2].startswith(f"Portal on entity {door}: its MeshRef.mesh 'deep'")


def test_a_portal_whose_mesh_is_not_its_size_is_said_when_given(world):
    """The view shows on the mesh's pixels and things go through Portal.size's rectangle: a
    quad of another size (a 1.6 x 2.5 door with the default size (2, 3), the level file's easy
    slip) is said when the Portal or the MeshRef joins, the mesh is replaced or the size is
    set, naming both outlines; a quad of the portal's size, and one within 1% of it, say nothing."""
    from components import ComponentWarning

    def said(caught):
        return [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fits = world.spawn(Transform(), MeshRef(quad(1.6, 2.5)), Material(), Portal(size=(1.6, 2.5)))
        near = world.spawn(Transform(), MeshRef(quad(2.01, 3.0)), Material(), Portal())
        assert said(caught) == []
        door = world.spawn(Transform(), MeshRef(quad(1.6, 2.5)), Material(), Portal())
        assert len(said(caught)) == 1
        assert said(caught)[0].startswith(f"Portal on entity {door}: its MeshRef.mesh 'quad' spans x -0.8 to 0.8, "
                                          "y -1.25 to 1.25, but Portal.size (2.0, 3.0) is the rectangle x -1 to 1")
        world.get(door, Portal).size = (1.6, 2.5)   # made to fit: nothing more
        world.get(fits, Portal).size = (3.0, 2.5)   # the size set: said at the write
        assert len(said(caught)) == 2 and said(caught)[1].startswith(f"Portal on entity {fits}: ")
        world.get(near, MeshRef).mesh = quad(4.0, 4.0)   # the mesh replaced
        assert len(said(caught)) == 3 and said(caught)[2].startswith(f"Portal on entity {near}: ")
        bare = world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Material())
        world.add_component(bare, Portal())   # a Portal joining a mesh
        assert len(said(caught)) == 4 and said(caught)[3].startswith(f"Portal on entity {bare}: ")


def test_a_mirrored_portal_is_refused_when_given(world):
    """A portal's pair carries a turn and a move: a Transform.scale with an odd number of
    negative parts (a scale of -1 to face it the other way) would make its view and what goes
    through it mirror images.  Refused at spawn, when the scale is set, and when a Portal joins
    a mirrored entity; two negative parts (a half turn) are a turn, and allowed."""
    with pytest.raises(ComponentValueError, match=r"Portal on entity \d+: Transform.scale \(-1.0, 1.0, 1.0\) "
                                                  r"mirrors it .* half turn"):
        world.spawn(Transform(scale=(-1.0, 1.0, 1.0)), MeshRef(quad(2.0, 3.0)), Material(), Portal())
    assert not world.query_one(Portal)
    door = world.spawn(Transform(scale=(-1.0, -1.0, 1.0)), MeshRef(quad(2.0, 3.0)), Material(), Portal())
    with pytest.raises(ComponentValueError, match=rf"Portal on entity {door}: Transform.scale \(1.0, 1.0, -2.0\)"):
        world.get(door, Transform).scale = (1.0, 1.0, -2.0)
    assert tuple(world.get(door, Transform).scale) == (-1.0, -1.0, 1.0)
    flipped = world.spawn(Transform(scale=(1.0, 1.0, -1.0)), MeshRef(quad(2.0, 3.0)), Material())
    with pytest.raises(ComponentValueError, match=rf"Portal on entity {flipped}: .* mirrors it"):
        world.add_component(flipped, Portal())
    assert not world.has(flipped, Portal)
    world.get(flipped, Transform).scale = (1.0, 1.0, -1.0)  # (no portal: a mirrored mesh is allowed)


@pytest.mark.parametrize("surface", ["Mirror", "Portal"])
@pytest.mark.parametrize("look", ["Reflective", "Refractive", "Emissive"])
def test_an_objects_look_on_a_mirror_or_portal_is_refused_when_given(world, surface, look):
    """A mirror's or portal's pixels show a view: a Reflective or an Emissive there changed
    nothing in the frame, and a Refractive drew the material's colour in place of the view,
    each silently.  Refused whichever comes first, at spawn or when added, naming both."""
    from components import Emissive, Reflective, Refractive

    make = {"Reflective": lambda: Reflective("skybox"), "Refractive": lambda: Refractive(ior=1.5),
            "Emissive": lambda: Emissive(2.0)}[look]
    kind = {"Mirror": Mirror, "Portal": Portal}[surface]
    pattern = rf"an? {look} on a {surface} (changes nothing|would hide)"
    with pytest.raises(ComponentValueError, match=pattern):
        world.spawn(Transform(), MeshRef(quad(2.0, 3.0)), Material(), kind(), make())
    with pytest.raises(ComponentValueError, match=pattern):
        world.spawn(Transform(), MeshRef(quad(2.0, 3.0)), Material(), make(), kind())
    assert not world.entities()
    pane = world.spawn(Transform(), MeshRef(quad(2.0, 3.0)), Material(), kind())
    with pytest.raises(ComponentValueError, match=rf"entity {pane}: " + pattern):
        world.add_component(pane, make())
    assert not world.has(pane, type(make()))
    lamp = world.spawn(Transform(), MeshRef(quad(2.0, 3.0)), Material(), make())
    with pytest.raises(ComponentValueError, match=pattern):
        world.add_component(lamp, kind())
    assert not world.has(lamp, kind)


def test_a_portal_mirrored_by_its_parent_stays_closed_and_is_said_once(world):
    """A parent's scale can mirror a portal below it (its own Transform cannot: refused):
    the pair stays closed (no view, no travel, no slicing) and the rules stage says so once;
    the parent turned back, the pair opens."""
    from components import ComponentWarning
    from engine.rules.frame_rules import open_portal_pairs
    from systems.frame_rules_system import FrameRulesSystem

    world.add_system(FrameRulesSystem(world), 100)
    frame = world.spawn(Transform(scale=(-1.0, 1.0, 1.0)))
    a = world.spawn(Transform(parent=frame), MeshRef(quad(2.0, 3.0)), Material(), Portal())
    b = world.spawn(Transform(position=(5.0, 0.0, 0.0)), MeshRef(quad(2.0, 3.0)), Material(), Portal(partner=a))
    world.get(a, Portal).partner = b
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        world.step(1 / 60)
        world.step(1 / 60)
        world.get(frame, Transform).position = (0.0, 0.0, 1.0)  # (a move: the rule asked again)
        world.step(1 / 60)
    said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)]
    assert len(said) == 1 and said[0].startswith(f"Portal on entity {a}: its parents' Transform.scale mirror it")
    assert open_portal_pairs(world) == {}  # b looks out of a, mirrored: closed too
    world.get(frame, Transform).scale = (1.0, 1.0, 1.0)
    assert open_portal_pairs(world) == {a: b, b: a}


def test_a_portal_pair_of_two_sizes_is_said_once(world):
    """A pair carries by its portals' transforms alone: with sizes that differ, what goes
    through the larger outside the smaller's rectangle comes out of the partner's wall.  The
    rules stage says it once for the pair (not again a frame later, nor from the partner's
    side), again for new sizes that still differ, and not once they match."""
    from components import ComponentWarning
    from systems.frame_rules_system import FrameRulesSystem

    world.add_system(FrameRulesSystem(world), 100)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        a = world.spawn(Transform(), MeshRef(quad(2.0, 3.0)), Material(), Portal(size=(2.0, 3.0)))
        b = world.spawn(Transform(position=(5.0, 0.0, 0.0)), MeshRef(quad(1.0, 1.5)), Material(),
                        Portal(size=(1.0, 1.5), partner=a))
        world.get(a, Portal).partner = b
        world.step(1 / 60)
        world.step(1 / 60)
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)
                and "its partner's" in str(w.message)]  # (a size that is not its mesh's is said apart)
        assert len(said) == 1, said
        assert "its partner's" in said[0] and said[0].startswith((f"Portal on entity {a}:", f"Portal on entity {b}:"))
        world.get(b, Portal).size = (1.5, 2.0)
        world.step(1 / 60)
        world.get(b, Portal).size = (2.0, 3.0)
        world.step(1 / 60)
        said = [str(w.message) for w in caught if issubclass(w.category, ComponentWarning)
                and "its partner's" in str(w.message)]  # (a size that is not its mesh's is said apart)
        assert len(said) == 2 and "(1.5, 2.0)" in said[1]
