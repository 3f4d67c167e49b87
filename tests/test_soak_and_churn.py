"""Short soak and churn runs (the benchmarks ``soak`` and ``churn`` at small sizes): nothing
the engine holds grows over a tour of the sample level, and everything made in waves of
mirrors, portals, probes, meshes and textures goes back when they are deleted."""
from __future__ import annotations

from benchmarks import churn, soak


def test_a_tour_of_the_sample_level_holds_its_resources_flat():
    rows = soak.run(frames=90, every=30, warmup=30)
    assert [row["frame"] for row in rows] == [0, 30, 60, 90]
    assert rows[1]["gl_resources"]["probe_cubes"] == 3 and rows[1]["gl_resources"]["batches"] > 20
    assert soak.grew(rows, warmup=30, rss_slack=20.0) == []


def test_waves_of_mirrors_portals_probes_meshes_and_textures_all_go_back():
    rows = churn.run(entities=40, waves=2, frames=2)
    peak = rows[1]["peak_gl_resources"]
    assert peak["probe_cubes"] == 8 and peak["textures"] == 1 + 8 and peak["meshes"] >= 1 + 8 + 8
    assert churn.leftovers(rows, rss_slack=40.0) == []
    assert rows[-1]["gl_resources"]["batches"] == rows[0]["gl_resources"]["batches"]
