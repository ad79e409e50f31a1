"""aerobench scenes: specs, the renderer, exact ground truth, the sequence folder and its cache.

Importing this package does not touch OpenGL; the first render does
(``scenes.render`` is the only module that imports pyrender).
"""

from scenes.cache import CacheResult, cache_key, cached_sequence, cached_sequence_result
from scenes.ground_truth import PairTruth
from scenes.render import RendererUnavailableError
from scenes.sequence import ManifestError, Sequence, open_sequence, render_sequence
from scenes.spec import (
    GENERATOR_VERSION,
    SceneSpec,
    SceneSpecError,
    list_presets,
    load_scene_spec,
    spec_hash,
)

__all__ = [
    "GENERATOR_VERSION",
    "SceneSpec",
    "SceneSpecError",
    "load_scene_spec",
    "list_presets",
    "spec_hash",
    "render_sequence",
    "open_sequence",
    "Sequence",
    "PairTruth",
    "ManifestError",
    "cached_sequence",
    "cached_sequence_result",
    "CacheResult",
    "cache_key",
    "RendererUnavailableError",
]
