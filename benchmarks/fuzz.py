"""Fuzz: every component's fields given adversarial values, several frames a case.

Each case builds one component (Visibility and Water among them) with one to three fields
drawn from a pool of awkward values (NaN, infinities, numbers past float32 and float16, huge
ints, wrong kinds, zero vectors, Euler-looking tuples), attaches it to an entity of a small
lit scene (a box, a quad for surfaces, the camera entity for Camera, FlyController, Tonemap,
Bloom, ColorGrading, Vignette, DepthOfField, MotionBlur, ChromaticAberration, FilmGrain, Fog,
AmbientOcclusion and ScreenReflections, the sky entity
for the Skybox) and
renders ``FRAMES`` 48 x 32 frames (``benchmarks/fuzz_cases.py``: what a first frame leaves
to later ones, probes captured a face a frame, is run too). A case passes when either the
component is refused with a ``ComponentValueError`` that names ``Class.field`` (or the
entity, for checks on the whole entity), or every frame renders with no NaN in the HDR
colour target and ``ctx.error`` clean. Any other exception, above all one raised from inside
a system, is a failure.

    python -m benchmarks fuzz --cases 5000 --level-cases 2000 --model-cases 500

``--budget-cases`` (default 100): ``ViewBudget`` values, plausible and adversarial, set on a
scene whose facing mirrors, every-frame probe and a pond (its fades, Water and Visibility
fields drawn too) spend it, several frames a case (``fuzz_budgets``).
``--level-cases`` runs the level-file fuzz as well (``benchmarks/level_fuzz.py``: a small
level's text mutated, loaded, spawned and rendered; a quarter of its cases name adversarial
files).  Every run also tries each of the level fuzz's file cases once (``FILE_CASES``:
symlink loops, FIFOs, a directory, /dev/zero, image bombs, deep nesting, 16-bit and float
images, paths outside the level's folder): each refused saying what it is, or loaded with
the right texel and drawn clean.  ``--model-cases`` (default 100) runs the model fuzz
(``benchmarks/model_fuzz.py``: model files and the maps they name made at random, loaded and
spawned with ``spawn_model`` outside any level).  ``--still-cases`` (default 50) runs the
still-frame fuzz (``benchmarks/still_fuzz.py``: a facing mirror or portal pair with end
images, glass of random alpha, still water; the camera still until the tree is kept and its
end images refill, then one random change (an awkward component value, an entity removed
mid-refill, a resize, a depth cap, keep_still_views toggled, a see-through surface added, a
light edited in place, the camera off); every frame equal bit for bit to an engine drawing
its whole tree each frame, and the resource counts back once the case's entities go).
``--hdr32`` makes the colour images float32 (``engine.render.targets.HDR_FORMAT``), so every
check also finds a value a shader wrote past a half float's 65504 (``fuzz_cases.hdr_problem``):
llvmpipe saturates those to 65504, a GPU whose conversion rounds correctly stores +inf.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import random
import traceback
import warnings
from typing import Any

from pyglm import glm

from benchmarks.fuzz_cases import FRAMES, fuzz_ripples, hdr_image, hdr_problem, random_value, run_cases
from components import (
    AmbientOcclusion,
    Bloom,
    Camera,
    ChromaticAberration,
    CloudLayer,
    ColorGrading,
    ComponentValueError,
    ContactShadows,
    Decal,
    DepthOfField,
    DirectionalLight,
    Emissive,
    FilmGrain,
    FlyController,
    Fog,
    FogVolume,
    IrradianceVolume,
    LensFlare,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    MotionBlur,
    ParticleEmitter,
    PointLight,
    Portal,
    PortalClone,
    ReflectionProbe,
    Reflective,
    Refractive,
    Ripples,
    ScreenReflections,
    Skybox,
    Slice,
    Splash,
    TimeOfDay,
    Tonemap,
    Transform,
    Traveller,
    Vignette,
    Visibility,
    VolumetricFog,
    Wake,
    Water,
    look_rotation,
)
from engine.assets.mesh import box, quad, sphere
from engine.core.frame_io import Output
from engine.core.game import Game
from engine.render.targets import CaptureTarget
from shell.app import Engine

SIZE = (48, 32)
CLASSES: tuple[type, ...] = (Transform, MeshRef, Material, Emissive, Reflective, Refractive, Mirror, Portal,
                             Traveller, Slice, PortalClone, ReflectionProbe, Camera, FlyController,
                             DirectionalLight, PointLight, Skybox, Tonemap, Bloom, ColorGrading, Vignette, DepthOfField,
                             MotionBlur, ChromaticAberration, FilmGrain, Fog, AmbientOcclusion, ContactShadows,
                             ScreenReflections, Visibility, VolumetricFog, Water, ParticleEmitter, Decal,
                             IrradianceVolume, FogVolume, LensFlare, TimeOfDay, CloudLayer, Ripples, Wake, Splash,
                             Monitor)

@dataclasses.dataclass
class Case:
    cls: type
    values: dict[str, Any]

    def describe(self) -> str:
        return f"{self.cls.__name__}({', '.join(f'{k}={v!r}' for k, v in self.values.items())})"


def random_case(rng: random.Random) -> Case:
    cls = rng.choice(CLASSES)
    names = [f.name for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")]
    chosen = rng.sample(names, rng.randint(1, min(3, len(names))))
    values = {name: random_value(rng) for name in chosen}
    if cls is MeshRef and "mesh" not in values:
        values["mesh"] = box()
    return Case(cls, values)


class _Scene(Game):
    title = "fuzz"

    def build(self, world) -> None:
        eye = glm.vec3(0, 1.5, 5)
        self.camera = world.spawn(Transform(position=eye, rotation=look_rotation(-eye + glm.vec3(0, 0.5, 0))),
                                  Camera())
        self.sky = world.spawn(Skybox(face_size=8))
        world.spawn(DirectionalLight(direction=(-0.3, -1, -0.5), intensity=2.0))
        world.spawn(Transform(position=(0, 0, -1.5)), MeshRef(box((3, 2, 0.2))), Material())


class Fuzzer:
    """One engine; each case is attached, rendered once, checked and taken away."""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.game = _Scene()
        self.engine = Engine(self.game, ctx)
        self.world = self.engine.world
        self.capture = CaptureTarget(ctx, SIZE)
        self.frame()
        self.refused = self.rendered = 0  # passing cases of each kind, for the report

    def frame(self) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a case that makes the camera inactive: the no-camera warning
            self.engine.frame(1.0 / 60.0, Output(self.capture.framebuffer, SIZE))

    def close(self) -> None:
        self.capture.release()
        self.engine.close()

    def run(self, case: Case, index: int = 0) -> str | None:
        """None when the case passed, else why it failed (``index``: the case's number, unused)."""
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                component = case.cls(**case.values)
        except ComponentValueError as exc:
            return self._refused(case, exc)
        except Exception as exc:  # noqa: BLE001 - any other kind is what the fuzz is looking for
            return f"construction raised {type(exc).__name__}: {exc}"
        world, restore, spawned = self.world, None, None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if case.cls in (Camera, FlyController, Tonemap, Bloom, ColorGrading, Vignette, DepthOfField,
                                MotionBlur, ChromaticAberration, FilmGrain, Fog, AmbientOcclusion,
                                ContactShadows, ScreenReflections, VolumetricFog):
                    restore = (self.game.camera, world.try_get(self.game.camera, case.cls))
                    world.add_component(self.game.camera, component)
                elif case.cls is Skybox:
                    restore = (self.game.sky, world.get(self.game.sky, Skybox))
                    world.add_component(self.game.sky, component)
                elif case.cls in (DirectionalLight, PointLight):
                    spawned = world.spawn(Transform(position=(0, 2, 1)), component)
                elif case.cls is TimeOfDay:   # (on the light it turns)
                    spawned = world.spawn(DirectionalLight(), component)
                else:
                    flat = case.cls in (Mirror, Portal, Water, Ripples)
                    parts: dict[type, Any] = {Transform: Transform(position=(0, 0.5, 0)),
                                              MeshRef: MeshRef(quad(1.5, 1.5) if flat else box()),
                                              Material: Material()}
                    if case.cls in (Water, Ripples):  # the surface it makes water, with waves
                        parts[Mirror] = Mirror()
                        parts[Material] = Material(color=(0.2, 0.3, 0.4, 0.6), normal_map=fuzz_ripples())
                    if case.cls is Ripples:   # (rippling from the start: a stone dropped in its middle)
                        parts[Water] = Water()
                        parts[Splash] = Splash()
                    if case.cls is Monitor and "camera" not in case.values:   # (a screen showing the camera)
                        component.camera = self.game.camera
                    parts[case.cls] = component
                    spawned = world.spawn(*parts.values())
        except ComponentValueError as exc:
            return self._refused(case, exc)
        except Exception as exc:  # noqa: BLE001
            return f"attach raised {type(exc).__name__}: {exc}"
        try:
            problem = None
            for _ in range(FRAMES):
                self.frame()
                problem = self._check_pixels()
                if problem is not None:
                    break
        except Exception as exc:  # noqa: BLE001
            problem = f"frame raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}"
        finally:
            self._undo(restore, spawned, case.cls)
        if problem is None:
            self.rendered += 1
        return problem

    def _refused(self, case: Case, exc: ComponentValueError) -> str | None:
        why = self._named(case, exc)
        if why is None:
            self.refused += 1
        return why

    def _undo(self, restore, spawned, cls) -> None:
        world = self.world
        try:
            if spawned is not None:
                world.delete_entity(spawned)
            if restore is not None:
                entity, old = restore
                if old is None:
                    world.remove_component(entity, cls)
                else:
                    world.add_component(entity, dataclasses.replace(old))
            self.frame()
        except Exception:  # noqa: BLE001 - a case that breaks the engine: start a fresh one
            self.close()
            self.__init__(self.ctx)

    def _check_pixels(self) -> str | None:
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            return f"ctx.error {error}"
        return hdr_problem(hdr_image(self.engine.renderer.targets))

    @staticmethod
    def _named(case: Case, exc: ComponentValueError) -> str | None:
        text = str(exc)
        name = case.cls.__name__
        if any(f"{name}.{field}" in text for field in case.values) or f"{name} on entity" in text \
                or "Transform.parent" in text or f"{name} given to entity" in text:
            return None
        return f"refused without naming {name}.<field>: {text}"


def fuzz(ctx, cases: int, seed: int = 0, report=None) -> tuple[int, list[tuple[str, str]], dict[str, int]]:
    """Run ``cases`` component cases (``run_cases``)."""
    return run_cases(Fuzzer(ctx), random_case, cases, seed, report)


# --- budgets, with the surfaces that spend them ----------------------------------------------

@dataclasses.dataclass
class BudgetCase:
    """A ``ViewBudget`` (its fields from the adversarial pool, or plausible small numbers)
    and the look of a pond and a mirror pair that spend it (their fades, Visibility and
    Water fields, plausible or not)."""

    budget: dict[str, Any]
    mirror: dict[str, Any]
    water: dict[str, Any]
    visibility: dict[str, Any]

    def describe(self) -> str:
        return (f"ViewBudget({self.budget}) mirror {self.mirror} water {self.water} "
                f"visibility {self.visibility}")


def _budget_value(rng: random.Random, name: str) -> Any:
    if rng.random() < 0.85:  # plausible: a small budget that starves something
        return {"views": rng.randint(0, 12), "pixels": rng.choice((0, 1, 500, 5000, 10 ** 6)),
                "probe_ms": rng.choice((0.001, 0.05, 1.0, 50.0)),
                "min_pixels": rng.choice((1, 16, 64, 400, 10 ** 6)),
                "frame_ms": rng.choice((0.001, 1.0, 16.7, 1e6)),
                "min_render_scale": rng.choice((0.25, 0.5, 0.9, 1.0))}[name]
    return random_value(rng)


def _fade_value(rng: random.Random) -> Any:
    if rng.random() < 0.85:
        start = rng.uniform(0.0, 10.0)
        return (start, start + rng.uniform(0.0, 10.0))
    return random_value(rng)


def random_budget_case(rng: random.Random) -> BudgetCase:
    budget = {name: _budget_value(rng, name)
              for name in rng.sample(("views", "pixels", "probe_ms", "min_pixels", "frame_ms", "min_render_scale"),
                                     rng.randint(1, 6))}
    mirror = {name: _fade_value(rng) for name in rng.sample(("fade_distance", "fade_angle"), rng.randint(0, 2))}
    water_fields = ("ior", "speed", "direction", "tiling", "cross", "offset")
    plausible_water = {"ior": lambda: rng.uniform(1.0, 2.0), "speed": lambda: rng.uniform(0.0, 2.0),
                       "direction": lambda: (rng.uniform(-1, 1), rng.uniform(0.1, 1)),
                       "tiling": lambda: rng.uniform(0.5, 8.0), "cross": lambda: rng.random(),
                       "offset": lambda: (rng.uniform(-5, 5), rng.uniform(-5, 5))}
    water = {name: plausible_water[name]() if rng.random() < 0.85 else random_value(rng)
             for name in rng.sample(water_fields, rng.randint(0, 2))}
    kinds = ("direct", "in_mirrors", "in_portals", "in_probes", "layers")
    visibility = {name: (rng.random() < 0.5 if name != "layers" else [rng.randint(0, 3)])
                  if rng.random() < 0.85 else random_value(rng) for name in rng.sample(kinds, rng.randint(0, 3))}
    return BudgetCase(budget, mirror, water, visibility)


class _BudgetScene(Game):
    """A facing pair of mirrors, a chrome ball with a probe recaptured every frame, a lit
    box: the views a budget has to share."""

    title = "fuzz: budgets"

    def build(self, world) -> None:
        eye = glm.vec3(0.4, 1.5, 3.0)
        world.spawn(Transform(position=eye, rotation=look_rotation(glm.vec3(0, 1, -3) - eye)), Camera())
        world.spawn(DirectionalLight(direction=(-0.3, -1, -0.5), intensity=2.0))
        world.spawn(Transform(position=(0.8, 0.5, 0)), MeshRef(box()), Material(color=(0.8, 0.3, 0.1)))
        for z, turn in ((-3.0, 0.0), (3.5, 3.14159)):
            world.spawn(Transform(position=(0, 1.2, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                        MeshRef(quad(2.5, 2.0)), Material(color=(0.2, 0.2, 0.2)), Mirror(max_depth=3))
        world.spawn(Transform(position=(-0.8, 0.6, 0)), MeshRef(sphere(0.5, 12, 6)),
                    Material(metallic=1.0, roughness=0.05), Reflective("cube"),
                    ReflectionProbe(resolution=16, refresh="every_frame", depth=1))


class BudgetFuzzer:
    """One engine of ``_BudgetScene``; each case sets the world's ViewBudget, spawns a pond
    (Mirror with the case's fades, Water, Visibility) and renders ``FRAMES`` frames.
    A case passes when what is refused is refused naming ``ViewBudget.<field>`` (or the
    component's field), or every frame renders clean (as ``Fuzzer``)."""

    def __init__(self, ctx) -> None:
        from engine.resources import ViewBudget

        self.ctx = ctx
        self.engine = Engine(_BudgetScene(), ctx)
        self.world = self.engine.world
        self.capture = CaptureTarget(ctx, SIZE)
        self.view_budget = ViewBudget
        self.refused = self.rendered = 0
        Fuzzer.frame(self)

    frame = Fuzzer.frame
    close = Fuzzer.close
    _check_pixels = Fuzzer._check_pixels

    def run(self, case: BudgetCase, index: int = 0) -> str | None:
        from engine.resources import ViewBudgetError

        world = self.world
        try:
            budget = self.view_budget(**case.budget)
        except ViewBudgetError as exc:
            return self._refused(exc, "ViewBudget", case.budget)
        except Exception as exc:  # noqa: BLE001
            return f"ViewBudget raised {type(exc).__name__}: {exc}"
        spawned = None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                parts = [Transform(position=(0, 0.02, 1.0), rotation=glm.angleAxis(-1.5708, glm.vec3(1, 0, 0))),
                         MeshRef(quad(2.0, 2.0)), Material(color=(0.2, 0.3, 0.4, 0.6), normal_map=fuzz_ripples())]
                for cls, values in ((Mirror, case.mirror), (Water, case.water), (Visibility, case.visibility)):
                    try:
                        parts.append(cls(**values))
                    except ComponentValueError as exc:
                        return self._refused(exc, cls.__name__, values)
                spawned = world.spawn(*parts)
        except ComponentValueError as exc:
            return self._refused(exc, "Water", case.water)
        except Exception as exc:  # noqa: BLE001
            return f"attach raised {type(exc).__name__}: {exc}"
        world.resources[self.view_budget] = budget
        problem = None
        try:
            for _ in range(FRAMES):
                self.frame()
                problem = self._check_pixels()
                if problem is not None:
                    break
        except Exception as exc:  # noqa: BLE001
            problem = f"frame raised {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}"
        finally:
            world.resources.pop(self.view_budget, None)
            try:
                if spawned is not None:
                    world.delete_entity(spawned)
                self.frame()
            except Exception:  # noqa: BLE001 - a case that breaks the engine: start a fresh one
                self.close()
                self.__init__(self.ctx)
        if problem is None:
            self.rendered += 1
        return problem

    def _refused(self, exc: Exception, name: str, values: dict[str, Any]) -> str | None:
        text = str(exc)
        if any(f"{name}.{field}" in text for field in values) or f"{name} on entity" in text:
            self.refused += 1
            return None
        return f"refused without naming {name}.<field>: {text}"


def fuzz_budgets(ctx, cases: int, seed: int = 0, report=None) -> tuple[int, list[tuple[str, str]], dict[str, int]]:
    """Run ``cases`` budget cases (``run_cases``): budgets with the mirrors, probe, water,
    fades and Visibility that spend them, several frames each."""
    return run_cases(BudgetFuzzer(ctx), random_budget_case, cases, seed, report)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cases", type=int, default=1000, help="how many cases to run (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (the cases are reproducible)")
    parser.add_argument("--budget-cases", type=int, default=100,
                        help="view-budget cases, with mirrors, a probe, water, fades and Visibility spending it "
                             "(default 100)")
    parser.add_argument("--level-cases", type=int, default=0,
                        help="also run this many level-file cases (mutated level files; default 0)")
    parser.add_argument("--still-cases", type=int, default=50,
                        help="still-frame cases: a mirror or portal pair with end images kept and refilled by a "
                             "still camera, one random change, every frame equal to an engine drawing its whole "
                             "tree, resources back after (benchmarks/still_fuzz.py; default 50)")
    parser.add_argument("--hdr32", action="store_true",
                        help="make the colour images float32 (engine.render.targets.HDR_FORMAT), so that every "
                             "frame's check also finds values past a half float's 65504, which llvmpipe saturates "
                             "and a GPU that rounds correctly stores as +inf")
    add_model_arguments(parser)


# --- model files outside a level (benchmarks/model_fuzz.py) ---------------------------------------

def add_model_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model-cases", type=int, default=100,
                        help="model files made at random, loaded and spawned with spawn_model outside a level "
                             "(benchmarks/model_fuzz.py; default 100)")


def run_model_fuzz(ctx, args: argparse.Namespace, report) -> tuple[int, list, dict[str, int]]:
    """The model fuzz's cases (``benchmarks.model_fuzz.fuzz_models``), in a folder of their own."""
    import tempfile
    from pathlib import Path

    from benchmarks.model_fuzz import fuzz_models

    with tempfile.TemporaryDirectory() as folder:
        return fuzz_models(ctx, Path(folder), args.model_cases, args.seed, report)


def print_model_fuzz(args: argparse.Namespace, ran: int, failures: list, passes: dict[str, int]) -> None:
    if args.json:
        print(json.dumps({"model_cases": ran, "failed": len(failures), **passes, "failures": failures[:50]}))
    else:
        print(f"model fuzz: {ran} model files ran, {len(failures)} failed ({passes['refused']} refused naming the "
              f"file, {passes['rendered']} spawned and rendered clean for {FRAMES} frames; seed {args.seed})")


def main(args: argparse.Namespace) -> int:
    import tempfile
    from pathlib import Path

    from benchmarks.level_fuzz import fuzz_files, fuzz_levels
    from benchmarks.still_fuzz import fuzz_still
    from engine.render.gl_context import create_headless_context

    if args.hdr32:
        import engine.render.targets as targets

        targets.HDR_FORMAT = "f4"  # (before any engine makes its targets)
    ctx = create_headless_context()
    try:
        def report(index: int, case, why: str) -> None:
            if not args.json:
                print(f"case {index}: {case.describe()}\n  {why.strip().splitlines()[0]}")

        ran, failures, passes = fuzz(ctx, args.cases, args.seed, report)
        budget_ran, budget_failures, budget_passes = fuzz_budgets(ctx, args.budget_cases, args.seed, report)
        failures = failures + budget_failures
        with tempfile.TemporaryDirectory() as folder:
            level_ran, level_failures, level_passes = fuzz_levels(ctx, Path(folder), args.level_cases, args.seed,
                                                                  report)
        with tempfile.TemporaryDirectory() as folder:
            file_ran, file_failures, file_passes = fuzz_files(ctx, Path(folder), report)
        model_ran, model_failures, model_passes = run_model_fuzz(ctx, args, report)
        still_ran, still_failures, still_passes = fuzz_still(ctx, args.still_cases, args.seed, report)
    finally:
        ctx.release()
    if args.json:
        print(json.dumps({"cases": ran, "failed": len(failures) - len(budget_failures), **passes,
                          "failures": failures[:50]}))
        print(json.dumps({"budget_cases": budget_ran, "failed": len(budget_failures), **budget_passes,
                          "failures": budget_failures[:50]}))
        if args.level_cases:
            print(json.dumps({"level_cases": level_ran, "failed": len(level_failures), **level_passes,
                              "failures": level_failures[:50]}))
        print(json.dumps({"file_cases": file_ran, "failed": len(file_failures), **file_passes,
                          "failures": file_failures[:50]}))
    else:
        print(f"fuzz: {ran} cases ran, {len(failures) - len(budget_failures)} failed ({passes['refused']} refused "
              f"naming the field, {passes['rendered']} rendered clean, {FRAMES} frames each; "
              f"seed {args.seed})")
        print(f"budget fuzz: {budget_ran} cases ran, {len(budget_failures)} failed ({budget_passes['refused']} "
              f"refused naming the field, {budget_passes['rendered']} rendered clean)")
        if args.level_cases:
            print(f"level fuzz: {level_ran} level files ran, {len(level_failures)} failed "
                  f"({level_passes['refused']} refused naming the file, {level_passes['rendered']} rendered clean; "
                  f"seed {args.seed})")
        print(f"file cases: {file_ran} ran, {len(file_failures)} failed ({file_passes['refused']} refused saying what "
              f"the file is, {file_passes['rendered']} loaded right and rendered clean)")
    print_model_fuzz(args, model_ran, model_failures, model_passes)
    if args.json:
        print(json.dumps({"still_cases": still_ran, "failed": len(still_failures), **still_passes,
                          "failures": still_failures[:50]}))
    else:
        print(f"still fuzz: {still_ran} cases ran, {len(still_failures)} failed ({still_passes['refused']} refused "
              f"naming the field, {still_passes['rendered']} rendered equal to a whole-drawn engine with resources "
              f"back after; {still_passes['refill_frames']} refilled frames, {still_passes['glass_between_frames']} "
              f"with glass between see-through surfaces, {still_passes['glass_layered_frames']} with glass behind "
              f"glass drawn in layers, {still_passes['slot_cut_frames']} with see-through things drawn in part after "
              f"the glass, {still_passes['pictures_kept_frames']} that kept a monitor's picture, "
              f"{still_passes['program_restarts']} restarts for the programs held; seed {args.seed})")
    return 1 if failures or level_failures or file_failures or model_failures or still_failures else 0
