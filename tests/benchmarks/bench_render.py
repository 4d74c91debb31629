"""Whole frames of the paper's experiment (depth 2, no shadow rays, 128x128, 2 spp)
per scene and configuration, the same configurations as ``raysort bench``
(every installed traversal, yardsticks included)."""
import pytest

import raysort
from raysort.bench import load_table

CONFIGS = {c.label: c for c in load_table().frame_configs()}


@pytest.mark.parametrize("label", list(CONFIGS))
@pytest.mark.parametrize("scene_name", ["sibenik", "sponza", "forest"])
def test_render(benchmark, scene_cache, scene_name, label):
    config = CONFIGS[label]
    pipe = raysort.Pipeline(scene_cache(scene_name),
                            shader={"type": "lambert", "max_depth": 2, "shadow_rays": False},
                            traversal=config.traversal, sorter=config.sorter)
    results = []
    benchmark.group = f"{scene_name}: render"
    benchmark.pedantic(lambda: results.append(pipe.render(128, 128, 2, 0)), rounds=3,
                       warmup_rounds=1)
    stats = results[-1].stats
    benchmark.extra_info.update(
        rays=stats.total_rays, mrays_per_second=stats.total_rays / benchmark.stats.stats.min / 1e6,
        counters_per_ray=stats.closest_hit_counters().per_ray())
