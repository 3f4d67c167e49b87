"""A scripted player: turns a list of commands into the ``Input`` a person would give, one
frame at a time (the tests drive the game with it; a headless run with no person plays a
level's ``solution`` with it, so its frames show the game being played).

Commands (one string each, numbers in metres and degrees):

* ``aim X Y Z``: turn to look at a world point (one frame of mouse motion);
* ``look YAW PITCH``: turn to a heading (yaw 0 looks down -Z, 90 down -X);
* ``click left|right``: one mouse click (places portal A / B where the player looks);
* ``press KEY``: one key press (``space`` jumps, ``r`` restarts);
* ``hold KEYS N``: hold keys (``w`` or ``w+d``) for N frames;
* ``wait N``: N frames with no input;
* ``walk_to X Z [N]``: steer towards a point on the ground, eyes level, and walk (``w``) until within
  ``ARRIVED`` of it, through a portal, or N frames (default 600) have passed.

Aiming is done the way a mouse does it: ``mouse_dx`` / ``mouse_dy`` worth the turn at the
player's mouse sensitivity.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from components import yaw_pitch_of
from engine.core.errors import SpeculumError
from engine.core.frame_io import Input

ARRIVED = 0.3  # m
_ARITY = {"aim": (3, 3), "look": (2, 2), "click": (1, 1), "press": (1, 1), "hold": (2, 2), "wait": (1, 1),
          "walk_to": (2, 3)}


class ScriptError(SpeculumError, ValueError):
    """A script command that cannot be played (names the step and why)."""


class Pilotable(Protocol):
    """What the autopilot reads from the game it plays."""

    def player_view(self) -> tuple[tuple[float, float, float], float, float, float]:
        """(eye position, yaw, pitch, mouse sensitivity)."""

    def travel_count(self) -> int:
        """How many times the player has gone through a portal."""


@dataclass(frozen=True)
class Command:
    verb: str
    args: tuple[str, ...]


def parse_script(script: Sequence[str], where: str = "script") -> list[Command]:
    """Check every step first, so a bad one is an error before the first frame."""
    if isinstance(script, str) or not isinstance(script, Sequence):
        raise ScriptError(f"{where} must be a list of command strings, got {script!r}")
    commands = []
    for index, step in enumerate(script):
        if not isinstance(step, str) or not step.split():
            raise ScriptError(f"{where} step {index + 1} must be a command string, got {step!r}")
        verb, *args = step.split()
        if verb not in _ARITY:
            raise ScriptError(f"{where} step {index + 1} {step!r}: unknown command {verb!r} "
                              f"(one of {', '.join(sorted(_ARITY))})")
        low, high = _ARITY[verb]
        if not low <= len(args) <= high:
            raise ScriptError(f"{where} step {index + 1} {step!r}: {verb} takes {low}"
                              f"{'' if low == high else f' to {high}'} argument(s), got {len(args)}")
        numbers = {"aim": args, "look": args, "walk_to": args, "wait": args, "hold": args[1:]}.get(verb, ())
        for value in numbers:
            try:
                ok = math.isfinite(float(value))
            except ValueError:
                ok = False
            if not ok:
                raise ScriptError(f"{where} step {index + 1} {step!r}: {value!r} is not a number")
        if verb in ("wait", "hold") and not float(args[-1]) >= 1:
            raise ScriptError(f"{where} step {index + 1} {step!r}: the frame count must be >= 1")
        if verb == "click" and args[0] not in ("left", "right"):
            raise ScriptError(f"{where} step {index + 1} {step!r}: click takes left or right, got {args[0]!r}")
        commands.append(Command(verb, tuple(args)))
    return commands


class Autopilot:
    """Plays a script: ``fill(input, game)`` once before each frame."""

    def __init__(self, script: Sequence[str], where: str = "script") -> None:
        self.commands = parse_script(script, where)
        self.index = 0
        self._frames = 0  # frames spent on the current command
        self._travels = 0

    @property
    def done(self) -> bool:
        return self.index >= len(self.commands)

    def fill(self, state: Input, game: Pilotable) -> None:
        """Write this frame's input for the current command; move on when it is finished."""
        state.held.clear()
        while not self.done:
            command = self.commands[self.index]
            if self._frames == 0:
                self._travels = game.travel_count()
            finished = self._play(command, state, game)
            self._frames += 1
            if finished:
                self.index += 1
                self._frames = 0
            if finished is None:
                continue  # took no frame: go straight on to the next command
            return

    def _play(self, command: Command, state: Input, game: Pilotable) -> bool | None:
        verb, args = command.verb, command.args
        eye, yaw, pitch, sensitivity = game.player_view()
        if verb == "aim":
            x, y, z = (float(a) for a in args)
            dx, dy, dz = x - eye[0], y - eye[1], z - eye[2]
            self._turn(state, yaw, pitch, *yaw_pitch_of((dx, dy, dz)), sensitivity)
            return True
        if verb == "look":
            self._turn(state, yaw, pitch, float(args[0]), float(args[1]), sensitivity)
            return True
        if verb == "click":
            state.clicks.add(args[0])
            return True
        if verb == "press":
            state.press(args[0])
            return True
        if verb == "hold":
            state.press(*args[0].split("+"))
            return self._frames + 1 >= int(float(args[1]))
        if verb == "wait":
            return self._frames + 1 >= int(float(args[0]))
        # walk_to
        x, z = float(args[0]), float(args[1])
        limit = int(float(args[2])) if len(args) > 2 else 600
        dx, dz = x - eye[0], z - eye[2]
        if math.hypot(dx, dz) <= ARRIVED or game.travel_count() != self._travels or self._frames >= limit:
            return None if self._frames == 0 else True
        level = pitch - max(-10.0, min(10.0, pitch))  # eyes back to the horizon, 10 degrees a frame
        self._turn(state, yaw, pitch, yaw_pitch_of((dx, 0.0, dz))[0], level, sensitivity)
        state.press("w")
        return False

    @staticmethod
    def _turn(state: Input, yaw: float, pitch: float, to_yaw: float, to_pitch: float, sensitivity: float) -> None:
        turn = (to_yaw - yaw + 180.0) % 360.0 - 180.0
        state.mouse_dx += -turn / sensitivity
        state.mouse_dy += -(to_pitch - pitch) / sensitivity
