"""The report's 'Real footage' and 'Synthetic vs real' sections on a run of tiny beside tiny read back as footage."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from harness.runner import run_suite
from harness.suites import parse_suite
from reports import write_report
from reports.model import build_model

PIPES = ["dis", "farneback", "pyramidal-lk"]
# the synthetic reading knows its ground sampling distance and applies the detection's limits in m^2; footage
# has none: without those limits both readings give the pipelines the same inputs, so the same counts
_NO_M2 = {"detection": {"min_area_m2": None, "max_area_m2": None, "min_box_m2": None}}


@pytest.fixture(scope="module")
def mixed_run(tmp_path_factory) -> Path:
    """tiny (seed 1) rendered, and the same frames exported with MOTChallenge truth as a real clip."""
    from scenes import cached_sequence, load_scene_spec, open_sequence
    from scenes.footage import export_mot_gt

    base = tmp_path_factory.mktemp("real_sections")
    cache = base / "cache"
    seq = open_sequence(cached_sequence(load_scene_spec("tiny", overrides={"seed": 1}), cache))
    frames = base / "clip" / "img1"
    frames.mkdir(parents=True)
    for i in range(len(seq)):
        (frames / f"{i + 1:06d}.png").write_bytes((seq.path / "frames" / f"{i:06d}.png").read_bytes())
    gt = export_mot_gt(seq.tracks, base / "clip" / "gt" / "gt.txt")
    suite = parse_suite({"name": "mixed", "scenes": [{"preset": "tiny"},
                                                      {"real": str(frames), "label": "clip", "gt": str(gt)}],
                         "seeds": [1], "pipelines": [{"name": p, "base": p, "spec": _NO_M2} for p in PIPES],
                         "picture_pairs": [0]})
    result = run_suite(suite, base / "run", workers=1, cache_dir=cache, progress=False)
    assert result.ok
    return base / "run"


def test_the_same_frames_read_as_footage_rank_the_pipelines_the_same_way(mixed_run):
    model = build_model(mixed_run)
    assert model.real_scenes == ["clip"]
    svr = model.synthetic_vs_real
    assert svr.synthetic_scenes == ["tiny"] and svr.real_scenes == ["clip"]
    by = {v.label: v for v in svr.views}
    # the tracking counts are the same on both readings (the round trip), so are the ranks
    assert "mota (multi)" in by
    m = by["mota (multi)"]
    np.testing.assert_allclose(m.synthetic, m.real, atol=1e-12)
    np.testing.assert_array_equal(m.rank_synthetic, m.rank_real)
    # flow truth exists for the synthetic scene only: no flow view can be compared
    assert not any(v.metric.startswith("epe") for v in svr.views)
    table = model.real_tables["clip"]
    assert table.pipelines == PIPES
    assert all(np.isfinite(table.values[(p, "mota")]) for p in PIPES)
    assert "epe_mean" not in {c.metric for c in table.columns}


def test_the_sections_show_tables_pictures_and_one_verdict_and_n_a_where_truth_is_absent(mixed_run):
    write_report(mixed_run, workers=1)
    page = (mixed_run / "report.html").read_text()
    assert '<section id="real-footage">' in page and '<section id="synthetic-vs-real">' in page
    real = page[page.index('<section id="real-footage">'):page.index('<section id="synthetic-vs-real">')]
    pics = re.findall(r'src="(report_files/[^"]+)"', real)
    assert len(pics) == len(PIPES)  # one annotated frame per pipeline
    assert all((mixed_run / p).is_file() for p in pics)
    svr = page[page.index('<section id="synthetic-vs-real">'):]
    svr = svr[:svr.index("</section>")]
    assert svr.count('class="verdict-line"') == 1 and "Spearman" in svr
    md = (mixed_run / "report.md").read_text()
    assert "## Real footage" in md and "## Synthetic vs real" in md
    # the per-scene table of the clip: flow errors have no truth there, printed n/a (never 0)
    clip = md[md.index("### clip"):]
    clip = clip[:clip.index("\n\n", clip.index("|"))]
    assert "n/a" in clip or "epe" not in clip
