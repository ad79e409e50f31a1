"""Pipeline: validation of descriptions, a run on a synthetic sequence with known motion, bounded memory."""

import gc
import tracemalloc

import cv2
import numpy as np
import pytest

from algorithms.jitter import fit_flight_path, remove_jitter
from algorithms.pipeline import _compensate, _compose
from algorithms.pipeline import PIPELINES, PairEstimate, Pipeline, PipelineError, SequenceEstimate, get_pipeline
from algorithms.registry import FLOW_METHODS, register_flow
from algorithms.shared_work import SharedWork

SQUARE = 255.0  # the moving square's gray value; the texture stays below it
SIZE = 80
SQ = 6


@register_flow
def _square_oracle_flow(frame0, frame1, *, unused: float = 0.0):
    """Exact flow of the synthetic scene on a compensated pair: the square's displacement, zero elsewhere."""
    m0, m1 = frame0 >= SQUARE - 0.5, frame1 >= SQUARE - 0.5
    flow = np.zeros(frame0.shape + (2,), np.float32)
    if m0.any() and m1.any():
        y0, x0 = np.argwhere(m0).mean(axis=0)
        y1, x1 = np.argwhere(m1).mean(axis=0)
        flow[m0] = (x1 - x0, y1 - y0)
    return flow, np.ones(frame0.shape, bool)


def _texture(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    noise = rng.uniform(0, 1, size=(h, w)).astype(np.float32)
    smooth = cv2.GaussianBlur(noise, (0, 0), 1.0)
    smooth = (smooth - smooth.min()) / np.ptp(smooth)
    return (254 * smooth).astype(np.float32)


class Frames:
    """A synthetic sequence built on demand: a camera crop of a textured ground plus a moving square.

    The crop origin moves by a straight line plus integer jitter; ground content
    therefore moves by minus the origin's step. The square moves by ``(3, -2)``
    px per frame relative to the ground. Counts reads and frames alive.
    """

    def __init__(self, n: int, seed: int = 0, step=(3, -2), sq: int = SQ):
        rng = np.random.default_rng(seed)
        self.sq = sq
        self.n = n
        self.ground = _texture(rng, SIZE + 4 * n + 40, SIZE + 4 * n + 40)
        t = np.arange(n)
        jitter = rng.integers(-2, 3, size=(n, 2))
        self.origin = np.column_stack([2 * t, t]) + jitter + 10  # crop origin (x, y) on the ground
        self.content_path = -(self.origin - self.origin[0]).astype(float)  # cumulative ground displacement
        self.square_ground = np.column_stack([30 + step[0] * t, 60 + step[1] * t]) + self.origin[0]  # top-left on the ground
        self.reads = 0

    def __len__(self):
        return self.n

    def square_topleft(self, i):  # in frame i pixels
        return self.square_ground[i] - self.origin[i]

    def __getitem__(self, i):
        if not 0 <= i < self.n:
            raise IndexError(i)
        self.reads += 1
        ox, oy = self.origin[i]
        img = self.ground[oy:oy + SIZE, ox:ox + SIZE].copy()
        sx, sy = self.square_topleft(i)
        img[max(sy, 0):sy + self.sq, max(sx, 0):sx + self.sq] = SQUARE
        return img.astype(np.uint8)


BASE = {
    "name": "oracle",
    "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 8}},
    "jitter": {"model": "line"},
    "compensation": "shift",
    "flow": {"method": "_square_oracle_flow"},
    "threshold": {"min_magnitude_px": 1.0},
    "spatial": True,
    "temporal": True,
    "detection": {"min_magnitude_px": 1.0, "min_area_px": 10},
    "tracking": {"point": True, "multi": {"gate_px": 5.0, "birth_hits": 2}},
}


def _run(p: Pipeline, frames, seeds=None):
    out = list(p.run(frames, seeds=seeds))
    assert all(isinstance(e, PairEstimate) for e in out[:-1]) and isinstance(out[-1], SequenceEstimate)
    assert [e.index for e in out[:-1]] == list(range(len(frames) - 1))
    return out[:-1], out[-1]


def test_run_recovers_global_shifts_total_flow_jitter_and_the_square():
    frames = Frames(10)
    centre0 = frames.square_topleft(0) + (SQ - 1) / 2
    d = dict(BASE, tracking={"point": {"field": "local"}, "multi": {"gate_px": 5.0, "birth_hits": 2}})
    pairs, seq = _run(Pipeline.from_dict(d), frames, seeds=[(42, *centre0)])
    true_shifts = np.diff(frames.content_path, axis=0)
    np.testing.assert_array_equal(seq.shifts_px, true_shifts)
    np.testing.assert_array_equal(seq.cumulative_px, frames.content_path)
    np.testing.assert_allclose(seq.jitter_px, frames.content_path - fit_flight_path(frames.content_path), atol=1e-9)
    for e in pairs:
        t = e.index
        s = true_shifts[t]
        np.testing.assert_array_equal(e.global_shift_px, s)
        np.testing.assert_array_equal(e.flow_global[5, 5], s)
        sx, sy = frames.square_topleft(t)
        on_square = np.zeros((SIZE, SIZE), bool)
        on_square[sy:sy + SQ, sx:sx + SQ] = True
        # total = camera + object motion on the square, camera alone on the ground (where valid)
        np.testing.assert_allclose(e.flow_total[on_square], np.broadcast_to(s + (3.0, -2.0), (SQ * SQ, 2)), atol=1e-5)
        ground = e.valid & ~cv2.dilate(on_square.astype(np.uint8), np.ones((3, 3))).astype(bool)
        np.testing.assert_allclose(e.flow_total[ground], np.broadcast_to(s, (ground.sum(), 2)), atol=1e-6)
        # one detection, at the square's centre in frame t; the temporal filter (eq. 4.12, pixel by
        # pixel) mixes in the square's places in t-1 and t+1, several px away, so allow 1.5 px
        assert len(e.detections) == 1
        np.testing.assert_allclose(e.detections[0][:2], (sx + (SQ - 1) / 2, sy + (SQ - 1) / 2), atol=1.5)
        assert set(e.stage_ms) >= {"global_motion", "flow", "threshold", "spatial", "temporal", "tracking"}
    tr = seq.tracks
    point = tr[tr.source == "point"].sort_values("frame")
    assert list(point.frame) == list(range(10)) and set(point.seed_vehicle_id) == {42}
    last = frames.square_topleft(9) + (SQ - 1) / 2
    # global shift + exact local flow at the point: followed exactly
    np.testing.assert_allclose(point[["x_px", "y_px"]].to_numpy()[-1], last, atol=1e-4)
    multi = tr[tr.source == "multi"]
    # frames 0..8 from the pairs' detections, frame 9 (no pair starts there) extrapolated by the velocity
    assert multi.track_id.nunique() == 1 and len(multi) == 10
    xy = multi.sort_values("frame")[["x_filt_px", "y_filt_px"]].to_numpy()
    truth = np.array([frames.square_topleft(t) + (SQ - 1) / 2 for t in range(10)])
    assert np.abs(xy - truth).max() < 1.5  # no worse than the detections it filters


def test_affine_compensation_of_a_translating_ground_is_the_shift():
    frames = Frames(4, seed=1)
    frames.square_ground[:] = frames.origin + 200  # ground only: ECC sees a pure translation
    d = dict(BASE, compensation="affine", tracking={"point": False, "multi": None})
    pairs, seq = _run(Pipeline.from_dict(d), frames)
    for e in pairs:
        s = seq.shifts_px[e.index]
        # ECC's six affine parameters fitted on 80x80 px: a tenth of a pixel at the corners
        np.testing.assert_allclose(e.flow_global[e.valid], np.broadcast_to(s, (e.valid.sum(), 2)), atol=0.1)
        # the oracle sees no local motion after compensation: total = global there
        np.testing.assert_allclose(e.flow_total, e.flow_global, atol=1e-5)


def test_warp_compensation_and_composition_are_exact():
    # M: rotation by 2 degrees about (20, 15) then a shift; I1(M x) = I0(x) by construction
    a = np.deg2rad(2.0)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    C = np.array([[1, 0, 20], [0, 1, 15], [0, 0, 1.0]])
    M = np.array([[1, 0, 1.5], [0, 1, -0.5], [0, 0, 1.0]]) @ C @ R @ np.linalg.inv(C)
    w = np.zeros((30, 40, 2), np.float32)
    w[10, 12] = (0.5, -1.0)
    total = _compose(M, w, is_shift=False)
    p = M @ np.array([12 + 0.5, 10 - 1.0, 1.0])
    np.testing.assert_allclose(total[10, 12], p[:2] - (12, 10), atol=1e-5)
    q = M @ np.array([3.0, 7.0, 1.0])
    np.testing.assert_allclose(total[7, 3], q[:2] - (3, 7), atol=1e-5)
    # a smooth image and its M-warped version: compensation brings frame t+1 back onto frame t
    ys, xs = np.mgrid[0:30, 0:40].astype(np.float32)
    f = lambda x, y: 100 + 40 * np.sin(0.3 * x) * np.cos(0.2 * y)  # noqa: E731
    I0 = f(xs, ys)
    Minv = np.linalg.inv(M)
    X = Minv[0, 0] * xs + Minv[0, 1] * ys + Minv[0, 2]
    Y = Minv[1, 0] * xs + Minv[1, 1] * ys + Minv[1, 2]
    I1 = f(X, Y).astype(np.float32)  # I1(M x) = I0(x)
    I1c, fg, inside = _compensate(I1, M)
    inner = inside.copy()
    inner[:2], inner[-2:], inner[:, :2], inner[:, -2:] = False, False, False, False
    assert np.abs(I1c - I0)[inner].max() < 1.0  # bilinear sampling of a smooth image
    np.testing.assert_allclose(fg, _compose(M, np.zeros_like(w), is_shift=False), atol=1e-5)


class _Guarded(Frames):
    """Counts frames handed out and still referenced (their arrays are tracked by weak finalizers)."""

    def __init__(self, n):
        super().__init__(n)
        self.alive = 0
        self.max_alive = 0

    def __getitem__(self, i):
        img = super().__getitem__(i).view(_Tracked)
        self.alive += 1
        self.max_alive = max(self.max_alive, self.alive)
        import weakref
        weakref.finalize(img, self._gone)
        return img

    def _gone(self):
        self.alive -= 1


class _Tracked(np.ndarray):
    pass


def _peak_bytes(n: int, max_bytes: int | None = None) -> int:
    frames = Frames(n)
    p = Pipeline.from_dict(dict(BASE, tracking={"point": False, "multi": None}))
    shared = SharedWork(frames, max_bytes=max_bytes) if max_bytes is not None else None
    gc.collect()
    tracemalloc.start()
    for _ in p.run(frames, shared=shared):
        pass  # the consumer keeps nothing
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak  # the ground texture was allocated before tracing started


def test_streaming_reads_each_frame_once_and_memory_is_bounded_by_the_gray_frames_kept():
    frames = _Guarded(12)
    for _ in Pipeline.from_dict(BASE).run(frames):
        gc.collect()
    assert frames.reads == 12  # decoded once; pass 2 takes the gray frame pass 1 kept
    assert frames.max_alive <= 2  # the pipeline keeps gray copies, never the frames it was handed
    # with room for two gray frames only, memory does not grow with the sequence's length
    h, w = Frames(1)[0].shape[:2]
    one_frame = h * w * 4
    small, large = _peak_bytes(6, 2 * one_frame), _peak_bytes(30, 2 * one_frame)
    assert large < 1.3 * small, (small, large)
    # by default every gray frame of a short sequence is kept: it grows by about a frame a frame
    assert _peak_bytes(30) > _peak_bytes(6) + 20 * one_frame


def test_pipelines_sharing_work_give_the_estimates_each_gives_alone():
    """Shared gray frames, pass-1 shifts and compensated frames change no number (lock-step, as the runner runs)."""
    frames = Frames(7)
    descs = [dict(BASE, name="a"), dict(BASE, name="b", flow={"method": "horn_schunck", "params": {"levels": 2}}),
             dict(BASE, name="c", global_motion={"method": "ncc_global_motion", "params": {"subpixel": False}})]
    alone = [list(Pipeline.from_dict(d).run(frames, seeds=[(1, 30.0, 30.0)])) for d in descs]
    shared = SharedWork(frames)
    runs = [Pipeline.from_dict(d).run(frames, seeds=[(1, 30.0, 30.0)], shared=shared) for d in descs]
    together: list[list] = [[] for _ in descs]
    for _ in range(len(alone[0])):
        for k, it in enumerate(runs):
            together[k].append(next(it))
    for a_run, t_run in zip(alone, together):
        for a, t in zip(a_run[:-1], t_run[:-1]):
            for name in ("flow_total", "flow_local", "flow_filtered", "flow_global", "valid", "motion_mask",
                         "global_shift_px"):
                assert np.array_equal(getattr(a, name), getattr(t, name)), name
        np.testing.assert_array_equal(a_run[-1].shifts_px, t_run[-1].shifts_px)
        assert a_run[-1].tracks.equals(t_run[-1].tracks)
    assert shared.misses["shifts"] == 2 and shared.hits["shifts"] == 1  # a and b measure the same shifts
    assert shared.misses["gray"] == len(frames)
    assert shared.hits["compensated"] >= 1


def test_shared_work_hands_out_read_only_views_and_refuses_other_frames():
    frames = Frames(3)
    shared = SharedWork(frames)
    g = shared.gray(1)
    with pytest.raises(ValueError, match="read-only"):
        g[:] = -1  # a caller cannot write into what another pipeline sees
    with pytest.raises(ValueError):
        g.flags.writeable = True
    assert shared.gray(1).min() >= 0
    warped = shared.compensated(0, "shift", np.eye(3), lambda: (g + 1, np.zeros(g.shape + (2,), np.float32),
                                                                np.ones(g.shape, bool)))
    assert all(not a.flags.writeable for a in warped)
    with pytest.raises(ValueError, match="read-only"):
        warped[1][...] = 1.0
    with pytest.raises(ValueError, match="the SharedWork made for these frames"):
        next(Pipeline.from_dict(BASE).run(Frames(3), shared=shared))
    with pytest.raises(ValueError, match="max_bytes: expected >= 0"):
        SharedWork(frames, max_bytes=-1)


BAD = [
    ({"flow": {"method": "lucas_kanade"}}, r"name: missing"),
    ({"name": "x"}, r"flow: missing"),
    (dict(BASE, flw={}), r"flw: unknown key; valid: name, description"),
    (dict(BASE, flow={"method": "lucas_kanad"}), r"flow.method: unknown flow method 'lucas_kanad'; valid: .*horn_schunck.*lucas_kanade"),
    (dict(BASE, flow={"method": "lucas_kanade", "window": 15}), r"flow.window: unknown key; .*flow.params"),
    (dict(BASE, flow={"method": "lucas_kanade", "params": {"windw": 15}}), r"flow.params.windw: unknown parameter of lucas_kanade; valid: window"),
    (dict(BASE, flow={"method": "lucas_kanade", "params": {"window": "15"}}), r"flow.params.window: expected an integer, got '15'"),
    (dict(BASE, global_motion={"method": "phase"}), r"global_motion.method: unknown global motion method 'phase'; valid: ncc_global_motion"),
    (dict(BASE, jitter={"model": "spline"}), r"jitter.model: expected one of line, smooth"),
    (dict(BASE, jitter={"window_frames": 4}), r"jitter.window_frames: expected an odd integer"),
    (dict(BASE, compensation="warp"), r"compensation.model: expected one of none, shift, affine, homography"),
    (dict(BASE, spatial="yes"), r"spatial: expected true/false, got 'yes'"),
    (dict(BASE, threshold={"min_magnitude_px": float("nan")}), r"threshold.min_magnitude_px: expected a finite number"),
    (dict(BASE, threshold={"direction": [0, 0]}), r"threshold: direction: expected an angle"),
    (dict(BASE, tracking={"multi": {"birth_hits": 0}}), r"tracking.multi.birth_hits: expected an integer >= 1, got 0"),
    (dict(BASE, tracking={"point": {"kalman": {"q": 1.0, "Q": 2}}}), r"tracking.point.kalman.Q: unknown key"),
]


@pytest.mark.parametrize("d, match", BAD)
def test_from_dict_rejects_bad_descriptions_naming_the_field(d, match):
    with pytest.raises(PipelineError, match=match):
        Pipeline.from_dict(d)


def test_builtin_pipelines_validate_and_hash_is_stable():
    assert {"thesis-lk", "thesis-hs", "pyramidal-lk", "pyramidal-hs", "dis", "farneback", "tvl1", "tv-l1"} <= set(PIPELINES)
    hashes = set()
    for name, d in PIPELINES.items():
        p = get_pipeline(name)
        assert d["description"] and p.name == name
        assert Pipeline.from_dict(p.to_dict()).hash == p.hash  # resolving is idempotent
        hashes.add(p.hash)
    assert len(hashes) == len(PIPELINES)
    a = Pipeline.from_dict(BASE)
    b = Pipeline.from_dict(dict(reversed(list(BASE.items())), name="other", description="same stages"))
    assert a.hash == b.hash  # name and key order do not change what is computed
    c = Pipeline.from_dict(dict(BASE, spatial=False))
    assert c.hash != a.hash
    with pytest.raises(KeyError, match="unknown pipeline 'nope'; valid: dis"):
        get_pipeline("nope")
    assert "_square_oracle_flow" in FLOW_METHODS


def test_thesis_lk_on_the_synthetic_sequence():
    # single-level LK (thesis) needs slow targets: a 10 px square moving (1, -1) px per frame
    frames = Frames(5, seed=3, step=(1, -1), sq=10)
    d = get_pipeline("thesis-lk").to_dict()
    d["global_motion"]["params"]["max_shift"] = 8
    # no parallax test: the square's 1.4 px a frame, of which LK's window sees 0.8, lie within 45 degrees of the
    # camera's 3 px a frame in pair 2, as a roof's parallax would (the ambiguity of algorithms.detection)
    d["detection"] = {"min_magnitude_px": 0.5, "min_area_px": 10, "parallax_max_ratio": 0.0}
    pairs, seq = _run(Pipeline.from_dict(d), frames)
    np.testing.assert_array_equal(seq.shifts_px, np.diff(frames.content_path, axis=0))
    for e in pairs:
        sx, sy = frames.square_topleft(e.index) + 4.5
        # found where it is, within 3 px: LK's 15x15 window spreads its motion up to 7 px around
        assert any(abs(d.x_px - sx) < 3 and abs(d.y_px - sy) < 3 for d in e.detections), e.detections
        np.testing.assert_allclose(e.flow_local[int(sy), int(sx)], (1.0, -1.0), atol=0.3)


@pytest.mark.parametrize("name", sorted(PIPELINES))
def test_every_builtin_pipeline_runs_end_to_end(name):
    frames = Frames(4, seed=3, step=(1, -1), sq=10)
    d = get_pipeline(name).to_dict()
    d["global_motion"]["params"]["max_shift"] = 8
    pairs, seq = _run(Pipeline.from_dict(d), frames, seeds=[(1, 34.5, 64.5)])
    # integer or parabola-refined NCC peak on integer shifts: within a tenth of a pixel
    np.testing.assert_allclose(seq.shifts_px, np.diff(frames.content_path, axis=0), atol=0.1)
    for e in pairs:
        assert np.isfinite(e.flow_total).all() and e.valid.mean() > 0.5
        np.testing.assert_allclose(e.flow_total - e.flow_global, e.flow_local, atol=1e-4)  # shift model
    point = seq.tracks[seq.tracks.source == "point"]
    assert list(point.frame) == [0, 1, 2, 3]
    assert seq.pipeline == name and seq.pipeline_hash == Pipeline.from_dict(d).hash != get_pipeline(name).hash


def test_jitter_iterations_remeasure_the_corrected_frames_and_two_frames_suffice():
    frames = Frames(8, seed=2)
    d = dict(BASE, jitter={"model": "line", "iterations": 2}, tracking={"point": False, "multi": None})
    _, seq = _run(Pipeline.from_dict(d), frames)
    assert frames.reads == 8  # pass 1, one re-measuring round and pass 2 all take the gray frames kept
    one = remove_jitter(seq.shifts_px)
    # the integer NCC of the corrected frames sees at most the rounding of the first correction
    assert np.abs(seq.correction_px - one.correction_px).max() <= 1.0
    corrected = seq.cumulative_px + seq.correction_px
    assert np.abs(corrected - fit_flight_path(corrected)).max() <= np.abs(one.jitter_px).max()
    pairs, seq2 = _run(Pipeline.from_dict(BASE), Frames(2))
    assert len(pairs) == 1 and seq2.cumulative_px.shape == (2, 2)


def test_px_sizes_scale_with_the_frame_lengths_by_the_factor_and_areas_by_its_square(monkeypatch):
    import algorithms.pipeline as P

    assert P.px_scale_factor("auto", (480, 640)) == 1.0 and P.px_scale_factor("auto", (1080, 1920)) == 2.25
    assert P.px_scale_factor("auto", (240, 320)) == 1.0 and P.px_scale_factor(0.5, (1080, 1920)) == 0.5
    got = P.scale_px({"min_area_px": 20, "close_px": 2, "min_magnitude_px": 0.5, "max_area_px": None, "x": 3},
                     P.PX_SCALED_KEYS["detection"], 2.25)
    assert got == {"min_area_px": 101, "close_px": 4, "min_magnitude_px": 1.125, "max_area_px": None, "x": 3}
    assert P.scale_px({"open_px": 1}, P.PX_SCALED_KEYS["detection"], 0.3) == {"open_px": 1}  # never 0 from 1
    # what the run hands its stages: the detector's and the tracker's sizes for a 960x1280 frame (factor 2)
    seen = {}
    real_stage = P._stage

    def spy(kind):
        fn = real_stage(kind)
        if kind != "detection":
            return fn

        def detect(*a, **kw):
            seen.update(kw)
            return fn(*a, **kw)
        return detect
    monkeypatch.setattr(P, "_stage", spy)
    made = {}
    real_get = P.get_stage

    def get(kind, name):
        cls = real_get(kind, name)
        if (kind, name) != ("tracking", "multi"):
            return cls

        def build(**kw):
            made.update(kw)
            return cls(**kw)
        return build
    monkeypatch.setattr(P, "get_stage", get)
    frames = [np.full((960, 1280), 100 + k, np.uint8) for k in range(2)]
    list(get_pipeline("dis").run(frames))
    from algorithms.detection import DETECTION_DEFAULTS
    from algorithms.tracking import MULTI_DEFAULTS

    assert seen["min_area_px"] == 4 * DETECTION_DEFAULTS["min_area_px"]
    assert seen["min_magnitude_px"] == 2 * DETECTION_DEFAULTS["min_magnitude_px"]
    assert seen["split_px"] == DETECTION_DEFAULTS["split_px"]     # a noise threshold: not scaled
    # a width in px (the narrowest car a band of road leaves after a cut) is scaled as a length
    assert seen["gap_split_width_px"] == 2 * PIPELINES["dis"]["detection"]["gap_split_width_px"] > 0
    # the wide search's radius (how far a vehicle moves a frame) too
    assert seen["refine_wide_px"] == 2 * PIPELINES["dis"]["detection"]["refine_wide_px"] > 0
    assert made["gate_px"] == 2 * MULTI_DEFAULTS["gate_px"]


def test_vehicle_scale_is_the_median_side_over_the_reference_between_its_floor_and_the_frames_factor():
    import algorithms.pipeline as P

    ref, few = P.VEHICLE_REFERENCE_PX, P.SIZE_SAMPLE_MIN
    assert P.vehicle_scale([1.5 * ref] * few, 2.25) == pytest.approx(1.5)
    assert P.vehicle_scale([1.5 * ref] * (few - 1), 2.25) == 2.25  # too few to judge: the frame's factor
    assert P.vehicle_scale([4 * ref] * few, 2.25) == 2.25  # never above the frame's factor
    assert P.vehicle_scale([0.85 * 2.25 * ref] * few, 2.25) == 2.25  # nor a little below it: the boxes' scatter
    # cars a little smaller than the reference's: within the boxes' scatter of 1, the sizes as tuned
    assert P.vehicle_scale([0.85 * ref] * few, 2.25) == 1.0
    # smaller still: the geometric mean of their size's factor and 1, down to the floor
    assert P.vehicle_scale([0.64 * ref] * few, 1.125) == pytest.approx(0.8)
    assert P.vehicle_scale([0.64 * ref] * few, 2.25) == pytest.approx(0.8)
    assert P.vehicle_scale([0.2 * ref] * few, 2.25) == P.VEHICLE_SCALE_MIN == 0.5
    sides = [ref] * few + [10 * ref] * (few - 1)  # a minority of joined or oversized boxes does not move it
    assert P.vehicle_scale(sides, 2.25) == pytest.approx(1.0)


def _small_movers(n: int, size: int = 960, car=(30, 14), seed: int = 4) -> list[np.ndarray]:
    """A still camera over texture at ``size`` px; twelve textured 'cars' of ``car`` (w, h) px driving 3 px a frame."""
    rng = np.random.default_rng(seed)
    ground = _texture(rng, size, size) * 0.6
    cars = [(_texture(rng, car[1], car[0]) * 0.4 + 150.0, 60 + 220 * (k % 4), 80 + 260 * (k // 4)) for k in range(12)]
    frames = []
    for t in range(n):
        f = ground.copy()
        for tex, x, y in cars:
            f[y:y + car[1], x + 3 * t:x + 3 * t + car[0]] = tex
        frames.append(np.clip(f, 0, 255).astype(np.uint8))
    return frames


def test_px_scale_auto_follows_the_size_of_the_vehicles_not_only_the_frame():
    from algorithms.pipeline import px_scale_factor

    # three frames: two pairs of twelve cars give 24 boxes to take the median of (SIZE_SAMPLE_MIN is 10)
    frames = _small_movers(3)
    d = get_pipeline("dis").to_dict()
    d["tracking"] = {"point": False, "multi": None}
    _, seq = _run(Pipeline.from_dict(d), frames)
    assert px_scale_factor("auto", frames[0].shape) == 2.0  # 960 px: the frame alone says 2
    assert seq.px_scale == pytest.approx(1.0, abs=0.2)  # 30 px cars: the sizes as tuned at 640x480
    # the sample runs without the long pairs, dis's slower one (slow_frames 24) too: a sample pipeline that kept it
    # with frames 0 was refused; with it off the scale is the same
    assert d["detection"]["long_baseline"]["slow_frames"] > 0
    d["detection"]["long_baseline"]["slow_frames"] = 0
    _, without = _run(Pipeline.from_dict(d), frames)
    assert without.px_scale == seq.px_scale
    d["detection"]["px_scale"] = "frame"
    _, seq = _run(Pipeline.from_dict(d), frames)
    assert seq.px_scale == 2.0


def test_px_scale_auto_goes_below_one_for_cars_smaller_than_the_reference_on_a_larger_frame_only():
    d = get_pipeline("dis").to_dict()
    d["tracking"] = {"point": False, "multi": None}
    # 18 px cars on a 960 px frame: about half the reference's 35 px (boxes of 18-21 px), so sqrt(0.5-0.6)
    _, seq = _run(Pipeline.from_dict(d), _small_movers(3, car=(18, 9)))
    assert 0.68 <= seq.px_scale <= 0.8
    # the same cars on a frame of the reference's size keep the sizes as tuned there (no sample is taken)
    _, seq = _run(Pipeline.from_dict(d), [f[:480, :480] for f in _small_movers(3, car=(18, 9))])
    assert seq.px_scale == 1.0


def test_the_tracker_gets_a_vehicles_motion_in_its_coordinates_the_ground_residual_added():
    # the compensation left the ground a residual of (1.5, -1.0) px a pair (perspective, a shift tall roofs pulled);
    # a vehicle 3 px a frame to the right over the ground moves (4.5, -1.0) in the compensated frame, which is what
    # the tracker's coordinates (image minus the camera path) move with
    from algorithms.detection import detect_vehicles
    from algorithms.pipeline import _in_path_frame
    from algorithms.tracking import MultiTargetTracker

    rng = np.random.default_rng(5)
    field = (np.array([1.5, -1.0], np.float32) + rng.normal(0, 0.05, (120, 160, 2))).astype(np.float32)
    field[50:62, 60:84] = (4.5, -1.0)
    valid = np.ones((120, 160), bool)
    (d,) = detect_vehicles(field, valid)
    assert (d.u_px, d.v_px) == pytest.approx((3.0, 0.0), abs=0.2)  # its motion over the ground
    (m,) = _in_path_frame([d], field, valid, "affine")
    assert (m.u_px, m.v_px) == pytest.approx((4.5, -1.0), abs=0.2)
    assert m[:7] == d[:7]  # the place, area and box as they were
    assert _in_path_frame([d], field, valid, "none") == [d]  # no fit: the flow is that motion already
    # why: fed the motion over the ground, the tracker's constant-velocity filter lags a vehicle that moves 4.5 px a
    # frame in its coordinates by 1.5 px for good; fed the motion in its coordinates, it does not
    for vel, lag in ((3.0, 1.0), (4.5, 0.1)):
        trk = MultiTargetTracker()
        for f in range(20):
            x = 20 + 4.5 * f
            trk.step(f, [d._replace(x_px=x, x0_px=x - 10, x1_px=x + 10, u_px=vel)])
        rows = [r for r in trk.rows() if r["frame"] >= 10]
        err = [abs(r["x_filt_px"] - (20 + 4.5 * r["frame"])) for r in rows]
        assert (min(err) > lag) if vel == 3.0 else (max(err) < lag), (vel, err)
