"""Stage "sun": each ``TimeOfDay`` moves its clock on and turns its ``DirectionalLight`` to
shine from where the sun stands then, or a moon's (``DirectionalLight.body``) from where the
moon does, its age moved on with the clock (``components/time_of_day.py``).

Before the stages that read the lights (prepare: the lights' rows, the sky's sun; shadows),
so a frame's light, its shadows and an atmosphere's sky agree.  The light's direction is
written every frame; a clock that stands still writes the value it holds, which changes
nothing (a component's field set to its own value raises no change flag: its shadow maps and
the sky's cube map are kept), and a light turned by other code is turned back."""
from __future__ import annotations

import warnings

import esper

from components import ComponentWarning, DirectionalLight
from components.time_of_day import DAYS_A_YEAR, SYNODIC_MONTH, TimeOfDay, moon_towards, sun_towards
from engine.core.world import World


class TimeOfDaySystem(esper.Processor):
    """Moves each TimeOfDay's clock and points its light."""

    def __init__(self, world: World) -> None:
        super().__init__()
        self.world = world
        self._said: set[int] = set()   # entities told they have no light

    def process(self, dt: float) -> None:
        world = self.world
        clocks = world.query_one(TimeOfDay)
        for entity, time in clocks:
            if time.hours_per_second != 0.0 and dt > 0.0:
                days, hour = divmod(time.hour + time.hours_per_second * dt, 24.0)
                if days:
                    time.day = (time.day - 1 + int(days)) % DAYS_A_YEAR + 1
                time.hour = hour
                time.moon_age = (time.moon_age + time.hours_per_second * dt / 24.0) % SYNODIC_MONTH
            light = world.try_get(entity, DirectionalLight)
            if light is None:
                if entity not in self._said:
                    self._said.add(entity)
                    warnings.warn(f"TimeOfDay on entity {entity}, which has no DirectionalLight: it turns nothing",
                                  ComponentWarning, stacklevel=2)
                continue
            light.direction = -(moon_towards(time) if light.body == "moon" else sun_towards(time))
        if self._said:
            self._said &= {entity for entity, _ in clocks}
