"""The frame report and the budget ledger: what one frame cost (``RenderStats``, a world
resource made fresh by ``shell.app.Engine.frame``; re-exported by ``engine.resources``) and
what its ``ViewBudget`` allowed and what was spent of it (``BudgetLedger``).

Plain data, no GL.  The passes count into the report while the frame runs (the renderer
holds the frame's object); the stages that draw extra views spend the ledger in the order
the frame runs them (the shadows stage's virtual lights, the probes stage's faces, the
reflect stage's view trees, the recaptures after present), each asking ``views_left`` (the
view trees ``pixels_left`` too) before it draws, and the probes' scheduler defers the faces
``probe_ms_budget`` leaves out; tests, benchmarks and the overlay read both after the frame.
The report is a ledger (one object a frame, so every spender and reader sees the same
counts): its fields are the ledger's and its own.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BudgetLedger", "RenderStats"]


@dataclass
class BudgetLedger:
    """The frame's view budget (``engine.resources.ViewBudget``): its limits (None: none),
    and what was spent (reflection views of every tree and probe faces drawn) and cut
    (views with pixels and probe faces the budget left out; the faces wait for a later
    frame)."""

    view_budget: int | None = None
    views_spent: int = 0
    views_cut: int = 0
    probe_ms_budget: float | None = None
    probe_ms_spent: float = 0.0         # the captures' cost by their measured ms a face
    probe_faces_deferred: int = 0       # faces due that the budgets left for a later frame
    pixel_budget: int | None = None
    pixels_spent: int = 0               # reflection pixels drawn, at the screen's resolution
    levels_downscaled: int = 0          # levels the pixel budget drew at a lower resolution
    min_view_pixels: int | None = None  # ViewBudget.min_pixels: a smaller view is not drawn
    views_small: int = 0                # views with pixels under it, shown as their fallback

    def pixels_left(self) -> int | None:
        """Reflection pixels the frame's budget still allows (None: no limit)."""
        return None if self.pixel_budget is None else max(self.pixel_budget - self.pixels_spent, 0)

    def views_left(self) -> int | None:
        """Views the frame's budget still allows (None: no limit)."""
        return None if self.view_budget is None else max(self.view_budget - self.views_spent, 0)


@dataclass
class RenderStats(BudgetLedger):
    """What the last frame cost, and its budget ledger: read by tests, benchmarks and the
    overlay."""

    passes: int = 0
    draw_calls: int = 0
    render_scale: float = 1.0              # the share of the output's size the main view was drawn at
    gpu_frame_ms: float | None = None      # the GPU's time over a recent frame (timed under ViewBudget.frame_ms)
    draws_culled: int = 0     # scene draws left out of a view their batch's boxes cannot reach (batch_cull)
    uploaded_bytes: int = 0
    instances: int = 0
    reflection_views: int = 0
    probe_captures: int = 0   # probes that captured at least one face this frame
    probe_faces: int = 0      # cube faces captured this frame
    volume_points: int = 0    # irradiance volume points captured this frame (six faces each)
    probe_path: str = ""      # the path of the last probe capture: "six_pass" or "layered" (while there are probes)
    reflection_views_dropped: int = 0   # views with pixels a level's view budget left out
    reflection_depth_capped: int = 0    # views the surfaces' own depth limits allowed below the tree's cap
    reflection_views_faded: int = 0     # mirror views their fades took out (each cost nothing)
    reflection_end_views: int = 0       # views past the depth limits shown as last frame's image
    reflection_visibility: str = ""     # "exact" or "predicted": how the main tree's levels knew their pixels
    reflection_views_unseen: int = 0    # views drawn that had no pixels last frame (predicted visibility)
    reflection_views_kept: int = 0      # main-tree views kept as last drawn: nothing they show changed
                                        # (ReflectionSystem.keep_still_views; not in passes)
    reflection_end_refills: int = 0     # end views filled again over a main tree otherwise kept: still, its
                                        # end images not settled yet (StillTree.keep; its views not kept above)
    # How reflection levels were drawn: "per_mirror", "batched", "mixed" (auto chose both in
    # one frame), or "" when no reflection view was drawn (ReflectionSystem.path); a frame that
    # kept its tree (reflection_views_kept) reports the path the kept views were drawn by.
    reflection_path: str = ""
    # The path self-check's verdicts so far on this context (engine/render/path_checks.py):
    # the alternative GL paths compared with their plain counterparts and trusted, or refused.
    paths_verified: tuple[str, ...] = ()
    paths_refused: tuple[str, ...] = ()
    # Shadow maps (systems/shadow_system.py): drawn this frame, kept from an earlier frame (no
    # caster or light changed), and lights whose shadows a limit left out (point lights past
    # MAX_POINT_SHADOWS); how the last point light's cube was drawn ("layered" or "six_pass").
    shadow_maps_drawn: int = 0           # (their draws: shadow_draw_calls, not in passes or draw_calls)
    shadow_draw_calls: int = 0
    shadow_texels_drawn: int = 0         # of directional maps: a moved caster redraws only its footprint's
    shadow_faces_drawn: int = 0          # of point lights' cubes: a spot's cone lights only some
    shadow_maps_kept: int = 0
    shadows_cut: int = 0
    # A sun's cascades about the camera (DirectionalLight.shadow_cascades; each a map, counted
    # in shadow_maps_drawn and _kept too) left out: the atlas's four tiles were taken.
    shadow_cascades_cut: int = 0
    # A monitor's picture's rings about its own camera (systems/shadow_rings.py) left out: the
    # free tiles' quarters were taken; it read the active camera's rings.
    picture_cascades_cut: int = 0
    # Lights past the Lights block's slots (views.MAX_DIRECTIONAL_LIGHTS directional,
    # MAX_POINT_LIGHTS point: those that matter most are kept, engine/rules/light_rules.py),
    # which light nothing this frame; set every frame while it lasts (the prepare stage warns
    # when it starts).
    lights_cut: int = 0
    contact_lamps_cut: int = 0           # point lights with contact_shadows past MAX_CONTACT_LAMPS (none there)
    rect_lights_cut: int = 0             # rectangle lights past MAX_RECT_LIGHTS (lit as points from their centres)
    fog_volumes_cut: int = 0             # FogVolumes past MAX_FOG_VOLUMES (the farthest from the camera: no fog)
    caustic_waters_cut: int = 0          # waters with caustics past MAX_CAUSTIC_WATERS (the farthest: no caustics)
    caustic_lamps_cut: int = 0           # lamps over caustic waters past MAX_CAUSTIC_LAMPS (the last slots: none)
    foam_waters_cut: int = 0             # waters with foam past MAX_FOAM_WATERS (the last by entity: none)
    ripple_waters_cut: int = 0           # waters with Ripples past MAX_RIPPLE_WATERS (the last by entity: still)
    ripple_drops: int = 0                # drops pushed into the waters' ripples this frame (Wakes', rain's)
    ripple_drops_cut: int = 0            # a water's drops this frame past MAX_RIPPLE_DROPS (left out)
    ripple_steps: int = 0                # simulation steps of the waters' ripples this frame (0: all calm)
    monitor_views: int = 0               # views drawn for monitors' pictures this frame (each picture's and its tree's)
    monitors_cut: int = 0                # monitors due this frame past MAX_MONITORS (their pictures kept)
    monitors_kept: int = 0               # monitors due this frame whose pictures nothing changed (kept, not drawn)
    monitors_unseen: int = 0             # monitors due this frame not drawn: update "when_seen", no view sees them
    volumetric_lamps_cut: int = 0        # point lights with volumetric past MAX_VOLUMETRIC_LAMPS (not in the air)
    virtual_lights: int = 0              # lights shining through mirrors and portals this frame
    virtual_lights_cut: int = 0          # ... that the limit or the view budget left out
    shadow_path: str = ""
    # Mirrors and portals seen without a view of their own (cut by a budget, faded, past the
    # depth limit, switched off), or partly faded, or an end view's pixels last frame's image
    # did not hold, that showed the fallback (the probe's or the sky's reflection) this
    # frame, in every tree: one per (parent view, surface).
    reflection_fallbacks: int = 0
    # Transparent batches a view blended between two see-through surfaces they cover (behind
    # one, in front of the other: slot_order.split_slot's limit of one claim a pixel), so
    # where they cover the farther surface it shows its own colour, not its reflection: one
    # per (view, batch) this frame.
    glass_between_surfaces: int = 0
    # Screen-space refraction (engine/render/screen_refraction.py): the most layers of glass
    # behind glass a level drew this frame (each its own copy and pass), and the refracting
    # instances past MAX_REFRACTION_LAYERS drawn in the last layer (RefractionLimitWarning).
    refraction_layers: int = 0
    refraction_layers_cut: int = 0
    # Views (or batched groups of a level's views) whose transparent slot was drawn in part after
    # their refracting surfaces: from the first of its things, back to front, that lies in front
    # of glass it meets on screen (ScenePass._slot_and_glass; the things before it are drawn
    # before the glass and shown through it, those after it that lie behind glass are not).
    slot_after_glass: int = 0
    # Particles (systems/particle_system.py): living this frame, every emitter's; and those the
    # emitters could not spawn this frame, their max_particles reached (ParticleLimitWarning).
    particles: int = 0
    particles_capped: int = 0
