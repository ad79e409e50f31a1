"""Slow movers: detection over a longer time baseline, frame t against frame t-k registered into it.

Beyond the thesis. A vehicle that moves under about a pixel a frame (a queue creeping at a
junction, town traffic at 1 m/s: 0.57 px a frame at 25 fps and 0.07 m/px) stays under the
one-pair detection's speed threshold (``detection.min_magnitude_px``, and ``noise_k`` times the
ground's residual), and flow methods under-estimate the sub-pixel motion of a uniform roof
further. Over ``k`` frames the same vehicle has moved ``k`` times as far while the flow's noise on
the ground does not grow (one flow over the long pair, not a sum of ``k`` noisy ones).

:func:`long_baseline_detections` runs the one-pair detector,
:func:`algorithms.detection.detect_vehicles`, on the pair (frame t, frame t-k in frame t's
pixels, :func:`register_into` by the composed pair models, :func:`compose_models`): the flow of
that pair is ``-k`` times a vehicle's velocity; the global motion of the pair is that of the
composed model inverted (the parallax test scales with it: a roof's parallax over ``k`` frames is
``k`` times a pair's, as is the camera's motion); the ``min_explained`` test and the box compare
frames t and t-k, whose change the slow vehicle's ``k``-frame motion explains and flow noise does
not. Three things the long pair sees that a pair does not are left out: the camera's residual
rotation and tilt, ``k`` times a pair's (a quadratic ground fit, ``ground_model``); the edge of
what frame t-k covers, ``k`` camera motions into the frame (:func:`register_into`'s margin, the
detector's ``border_px``); and anything faster than ``max_speed_px`` a frame, by its ``k``-frame
motion or by the pair's own flow over its box (a fast vehicle whose flow the long pair lost, a
roof whose parallax the one-pair detector rejected). A slow mover must also not be a static structure's
parallax (``parallax_max_ratio``): over ``k`` frames a building's roof moves ``gamma`` times the camera's
``k``-frame motion over the ground (``gamma = h / (Z - h)``), which passes the speed threshold where the
one pair did not, and the detector's own parallax test stops at ``gamma`` 0.25 and judges the flow's
direction, which the one-dimensional texture of roofs and facades (seams, rows of windows) turns: the
flow slides along the lines. :func:`long_baseline_detections` therefore judges the frames: the change in
the box must be explained better by the detection's motion than by every ``gamma`` times the pair's
global motion up to ``parallax_max_ratio`` (by half ``detection.min_explained``, the margin the detector
asks of a motion over its opposite). On the 1080p city stand-in (dis, 60 frames) the 99 long-baseline
detections added on no road user were the roof of a tall block and the facade of a tower at 0.2-0.7
times the camera's motion; the test leaves out 98 of them and none of the 36 that match a car. :func:`merge_detections` then adds the slow
movers where no one-pair detection lies, nor the path a fast one swept over the ``k`` frames, and
puts one in place of a slow one-pair detection of a part of the same vehicle.

What a single long pair cannot tell apart, the frames that follow can (:class:`ParallaxChains`, the
``parallax_trend`` keys): a roof's ratio to the pair's global motion is its ``gamma``, fixed by the heights, while a
vehicle's changes as soon as its speed does. The detections the parallax tests reject are chained over the frames,
and those of a chain whose ratio changed well beyond its scatter are kept: added after every other detection, where
none lies, and never in place of one (a moving car's long box holds the road it left).

A slow mover must also show its creep from frame t-m (``m = k // 2``) to frame t (``mid_check``): the
place a fast vehicle left before frame t is a region of the long pair too, which neither it nor its
swept path covers at t when the pair detector lost it (on KIT AIS's 2-3 fps the most common false one).

The keys are those of :data:`LONG_BASELINE_DEFAULTS` (the pipeline's ``detection.long_baseline``
section; ``frames: 0``, the default, turns the stage off; every non-thesis built-in pipeline turns it on
with 6, the thesis ones leave it off: what it gains and loses on the synthetic scenes, the 1080p held-out stand-ins and
KIT AIS is measured there and in those pipelines' files).
A second, longer baseline (``slow_frames``, ``k2``) runs the same stage over ``k2`` frames for movers slower
still (at the sequence's start over the frames there are, from two more than the first's), added where neither the
pair nor the first long pair found anything (:func:`merge_detections` without replacing).
The pipeline keeps the last ``max(k, k2)`` gray frames and pair models, and runs its own flow method once
more a pair for each baseline: dis with one costs twice its CPU time a pair (``benchmarks/pipeline_speed.py speed``,
640x480: 75.0 against 37.5 ms a pair).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from algorithms.detection import (DETECTION_DEFAULTS, Detection, detect_vehicles, explained_in_box, ground_fit_at,
                                  ground_fit_map, iou_xyxy, moves_lengthwise)
from algorithms.global_motion import global_flow, is_translation

__all__ = ["LONG_BASELINE_DEFAULTS", "check_long_baseline", "compose_models", "register_into", "registration_fix",
           "long_baseline_detections", "merge_detections", "ParallaxChains"]

# The keys of the pipeline's `detection.long_baseline` section and their defaults (one home; pipeline_spec checks
# them with check_long_baseline):
# frames: the baseline k, frames (0, the default, turns the stage off; 6 is what was measured: a car at 0.25 px a
#   frame moves 1.5 px, and at 10 fps the baseline is 0.6 s); the first pairs of a sequence use the frames there
#   are, from 2. Off by default; on (6) in every non-thesis built-in pipeline, whose files give the figures at the
#   final code (1080p realistic stand-in dis 0.368 -> 0.458, the city one unchanged). With 6, off -> on at main
#   539a6c8 + the parallax and mid-frame tests (docs/long_baseline.md has the commands and what the pictures show):
#     1080p city stand-in (60 frames, aerobench eval-video): dis 0.246 -> 0.306 (FP 56 -> 61, FN 294 -> 261),
#       pyramidal-hs 0.246 -> 0.265, tv-l1 0.244 -> 0.218 (FP 58 -> 90), pyramidal-lk 0.151 -> 0.134; IDF1 up for
#       all four (0.493 -> 0.558 dis). What is left of the false positives are real vehicles boxed short of their
#       truth: a truck the image's left border cuts (amodal truth box, IoU 0.25 over 25-32 frames for tv-l1,
#       pyramidal-hs and -lk), cars entering at the top;
#     synthetic, 30 frames (benchmarks/tracking_quality.py): realistic dis 0.222 -> 0.350, tv-l1 0.433 -> 0.502,
#       pyramidal-hs 0.192 -> 0.414; city dis 0.162 -> 0.158, tv-l1 -0.079 -> 0.046, pyramidal-hs -0.133 -> -0.092;
#       nominal unchanged;
#     KIT AIS detection precision: dis 0.241 -> 0.233, pyramidal-hs 0.254 -> 0.254, tv-l1 0.217 -> 0.216, recall
#       unchanged (tree crowns, a lamp post's and a shelter's parallax in registered-looking frames, a fast car's
#       trail the mid frame still holds part of);
#   it does not help everywhere (tv-l1 and pyramidal-lk on the stand-in, dis's precision on KIT AIS), hence off by
#   default;
# slow_frames: a second, longer baseline k2 > frames (0, the default: none): its slow movers (the same keys,
#   min_displacement_px over the k2 frames) join where none of the pair's or the first long pair's detections lies,
#   nor the path one swept over the k2 frames, and never replace one (replace_rel does not apply). A queue creeping at
#   0.1-0.25 px a frame moves 0.6-1.5 px over six frames, under the floor, and 2.4-6 px over 24. At the sequence's
#   start it runs, as the first does, over the frames there are, from frames + 2 behind frame t (a baseline two frames
#   longer than the first's) up to k2; run from the k2-th frame alone, it left a 100-frame clip's first quarter to
#   the six-frame pair (the 1080p city-wide worlds, dis: from k2 0.549 / 0.551 / 0.685, from 8 0.601 / 0.572 / 0.722;
#   docs/long_baseline.md). It costs one more flow a pair (dis's long flow from full resolution). 24 in dis; the
#   figures there.
# min_displacement_px: the detector's speed threshold on the long pair, px over the k frames (min_magnitude_px
#   there; px-scaled): 0.25 px a frame at k = 6; the detector's noise_k times the long pair's median residual
#   raises it where the flow is noisier. 1.0 in dis (algorithms/pipelines/dis.yaml: the 1080p city-wide worlds' long
#   pairs have a residual of 0.14 px, and a queue creeping at 0.25 px a frame was under the 1.5 px floor);
# max_speed_px: a long-baseline detection faster than this, px a frame (px-scaled), is left out: faster vehicles
#   are the one-pair detector's, and what it did not find at that speed it rejected (parallax of a roof that
#   the camera's motion over k frames makes look like a mover, a fast vehicle's trail);
# ground_model: the detector's ground_model on the long pair (the camera's residual rotation and tilt over k
#   frames is k times a pair's; a quadratic fit keeps it off the image's corners);
# min_box_px: a long-baseline detection whose box holds fewer pixels is left out (px-scaled area: a car's top
#   view is 24 x 16 px at 0.22 m/px; a pedestrian walking 1.4 m/s is a slow mover too, and without a ground
#   sampling distance nothing else tells it);
# replace_rel: a slow one-pair detection (at most max_speed_px) whose box is under this many times the box of
#   the long-baseline detection over it is replaced by that one (0: never).
# parallax_max_ratio: a long-baseline detection whose box's change (frame t against frame t-k) gamma times the
#   long pair's global motion explains as well as its own motion does, up to half detection.min_explained, for
#   some gamma up to this, is a static structure's parallax (gamma = h / (Z - h): 1 is a building half the flight
#   height; the city stand-in's tower reaches 0.7), and is left out (0: off). It gives up a vehicle creeping along
#   the camera's motion, in its sense, slower than this many times it: from two views it is the roof of a building
#   (what that costs on realistic: beside detection.parallax_max_ratio, which this stage's detector applies too;
#   a detection that moves along its length, detection.parallax_lengthwise_rel, is judged by neither).
# mid_check: a long-baseline detection must also explain the change from frame t-m (m = k // 2, registered the same
#   way) to frame t by m times its per-frame motion, at least detection.min_explained (long_baseline_detections'
#   mid_frame): a slow mover crept there; the place a fast vehicle left before frame t, a region of the long pair
#   that neither it nor the path it swept covers any more (KIT AIS at 2-3 fps: cars move 10-30 px a frame), is
#   road at t-m and t alike, or holds the vehicle where its slow motion does not explain it (false: off).
# flow_params: the flow method's parameters for the long pair, over the pipeline's flow.params ({}: the same flow):
#   the long pair runs once a pair beside the pair's flow, and a setting too noisy or too costly for every pair can
#   serve it (DIS's flow from full resolution, finest_scale 0: the medium preset's half-resolution patches average a
#   small car with the ground around it; the long pair's parallax test judges the frames, and rejects the roofs and
#   crowns the finer flow resolves, which the one-pair detector passes: dis.yaml has the figures).
# reregister_px: where the robust affine fit of the long pair's ground flow moves a corner of the frame by more than
#   this, px, frame t-k (and t-m) are registered again through it and the long pair's flow taken again
#   (registration_fix; 0: off). The pairs' shift models leave a turning camera's rotation k times over: on a 1080p
#   city-wide world turned 2 degrees a second (about the image centre, 25 fps) the 24-frame pair's residual reaches
#   33 px at the corners, and dis found 1260 of 3181 counted vehicle boxes (IoU 0.5) where the world as rendered
#   gave 1609, the slow ones lost (0.3-1 m/s: 69 of 561 against 205); with the key 3, 1580, and MOTA 0.375 -> 0.500
#   (0.499 as rendered; turned 0.5 degree a second: 1504 -> 1597 boxes, MOTA 0.495 -> 0.467). 3, the default: the
#   world's own residual as rendered stays under 1.5 px over 24 frames, as do the synthetic scenes' but
#   urban-parallax's and jitter's, whose MOTA it leaves as it was; at 1 it also re-registered realistic's lens
#   distortion (pyramidal-hs 0.944 -> 0.803 at 30 frames). Frame px, not scaled by px_scale (a registration error,
#   not a vehicle's size). docs/long_baseline.md, "A camera that turns";
# parallax_trend, parallax_trend_frames, parallax_trend_snr: the detections the parallax tests reject (this stage's
#   and its detector's) are chained over the frames (ParallaxChains); a chain of at least parallax_trend_frames
#   whose ratio gamma to the pair's global motion changes along it by parallax_trend or more, and by
#   parallax_trend_snr times its scatter about a straight line, is no static structure's (gamma is fixed by the
#   heights), and its detections are kept from then on while it goes on. What it takes back is a vehicle that speeds
#   up or slows down along the flight line; one at a steady ratio stays a roof. 0: off, the default (figures in the
#   pipelines that turn it on);
LONG_BASELINE_DEFAULTS = {"frames": 0, "slow_frames": 0, "min_displacement_px": 1.5, "max_speed_px": 1.5,
                          "ground_model": "quadratic", "replace_rel": 0.5, "min_box_px": 300, "parallax_max_ratio": 1.0,
                          "mid_check": True, "flow_params": {}, "reregister_px": 3.0, "parallax_trend": 0.0,
                          "parallax_trend_frames": 8, "parallax_trend_snr": 5.0}


def check_long_baseline(params: Mapping) -> dict:
    """``params`` over :data:`LONG_BASELINE_DEFAULTS`, checked; raises ValueError naming the key."""
    unknown = sorted(set(params) - set(LONG_BASELINE_DEFAULTS))
    if unknown:
        raise ValueError(f"long_baseline: unknown key(s) {unknown}; valid: {', '.join(LONG_BASELINE_DEFAULTS)}")
    p = {**LONG_BASELINE_DEFAULTS, **params}
    k = p["frames"]
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0 or k == 1:
        raise ValueError(f"frames: expected 0 (off) or an integer >= 2, got {k!r}")
    k2 = p["slow_frames"]
    if isinstance(k2, bool) or not isinstance(k2, (int, np.integer)) or k2 < 0 or (k2 and (not k or k2 <= k)):
        raise ValueError(f"slow_frames: expected 0 (off) or an integer over frames ({k}, which must be on), "
                         f"got {k2!r}")
    for key in ("min_displacement_px", "max_speed_px"):
        s = p[key]
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s) or not s > 0:
            raise ValueError(f"{key}: expected a finite number > 0, got {s!r}")
    if p["ground_model"] not in ("affine", "quadratic", "none"):
        raise ValueError(f"ground_model: expected affine, quadratic or none, got {p['ground_model']!r}")
    b = p["min_box_px"]
    if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or b < 0:
        raise ValueError(f"min_box_px: expected an integer >= 0, got {b!r}")
    if not isinstance(p["mid_check"], bool):
        raise ValueError(f"mid_check: expected true/false, got {p['mid_check']!r}")
    fp = p["flow_params"]
    if not isinstance(fp, Mapping) or not all(isinstance(key, str) for key in fp):
        raise ValueError(f"flow_params: expected a mapping of the flow method's parameters, got {fp!r}")
    n = p["parallax_trend_frames"]
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3:
        raise ValueError(f"parallax_trend_frames: expected an integer >= 3 (a line through fewer has no scatter), "
                         f"got {n!r}")
    for key in ("replace_rel", "parallax_max_ratio", "reregister_px", "parallax_trend", "parallax_trend_snr"):
        r = p[key]
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) or r < 0:
            raise ValueError(f"{key}: expected a finite number >= 0, got {r!r}")
    return p


def registration_fix(flow: np.ndarray, valid: np.ndarray, *, tol_px: float) -> np.ndarray | None:
    """Where the long pair's frames are registered worse than ``tol_px``: the map that registers them again.

    The pairs' models composed (:func:`compose_models`) leave the ground a residual ``k`` times a pair's; a shift
    model leaves a turning camera's rotation whole (2 degrees a second at 25 fps is 1.4 px a frame at 1,000 px from
    the image centre: 34 px over 24 frames). The long pair's flow ``flow`` (frame t to frame t-k as registered)
    shows it on the ground. Its robust affine fit (:func:`algorithms.detection.ground_fit_map`, ``x -> x + F(x)``),
    where it moves a corner of the frame by more than ``tol_px``, is returned: frame t-k registered by
    ``inv(B) @ C`` in place of ``C`` meets frame t on the ground. None where the fit stays within ``tol_px`` at
    every corner (the detector's own ground fit takes such a residual out), or there is no fit.

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
    valid : ndarray, (H, W) bool
    tol_px : float
        > 0, px.

    Returns
    -------
    ndarray (3, 3) or None
    """
    if not tol_px > 0:
        raise ValueError(f"tol_px: expected a number > 0, got {tol_px!r}")
    B = ground_fit_map(flow, valid)
    if B is None:
        return None
    h, w = np.shape(flow)[:2]
    corners = np.array([[0.0, 0.0, 1.0], [w - 1.0, 0.0, 1.0], [0.0, h - 1.0, 1.0], [w - 1.0, h - 1.0, 1.0]])
    return B if float(np.abs(corners @ B.T - corners)[:, :2].max()) > tol_px else None


def compose_models(matrices: Sequence[np.ndarray]) -> np.ndarray:
    """The global model from frame t-k to frame t: ``M_{t-1} ... M_{t-k}``.

    Parameters
    ----------
    matrices : sequence of ndarray, (3, 3) float
        The pairs' models, oldest first: ``M_j`` maps frame-j points to frame j+1 (as
        :func:`algorithms.global_motion.global_flow` reads it).

    Returns
    -------
    ndarray, (3, 3) float64
        Maps frame t-k points to frame t (the identity for no matrix).
    """
    C = np.eye(3)
    for M in matrices:
        M = np.asarray(M, dtype=np.float64)
        if M.shape != (3, 3) or not np.isfinite(M).all():
            raise ValueError(f"matrices: expected finite (3, 3) arrays, got {M.shape}")
        C = M @ C
    return C / C[2, 2]


def register_into(gray: np.ndarray, C: np.ndarray, *, margin_px: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Frame t-k in frame t's pixels, ``I_{t-k}(C^-1 x)``, and where that falls inside frame t-k.

    Parameters
    ----------
    gray : ndarray, (H, W)
        Frame t-k (any dtype cv2 warps; the output keeps it).
    C : ndarray, (3, 3)
        Frame t-k points to frame t (:func:`compose_models`).
    margin_px : int
        The inside mask leaves out this many px along the edge of what frame t-k covers (as
        ``detection.border_px`` does at the image's border: a flow window that the edge clips, content
        that entered; over ``k`` frames that edge lies ``k`` camera motions into the frame).

    Returns
    -------
    (ndarray (H, W), ndarray (H, W) bool)
        The registered frame (border replicated) and its inside mask.
    """
    if isinstance(margin_px, bool) or not isinstance(margin_px, (int, np.integer)) or margin_px < 0:
        raise ValueError(f"margin_px: expected an integer >= 0, got {margin_px!r}")
    g = np.asarray(gray)
    if g.ndim != 2:
        raise ValueError(f"gray: expected (H, W), got {g.shape}")
    h, w = g.shape
    size = (w, h)
    affine = np.allclose(C[2], [0, 0, 1])
    # cv2 maps dst(x) = src(C^-1 x) without WARP_INVERSE_MAP
    warp = ((lambda a, bm: cv2.warpAffine(a, C[:2], size, flags=cv2.INTER_LINEAR, borderMode=bm)) if affine else
            (lambda a, bm: cv2.warpPerspective(a, C, size, flags=cv2.INTER_LINEAR, borderMode=bm)))
    out = warp(g, cv2.BORDER_REPLICATE)
    inside = warp(np.ones((h, w), np.uint8), cv2.BORDER_CONSTANT)
    if margin_px:
        # the image's own border stays in: that is border_px's
        pad = cv2.copyMakeBorder(inside, margin_px, margin_px, margin_px, margin_px, cv2.BORDER_REPLICATE)
        inside = cv2.erode(pad, np.ones((2 * margin_px + 1, 2 * margin_px + 1), np.uint8))[
            margin_px:-margin_px, margin_px:-margin_px]
    return out, inside > 0


def long_baseline_detections(flow: np.ndarray, valid: np.ndarray, *, baseline_frames: int, frames,
                             composed: np.ndarray,
                             min_displacement_px: float = LONG_BASELINE_DEFAULTS["min_displacement_px"],
                             max_speed_px: float = LONG_BASELINE_DEFAULTS["max_speed_px"],
                             ground_model: str = LONG_BASELINE_DEFAULTS["ground_model"],
                             gsd_m_per_px: float | None = None, detection_params: Mapping | None = None,
                             pair_flow: np.ndarray | None = None, pair_valid: np.ndarray | None = None,
                             min_box_px: int = LONG_BASELINE_DEFAULTS["min_box_px"],
                             parallax_max_ratio: float = LONG_BASELINE_DEFAULTS["parallax_max_ratio"],
                             mid_frame: tuple[np.ndarray, int] | None = None,
                             parallax_chains: ParallaxChains | None = None, frame: int | None = None
                             ) -> list[Detection]:
    """The slow movers of frame t over the pair (frame t, frame t-k registered into it) (module docstring).

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
        Flow from frame t to frame t-k registered into frame t (the pair ``frames``), px; frame t
        pixels: a vehicle of velocity ``v`` px/frame shows ``-k v``.
    valid : ndarray, (H, W) bool
        Where it is defined (and frame t-k covers frame t).
    baseline_frames : int
        ``k`` >= 1.
    frames : (ndarray, ndarray)
        Gray frame t and frame t-k registered into it, (H, W) (:func:`register_into`).
    composed : ndarray, (3, 3)
        The model from frame t-k to frame t (:func:`compose_models`): the long pair's global motion
        is its inverse's field (the parallax test).
    min_displacement_px : float
        The detector's ``min_magnitude_px`` on the long pair: the least motion over the ``k`` frames, px.
    max_speed_px : float
        Per-frame speed above which a detection is left out, px/frame.
    ground_model : str
        The detector's ``ground_model`` on the long pair (the residual of the camera's rotation and
        of the lens over ``k`` frames is ``k`` times a pair's: ``"quadratic"`` by default).
    gsd_m_per_px : float, optional
        As :func:`algorithms.detection.detect_vehicles`; the m^2 size limits also apply to the box.
    detection_params : mapping, optional
        Keys of :data:`algorithms.detection.DETECTION_DEFAULTS` (the pipeline's, px-scaled);
        ``box_three_frames`` is off (no frame t+k).
    min_box_px : int
        A detection whose box holds fewer pixels is left out (a walking pedestrian over ``k`` frames:
        where the ground sampling distance is unknown, the size limits in m^2 do not apply).
    pair_flow, pair_valid : ndarray (H, W, 2) float and (H, W) bool, optional
        The local flow of pair t -> t+1 and where it is defined: a detection whose box's median pair
        flow, about the median of the whole valid field, is faster than ``max_speed_px`` is left out
        (a fast vehicle whose flow the long pair lost: the k-frame motion found there is no velocity).
    parallax_max_ratio : float
        A detection whose box's change ``gamma`` times the pair's global motion explains about as well as its
        own motion does (half ``detection_params["min_explained"]``), for a ``gamma`` up to this, is a static
        structure's parallax and is left out (module docstring; 0: off).

    mid_frame : (ndarray (H, W), int), optional
        Frame t-m registered into frame t (:func:`register_into`) and ``m``, 0 < m < k: a detection must
        also explain the change from it to frame t by ``m`` times its per-frame motion (at least
        ``detection_params["min_explained"]``): a slow mover crept there, while the place a fast vehicle
        left before frame t (its trail in the long pair, which neither it nor its swept path covers any
        more) is ground in both frames, or holds the vehicle at a place its slow motion does not explain.
    parallax_chains : ParallaxChains, optional
        The chains of this baseline's earlier frames: what the parallax tests (this stage's and its detector's)
        reject here is added to them, and kept where its chain's ratio to the global motion changed
        (:class:`ParallaxChains`). It needs ``frame``, the index of frame t (frames in order).

    Returns
    -------
    list of Detection
        Boxes in frame t; ``u_px, v_px`` the per-frame velocity, ``-flow / k``, px/frame.
    """
    k = baseline_frames
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"baseline_frames: expected an integer >= 1, got {k!r}")
    for key, x in (("min_displacement_px", min_displacement_px), ("max_speed_px", max_speed_px)):
        if not (math.isfinite(x) and x > 0):
            raise ValueError(f"{key}: expected a finite number > 0, got {x!r}")
    f = np.asarray(flow)
    if f.ndim != 3 or f.shape[2] != 2:
        raise ValueError(f"flow: expected (H, W, 2), got {tuple(f.shape)}")
    h, w = f.shape[:2]
    C = np.asarray(composed, dtype=np.float64)
    if C.shape != (3, 3) or not np.isfinite(C).all():
        raise ValueError(f"composed: expected a finite (3, 3) matrix, got {C.shape}")
    # the long pair runs from frame t back to frame t-k: its global motion is the composed model's inverse
    g = -C[:2, 2] if is_translation(C) else global_flow(np.linalg.inv(C), (h, w))
    params = {**(detection_params or {}), "box_three_frames": False, "ground_model": ground_model,
              "min_magnitude_px": min_displacement_px}
    exempt = None
    if parallax_chains is not None:
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
            raise ValueError(f"frame: expected the index of frame t with parallax_chains, got {frame!r}")
        parallax_chains.begin(int(frame), g, k)
        exempt = parallax_chains.exempt
    found = detect_vehicles(f, valid, global_flow_px=g, frames=frames, gsd_m_per_px=gsd_m_per_px,
                            parallax_exempt=exempt, **params)
    lo, hi = params.get("min_area_m2", DETECTION_DEFAULTS["min_area_m2"]), params.get("max_area_m2")
    ref = None
    if pair_flow is not None:
        pf = np.asarray(pair_flow)
        pv = np.ones((h, w), bool) if pair_valid is None else np.asarray(pair_valid, bool)
        if pf.shape != (h, w, 2) or pv.shape != (h, w):
            raise ValueError(f"pair_flow, pair_valid: expected {(h, w, 2)} and {(h, w)}, got {pf.shape} and {pv.shape}")
        grid = pf[4::8, 4::8][pv[4::8, 4::8]]
        ref = np.median(grid, axis=0) if len(grid) else np.zeros(2)
    min_explained = params.get("min_explained", DETECTION_DEFAULTS["min_explained"])
    # a vehicle moving along its length is not judged as parallax (detection.parallax_lengthwise_rel)
    lengthwise = params.get("parallax_lengthwise_rel", DETECTION_DEFAULTS["parallax_lengthwise_rel"])
    if mid_frame is not None:
        mid, m = mid_frame
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or not 0 < m < k:
            raise ValueError(f"mid_frame: expected (frame, m) with 0 < m < {k}, got m = {m!r}")
        if np.shape(mid) != (h, w):
            raise ValueError(f"mid_frame: expected a gray frame of shape {(h, w)}, got {np.shape(mid)}")
    if (parallax_max_ratio > 0 or mid_frame is not None) and found:
        ground = (ground_fit_at(f, valid, [(d.x_px, d.y_px) for d in found], model=ground_model)
                  if ground_model != "none" else np.zeros((len(found), 2)))
    out = []
    for i, d in enumerate(found):
        u, v = -d.u_px / k, -d.v_px / k
        if math.hypot(u, v) > max_speed_px or _box_area(d) < min_box_px:
            continue
        if ref is not None:
            x0, y0, x1, y1 = (int(round(c)) for c in (d.x0_px, d.y0_px, d.x1_px, d.y1_px))
            box, ok = pf[y0:y1 + 1, x0:x1 + 1], pv[y0:y1 + 1, x0:x1 + 1]
            if ok.any() and math.hypot(*(np.median(box[ok], axis=0) - ref)) > max_speed_px:
                continue
        if gsd_m_per_px is not None:
            # the region over k frames holds the ground the vehicle crossed: its box is the size to check
            box_m2 = (d.x1_px - d.x0_px + 1) * (d.y1_px - d.y0_px + 1) * gsd_m_per_px ** 2
            if (lo is not None and box_m2 < lo) or (hi is not None and box_m2 > hi):
                continue
        if parallax_max_ratio > 0 and not moves_lengthwise(d, lengthwise) and _parallax_explains(
                d, frames, g, ground[i], parallax_max_ratio, min_explained / 2) and not (exempt and exempt(d)):
            continue
        if mid_frame is not None and min_explained > 0:
            # frame t-m: m of the k motions, about m / k of the ground's residual
            r = m / k
            e = explained_in_box((frames[0], mid), (d.x0_px, d.y0_px, d.x1_px, d.y1_px), [(r * d.u_px, r * d.v_px)],
                                 ground_px=(r * ground[i][0], r * ground[i][1]))
            if e[0] < min_explained:
                continue
        out.append(d._replace(u_px=u, v_px=v))
    return out


def merge_detections(pair: Sequence[Detection], long: Sequence[Detection], *, baseline_frames: int,
                     nms_iou: float = 0.1, max_speed_px: float = LONG_BASELINE_DEFAULTS["max_speed_px"],
                     replace_rel: float = LONG_BASELINE_DEFAULTS["replace_rel"]) -> list[Detection]:
    """The one-pair detections of frame t with the long-baseline ones added where none lies.

    A long-baseline detection joins when no one-pair detection overlaps it (boxes at ``nms_iou``,
    or the centre of one inside the other's box) nor the path a one-pair detection swept over the
    ``baseline_frames`` frames (its box and the box ``k`` of its motions back: a fast vehicle leaves
    the long pair a region where it was at t-k, and the flow between two places that far apart
    is no motion). Where a one-pair detection overlaps it, that one stays unless it is slow (at most
    ``max_speed_px``) and its box is under ``replace_rel`` times the long one's (a slow car whose
    uniform roof moved too little between two frames is found by its front or rear edge alone, and
    its centre wanders from frame to frame; over ``k`` frames its whole top changed): then the long
    one takes its place.

    Returns
    -------
    list of Detection
        Largest region first, as :func:`algorithms.detection.detect_vehicles` orders them.
    """
    k = baseline_frames
    swept = [e._replace(x0_px=min(e.x0_px, e.x0_px - k * e.u_px), x1_px=max(e.x1_px, e.x1_px - k * e.u_px),
                        y0_px=min(e.y0_px, e.y0_px - k * e.v_px), y1_px=max(e.y1_px, e.y1_px - k * e.v_px))
             for e in pair if math.isfinite(e.u_px) and math.isfinite(e.v_px)]
    out = list(pair)
    for d in long:
        hits = [i for i, e in enumerate(out) if _overlaps(d, e, nms_iou)]
        if not hits:
            if not any(_overlaps(d, e, nms_iou) for e in swept):
                out.append(d)
            continue
        if len(hits) == 1 and replace_rel > 0:
            e = out[hits[0]]
            if math.hypot(e.u_px, e.v_px) <= max_speed_px and _box_area(e) < replace_rel * _box_area(d):
                out[hits[0]] = d
    return sorted(out, key=lambda d: -d.area_px)


def _parallax_explains(d: Detection, frames, g: np.ndarray, ground, ratio: float, margin: float) -> bool:
    """Whether a static structure's parallax explains the change in ``d``'s box within ``margin`` of ``d``'s motion.

    The parallax of a point ``gamma`` times as far from the ground as the camera is close to it (``gamma =
    h / (Z - h)``) is ``gamma`` times the long pair's global motion ``G`` at it (``g``: the field or the shift);
    the change in the box (frame t against frame t-k) is warped by ``d``'s motion and by ``gamma G`` for
    ``gamma`` up to ``ratio`` in steps of at most 0.5 px (:func:`algorithms.detection.explained_in_box`).
    Judging the frames and not the flow's direction matters where the texture is one-dimensional (a roof's
    seams, a facade's rows of windows): the flow slides along the lines by any amount, and only the
    component across them is the parallax's.
    """
    G = _motion_at(g, d)
    gn = math.hypot(*G)
    if not gn > 0:
        return False
    # a shift over half the box's extent along G matches its content with what lies beside it (the next car of a
    # queue), not with itself: such parallax (a mast, a narrow tower) is not judged here
    extent = abs(G[0]) / gn * (d.x1_px - d.x0_px + 1) + abs(G[1]) / gn * (d.y1_px - d.y0_px + 1)
    top = min(ratio, 0.5 * extent / gn)
    n = max(1, math.ceil(top * gn / 0.5))
    gammas = top * np.arange(n + 1) / n
    gu, gv = ground
    # about the ground fit and about the registration's ground alike: a large structure at the image's edge pulls
    # the quadratic fit there towards its own parallax
    cands = [(a * G[0], a * G[1]) for a in gammas[1:]] + [(a * G[0] - gu, a * G[1] - gv) for a in gammas]
    e = explained_in_box(frames, (d.x0_px, d.y0_px, d.x1_px, d.y1_px), [(d.u_px, d.v_px)] + cands,
                         ground_px=(gu, gv))
    return bool(e[1:].max() >= e[0] - margin)


class ParallaxChains:
    """The detections a long pair's parallax tests reject, chained over the frames: a ratio that changes is no roof's.

    A static point ``gamma`` times as far above the ground as the camera is above it moves ``gamma`` times the long
    pair's global motion ``G`` against the ground (module docstring), and from the pair alone nothing tells it
    from a vehicle that creeps along ``G`` at that ratio. Over frames something does: ``gamma`` is fixed by the
    heights, and holds while the camera keeps its height, while a vehicle's ratio changes as its speed (or the
    camera's) does. On ``realistic`` at seed 1 (dis, the 6-frame pair) a car pulling away along the flight line went
    from 0.07 to 0.26 over 41 frames, 0.008 about a straight line, while the chains of roofs and crowns stayed
    within 0.03 of their start, 0.002-0.013 about it; on the 1080p city-wide worlds (24-frame pair) the chains whose
    ratio changed by 0.1 or more at five times their scatter were eight, on seven creeping cars, none on a static
    structure.

    Each rejected detection joins the chain whose last box, moved by the parallax of its last ``gamma`` over the
    frames since (``(1 + gamma) G / k`` a frame; a chain that missed more than ``max_gap`` frames has ended), it
    overlaps most, at IoU ``link_iou`` or more; else it starts one. A chain of ``min_frames`` or more whose
    least-squares line of ``gamma`` against the frame changes by ``min_change`` or more along it, and by ``snr``
    times the scatter about it, is released: its detections are kept (:meth:`exempt`) from then on, while it goes
    on.
    """

    def __init__(self, *, min_change: float, min_frames: int = LONG_BASELINE_DEFAULTS["parallax_trend_frames"],
                 snr: float = LONG_BASELINE_DEFAULTS["parallax_trend_snr"], link_iou: float = 0.3, max_gap: int = 2):
        check_long_baseline({"parallax_trend": min_change, "parallax_trend_frames": min_frames,
                             "parallax_trend_snr": snr})
        self.min_change, self.min_frames, self.snr = float(min_change), int(min_frames), float(snr)
        self.link_iou, self.max_gap = float(link_iou), int(max_gap)
        self._chains: list[dict] = []
        self._frame, self._g, self._k = -1, np.zeros(2), 1
        self._now: dict[tuple, dict] = {}

    def begin(self, frame: int, g: np.ndarray, k: int) -> None:
        """Frame ``frame``'s long pair, over ``k`` frames, global motion ``g`` (a shift ``(2,)`` or a field ``(H, W,
        2)``, frame t back to frame t-k); frames come in order."""
        if frame <= self._frame:
            raise ValueError(f"frame: expected frames in order, got {frame} after {self._frame}")
        self._frame, self._g, self._k, self._now = frame, np.asarray(g, dtype=np.float64), int(k), {}
        self._chains = [c for c in self._chains if c["frames"][-1] >= frame - 1 - self.max_gap]

    def exempt(self, d: Detection) -> bool:
        """Add ``d``, rejected by a parallax test in the current frame, to its chain; whether that chain is released.
        A detection added already this frame (both tests judged it) is not added again."""
        key = (d.x0_px, d.y0_px, d.x1_px, d.y1_px)
        if key in self._now:
            return self._now[key]["released"]
        g = _motion_at(self._g, d)
        gn2 = float(g @ g)
        if not gn2 > 0:
            return False
        gamma = (d.u_px * g[0] + d.v_px * g[1]) / gn2
        best, best_iou = None, self.link_iou
        for c in self._chains:
            gap = self._frame - c["frames"][-1]
            if gap < 1:
                continue
            step = -(1.0 + c["gammas"][-1]) * g / self._k * gap
            moved = c["box"] + np.r_[step, step]
            iou = iou_xyxy(key, moved)
            if iou >= best_iou:
                best, best_iou = c, iou
        if best is None:
            best = {"frames": [], "gammas": [], "released": False}
            self._chains.append(best)
        best["frames"].append(self._frame)
        best["gammas"].append(gamma)
        best["box"] = np.asarray(key, dtype=np.float64)
        if not best["released"] and len(best["frames"]) >= self.min_frames:
            best["released"] = _ratio_changes(best["frames"], best["gammas"], self.min_change, self.snr)
        self._now[key] = best
        return best["released"]


    def kept(self, d: Detection) -> bool:
        """Whether ``d`` (this frame's, its velocity per frame or over the pair alike) was kept by a released chain."""
        c = self._now.get((d.x0_px, d.y0_px, d.x1_px, d.y1_px))
        return c is not None and c["released"]


def _ratio_changes(frames, gammas, min_change: float, snr: float) -> bool:
    """Whether the least-squares line of ``gammas`` over ``frames`` changes by ``min_change`` or more along them, and
    by ``snr`` times the root-mean-square scatter about it."""
    t = np.asarray(frames, dtype=np.float64)
    y = np.asarray(gammas, dtype=np.float64)
    A = np.stack([t - t.mean(), np.ones_like(t)], axis=1)
    coef = np.linalg.lstsq(A, y, rcond=None)[0]
    change = abs(coef[0]) * (t[-1] - t[0])
    scatter = math.sqrt(float(np.mean((y - A @ coef) ** 2)))
    return bool(change >= min_change and change >= snr * scatter)


def _motion_at(g: np.ndarray, d: Detection) -> np.ndarray:
    """The global motion ``g`` (a shift ``(2,)`` or a field ``(H, W, 2)``) at ``d``'s centre, clipped into the image."""
    if g.ndim == 1:
        return g
    h, w = g.shape[:2]
    return g[min(h - 1, max(0, round(d.y_px))), min(w - 1, max(0, round(d.x_px)))]


def _box_area(d: Detection) -> float:
    return (d.x1_px - d.x0_px + 1) * (d.y1_px - d.y0_px + 1)


def _overlaps(a: Detection, b: Detection, iou: float) -> bool:
    """Boxes overlap by ``iou``, or the centre of one lies in the other's box."""
    def inside(p: Detection, q: Detection) -> bool:
        return q.x0_px <= p.x_px <= q.x1_px and q.y0_px <= p.y_px <= q.y1_px

    iw = min(a.x1_px, b.x1_px) - max(a.x0_px, b.x0_px) + 1
    ih = min(a.y1_px, b.y1_px) - max(a.y0_px, b.y0_px) + 1
    if iw > 0 and ih > 0:
        inter = iw * ih
        if inter / (_box_area(a) + _box_area(b) - inter) >= iou:
            return True
    return inside(a, b) or inside(b, a)
