"""Level-file fuzz: a small level's text mutated at random, loaded, spawned and rendered.

Each case applies one to three mutations to ``BASE`` (a field's value replaced by an awkward
TOML value, a component or field renamed, a name or reference changed, a mesh or texture
spec replaced, a line broken, a table emptied) and writes the result to a file.  A case
passes when either loading or spawning raises a ``LevelError`` that names the file (and the
entity where the mutation touched one), or the level spawns and renders a 48 x 32 frame
with no NaN in the HDR target and ``ctx.error`` clean.  Any other exception is a failure,
as is an entity left in the world by a refused level.

    python -m benchmarks fuzz --level-cases 2000
"""
from __future__ import annotations

import random
import re
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.app import Engine, Game
from engine.frame_io import Output
from engine.level_file import LevelError, load_level
from engine.render.targets import CaptureTarget

SIZE = (48, 32)
BASE = """\
[level]
name = "fuzz"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 1.5, 5.0]
rotation = { yaw = 0, pitch = -10 }
[entity.Camera]
fov_y = 60.0

[[entity]]
name = "sky"
[entity.Skybox]
face_size = 8

[[entity]]
name = "sun"
[entity.DirectionalLight]
direction = [-0.3, -1.0, -0.5]
intensity = 2.0

[[entity]]
name = "floor"
[entity.Transform]
position = [0.0, 0.0, 0.0]
[entity.MeshRef]
mesh = { plane = [6.0, 6.0], uv_repeat = 2.0 }
[entity.Material]
texture = { checker = [32, 4] }
roughness = 0.8

[[entity]]
name = "crate"
[entity.Transform]
position = [0.8, 0.5, 0.0]
scale = [1.0, 1.0, 1.0]
parent = "floor"
[entity.MeshRef]
mesh = { box = [1.0, 1.0, 1.0] }
[entity.Material]
color = [0.8, 0.3, 0.1, 1.0]
[entity.Emissive]
power = 0.5

[[entity]]
name = "mirror"
[entity.Transform]
position = [0.0, 1.0, -2.0]
[entity.MeshRef]
mesh = { quad = [2.0, 1.5] }
[entity.Material]
[entity.Mirror]
color = [0.9, 1.0, 0.9]
roughness = 0.1

[[entity]]
name = "door_a"
[entity.Transform]
position = [-2.0, 1.0, -1.0]
rotation = { look = [1.0, 0.0, 0.0] }
[entity.MeshRef]
mesh = { quad = [1.0, 2.0] }
[entity.Material]
[entity.Portal]
partner = "door_b"
size = [1.0, 2.0]

[[entity]]
name = "door_b"
[entity.Transform]
position = [2.5, 1.0, 1.0]
rotation = [0.7071, 0.0, -0.7071, 0.0]
[entity.MeshRef]
mesh = { quad = [1.0, 2.0] }
[entity.Material]
[entity.Portal]
partner = "door_a"
size = [1.0, 2.0]

[[entity]]
name = "ball"
[entity.Transform]
position = [-0.8, 0.6, 0.5]
[entity.MeshRef]
mesh = { sphere = 0.5, segments = 16, rings = 8 }
[entity.Material]
metallic = 1.0
roughness = 0.05
[entity.Reflective]
mode = "cube"
[entity.ReflectionProbe]
resolution = 16
"""

_VALUES = ["0", "1", "-1", "0.5", "1e-30", "65505.0", "1e20", "3.4e38", "1e39", "nan", "inf", "-inf",
           "99999999999999999999", "true", "\"x\"", "\"cube\"", "\"door_a\"", "\"nobody\"", "[]", "[1.0]",
           "[1.0, 2.0]", "[0.0, 0.0, 0.0]", "[1.0, nan, 0.0]", "[1e39, 0.0, 0.0]", "[1.0, 1.0, 1.0, 1.0]",
           "[0.0, 0.0, 0.0, 0.0]", "[\"a\", 1, 2]", "{ yaw = 90 }", "{ look = [0.0, 0.0, 0.0] }", "{}",
           "{ box = [1.0, 0.0, 1.0] }", "{ quad = [0.0, 0.0] }", "{ sphere = -1.0 }", "{ file = \"gone.obj\" }",
           "{ checker = [0, 0] }", "{ checker = [100000, 2] }", "{ checker = [inf, 2] }", "{ checker = [8.5, 2] }",
           "{ box = [inf, 1.0, 1.0] }", "{ sphere = 1e39 }", "{ plane = [1.0, 1.0], uv_repeat = nan }",
           "{ sphere = 0.5, segments = 100000000 }", "{ file = \"gone.png\" }", "1979-05-27"]
_NAMES = ["Transform", "MeshRef", "Material", "Mirror", "Portal", "Camera", "Skybox", "Emissive", "Slice",
          "PortalClone", "Nope", "transform"]
_FIELDS = ["position", "rotation", "scale", "parent", "partner", "color", "colour", "mesh", "texture", "size",
           "enabled", "mode", "resolution", "refresh", "fov_y", "near", "far", "power", "bogus"]


@dataclass
class LevelCase:
    text: str
    mutations: list[str]

    def describe(self) -> str:
        return "; ".join(self.mutations)


def mutate(rng: random.Random, text: str) -> tuple[str, str]:
    """One random change to a level's text, and what it was."""
    lines = text.splitlines()
    kind = rng.choice(["value", "value", "value", "table", "field", "name", "break", "drop"])
    assignments = [i for i, line in enumerate(lines) if re.match(r"^\w+ = ", line)]
    tables = [i for i, line in enumerate(lines) if line.startswith("[entity.")]
    if kind == "value":
        i = rng.choice(assignments)
        key = lines[i].split(" = ")[0]
        value = rng.choice(_VALUES)
        lines[i] = f"{key} = {value}"
        return "\n".join(lines), f"line {i + 1}: {key} = {value}"
    if kind == "table":
        i = rng.choice(tables)
        name = rng.choice(_NAMES)
        lines[i] = f"[entity.{name}]"
        return "\n".join(lines), f"line {i + 1}: table [entity.{name}]"
    if kind == "field":
        i = rng.choice([j for j in assignments if not lines[j].startswith("name")])
        field = rng.choice(_FIELDS)
        lines[i] = f"{field} = {lines[i].split(' = ', 1)[1]}"
        return "\n".join(lines), f"line {i + 1}: field renamed {field}"
    if kind == "name":
        names = [i for i, line in enumerate(lines) if line.startswith("name = ") and i > 2]
        i = rng.choice(names)
        new = rng.choice(["\"camera\"", "\"door_b\"", "\"\"", "\"x y\"", "5"])
        lines[i] = f"name = {new}"
        return "\n".join(lines), f"line {i + 1}: name = {new}"
    if kind == "break":
        i = rng.randrange(len(lines))
        lines[i] = lines[i][: rng.randrange(len(lines[i]) + 1)] + rng.choice(["[", "= ", "\"", "}", ""])
        return "\n".join(lines), f"line {i + 1}: broken"
    i = rng.choice(assignments + tables)
    dropped = lines.pop(i)
    return "\n".join(lines), f"line {i + 1}: dropped {dropped!r}"


def random_level_case(rng: random.Random) -> LevelCase:
    text, done = BASE, []
    for _ in range(rng.randint(1, 3)):
        text, what = mutate(rng, text)
        done.append(what)
    return LevelCase(text, done)


class _Empty(Game):
    title = "level fuzz"

    def build(self, world) -> None:
        pass


class LevelFuzzer:
    """One engine on an empty world; each case's level is spawned, rendered and deleted."""

    def __init__(self, ctx, folder: Path) -> None:
        self.ctx = ctx
        self.folder = folder
        self.engine = Engine(_Empty(), ctx)
        self.world = self.engine.world
        self.capture = CaptureTarget(ctx, SIZE)
        self.refused = self.rendered = 0

    def close(self) -> None:
        self.capture.release()
        self.engine.close()

    def run(self, case: LevelCase, index: int = 0) -> str | None:
        """None when the case passed, else why it failed."""
        path = self.folder / f"case_{index}.toml"
        path.write_text(case.text)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load_level(path).spawn(self.world)
        except LevelError as exc:
            if str(path) not in str(exc):
                return f"LevelError without the file's name: {exc}"
            if self.world.entities():
                return f"refused, but left entities {self.world.entities()} in the world"
            self.refused += 1
            return None
        except Exception as exc:  # noqa: BLE001 - any other kind is what the fuzz is looking for
            return f"load raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}"
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self.engine.frame(1.0 / 60.0, Output(self.capture.framebuffer, SIZE))
            problem = self._check_pixels()
        except Exception as exc:  # noqa: BLE001
            problem = f"frame raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}"
        finally:
            for entity in list(self.world.entities()):
                self.world.delete_entity(entity)
        if problem is None:
            self.rendered += 1
        return problem

    def _check_pixels(self) -> str | None:
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            return f"ctx.error {error}"
        targets = self.engine.renderer.targets
        if targets is None:
            return None  # nothing drawn (no camera left): nothing to be NaN
        hdr = np.frombuffer(targets.color.read(), np.float16)
        if not np.isfinite(hdr).all():
            return f"{int((~np.isfinite(hdr)).sum())} non-finite values in the HDR colour target"
        return None


def fuzz_levels(ctx, folder: Path, cases: int, seed: int = 0, report=None) -> tuple[int, list, dict[str, int]]:
    """Run ``cases`` level cases (``benchmarks.fuzz.run_cases``), their files in ``folder``."""
    from benchmarks.fuzz import run_cases

    return run_cases(LevelFuzzer(ctx, folder), random_level_case, cases, seed, report)
