"""The debug overlay's text, worded from the engine's last frame.

Kept apart from ``shell/overlay.py`` (which draws it with Dear ImGui) so that what the
overlay says can be read and tested where imgui-bundle is not installed: a GPU machine the
report runs on, or a game that never opens the overlay.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import TYPE_CHECKING

from engine.core.budget import ViewBudget
from engine.core.frame_io import Output

if TYPE_CHECKING:  # the engine is the app's, which draws the overlay with this text
    from shell.app import Engine


def overlay_lines(engine: Engine, frame_times: Sequence[float]) -> list[str]:
    """The overlay's text, from the engine's last frame: the one place it is worded, shared by
    the overlay and the tests that check its numbers against ``RenderStats``."""
    stats = engine.renderer.stats
    reflect = engine.reflection_system
    probes = engine.stages["probes"]
    shadows_on = engine.stages["shadows"].enabled
    monitors = bool(engine.renderer.monitors.entities)   # (a line while there are monitors, not only when drawn)
    seconds = sum(frame_times) / len(frame_times) if frame_times else 0.0
    fps = 1.0 / seconds if seconds > 0 else 0.0
    levels = Counter(view.level for view in reflect.views)
    per_level = " / ".join(str(levels[level]) for level in range(max(levels) + 1)) if levels else "-"
    budget = "none" if reflect.level_budget is None else str(reflect.level_budget)
    chosen = f", chose {probes.chosen_path}" if probes.path == "auto" and probes.chosen_path else ""
    stopped = engine.game_guard.stopped
    return [
        *([f"game stopped in {stopped} (F5 resumes; the traceback is on the console)"] if stopped else []),
        f"{fps:.1f} fps, {seconds * 1000.0:.2f} ms a frame",
        f"passes {stats.passes}, draw calls {stats.draw_calls}",
        f"particles {stats.particles}"
        f"{f', {stats.particles_capped} not born (max_particles)' if stats.particles_capped else ''}",
        f"views per level {per_level}",
        f"reflection views {stats.reflection_views}, dropped {stats.reflection_views_dropped}, "
        f"capped {stats.reflection_depth_capped}, faded {stats.reflection_views_faded}, "
        f"fallbacks {stats.reflection_fallbacks}",
        f"probe captures {stats.probe_captures} ({stats.probe_faces} faces)"
        f"{f', volume points {stats.volume_points}' if stats.volume_points else ''}; shadow maps "
        f"{stats.shadow_maps_drawn}{f' ({stats.shadow_faces_drawn} cube faces)' if stats.shadow_faces_drawn else ''}"
        f" + {stats.shadow_maps_kept} kept{'' if shadows_on else ' (off)'}",
        *([f"monitors: views {stats.monitor_views}, pictures kept {stats.monitors_kept}, unseen "
            f"{stats.monitors_unseen}"] if monitors else []),
        f"cut: lights {stats.lights_cut}, shadows {stats.shadows_cut}"
        f"{f', cascades {stats.shadow_cascades_cut}' if stats.shadow_cascades_cut else ''}"
        f"{f', picture cascades {stats.picture_cascades_cut}' if stats.picture_cascades_cut else ''}"
        f"{f', rectangles (lit as points) {stats.rect_lights_cut}' if stats.rect_lights_cut else ''}"
        f"{f', fog volumes {stats.fog_volumes_cut}' if stats.fog_volumes_cut else ''}"
        f"{f', caustic waters {stats.caustic_waters_cut}' if stats.caustic_waters_cut else ''}"
        f"{f', caustic lamps {stats.caustic_lamps_cut}' if stats.caustic_lamps_cut else ''}"
        f"{f', rippling waters {stats.ripple_waters_cut}' if stats.ripple_waters_cut else ''}"
        f"{f', ripple drops {stats.ripple_drops_cut}' if stats.ripple_drops_cut else ''}"
        f"{f', monitors {stats.monitors_cut}' if stats.monitors_cut else ''}, "
        f"lights through mirrors {stats.virtual_lights_cut} (shining {stats.virtual_lights})",
        f"view budget {'none' if stats.view_budget is None else stats.view_budget}: spent {stats.views_spent}, "
        f"cut {stats.views_cut}",
        f"smallest view {'any' if stats.min_view_pixels is None else f'{stats.min_view_pixels} px'}: "
        f"{stats.views_small} smaller shown as fallbacks",
        f"pixel budget {'none' if stats.pixel_budget is None else stats.pixel_budget}: spent {stats.pixels_spent}, "
        f"{stats.levels_downscaled} levels smaller",
        f"probe budget {'none' if stats.probe_ms_budget is None else f'{stats.probe_ms_budget:g} ms'}: "
        f"spent {stats.probe_ms_spent:.1f} ms, {stats.probe_faces_deferred} faces wait",
        f"reflection path {stats.reflection_path or '-'} (set: {reflect.path}, budget {budget})",
        f"visibility {stats.reflection_visibility or '-'} (set: {reflect.visibility}), "
        f"{stats.reflection_views_unseen} views drawn unseen",
        f"views kept {stats.reflection_views_kept}, end views refilled {stats.reflection_end_refills} "
        f"(keep still views: {'on' if reflect.keep_still_views else 'off'})",
        f"probe path {stats.probe_path or '-'} (set: {probes.path}{chosen})",
        f"GL paths verified: {', '.join(stats.paths_verified) or '-'}; "
        f"refused: {', '.join(stats.paths_refused) or '-'}",
        *post_lines(engine),
    ]


def post_lines(engine: Engine) -> list[str]:
    """The present stage's post-processing in the last frame, a line: the tone curve (and
    whose it is), the exposure, the bloom (intensity, levels), the grade (and its colour
    table's name), the post passes drawn; and a line of the main stage's screen-space
    passes: ambient occlusion (radius, intensity) and reflections (reach, quality), and the
    materials' sky reflections where the overlay turned them off, and the camera's depth of
    field (its f-number and focus: autofocus's read back, a wait too) and motion blur (its
    shutter, and how many things streak by their own motion, or "camera only").  (One
    line grew the overlay's window over the view it is clicked through.)  The automatic
    exposure's adapted value is read back from the GPU (a wait, only while the overlay
    shows it)."""
    present, renderer = engine.stages["present"], engine.renderer
    tonemap, bloom = present.tonemap, present.bloomed
    camera_curve = tonemap.curve if tonemap is not None else "none"
    curve = present.curve or camera_curve
    whose = "camera" if present.curve is None else f"set; camera {camera_curve}"
    if tonemap is None:
        exposure = f"x{renderer.exposure:g}"
    else:
        exposure = f"{tonemap.exposure:+.2f} EV"
        if tonemap.auto_exposure:
            adapted = renderer.present_pass.auto_exposure.adapted_ev()
            exposure += f", auto {'-' if adapted is None else f'{adapted:+.2f}'}"
    if bloom is not None:
        glow = f"bloom {bloom.intensity:g} x{renderer.present_pass.bloom.levels}"
    else:
        glow = "bloom off" + (" (set)" if not present.bloom else "")
    graded, grade = present.graded, ""
    if graded is not None:
        grade = "; graded" + (f", table {graded.lut.name!r}" if graded.lut is not None else "")
    elif not present.grade:
        grade = "; grade off (set)"
    if present.vignetted is not None:
        grade += f"; vignette {present.vignetted.intensity:g}"
    if present.fringed is not None:
        grade += f"; fringes {present.fringed.intensity:g}"
    if present.grained is not None:
        grade += f"; grain {present.grained.intensity:g}"
    main = engine.stages["main"]
    occluded = main.occluded
    if occluded is not None:
        occlusion = (f"AO r {occluded.radius:g} x{occluded.intensity:g}"
                     f"{'' if occluded.half_resolution else ' full'}{_levels(occluded.reflection_depth)}")
    else:
        occlusion = "AO off" + (" (set)" if not main.occlusion else "")
    if main.contact_shadowed is not None:
        contact = main.contact_shadowed
        lamps = main.contact_lamps
        occlusion += (f"; contact shadows {contact.length:g} m{' half' if contact.half_resolution else ''}"
                      f"{_levels(contact.reflection_depth)}{f', {lamps} lamp' + 's' * (lamps > 1) if lamps else ''}")
    reflected = main.reflected
    if reflected is not None:
        reflections = (f"SSR {reflected.max_distance:g} m {reflected.quality}"
                       f"{' half' if reflected.half_resolution else ''}{_levels(reflected.reflection_depth)}")
    else:
        reflections = "SSR off" + (" (set)" if not main.reflections else "")
    if not engine.stages["prepare"].environment_reflections:
        reflections += "; sky reflections off (set)"
    focused = present.focused
    if focused is not None:
        distance = renderer.present_pass.depth_of_field.focused() if focused.autofocus else focused.focus_distance
        reflections += (f"; DoF f/{focused.f_stop:g} at {'-' if distance is None else f'{distance:.3g}'} m"
                        f"{' auto' if focused.autofocus else ''}")
    elif not present.depth_of_field:
        reflections += "; DoF off (set)"
    if present.streaked is not None:
        movers = renderer.object_motion.count
        reflections += (f"; motion blur {present.streaked.shutter:g}"
                        + (f", {movers} moving" if present.streaked.objects else ", camera only"))
    elif not present.motion_blur:
        reflections += "; motion blur off (set)"
    if main.shafts is not None:
        reflections += f"; shafts {main.shafts.steps} steps{' half' if main.shafts.half_resolution else ''}"
    passes = renderer.present_pass.post_passes
    return [f"post: {curve} ({whose}), {exposure}; {glow}, {passes} passes{grade}{picture(engine)}",
            f"screen: {occlusion}; {reflections}"]


def picture(engine: Engine) -> str:
    """At a render scale other than 1, the size the picture is drawn at against the output's
    and how it is brought up (or, supersampled, down); under a ViewBudget's ``frame_ms`` the dynamic scale and the GPU's
    frame time against it; the sharpening where there is some ("" for none of them)."""
    renderer = engine.renderer
    output = engine.world.resources.get(Output)
    words = ""
    if output is not None and renderer.targets is not None and renderer.targets.size != output.size:
        (w, h), (ow, oh) = renderer.targets.size, output.size
        how = "a box filter" if w > ow else "TAA" if renderer.antialias == "taa" else "Catmull-Rom"
        words += f"; drawn {w}x{h} of {ow}x{oh} by {how}"
    budget = engine.world.resources.get(ViewBudget)
    if isinstance(budget, ViewBudget) and budget.frame_ms is not None:
        gpu = renderer.stats.gpu_frame_ms
        words += (f"; dynamic x{renderer.stats.render_scale:.2f}, GPU {'-' if gpu is None else f'{gpu:.2f}'} "
                  f"of {budget.frame_ms:g} ms")
    if renderer.sharpness > 0.0:
        words += f"; sharpen {renderer.sharpness:g}"
    return words


def _levels(depth: int) -> str:
    """How many mirror and portal levels a screen pass reaches (``reflection_depth``), for its line."""
    return "" if depth == 0 else f", {depth} mirror level{'s' if depth > 1 else ''}"
