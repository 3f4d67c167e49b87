"""A model file placed whole: the entity it is on is the model's root.

A level file (or the editor, or a game's code) places a glTF, OBJ, PLY or STL model as one
entity: ``Model(file="car.glb")`` with a Transform.  Its parts (one entity a mesh part,
with the file's materials, and its lights) are made under that entity by the models stage
(``systems/model_system.py``; ``engine.assets.models.spawn_model`` makes them at once) and
each carries a ``FromModel`` naming the root: they are what the file says, made again
whenever the file is loaded, so a level file holds the root alone (as Godot's instanced
scenes and Unity's prefabs keep a reference, not a copy).  Changing a ``Model`` field makes
the parts again; deleting the root deletes them.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from components.pose import SKINNING_METHODS
from components.tracking import ComponentValueError, TrackedComponent, boolean, choice, finite, integer

MAX_MODEL_PROBES = 4  # curved reflective or glass parts of one model that get a cube-map probe each (by default)
MAX_MODEL_PROBES_LIMIT = 64  # the most Model.max_probes may ask for (each probe is six views a capture)


@dataclass(eq=False)
class Model(TrackedComponent):
    """The model file ``file`` (a path: relative to where the program runs, or, in a level
    file, to the level's folder; "" for none yet, as the editor adds one) spawned under
    this entity.  ``light_scale`` multiplies the
    intensities of the lights the file carries (glTF's ``KHR_lights_punctual``: physical
    units to the scene's exposure); ``max_probes`` is how many of its curved reflective or
    glass parts get a cube-map probe of their own (the largest; the others reflect the sky).
    ``variant`` is the glTF material variant its parts wear (``KHR_materials_variants``: a
    shoe's colourway, a car's paint; "" the file's default look).  ``skinning`` is how its
    skinned parts blend their joints (each part's ``Skin.skinning``: "linear", the default, or
    "dual_quaternion", which keeps a twisted wrist its thickness).
    What the file holds is checked when it is loaded: by ``spawn_model`` and a level file's
    reader at once, by the models stage for a Model added or changed otherwise (naming the
    entity and the file)."""

    SHAREABLE = False  # one root's own: its parts are made under it
    file: str = ""
    light_scale: float = 1.0
    max_probes: int = MAX_MODEL_PROBES
    variant: str = ""
    skinning: str = "linear"

    def _validate(self, name: str, value: Any) -> Any:
        if name == "skinning":
            return choice(self, name, value, SKINNING_METHODS)
        if name == "file":
            if isinstance(value, os.PathLike):
                value = os.fspath(value)
            if not isinstance(value, str) or "\0" in value:
                raise ComponentValueError(f"Model.file must be a model file's path (a str), got {value!r}")
            return value
        if name == "light_scale":
            return finite(self, name, value, low=0.0)
        if name == "max_probes":
            return integer(self, name, value, low=0, high=MAX_MODEL_PROBES_LIMIT)
        if name == "variant" and not isinstance(value, str):
            raise ComponentValueError(f"Model.variant must be a variant's name (a str; \"\": none), got {value!r}")
        return value


@dataclass(eq=False)
class FromModel(TrackedComponent):
    """Made by the models stage on each entity it spawns from a ``Model`` (derived: a level
    file never holds one, nor the entities carrying it): ``model`` is the root entity."""

    SHAREABLE = False
    model: int = 0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "model" and (isinstance(value, bool) or not isinstance(value, int) or value <= 0):
            raise ComponentValueError(f"FromModel.model must be an entity id, got {value!r}")
        return value


@dataclass(eq=False)
class Animation(TrackedComponent):
    """Plays one of a model's animation clips (glTF's ``animations``: a door opening, a fan
    turning, a lid lifting) on the entity whose ``Model`` made the parts: ``clip`` its name
    ("" for none: the parts at rest), ``time`` where it is (seconds, moved on by the models
    stage by the frame's time x ``speed`` while ``playing``), ``loop`` starting it again at
    its end (else it stops there).  The parts' Transforms are the clip's pose each frame
    (engine/assets/gltf_animations.py); a clip the file lacks is an error naming those it has.

    A cross-fade (a walk easing into a run): while ``fade_from`` names a clip, the pose is
    that clip's at ``fade_from_time`` (moved on as ``time`` is) blended into ``clip``'s by
    ``faded`` / ``fade_seconds`` (translations and scales mixed, rotations along the shorter
    arc), ``faded`` moved on by the frame's time; once it reaches ``fade_seconds`` the fade
    ends (``fade_from`` ""). ``engine.assets.models.crossfade`` starts one.

    Root motion (Unity's "Apply Root Motion", Godot's root motion track): ``root_motion``
    names the node whose travel carries a walk (a character's hips; "" none).  Its travel
    across the ground (the model's x and z) from the clip's first key is taken out of the
    pose, so the model walks on the spot, and moves the root's Transform instead, each frame
    by what the clip travelled in that frame (turned and scaled as the root is; a loop's
    wrap carries on from where it ended), so a game steers and collides the root.  Its
    height (a walk's bob) stays in the pose.  The travel is the clip's own (``clip``'s, not
    a fade's or a layer's).  With ``root_turn`` the node's turn about the vertical since the
    clip's first key (a turn on the spot, a walk round a corner) comes out of the pose too and
    turns the root instead, each frame by what the clip turned in it, the travel following the
    turned root (Unity's root rotation; off, the default, a turn stays in the pose, as a
    walk's sway should: Unity's "Bake Into Pose")."""

    SHAREABLE = False
    clip: str = ""
    time: float = 0.0
    speed: float = 1.0
    playing: bool = True
    loop: bool = True
    fade_from: str = ""
    fade_from_time: float = 0.0
    fade_seconds: float = 0.0
    faded: float = 0.0
    root_motion: str = ""
    root_turn: bool = False

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("clip", "fade_from") and not isinstance(value, str):
            raise ComponentValueError(f"Animation.{name} must be a clip's name (a str; \"\": none), got {value!r}")
        if name == "root_motion" and not isinstance(value, str):
            raise ComponentValueError(f"Animation.root_motion must be a node's name (a str; \"\": none), got {value!r}")
        if name in ("time", "fade_from_time", "faded"):
            return finite(self, name, value, low=0.0)
        if name == "fade_seconds":
            return finite(self, name, value, low=0.0, high=3600.0)
        if name == "speed":
            return finite(self, name, value, low=-1000.0, high=1000.0)
        if name in ("playing", "loop", "root_turn"):
            return boolean(self, name, value)
        return value


MAX_ANIMATION_EVENTS = 1024  # AnimationEvents.events: a character's footsteps and cues, not a data store


@dataclass(eq=False)
class AnimationEvents(TrackedComponent):
    """Named moments of a model's clips, fired as its ``Animation`` (or ``AnimationLayer``)
    plays past them, as Unity's animation events and Godot's method tracks: a footstep's
    sound and dust, a sword's hit, a door's click.  ``events`` is (clip, time in seconds,
    name) triples, on the model's root.  Each frame the models stage puts the ones the
    playback passed in the ``FiredEvents`` resource (``engine.resources``), in the order
    met (``engine/core/clip_events.py``: looping, backwards, several wraps in one frame); a
    game reads them in its ``update`` (last frame's) or in a system after "models".  A clip
    the model lacks, or a time past the clip's end, is an AssetError naming the entity, the
    event and what the clip has, when the model is known.  Shareable: a character's events
    serve every copy of it."""

    events: Any = ()

    def _validate(self, name: str, value: Any) -> Any:
        if name != "events":
            return value
        try:
            items = list(value)
        except TypeError:
            raise ComponentValueError(f"AnimationEvents.events must be (clip, time, name) triples, got {value!r}") \
                from None
        if len(items) > MAX_ANIMATION_EVENTS:
            raise ComponentValueError(f"AnimationEvents.events holds at most {MAX_ANIMATION_EVENTS} events, "
                                      f"got {len(items)}")
        events = []
        for item in items:
            try:
                clip, time, label = item
            except (TypeError, ValueError):
                raise ComponentValueError(f"AnimationEvents.events must be (clip, time, name) triples, got {item!r}") \
                    from None
            if not isinstance(clip, str) or not clip or not isinstance(label, str) or not label:
                raise ComponentValueError(f"AnimationEvents.events: a clip's name and an event's name are non-empty "
                                          f"strs, got {item!r}")
            events.append((clip, finite(self, "events", time, low=0.0), label))
        return tuple(sorted(events, key=lambda event: (event[0], event[1])))

    def of_clip(self, clip: str) -> tuple[tuple[float, str], ...]:
        """``clip``'s events as (time, name), by time."""
        return tuple((time, label) for name, time, label in self.events if name == clip)


ANIMATION_LAYER_BLENDS = ("override", "additive")  # AnimationLayer.blend


@dataclass(eq=False)
class AnimationLayer(TrackedComponent):
    """A second clip played over a model's ``Animation`` (or over its rest pose without one),
    as Unity's animator layers, Godot's blend and add nodes and three.js's mixed actions:
    a wave over a walk, a breath or a recoil added to any pose.  ``clip``, ``time``,
    ``speed``, ``playing`` and ``loop`` play it as ``Animation``'s do.  It acts on the
    nodes its clip animates (and their morph weights), and of those only ``root`` and the
    nodes under it where ``root`` names one (a node's name in the file: an avatar mask, the
    arms from the shoulders down; "" the whole model):

    ``blend`` "override" (the default): their pose moves from the base's towards the
    layer's by ``weight`` (0 none, 1 the layer's alone; translations and scales mixed,
    rotations along the shorter arc).  "additive": the layer's change from its clip's first
    key is added to the base pose, times ``weight`` (a rotation turned on by the layer's
    turn, a translation moved by its move, a scale by its change added, not multiplied), as three.js's
    additive blending of a clip made additive against its first frame.

    A clip or root the model lacks is an error naming those it has."""

    SHAREABLE = False
    clip: str = ""
    time: float = 0.0
    speed: float = 1.0
    playing: bool = True
    loop: bool = True
    weight: float = 1.0
    blend: str = "override"
    root: str = ""

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("clip", "root") and not isinstance(value, str):
            what = "a clip's name" if name == "clip" else "a node's name"
            raise ComponentValueError(f"AnimationLayer.{name} must be {what} (a str; \"\": none), got {value!r}")
        if name == "time":
            return finite(self, name, value, low=0.0)
        if name == "speed":
            return finite(self, name, value, low=-1000.0, high=1000.0)
        if name == "weight":
            return finite(self, name, value, low=0.0, high=1.0)
        if name in ("playing", "loop"):
            return boolean(self, name, value)
        if name == "blend":
            return choice(self, name, value, ANIMATION_LAYER_BLENDS)
        return value
