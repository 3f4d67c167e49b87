"""Errors the engine raises for bad input; each message names the thing and the reason."""


class SpeculumError(Exception):
    """Base of the engine's own errors."""


class AssetError(SpeculumError):
    """A mesh or texture file is missing, unreadable, or holds data the engine cannot use."""


class GLCapabilityError(SpeculumError):
    """The OpenGL context lacks a version or feature the engine needs."""


class GLLimitError(GLCapabilityError):
    """A texture, target or probe larger than this context's limits (named, with the limit)."""


class GLPassError(SpeculumError):
    """An OpenGL error raised by a named pass (seen in debug mode, ``Renderer.debug``)."""


class MirrorError(SpeculumError, ValueError):
    """A Mirror component on something that cannot be a mirror."""


class ShaderError(SpeculumError):
    """A shader failed to load, include, compile or link."""


class StartOptionError(SpeculumError, ValueError):
    """A start option (``--camera``, ``--ao``, ``--ssr``, ``--altitude``) the game's world
    cannot take: it has no active camera to place or give the effect to, no atmosphere to
    stand in."""


class NoCameraWarning(UserWarning):
    """Frames are drawn with no active camera: they show nothing (said once until one comes)."""


class LightLimitWarning(UserWarning):
    """More lights of a kind than the Lights block holds: those that matter least light
    nothing (``engine/rules/light_rules.py``: point lights by their importance to the active
    camera, directional ones by luminance; said when the count grows, counted every frame in
    ``RenderStats.lights_cut``)."""


class GLLimitWarning(UserWarning):
    """A feature this context cannot draw (a limit below what it needs, named with the
    limit): what is drawn goes on without it, said once."""


class ParticleLimitWarning(UserWarning):
    """An emitter asked for more living particles than its ``ParticleEmitter.max_particles``:
    those past it are not spawned (counted every frame in ``RenderStats.particles_capped``;
    said when an emitter starts to be capped)."""


class VolumeLimitWarning(UserWarning):
    """More than ``MAX_IRRADIANCE_VOLUMES`` ``IrradianceVolume``s in a world: the lowest
    entities' light it, the others are ignored (said once)."""


class FogLimitWarning(UserWarning):
    """More ``FogVolume``s than ``MAX_FOG_VOLUMES``: those farthest from the active camera are
    left out (said when the count grows, counted every frame in ``RenderStats.fog_volumes_cut``)."""


class CausticLimitWarning(UserWarning):
    """More waters with caustics than ``MAX_CAUSTIC_WATERS``: only that many, the nearest the
    active camera, gather the sun (said when the count grows, counted every frame in
    ``RenderStats.caustic_waters_cut``)."""


class WaterLimitWarning(UserWarning):
    """More waters with foam than ``MAX_FOAM_WATERS`` (engine/render/foam.py): only that
    many, the first by entity, are drawn with it (said when the count grows, counted every
    frame in ``RenderStats.foam_waters_cut``); the same for ``Ripples`` past
    ``MAX_RIPPLE_WATERS`` (``RenderStats.ripple_waters_cut``), a water's drops past
    ``MAX_RIPPLE_DROPS`` a frame, and a ripple field too fine for ``MAX_RIPPLE_TEXELS``
    (engine/render/ripples.py)."""


class MonitorLimitWarning(UserWarning):
    """More monitors due to be drawn in a frame than ``MAX_MONITORS`` (engine/render/monitors.py):
    those that have waited longest are drawn, the others keep their pictures a frame longer
    (said when the count grows, counted every frame in ``RenderStats.monitors_cut``)."""


class RefractionLimitWarning(UserWarning):
    """More refracting surfaces lie behind one another on screen than
    ``MAX_REFRACTION_LAYERS``: those past it are drawn in the last layer and do not show the
    glass of that layer behind them (said once, counted every frame in
    ``RenderStats.refraction_layers_cut``)."""
