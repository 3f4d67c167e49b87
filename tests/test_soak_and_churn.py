"""Short soak and churn runs (the benchmarks ``soak`` and ``churn`` at small sizes, the tours'
probes' faces 32 texels: at 128 a quarter of a tour's time, and the same resources): nothing
the engine holds grows over a tour of the sample level, and everything made in waves of
mirrors, portals, probes, meshes, textures, particle emitters, decals and weather (a pond with
caustics, lamps that cast, a spot's cookie, clouds, a fog volume) goes back when they are deleted."""
from __future__ import annotations

from benchmarks import churn, soak


def test_a_tour_of_the_sample_level_holds_its_resources_flat():
    rows = soak.run(frames=90, every=30, warmup=30, size=(160, 90), probe_resolution=32)
    assert [row["frame"] for row in rows] == [0, 30, 60, 90]
    assert rows[1]["gl_resources"]["probe_cubes"] == 3 and rows[1]["gl_resources"]["batches"] > 10
    assert soak.grew(rows, warmup=30, rss_slack=20.0) == []


def test_a_tour_through_a_lens_with_motion_blur_and_dynamic_resolution_holds_its_resources_flat():
    """The same tour with depth of field and motion blur on the camera (the spinning crates
    streaking by their own motion), temporal AA, and dynamic resolution driven to its floor
    (frames 0-39) and back up (from 40, step by step): the post images, the movers' texture,
    the four-channel seen images and TAA's history are made once and kept (the lens and the
    blur run at the output's size after temporal upsampling); every level's targets and the
    reactive mask are made again at each step; nothing grows from frame 32 (at the floor) to
    64 (three steps up)."""
    rows = soak.run(frames=64, every=32, warmup=32, size=(96, 54), lens=True, dynamic=True,
                    probe_resolution=32)
    counts = rows[-1]["gl_resources"]
    assert counts["object_motion"] == 1 and counts["post_targets"] > 4
    assert soak.grew(rows, warmup=32, rss_slack=20.0) == []


def test_a_day_and_a_night_under_an_atmosphere_hold_their_resources_flat():
    """The tour under an atmosphere with stars, its sun going a quarter of the way round the
    sky from frame 30 to 90 (its sky-view table drawn every frame, the cube map and the sky's
    light every degree): nothing grows."""
    rows = soak.run(frames=90, every=30, warmup=30, size=(96, 54), day=True, probe_resolution=32)
    counts = rows[-1]["gl_resources"]
    assert counts["sky_view"] == 1 and counts["sky_space"] == 1
    assert soak.grew(rows, warmup=30, rss_slack=20.0) == []


def test_waves_of_mirrors_portals_probes_meshes_and_textures_all_go_back():
    rows = churn.run(entities=40, waves=2, frames=2)
    peak = rows[1]["peak_gl_resources"]
    mirrors, spheres, boxes, textured, emitters, decals = (churn.of_kind(kind, 40) for kind in (0, 2, 3, 4, 5, 6))
    # (A probe cube a chrome sphere, and the wave's irradiance volume's scratch cube; the
    # weather's pond has its wave map; its spot's cookie is in the cookie atlas.)
    assert peak["probe_cubes"] == spheres + 1
    assert peak["textures"] == 1 + textured + emitters + decals + churn.WEATHER_TEXTURES
    assert peak["shadow_cubes"] >= 1 and peak["spot_cookies"] == 1
    assert peak["meshes"] >= 1 + mirrors + boxes + decals and peak["particle_buffers"] == emitters
    assert churn.leftovers(rows, rss_slack=40.0) == []
    assert rows[-1]["gl_resources"]["batches"] == rows[0]["gl_resources"]["batches"]


def _churn_arena():
    """The churn benchmark's arena, one frame drawn (a test spawns its waves with
    ``churn.spawn_wave``): the context, the engine, its capture target and output."""
    from engine.core.frame_io import Output
    from engine.render.gl_context import create_headless_context
    from engine.render.targets import CaptureTarget
    from shell.app import Engine

    ctx = create_headless_context()
    engine = Engine(churn.Arena(), ctx)
    capture = CaptureTarget(ctx, (96, 54))
    output = Output(capture.framebuffer, (96, 54))
    engine.frame(1 / 60, output)
    return ctx, engine, capture, output


def test_the_planners_memory_grows_with_the_surfaces_not_with_their_square():
    """A hundred things (17 mirrors, 17 portal pairs, 17 probes whose faces see them, and the rest): the
    planner keeps each view's camera-free rows by its view mask and winding, not by the
    surface it looks out of, so what it keeps is (classes x surfaces) rows, not (surfaces x
    surfaces) for each probe's face tree.  Kept by exit row, these frames peaked at 313 MiB
    of Python memory (the churn benchmark's thousand things: 24 GiB, and the process was
    killed); now about 18."""
    import tracemalloc

    ctx, engine, capture, output = _churn_arena()
    try:
        tracemalloc.start()
        try:
            churn.spawn_wave(engine.world, 100, 1)
            for _ in range(3):
                engine.frame(1 / 60, output)
            ctx.finish()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert engine.renderer.stats.reflection_views > 0  # the surfaces were planned and drawn
        assert peak < 60 * 2**20, f"{peak / 2**20:.0f} MiB of Python memory at the peak"
    finally:
        capture.release()
        engine.close()
        ctx.release()


def test_the_cull_keeps_a_bias_row_a_class_of_view_not_a_row_a_surface_looked_out_of():
    """The cull's bias tables (which surfaces a parent may see) keep a row for each class of
    view (view mask and winding), the surface a view looks out of knocked out as the rows are
    gathered: kept a row an ids number (one a surface looked out of, a class), they were
    (surfaces x classes) x surfaces, 128 MB a table at 2000 surfaces, grown by a copy of the
    whole table each time a new number came.  Which surfaces each parent may see is checked
    by tests/test_view_plan_grids.py against the rule written out."""
    from engine.render.plan_rows import CLASS_OF, IDS_OF
    from engine.render.surface_table import PlannerSurfaces
    from engine.resources import Surfaces

    ctx, engine, capture, output = _churn_arena()
    try:
        churn.spawn_wave(engine.world, 100, 1)
        for _ in range(3):
            engine.frame(1 / 60, output)
        table = engine.world.resources[PlannerSurfaces].table
        surfaces = len(table.states)
        undersides = len(engine.world.resources[Surfaces].undersides)   # (a water's: its second row)
        assert surfaces == churn.of_kind(0, 100) + 2 * churn.of_kind(1, 100) + churn.WEATHER_MIRRORS + undersides
        assert engine.renderer.stats.reflection_views > 0
        assert len(IDS_OF) > 2 * len(CLASS_OF)  # (numbers were many: a row each would show)
        tables = [rows for _, rows in table._bias_tables.values()]
        assert tables and all(rows.shape == (len(rows), surfaces + 1) for rows in tables)
        assert max(len(rows) for rows in tables) <= len(CLASS_OF)
    finally:
        capture.release()
        engine.close()
        ctx.release()


def test_deleting_every_mirror_and_portal_lets_the_planners_table_go():
    """The planner's table of the surfaces (tens of MB for hundreds of them) is named weakly by
    the caches that key on it (the water flows, the unlit mirrors, the end surfaces), so once
    every surface is deleted nothing keeps it: no later render comes to replace it."""
    import gc
    import weakref

    from engine.render.surface_table import PlannerSurfaces
    from engine.resources import Surfaces

    ctx, engine, capture, output = _churn_arena()
    try:
        made = churn.spawn_wave(engine.world, 40, 1)
        for _ in range(2):
            engine.frame(1 / 60, output)
        table = weakref.ref(engine.world.resources[PlannerSurfaces].table)
        undersides = len(engine.world.resources[Surfaces].undersides)   # (a water's: its second row)
        assert len(table().states) == (churn.of_kind(0, 40) + 2 * churn.of_kind(1, 40) + churn.WEATHER_MIRRORS
                                       + undersides)
        for entity in made:
            engine.world.delete_entity(entity)
        for _ in range(2):
            engine.frame(1 / 60, output)
        gc.collect()
        assert table() is None, [type(r).__name__ for r in gc.get_referrers(table())]
    finally:
        capture.release()
        engine.close()
        ctx.release()
