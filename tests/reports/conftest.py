"""A small synthetic run folder that follows the run-folder contract of docs/architecture.md.

2 scenes x 3 sweep values x 5 pipelines, one seed, one failed cell, two tiny
sequence folders (written with scenes.formats) in the cache dir named in
run.json, and the cell artifacts (flow_000002.flo, local_flow_000002.flo, stabilisation.csv,
tracks.csv, error.txt). The numbers are synthetic but self-consistent: every
row's value is sum / count, and counts differ between frames so a pooled
aggregate differs from an average of per-frame averages.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from algorithms.pipeline import PIPELINES as BUILTIN_PIPELINES
from harness import cell_artifacts as artifacts
from harness.results import check_schema, summarize, write_table
from harness.run_folder import cell_entry, write_run
from scenes.formats import write_flo, write_png

PIPELINES = ["lk_thesis", "hs_thesis", "lk_pyramid", "hs_pyramid", "dis"]
# names that do not say thesis-lk etc.: the report must find LK / HS twins by their flow method
SPECS = {"lk_thesis": "thesis-lk", "hs_thesis": "thesis-hs", "lk_pyramid": "pyramidal-lk",
         "hs_pyramid": "pyramidal-hs", "dis": "dis"}
# scene -> (swept parameter, values)
SCENES = {"urban": ("jitter_px", [0.0, 2.0, 4.0]), "rural": ("noise_sigma", [0.0, 5.0, 10.0])}
FAILED = ("rural", 10.0, "hs_thesis")
FAILED_ERROR = "FloatingPointError: Horn-Schunck iteration diverged at pair 2 (<alpha> too small)"
N_FRAMES = 5
H, W = 24, 32
PICTURE_FRAME = 2
VEHICLE_LOCAL_PX = (3.0, 1.0)  # the moving vehicle's own image motion per pair (flow - flow_camera)
# metric -> (unit, higher_is_better, kind), as harness.metrics registers them
METRICS = {
    "epe_mean": ("px", False, "accuracy"),
    "ae_mean": ("deg", False, "accuracy"),
    "outlier_3px": ("%", False, "accuracy"),
    "time_total_ms": ("ms", False, "timing"),
    "jitter_residual_rms": ("px", False, "accuracy"),
    "track_error": ("px", False, "accuracy"),
    "track_completeness": ("%", True, "accuracy"),
}
# pipeline quality factor: error grows with it (dis best, hs_thesis worst)
QUALITY = {"lk_thesis": 1.6, "hs_thesis": 2.1, "lk_pyramid": 0.9, "hs_pyramid": 1.1, "dis": 0.7}


def _scene_hash(scene: str, value: float) -> str:
    return f"{scene[:3]}{int(value * 10):04d}"


def _write_sequence(seq: Path, rng: np.random.Generator) -> None:
    """A tiny sequence folder: textured frames drifting right, constant truth flow, camera.csv."""
    t = np.arange(N_FRAMES)
    jitter_x = np.array([0.0, 1.5, -1.0, 0.5, -0.8])
    jitter_y = np.array([0.0, -0.7, 0.9, -0.3, 0.2])
    base = (rng.random((H, W * 2, 3)) * 255).astype(np.uint8)
    for i in range(N_FRAMES):
        write_png(seq / "frames" / f"{i:06d}.png", np.ascontiguousarray(base[:, i:i + W]))
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    for i in range(N_FRAMES - 1):
        flow = np.stack([np.full((H, W), 2.0, np.float32) + 0.1 * xs / W,
                         np.full((H, W), -1.0, np.float32) + 0.1 * ys / H], axis=-1)
        write_flo(seq / "flow_camera" / f"{i:06d}.flo", flow)  # the ground's motion
        flow[8:14, 10:18] += np.array(VEHICLE_LOCAL_PX, np.float32)  # a vehicle's own motion on top
        write_flo(seq / "flow" / f"{i:06d}.flo", flow)
        valid = np.full((H, W), 255, np.uint8)
        valid[:, -3:] = 0
        write_png(seq / "valid" / f"{i:06d}.png", valid)
        write_png(seq / "instances" / f"{i:06d}.png", np.zeros((H, W), np.uint16))
    cam = pd.DataFrame({
        "frame": t, "t_s": t / 10.0, "x_m": t * 2.0, "y_m": 0.0, "z_m": 100.0,
        "qw": 1.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "fx_px": 40.0, "fy_px": 40.0, "cx_px": 16.0,
        "cy_px": 12.0, "jitter_x_px": jitter_x, "jitter_y_px": jitter_y,
        "global_dx_px": [2.0 + jitter_x[i + 1] - jitter_x[i] for i in range(N_FRAMES - 1)] + [np.nan],
        "global_dy_px": [-1.0 + jitter_y[i + 1] - jitter_y[i] for i in range(N_FRAMES - 1)] + [np.nan],
    })
    cam.to_csv(seq / "camera.csv", index=False)
    pd.DataFrame({"frame": t, "vehicle_id": 1, "x_px": 14.0 + 5.0 * t, "y_px": 11.0 + 0.5 * t,
                  "bbox_x0_px": 10.0, "bbox_y0_px": 8.0, "bbox_x1_px": 18.0, "bbox_y1_px": 14.0,
                  "visible": 1, "speed_mps": 12.0, "parked": 0}).to_csv(seq / "tracks.csv", index=False)
    (seq / "meta.json").write_text(json.dumps({"width": W, "height": H, "n_frames": N_FRAMES, "fps": 10}))
    (seq / "MANIFEST.json").write_text("{}")


def _cell_rows(common: dict, rng: np.random.Generator, q: float, difficulty: float) -> list[dict]:
    rows = []

    def add(metric, frame, s, c, value, track_id=None, region="all", motion="total"):
        unit, hib, kind = METRICS[metric]
        rows.append({**common, "frame": frame, "track_id": track_id, "metric": metric, "region": region,
                     "motion": motion, "kind": kind, "value": value, "sum": s, "count": float(c),
                     "unit": unit, "higher_is_better": hib, "hist": "", "status": "ok", "error": ""})

    for f in range(N_FRAMES - 1):
        n = int(500 + 150 * f)  # valid pixels differ per pair
        epe = q * (0.4 + 0.15 * difficulty) * (1 + 0.3 * rng.random())
        add("epe_mean", f, epe * n, n, epe)
        n_veh = 40 + 7 * f
        add("epe_mean", f, 2.5 * epe * n_veh, n_veh, 2.5 * epe, region="vehicles")
        add("epe_mean", f, 0.6 * epe * n, n, 0.6 * epe, motion="local")
        add("ae_mean", f, 6.0 * epe * n, n, 6.0 * epe)
        n_out = round(min(0.9, 0.05 * epe) * n)
        add("outlier_3px", f, n_out, n, 100.0 * n_out / n)  # rate: 100 * sum / count
        ms = {0.7: 3.0, 0.9: 40.0, 1.1: 90.0, 1.6: 12.0, 2.1: 25.0}[q] * (1 + 0.1 * rng.random())
        add("time_total_ms", f, ms, 1, ms, motion="cost")
    for f in range(N_FRAMES):
        r = (0.2 + 0.1 * difficulty) * (1 + rng.random())
        add("jitter_residual_rms", f, r * r, 1, r, motion="jitter")  # rms: sqrt(sum / count)
        e = q * (0.5 + 0.2 * difficulty) * (1 + rng.random())
        add("track_error", f, e, 1, e, track_id=1, region="point", motion="track")
    k = 5 - round(q)  # vehicle-frames tracked out of 5
    add("track_completeness", None, k, 5, 100.0 * k / 5, track_id=1, region="point", motion="track")
    return rows


def _cell_artifacts(cell: Path, seq: Path | None, rng: np.random.Generator, q: float) -> None:
    t = np.arange(N_FRAMES, dtype=float)
    jit_true = np.array([[0.0, 0.0], [1.5, -0.7], [-1.0, 0.9], [0.5, -0.3], [-0.8, 0.2]])
    cum_true = np.stack([2.0 * t, -1.0 * t], 1) + jit_true - jit_true[0]
    cum = cum_true + 0.1 * q * rng.standard_normal((N_FRAMES, 2))
    A = np.stack([t, np.ones_like(t)], 1)
    coef, *_ = np.linalg.lstsq(A, cum, rcond=None)
    line = A @ coef
    jit = cum - line
    stab = pd.DataFrame({"frame": t.astype(int)})
    for k, a in enumerate("xy"):
        stab[f"cumulative_{a}_px"] = cum[:, k]
        stab[f"flight_line_{a}_px"] = line[:, k]
        stab[f"correction_{a}_px"] = -jit[:, k]
        stab[f"jitter_{a}_px"] = jit[:, k]
    for k, a in enumerate("xy"):
        stab[f"true_cumulative_{a}_px"] = cum_true[:, k]
    for k, a in enumerate("xy"):
        stab[f"true_jitter_{a}_px"] = jit_true[:, k]
    artifacts.write_stabilisation(cell, stab)
    gt_x, gt_y = 14.0 + 5.0 * t, 11.0 + 0.5 * t
    meas_x = gt_x + q * rng.standard_normal(N_FRAMES)
    meas_y = gt_y + q * rng.standard_normal(N_FRAMES)
    point = pd.DataFrame({"frame": t.astype(int), "track_id": 0, "x_px": meas_x, "y_px": meas_y,
                          "x_filt_px": (meas_x + gt_x) / 2, "y_filt_px": (meas_y + gt_y) / 2,
                          "x_pred_px": meas_x, "y_pred_px": meas_y, "source": "point", "seed_vehicle_id": 1,
                          "true_x_px": gt_x, "true_y_px": gt_y, "true_visible": 1})
    # the multi-target tracker numbers its tracks from 0 too, far from the point track, without truth
    mx, my = 2.0 + 0.2 * t[:-1], 21.0 - 0.1 * t[:-1]
    multi = pd.DataFrame({"frame": t[:-1].astype(int), "track_id": 0, "x_px": mx, "y_px": my, "x_filt_px": mx,
                          "y_filt_px": my, "x_pred_px": mx, "y_pred_px": my, "source": "multi",
                          "seed_vehicle_id": np.nan, "true_x_px": np.nan, "true_y_px": np.nan,
                          "true_visible": np.nan})
    artifacts.write_tracks(cell, pd.concat([point, multi], ignore_index=True))
    if seq is not None:
        from scenes.formats import read_flo
        gt = read_flo(seq / "flow" / f"{PICTURE_FRAME:06d}.flo")
        cam = read_flo(seq / "flow_camera" / f"{PICTURE_FRAME:06d}.flo")
        total = gt + (0.3 * q * rng.standard_normal(gt.shape)).astype(np.float32)
        # local = total - global: the true local motion plus noise and the global model's error
        local = gt - cam + np.float32(0.1 * q) + (0.3 * q * rng.standard_normal(gt.shape)).astype(np.float32)
        artifacts.write_pair_flows(cell, PICTURE_FRAME, total, total - local)


def build_run(root: Path) -> Path:
    """Write the fixture run folder under ``root`` and return its path."""
    rng = np.random.default_rng(20090501)
    run_dir, cache = root / "run", root / "cache"
    (run_dir / "cells").mkdir(parents=True)
    rows, cells = [], []
    for scene, (param, values) in SCENES.items():
        for k, value in enumerate(values):
            label = f"{scene}[{param}={value:g}]"  # variant labels as harness.suites writes them
            scene_hash = _scene_hash(scene, value)
            seq = None
            if k == 0:
                seq = cache / scene_hash
                _write_sequence(seq, rng)
            for pipeline in PIPELINES:
                cell_id = f"{scene}-{param}={value:g}-s0-{pipeline}"
                common = {"cell_id": cell_id, "scene": label, "scene_hash": scene_hash, "seed": 0,
                          "pipeline": pipeline, "pipeline_hash": f"p{PIPELINES.index(pipeline)}",
                          "sweep_param": param, "sweep_value": str(value), "config_hash": "cfg123",
                          "git_commit": "abc1234", "git_dirty": False, "renderer": "llvmpipe (LLVM 15)",
                          "machine": "fixture-host"}
                cell = run_dir / "cells" / cell_id
                cell.mkdir()
                cells.append(cell_entry(cell_id=cell_id, scene=label, seed=0, pipeline=pipeline,
                                        config_hash="cfg123", sequence=cache / scene_hash if k == 0 else None))
                if (scene, value, pipeline) == FAILED:
                    # what harness.runner.cell_task writes for a failed cell
                    rows.append({**common, "metric": "cell_failed", "value": np.nan, "sum": np.nan,
                                 "count": 0.0, "status": "failed", "error": FAILED_ERROR})
                    artifacts.write_error(cell, "Traceback (most recent call last):\n  ...\n" + FAILED_ERROR + "\n")
                    continue
                rows += _cell_rows(common, rng, QUALITY[pipeline], value / max(values))
                _cell_artifacts(cell, seq, rng, QUALITY[pipeline])
    table = check_schema(pd.DataFrame(rows), source="fixture")
    write_table(table, run_dir / "results.parquet")
    summarize(table).to_csv(run_dir / "summary.csv", index=False)
    write_run(run_dir, {
        "suite": "fixture_suite", "suite_source": "fixture.yaml",
        "resolved_suite": {"name": "fixture_suite", "pipelines": PIPELINES},
        "pipelines": [{**BUILTIN_PIPELINES[SPECS[p]], "name": p} for p in PIPELINES],
        "config_hash": "cfg123",
        "provenance": {"git_commit": "abc1234", "git_dirty": False, "renderer": "llvmpipe (LLVM 15)",
                       "machine": "fixture-host <2 cores>",
                       "versions": {"python": "3.11.2", "numpy": "2.4.0", "opencv": "5.0.0"}},
        "cache_dir": str(cache), "cells": cells, "status": "failed",
        "failed_cells": [f"{FAILED[0]} x {FAILED[2]}: {FAILED_ERROR}"],
        "started": "2026-11-22T10:00:00+00:00", "finished": "2026-11-22T10:05:00+00:00",
    })
    return run_dir


@pytest.fixture(scope="session")
def run_dir(tmp_path_factory) -> Path:
    return build_run(tmp_path_factory.mktemp("reports_fixture"))


# a real end-to-end run: `tiny` seed 1 with fast vehicles (20-30 m/s: a seed vehicle leaves the view after
# frame 0, the case the point tracker's error figure once got wrong), the thesis twins
# and the same twins with the multi-target tracker beside the point tracker
TINY_SUITE = {
    "name": "tiny-tracking", "description": "tiny, thesis LK / HS with and without the multi-target tracker",
    "scenes": [{"preset": "tiny", "overrides": {"vehicles.speed_range_mps": [20.0, 30.0]}}], "seeds": [1],
    "picture_pairs": [0],
    "pipelines": ["thesis-lk", "thesis-hs",
                  {"name": "lk-multi", "base": "thesis-lk",
                   "spec": {"tracking": {"point": {"correlation": {}}, "multi": {}}}},
                  {"name": "hs-multi", "base": "thesis-hs",
                   "spec": {"tracking": {"point": {"correlation": {}}, "multi": {}}}}],
}


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory) -> Path:
    """The run folder of :data:`TINY_SUITE` (rendered into a cache of its own; about 15 s)."""
    import copy
    import os

    from harness.runner import run_suite
    from harness.suites import parse_suite

    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    root = tmp_path_factory.mktemp("tiny_run")
    result = run_suite(parse_suite(copy.deepcopy(TINY_SUITE)), root / "run", workers=1, cache_dir=root / "cache",
                       progress=False)
    assert result.ok, result.failed_cells
    return root / "run"


@pytest.fixture(scope="session")
def fixture_report(run_dir, tmp_path_factory) -> dict[str, Path]:
    """``write_report`` of :func:`run_dir`, written once per session for every test that only reads it."""
    from reports import write_report

    return write_report(run_dir, out_dir=tmp_path_factory.mktemp("report"))
