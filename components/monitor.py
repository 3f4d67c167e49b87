"""Monitor: a screen that shows what a camera sees (a security camera's feed, a picture in a
picture, a periscope's eyepiece)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from components.tracking import HALF_MAX, TrackedComponent, _fail, choice, finite, integer

MIN_MONITOR_SIDE = 8       # pixels a side of a Monitor's picture at least
MAX_MONITOR_SIDE = 2048    # and at most (the GL context's own texture limit may be lower: said when drawn)
MAX_MONITOR_DEPTH = 8      # mirror and portal levels a monitor's picture may show
MONITOR_UPDATES = ("always", "when_seen")   # Monitor.update: when a due picture is drawn


@dataclass(eq=False)
class Monitor(TrackedComponent):
    """Makes its entity's mesh a screen showing what the entity ``camera`` sees: that entity's
    ``Camera`` (its field of view, near and far, projection and layers) from its ``Transform``,
    drawn by the same scene pass as every view into a picture of ``size`` pixels (its width
    over its height is the picture's aspect), which the mesh shows through its UVs as light it
    gives off: ``brightness`` x the camera's light (the linear colour the camera's own view
    would have before its tone curve), in place of its ``Emissive`` and emissive map.  The
    screen's Material still lights its glass (a dark, smooth one reflects a little of the room
    over the picture).  A camera that shows nobody's frame is one with ``Camera.active``
    False; the active camera may be shown too.

    - ``size``: (width, height) pixels of the picture, each in [8, 2048].
    - ``brightness``: how bright the picture is (1: as bright as what the camera sees).
    - ``every``: the picture is drawn again every ``every`` frames (1: every frame; a slow feed
      costs a view every few frames), the first on the frame it is added.
    - ``depth``: the mirror and portal levels its picture shows (0: each mirror and portal in
      it shows its fallback; at most ``MAX_MONITOR_DEPTH``).
    - ``update``: "always" (each time it is due) or "when_seen" (as Godot's viewports' "when
      visible"): a due picture is drawn only while its screen can be seen, by this frame's
      main view, a mirror's or portal's view of the frame before (so a screen first seen in a
      mirror shows its older picture for that one frame) or the last drawing of a monitor
      itself seen (its own camera's alone does not count), a probe's faces recaptured
      after the frame (a chrome ball by the screen reflects it), or on a ``ScreenPanel``; a
      monitor in another room costs nothing.  A probe's first capture (drawn before the
      monitors) and an irradiance volume's points keep the older picture of a screen unseen.

    On an entity with a ``ScreenPanel`` the panel is filled with the picture, over the frame
    (a rear-view mirror on the screen; the panel's colour multiplies it).

    A monitor that its own camera sees shows its picture of the frame before (a corridor of
    screens, as a real camera filming its monitor makes).  Up to ``MAX_MONITORS`` are drawn a
    frame (those that have waited longest; more keep their picture a frame longer, counted in
    ``RenderStats.monitors_cut`` and said when the count grows).  Level files name the camera by its entity's
    name (``camera = "lobby_camera"``)."""

    camera: int | None = None
    size: Any = field(default_factory=lambda: (256, 144))
    brightness: float = 1.0
    every: int = 1
    depth: int = 1
    update: str = "always"

    def _validate(self, name: str, value: Any) -> Any:
        if name == "camera":
            return None if value is None else integer(self, name, value, low=1, high=2**31 - 1)
        if name == "size":
            try:
                width, height = value
            except (TypeError, ValueError):
                raise _fail(self, name, value, "must be (width, height) in pixels") from None
            return (integer(self, name, width, low=MIN_MONITOR_SIDE, high=MAX_MONITOR_SIDE),
                    integer(self, name, height, low=MIN_MONITOR_SIDE, high=MAX_MONITOR_SIDE))
        if name == "brightness":
            return finite(self, name, value, low=0.0, high=HALF_MAX)
        if name == "every":
            return integer(self, name, value, low=1, high=10000)
        if name == "depth":
            return integer(self, name, value, low=0, high=MAX_MONITOR_DEPTH)
        if name == "update":
            return choice(self, name, value, MONITOR_UPDATES)
        return value
