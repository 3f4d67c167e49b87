"""The frames the golden-image tests guard: every sample-level view, README example and
benchmark scene, each at 320x180.

A case is a name, a Game to build, an optional camera pose (``Engine.place_camera``, as
``--camera`` does), a setup on the built engine (a benchmark's knob, such as the mirror
path or the portal depth) and how many frames to run before the one that is compared (the
sample level's crates spin, so frame 2 also checks that per-frame updates are drawn).
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from components import Portal
from engine.core.game import Game
from shell.app import Engine

SIZE = (320, 180)
REPO = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class GoldenCase:
    name: str
    game: Callable[[], Game]
    camera: tuple[float, float, float, float, float] | None = None
    setup: Callable[[Engine], None] | None = None
    frames: int = 2


def _hall() -> Game:
    from games.hall_of_mirrors.level import HallOfMirrors

    return HallOfMirrors()


def _mirror_ring(count: int) -> Callable[[], Game]:
    def make() -> Game:
        from benchmarks.mirrors import MirrorRing

        return MirrorRing(count)
    return make


def _facing_portals() -> Game:
    from benchmarks.portals import FacingPortals

    return FacingPortals()


def _grid() -> Game:
    from benchmarks.ecs import GridScene

    return GridScene(1_000)


def _path(path: str) -> Callable[[Engine], None]:
    def setup(engine: Engine) -> None:
        engine.reflection_system.path = path
    return setup


def _portal_depth(depth: int) -> Callable[[Engine], None]:
    """What the portal benchmark does for each depth row."""
    def setup(engine: Engine) -> None:
        for _, portal in engine.world.query_one(Portal):
            portal.max_depth = depth
        engine.reflection_system.max_depth_cap = max(depth, 1)
    return setup


def _partner_disabled(engine: Engine) -> None:
    """The portal the camera looks into keeps its Portal; its partner is switched off."""
    portals = sorted(engine.world.query_one(Portal), key=lambda item: item[0])
    _, looked_into = portals[0]
    engine.world.get(looked_into.partner, Portal).enabled = False


def readme_games() -> list[tuple[str, Callable[[], Game]]]:
    """Every Game subclass a ```python block of README.md defines, by class name."""
    text = (REPO / "README.md").read_text()
    games = []
    for index, block in enumerate(re.findall(r"```python\n(.*?)```", text, re.DOTALL)):
        namespace: dict = {"__name__": f"readme_block_{index}"}
        exec(compile(block, f"README.md python block {index + 1}", "exec"), namespace)
        for value in namespace.values():
            if isinstance(value, type) and issubclass(value, Game) and value is not Game:
                games.append((value.__name__, value))
    return games


# The sample level from the README's pose and five more: the mirror wall close up (tinted,
# rough and the facing pair), the left doorway (a portal across the hall), the tunnel
# (facing portals), the mirror behind the start pose, and the far side of the doorway
# where a crate stands half through.
HALL_POSES = {
    "start": None,
    "mirror_wall": (-1.5, 1.6, -1.0, 10.0, 0.0),
    "doorway": (-2.5, 1.5, 2.0, 50.0, -5.0),
    "tunnel": (2.5, 1.5, 2.0, -50.0, -5.0),
    "back_mirror": (1.0, 1.7, 4.0, 170.0, -5.0),
    "partner_side": (12.5, 1.4, -7.6, -105.0, -8.0),
}


def cases() -> list[GoldenCase]:
    found = [GoldenCase(f"hall_{pose}", _hall, camera) for pose, camera in HALL_POSES.items()]
    found += [GoldenCase(f"readme_{name.lower()}", game) for name, game in readme_games()]
    found += [GoldenCase(f"mirror_ring_{n}", _mirror_ring(n)) for n in (0, 2, 8, 16)]
    found += [GoldenCase(f"mirror_ring_8_{path}", _mirror_ring(8), setup=_path(path))
              for path in ("per_mirror", "batched")]
    found += [GoldenCase(f"portals_depth_{d}", _facing_portals, setup=_portal_depth(d)) for d in (0, 4, 8)]
    found += [GoldenCase("portals_partner_disabled", _facing_portals, setup=_partner_disabled)]
    found += [GoldenCase("ecs_grid_1000", _grid)]
    return found
