"""Moving-vehicle detection: regions of independent motion in the local flow, one per rigid mover.

Beyond the thesis (its 4.1 follows seeded pixels; it detects nothing). After the
global model is compensated, the local flow ``w`` of a pair is the motion the
camera does not explain: vehicles, and the parallax of whatever stands above the
ground. :func:`detect_vehicles` turns it into :class:`Detection` s in seven steps (an eighth optional),
each with its keys (``DETECTION_DEFAULTS``, the pipeline's ``detection`` section):

1. **mask**: valid pixels with ``|w| >= min_magnitude_px``, opened (``open_px``:
   speckle of the flow method) and closed (``close_px``: a vehicle's flow is often
   found on its edges only, with a hole where its roof has no texture);
2. **regions**: 8-connected components of at least ``min_area_px`` pixels;
3. **split by flow coherence**: a region whose pixels fall into two groups of
   velocities (2-means on ``w``) that differ by more than ``split_px +
   split_rel |w|`` becomes two (two adjacent cars driving apart, a car passing
   another); a bus or truck moves rigidly and stays whole. The relative term keeps
   a car from being split from its own halo (the flow window carries the car's
   motion onto the ground around it at a fraction of its speed);
4. **merge**: regions whose boxes lie within ``merge_gap_px`` and whose mean
   velocities agree within ``merge_px + merge_rel |w|`` are one mover;
5. **reject what is not independent motion**: depth-induced parallax (below),
   regions outside the size limits (``max_area_px``; in m^2 with the ground
   sampling distance ``gsd_m_per_px``: ``min_area_m2``, ``max_area_m2``; the upper
   limits judge the box of step 6 where the frames give one, not the flow region,
   which a smoothing flow method's halo makes several times the vehicle), and
   regions whose flow does not explain the change between the frames
   (``min_explained``: an illumination change or a moving shadow edge changes
   the grey values without moving the texture, and noise changes them at
   random, so warping frame t+1 back by the region's flow brings it no closer to
   frame t than warping by the opposite flow does). Parts whose boxes overlap by
   ``nms_iou`` are judged as one mover on the motion of the part that explains the
   change best (a vehicle faster than the flow method follows breaks into parts of
   different speeds). The frames are compared about the motion the ground fit
   leaves at the region (a shift compensation leaves the ground a residual);
6. **box**: the pixels the region's motion explains better than the ground's
   (``box_from_frames``; with frame t-1, ``box_three_frames``: those that explain
   the change from t-1 too, the vehicle at t without the ground it covers next),
   their parts joined unless static texture lies between them (``box_join``), and
   parts further along its lane too (``box_reach_px``: a long uniform roof whose
   flow reached the threshold at one edge alone; ``box_reach_parts``: judged on the
   parts' own pixels and a band of ground across the lane, static or, with
   ``box_reach_road_k``, road-coloured, for vehicles that drive diagonally), sought within 4 px (with frame
   t-1, plus ``box_margin_rel`` times the region's motion) of its box; a region
   with fewer than ``min_area_px`` such pixels is no mover; with ``box_split_rel``,
   a part kept out by static texture and at least that fraction of the first
   part's size is a second vehicle of its own (two cars a smoothing flow joined); with
   ``gap_split_width_px`` / ``gap_split_length_px``, a box that a band of road crosses from side to
   side, across or along its motion, is two or three vehicles that move together and is cut there
   (:func:`_gap_split`: cars leaving a parking row or a queue side by side, one close behind another;
   a bus has no band of road inside it; with ``gap_split_moved`` a band its motion does not move
   is one too); with ``leftover_rel``, the parts of a region outside every
   box found in it and in the lane of one go through steps 5 and 6 once more at their own flow
   (:func:`_left_over`: a slower car close behind a faster one, which step 3 did not split and
   ``core_rel`` left out as its halo), added where they overlap no other detection;
7. **changed at rest**: a mover carries its content away from its place between
   frames t and t+1, and brought it there since t-1; static texture that the flow
   saw move (aliasing of road markings and kerbs, compression, the flicker of tree
   crowns, a roof edge the registration left) keeps it up to noise. The box's
   dissimilarity ``1 - NCC`` to the same place in frame t+1 (and, with frame t-1,
   in t-1) must reach ``change_noise_k`` times what the pair's noise alone gives a
   static patch of its contrast (``sigma_d^2 / (2 var)``, ``sigma_d`` the robust
   spread of the frame difference, which static ground dominates), or
   ``change_enough`` (half decorrelated: a flat patch's noise test asks more than a
   replaced content gives). NCC leaves a change of brightness or contrast out.
8. **cast shadow** (``shadow_trim_rel``, off by default): a shadow moves with its vehicle, so the box of
   step 6 holds it; :func:`trim_cast_shadows` takes it off on the side the pair's detections vote dark
   (``shadow_scope: frame``). With ``shadow_scope: clip`` this function leaves the boxes alone and
   :class:`algorithms.pipeline.Pipeline` votes once over the clip (one sun): :func:`shadow_lean` each pair,
   the votes turned into frame 0's axes by the camera's yaw (:func:`image_yaw_rad`, :func:`turn`),
   :func:`clip_shadow_direction`, :func:`trim_toward`.
9. **lane fill** (``lane_fill_rel``, off by default): a uniform roof moving along itself changes neither the
   flow nor the frames inside it, so the box of step 6 may hold its front or rear edge alone; :func:`fill_lane`
   (applied by :class:`algorithms.pipeline.Pipeline` to the pair's boxes merged with the long pair's, after
   the shadow) grows each box along its motion over the lane's pixels that are no road, to a new end that moves
   with the vehicle.

Parallax (plane + parallax, Irani and Anandan 1998; Sawhney 1994): after the
ground's motion is compensated, a static point at height ``h`` above the ground
at depth ``Z`` keeps a residual ``w = gamma (global motion direction)``, with
``gamma = h / (Z - h) >= 0`` times the ground's image motion for a camera that
translates parallel to the image (a nadir flight): parallel to the global motion
(for a translation with a forward component, along the line through the focus
of expansion, which is the direction of the global flow there) and in its sense.
A region whose mean residual has a perpendicular part within
``parallax_perp_px + parallax_perp_rel |w|`` and a parallel part between 0 and
``parallax_max_ratio`` times the global motion at the region is explained by
parallax and is rejected. A vehicle that drives along the flight, in its
sense, slower than ``parallax_max_ratio`` times the camera's ground speed looks
exactly like a roof: from two views nothing tells them apart; the default 0.25
(buildings up to a fifth of the flight height) gives that up for roofs and tree
crowns. The minimum persistence over frames is the tracker's confirmation
(``tracking.multi.birth_hits``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import cv2
import numpy as np

from algorithms.registry import register_stage

__all__ = ["Detection", "DETECTION_DEFAULTS", "detect_vehicles", "ground_residual", "ground_fit_at", "ground_fit_map",
           "explained_in_box", "shadow_bands", "trim_cast_shadows", "shadow_lean", "clip_shadow_direction", "trim_toward",
           "image_yaw_rad", "turn", "box_extents", "moves_lengthwise", "fill_lane", "drop_parts_inside", "iou_xyxy"]


class Detection(NamedTuple):
    """One moving region of a frame (pixel coordinates of frame t: x right, y down, pixel centres at integers).

    ``x_px, y_px, area_px`` first (code indexing ``d[0], d[1], d[2]`` keeps working), then the
    bounding box (inclusive extent: the first and last column and row), then the region's
    median local flow (its ground-fixed motion to frame t+1, px/frame; NaN when unknown) and
    its area in m^2 (NaN without a ground sampling distance).
    """

    x_px: float
    y_px: float
    area_px: int
    x0_px: float
    y0_px: float
    x1_px: float
    y1_px: float
    u_px: float = math.nan
    v_px: float = math.nan
    area_m2: float = math.nan


# The keys of the pipeline's `detection` section and their defaults (one home; pipeline_spec validates against it).
# min_magnitude_px: slower local flow is ground (the flow methods' noise on ground is a few tenths of a px);
# open_px, close_px: radii of the opening and closing (0: none);
# min_area_px: smaller regions are noise; max_area_px: larger ones are no vehicle (null: no limit; with
#   box_from_frames and the frames, judged on the box's area, not the region's: see max_area_m2);
# split_px, split_rel: two velocity groups of a region are two movers when they differ by more than
#   split_px + split_rel * the larger speed;
# merge_gap_px, merge_px, merge_rel: regions this close whose velocities agree this well are one mover;
# parallax_max_ratio, parallax_perp_px, parallax_perp_rel: residuals along the global motion up to this fraction of
#   it are parallax (0 turns the test off). What that gives up, measured on realistic (camera 14 m/s;
#   benchmarks/tracking_quality.py --frames 30 --breakdown, seeds 8 / 2 / 3, main e36b2f0): the vehicles the best
#   pipeline misses for most of the clip drive against the flight at 0.11-0.26 of the ground's image motion (two
#   buses and a car slowing from 1.3-2.2 to 0.5-1 m/s, a car at 3.5-4.5 m/s). 0 here and in long_baseline (whose
#   detector applies this test too) finds them, and finds roof edges: MOTA pyramidal-hs 0.781 / 0.834 / 0.357 ->
#   0.781 / 0.809 / 0.464, dis 0.674 / 0.789 / 0.357 -> 0.685 / 0.719 / 0.357. A bus found so stays unconfirmed: it
#   travels 7-9 px over the clip, under tracking.multi.min_travel_rel times its 51-59 px length; that at 0.1 as well:
#   pyramidal-hs 0.837 / 0.809 / 0.464, dis 0.669 / 0.719 / 0.536 (dis FP 11 -> 34 on seed 8, the edge band of a
#   parallax-moved roof). Motion alone cannot tell such a vehicle from a roof; a cast shadow that moves with it might
#   (not built);
# parallax_lengthwise_rel: a detection whose box reaches at least this many times as far along its motion as across
#   it (moves_lengthwise) is not judged by the parallax tests, here nor the long pair's frames test
#   (long_baseline.parallax_max_ratio): a vehicle drives along its length, while a roof's parallax points along the
#   flight line whatever the roof's shape, and a roof's edge band seen moving lies across it. What it takes back is
#   the bus above, found at its ends and boxed whole by the reach: realistic's bus 5 (14.5 x 59 px, 2.1 -> 0.9 m/s
#   along the flight line, 0.16 -> 0.07 of the ground's image motion), lost in all 30 frames (main a2eace4) to the
#   long pair detector's parallax test, its box from the frames 17-22 x 52-69 px (2.2-3.4 times as long along its
#   motion), the only cause; a bus whose box is a diagonal's (as long as wide) or a car at 2.5 or less is not
#   covered, and a roof patch that happens to be boxed long along the flight line is let through (realistic,
#   pyramidal-hs: 3 such boxes in 30 frames, 2.5-3.8 times, at frames 8, 12 and 15, which the tracker's birth rule
#   keeps out; dis: a 66 x 12 px box confirmed for 4 frames, realistic 0.674 -> 0.652). Found, the bus stays
#   unconfirmed without tracking.multi.travel_lengthwise_rel. 0: off, the default; 2.5 in pyramidal-hs, pyramidal-lk
#   and farneback, with the tracker's key (figures there: realistic 0.781 / 0.742 / 0.657 -> 0.865 / 0.860 / 0.775,
#   the other scenes and KIT AIS unchanged);
# parallax_min_fraction, parallax_angle_deg, parallax_speed_rel: a direction shared by regions covering this
#   fraction of the image (and half the moving area) is a parallax field's (frames registered before they
#   came, see _common_parallax); its regions up to this many times their median speed are rejected
#   (parallax_min_fraction 0 turns it off);
# min_explained: the fraction of the grey-value change in a region that warping by its motion must remove,
#   and half of it the margin over warping by the opposite motion (interpolation alone smooths noise either
#   way; 0 turns the test off; needs the frames);
# core_rel: the centre, box and velocity of a region are those of its pixels at least this fraction of its
#   90th-percentile speed (a flow window spreads a vehicle's motion onto the ground around it at a lower
#   speed: that halo is left out of the box);
# leftover_rel: with the frames and box_from_frames, the pixels of a region that lie outside every box found in it
#   (2 px clear), in 8-connected parts of at least this fraction of the region and min_area_px, are each judged once
#   more as a mover at their own flow: a slower vehicle close behind a faster one (a car 0.64 px a frame behind a
#   van at 2.26 in a queue), which the 2-means does not split (their speeds differ by less than split_px + split_rel
#   times the faster) and core_rel leaves out as the faster one's halo; the rest of a bus whose box held one end.
#   Only parts in the lane of a box found in the region are judged (their centre within the box's half extent
#   across its motion): beside a mover, the parts are ground whose residual the flow joined to it (on KIT AIS, where
#   they were 37 of 46 new detections on MOS155-179, on no vehicle). A halo moved nothing and fails the motion test
#   (min_explained). A part's detection is added only where it overlaps none of the cores' detections (nms_iou):
#   ranked with them, a part's larger area outweighed their evidence and took the place of good boxes (nominal,
#   urban-parallax). 0, the default, is off;
# refine_px: the region's motion is refined by block matching within this radius of the flow's (needs the
#   frames; 0: the flow's median as it is);
# refine_wide_px: with the frames, the region's motion is also sought by masked block matching within this radius of
#   the ground's motion, on frames reduced WIDE_STEP times (_wide_velocity), and refined within refine_px as the flow's
#   is: a vehicle that moved further than the flow method follows (at 2-3 frames a second 10-50 px a frame; on KIT AIS
#   a fifth of dis's detections on moving cars had about a third of the car's motion backwards, and their box was the
#   place the car left). It only corrects the motion of a region the flow's motion already passes (min_explained
#   and its margin), where it lies beyond refine_px of every flow start and explains the change by at least
#   min_explained more, with its own margin over the opposite motion (a row of parked cars matches one period on and
#   one back alike); it adds no detection (on fast-vehicles, where every car has one look, a free candidate matched
#   other cars: dis MOTA 0.698 -> 0.611). 0 or at most refine_px: off, the default (figures in the files setting it);
# nms_iou: regions whose boxes overlap this much are parts of one mover (a vehicle moving more than the flow
#   method follows leaves parts of different speeds, and a region where the flow failed): with the frames
#   their union is judged on the motion of each part that explains the change best, without them the largest
#   stays; and of two detections whose boxes overlap this much the better-explained one stays (1 keeps all);
# nms_inside: in the pipeline, last (after the long pair's boxes are merged in, the shadows trimmed, the lanes filled
#   and the sizes judged), a detection whose box lies this share or more inside a larger detection's box, moving with
#   it (merge_px, merge_rel), is a part of that mover and is dropped (drop_parts_inside): a small box inside a large
#   one overlaps it by little IoU (a bus's rear edge, 27 x 17 px, 70 % inside its 62 x 85 px box: IoU 0.04, under
#   nms_iou), and two parts of a uniform roof grown along their lane (lane_fill_rel) end as one box twice. 0: off, the
#   default; figures in dis.yaml;
# box_from_frames: the box is that of the pixels the region's motion explains better than the ground's
#   (_moved_box: the vehicle without the flow's halo; needs the frames; a region with fewer than min_area_px
#   such pixels is no mover: flow noise, an edge the registration left), else of the region's fast core;
# box_join: parts of those pixels (a slow car with a uniform roof changes at its front and rear edges only)
#   join the box when at most this fraction of the pixels between them is static texture (ground between two
#   vehicles that follow each other; 0: the largest part alone, and box_reach_px is off too);
# box_three_frames: with the previous frame (Pipeline.run passes it) a vehicle pixel must also explain the
#   change from frame t-1, which leaves out the ground the vehicle covers next (false: frames t, t+1 only);
# box_reach_px, box_reach_join: parts of those pixels up to box_reach_px beyond the region's box join its box
#   when they lie in its lane (across the motion they overlap it by half the narrower) and at most
#   box_reach_join of the pixels in the convex hull of both that neither marks are static texture (a bus or
#   a long uniform roof moving about a pixel a frame: the flow reaches the threshold at one edge alone, the
#   other edge is the rest of it; ground between two cars that follow each other is textured; 0: off);
# box_reach_parts: the reach's test is taken over the convex hull of the pixels of the box's parts (and of each part
#   joined so far), not of the box's corners, and judges the band across the lane, not the hull as a whole: a part
#   joins unless some line across the motion (BAND_LINE_PX thick, the hull eroded by BAND_ERODE_PX) is more than half
#   static texture that the motion does not mark (_static_band: the ground between two vehicles that follow each
#   other); a part touching the grown box is judged too. The axis-aligned box of a vehicle that drives diagonally
#   holds the ground beside it, which the hull of its corners and a part far along the lane sweeps over: the
#   city-wide world's truck 202 (69 x 59 px box, 2.4 px a frame at 34 degrees) was boxed by its cab alone in 94 of 100
#   frames, the hull's pixels between the cab and its uniform trailer's rear edge 0.38 static, all of it ground beside
#   the trailer. Off (false) by default; on in dis, with the road test (box_reach_road_k), where the worlds gain and
#   KIT AIS does not lose (without the road test the synthetic city lost 0.660 -> 0.510: cars close together joined
#   into one box); the figures are in algorithms/pipelines/dis.yaml and pyramidal-hs.yaml;
# box_reach_road_k: with box_reach_parts, a line of the hull counts as ground also where its pixels are
#   road-coloured (marked by the motion or not): within box_reach_road_k robust standard deviations (1.4826 MAD, at
#   least 1 grey level) of the median grey of the ring of ground around the box (_road_grey, the road model of
#   _gap_split), the vehicle's marked pixels left out of the ring: untextured asphalt between two cars nose to tail is
#   not static texture (warping it changes nothing; next to a moving edge the motion explains it) but is the road's
#   grey, where a uniform trailer or bus roof is not (0: static texture alone). Its own key, not gap_split_road_k: a
#   line is judged here at half road, not at gap_split_valley, and the synthetic city's car roofs near the asphalt's
#   grey fall within 2-3 spreads (dis city with box_reach_parts: 0.510 without the road test, 0.621 at 1.0; a first
#   form that counted road pixels only where the motion left them unmarked: 0.650 at 1.0, 0.408 at 2.0, 0.359 at 3.0,
#   but it kept no asphalt gap of a few px, all of it marked);
# box_margin_rel: with frame t-1, those pixels are sought within 4 px plus this many times the region's motion (px)
#   of the region's box (without it within 4 px: frames t, t+1 alone mark the place it moves to as
#   well; a flow method that finds a vehicle's motion at its edges only, TV-L1 on a uniform roof, or follows part of
#   a fast one, leaves the region short of the vehicle by up to a motion: the changed bands at its front and
#   rear edges are a motion wide; 0: 4 px alone);
# box_split_rel: a part of those pixels that lies at least half in the region, stays out of its box (static texture
#   between) and holds at least this fraction of the pixels of the part the box started from is a second detection
#   at the region's motion: two cars at about one velocity, close together, whose flow a smoothing method (Farneback's
#   window) joined into one region. The parts kept out are first joined among themselves by the rule that joins
#   parts to the box (_join_parts): a second car whose front and rear edges alone changed (a uniform roof between)
#   is one box, not two halves each under the fraction (0: off, the default; the farneback pipeline sets 0.8:
#   urban-parallax MOTA 0.541 -> 0.730 there; dis sets 0.8 since the parts are joined, figures in dis.yaml: DIS beside
#   a lane joins two cars into one region too; before the join it lost KIT AIS track precision at 0.8);
# border_px: moving pixels this close to the image border are left out (a flow window the border clips,
#   content that enters the frame);
# noise_k: the speed threshold is at least this many times the median residual speed of the ground (the
#   flow method's noise on this pair: sensor noise, compression; 0 turns it off);
# change_noise_k, change_enough: a region whose content changed at its place, from frame t to t+1 (and, with
#   frame t-1, from t-1 to t), less than change_noise_k times what the pair's noise alone changes a static patch
#   of its contrast, and by less than change_enough (1 - NCC) at all, is no mover (_changed_at_rest: static
#   texture the flow saw move through aliasing, compression or flicker keeps its content; a vehicle carries its
#   own away; needs the frames; change_noise_k 0 turns it off);
# ground_model: "affine" or "quadratic" subtracts a robust fit of the local flow first (ground_residual: the
#   camera's rotation jitter, a tilted view, lens distortion leave the ground a smooth residual a shift model
#   cannot remove), "none" not;
# min_area_m2, max_area_m2: size limits where the ground sampling distance is known (a small car's top
#   view is about 6 m^2, an articulated bus's 45 m^2; flow halos add to both; motorbikes, about 1.5 m^2,
#   are given up by the default minimum, which flow noise on the ground passes too often). With box_from_frames
#   and the frames the maximum judges the detection's box (width x height), not the flow region: Farneback's
#   window spread a car moving 8-14 px a frame over 160-230 m^2 on fast-vehicles (a 22 px car is 23 m^2 there),
#   which the region test rejected (MOTA there: farneback 0.567 -> 0.668, pyramidal-lk 0.660 -> 0.694, the others
#   unchanged; benchmarks/tracking_quality.py --frames 30).
# max_area_halo_rel: with the box from the frames, a flow region larger than this many times max_area_px or
#   max_area_m2 is rejected on the region's area before its box is sought (no halo is that large: roofs, a
#   parallax field; the box of such a region is the costliest part of the stage); >= 1.
# min_box_m2: with box_from_frames, the frames and the ground sampling distance, a detection whose box (width x
#   height, the mover without the flow's halo) covers less is no vehicle (null: no limit). A car's box is at least
#   3.8 x 1.7 m (6.5 m^2; the synthetic cars' boxes: 5th percentile 6.8 m^2), a cyclist's, its shadow and the
#   3 x 3 average included, 3-4 m^2: the halo of a smoothing flow (Horn-Schunck, LK's window, Farneback) carries
#   a cyclist's motion over min_area_m2, which judges the flow region, and its box passes max_area_m2's test.
#   Motorbikes go with the cyclists, as min_area_m2 already gives them up. A box within border_px of the image's
#   edge is a vehicle the frame cuts and is not judged. benchmarks/tracking_quality.py --frames 30, MOTA null -> 4.0
#   (dis / pyramidal-hs / -lk / tv-l1 / farneback): city 0.558 / 0.283 / 0.288 / 0.412 / 0.421 -> 0.558 / 0.408 /
#   0.412 / 0.412 / 0.546 (a track on a cyclist, 29 false positives: the truth's cyclists are distractors, but a
#   21 x 11 px box on a 14 x 6 px cyclist is not IoU 0.5 with it); urban-parallax 0.711 / 0.786 / 0.786 / 0.780 /
#   0.730 -> 0.717 / 0.811 / 0.805 / 0.780 / 0.730; fast-vehicles 0.638 / 0.724 / 0.694 / 0.716 / 0.672 -> 0.642 /
#   0.716 / 0.701 / 0.735 / 0.724 (pyramidal-hs loses a fast car's fragments that kept its track, 2 frames);
#   nominal and realistic unchanged. KIT AIS and eval-video footage have no ground sampling distance: unchanged.
# gap_split_width_px, gap_split_length_px: a box from the frames that a band of road crosses from side to side is
#   two or three vehicles that move together (cars leaving a parking row or a queue side by side, a car close
#   behind another): it is cut along the band (_gap_split), across its motion where each part keeps at least
#   gap_split_width_px (a narrow car's width) across it, along its motion where each keeps gap_split_length_px
#   (a short car's length) along it (0: that cut off). A bus or truck has no band of road inside it and stays whole;
# gap_split_road_k, gap_split_valley: a pixel is road when its grey value lies within gap_split_road_k robust
#   standard deviations of the median of the ring of ground around the box; a band is road when at most
#   gap_split_valley of its pixels are not, and each part it leaves holds a line of which at least
#   GAP_SPLIT_PEAK are not. Both cuts off by default; dis, pyramidal-hs and pyramidal-lk set gap_split_width_px 8
#   (their files give the figures: the city-wide 1080p stand-in's joined boxes are cars side by side, 350 of dis's
#   888 unmatched track rows, 2 along the lane). gap_split_length_px 20 beside it measured (dis): city-wide MOTA
#   0.338 -> 0.333 (FN 3447 -> 3487), KIT AIS detection precision / recall 0.269 / 0.417 -> 0.265 / 0.419, the
#   synthetic scenes (30 frames) unchanged: left off, a key for footage with queues nose to tail.
# gap_split_moved: where no band of road grey crosses the box (or the parts it leaves hold too few moving pixels), a
#   band of ground that the box's motion does not move is one too (_gap_split with by_motion; a zebra crossing, a
#   marking or a shadow between two cars abreast is no road grey, yet nothing between them moves), each part reaching
#   further along the motion than across it. Off by default; the pipeline files that set it give the figures.
# shadow_trim_rel, shadow_ratio_lo, shadow_ratio_hi, shadow_vote, shadow_min_votes: a vehicle's cast shadow moves with
#   it and its flow is the vehicle's, so the box of step 6 holds it; annotators box the body alone
#   (trim_cast_shadows, last, needs the frames). A pixel is dark at shadow_ratio_lo to shadow_ratio_hi times the
#   grey of the ground around the box; a side is the pair's shadow side when, over at least shadow_min_votes
#   detections moving either way along its axis, the dark fraction next to it exceeds the opposite side's by
#   shadow_vote; each box loses the band there that is darker than the same depth from the opposite side, at most
#   shadow_trim_rel of its width (height) (0: off, the default). benchmarks/tracking_quality.py --frames 30, MOTA at
#   0.35 against off (dis / pyramidal-hs): nominal 0.866 / 0.872 -> 0.901 / 0.884, realistic 0.663 / 0.768 -> 0.641 /
#   0.746, urban-parallax and city dis unchanged, fast-vehicles pyramidal-hs 0.724 -> 0.713, city pyramidal-hs
#   0.408 -> 0.396; the city-wide 1080p stand-in 0.208 / 0.144 -> 0.215 / 0.184; KIT AIS (no cast shadows) dis
#   detection precision / recall 0.248 / 0.371 -> 0.244 / 0.363, pyramidal-hs unchanged, box-aware pseudo-MOT MOTA
#   -0.597 / -0.903 -> -0.564 / -0.890. Off until a sequence-level vote (one sun over a clip) makes it hold on every
#   set.
# shadow_lead_px: a band may start this far in from the box's side, and is trimmed with what lies before it (the
#   blurred edge; the ground where the shadow lies at t+1 or lay at t-1, which the box from the frames holds: the
#   synthetic city's boxes hold 2-5 px of lit ground, then the shadow, then the body). 2 as before it was a key.
# shadow_scope, shadow_clip_min_votes: "frame" (default), each pair votes its own shadow sides in detect_vehicles;
#   "clip", Pipeline.run votes once over the clip so far (clip_shadow_direction: the mean of the leans of the
#   vehicles driving either way along each axis, at least shadow_clip_min_votes of each, past shadow_vote; the
#   votes turned into frame 0's axes by the camera's yaw) and trims the sides that face that direction
#   (trim_toward), and detect_vehicles alone trims nothing. Where the boxes are off (benchmarks/box_sides.py, dis,
#   median px past the truth box, left / top / right / bottom): city 6.2 / 0.1 / -1.2 / -0.6, realistic 2.7 / 3.4 / 0.0
#   / -0.6, nominal 2.4 / 2.1 / 0.0 / -0.3, a 2.7.0 city-wide world (s1, 50 frames) 5.9 / 2.0 / -0.5 / -0.2: the shadow
#   sides, which the frame's vote at 0.35 hardly trimmed (city 6.2, realistic 2.7 / 3.1, s1 5.8 / 2.0: the band starts
#   past 2 px, and the frame's rule lost the city's shadow to its windscreens). The clip's vote at 0.35 with
#   shadow_lead_px 5: benchmarks/tracking_quality.py --frames 30 (box_sides.py prints the same MOTA), MOTA off -> clip
#   (dis / pyramidal-hs / pyramidal-lk / tv-l1 / farneback): nominal 0.947 / 0.953 / 0.953 / 0.906 / 0.935 -> 0.982 /
#   0.976 / 0.971 / 0.859 / 0.959; realistic 0.674 / 0.781 / 0.742 / 0.730 / 0.657 -> 0.719 / 0.736 / 0.697 / 0.697 /
#   0.601 (the point rule unchanged: boxes that fell under IoU 0.5); urban-parallax unchanged; fast-vehicles 0.698 /
#   0.778 / 0.774 / 0.806 / 0.806 -> 0.698 / 0.774 / 0.798 / 0.806 / 0.798; city 0.660 / 0.447 / 0.481 / 0.471 / 0.626
#   -> 0.660 / 0.461 / 0.490 / 0.505 / 0.621; city-wide worlds s1, s2, s3 (/work/diag/worlds, their first 50 frames,
#   dis) 0.340 / 0.304 / 0.428 -> 0.380 / 0.339 / 0.470 (the left side 5.9 / 5.9 / 5.8 px past the truth -> 4.2 / 2.0 /
#   2.7); but the 1080p stand-ins (aerobench run of a suite of the clip, gt270) dis city 0.564 -> 0.556 and city-wide
#   0.364 -> 0.310 (IDF1 0.545), KIT AIS (--kit-ais) detection precision / recall dis 0.269 / 0.417 -> 0.267 / 0.411,
#   pyramidal-hs 0.287 / 0.511 unchanged. With shadow_lead_px 2: realistic dis / pyramidal-hs / tv-l1 0.674 / 0.758 /
#   0.719. Off: it costs realistic to every pipeline but dis, and dis the city-wide stand-in. Those figures trimmed the
#   pair's boxes before the long pair's were merged in (merge_detections): a slow mover's box from the long pair held
#   its shadow, and beside a trimmed pair box of the same car it overlapped too little to replace it (two boxes, a
#   false positive). The clip's trim now applies to the merged boxes, the pair's alone still voting
#   (algorithms.pipeline; figures in dis.yaml).
# shadow_diagonal_deg: with shadow_scope clip, a box whose motion lies more than this many degrees off both image
#   axes is not trimmed: a vehicle driving diagonally fills its axis-aligned box only along a diagonal, and the band
#   darker than the opposite side's at the box's edge is a corner of its body or the ground beside it, not a shadow
#   along its side (the 1080p city-wide world at seed 1: vans on a 40-degree street cut to a corner, 63 rows off
#   their vehicle). 0: every box trimmed.
# lane_fill_rel, lane_fill_line, lane_fill_road_k (fill_lane; applied by the pipeline to the pair's detections, those of
#   the long pair merged in and trimmed of their shadow, before the tracker): a uniform roof (a bus, a van, a truck's
#   trailer, a car's) moving along itself changes neither the flow nor the frames inside it, so its box holds the
#   front or the rear edge and the tracker follows a part of the vehicle (the 1080p city-wide worlds: the track rows on a
#   vehicle at IoU 0.1-0.5 were a part of it in 582 of 936). Each box grows along its motion, forward and back, line by
#   line across the motion within its lane (the across-extent of its own body pixels), while at least lane_fill_line
#   of a line is no road (its grey more than lane_fill_road_k robust spreads from the ring of ground around the box, as
#   _gap_split tells road), at most lane_fill_rel times the body's length or width, whichever is larger (0: off, the
#   default). A band of road between two vehicles stops it; so does the road behind a car; and a new end that does not
#   move with the vehicle is not taken (frame t+1 at the box's motion must explain the lines around it: a crosswalk or
#   a stop line at a car's nose is no road either). Figures in dis.yaml.
DETECTION_DEFAULTS = {
    "min_magnitude_px": 0.5, "open_px": 1, "close_px": 2, "min_area_px": 20, "max_area_px": None,
    "split_px": 1.0, "split_rel": 0.6, "merge_gap_px": 3.0, "merge_px": 1.0, "merge_rel": 0.3,
    "parallax_max_ratio": 0.25, "parallax_perp_px": 0.5, "parallax_perp_rel": 0.25, "parallax_lengthwise_rel": 0.0,
    "parallax_min_fraction": 0.05, "parallax_angle_deg": 20.0, "parallax_speed_rel": 1.5,
    "min_explained": 0.2, "min_area_m2": 3.0, "max_area_m2": 120.0, "core_rel": 0.5, "ground_model": "affine", "noise_k": 3.0, "border_px": 8, "refine_px": 12, "nms_iou": 0.1, "box_from_frames": True,
    "box_join": 0.5, "box_three_frames": True, "box_reach_px": 48, "box_reach_join": 0.2, "box_reach_parts": False,
    "box_reach_road_k": 1.0, "nms_inside": 0.0,
    "change_noise_k": 5.0, "change_enough": 0.5, "box_margin_rel": 1.0, "box_split_rel": 0.0, "leftover_rel": 0.0,
    "max_area_halo_rel": 4.0, "min_box_m2": 4.0, "refine_wide_px": 0,
    "gap_split_width_px": 0, "gap_split_length_px": 0, "gap_split_road_k": 3.0, "gap_split_valley": 0.12,
    "gap_split_moved": False,
    "shadow_trim_rel": 0.0, "shadow_ratio_lo": 0.2, "shadow_ratio_hi": 0.8, "shadow_vote": 0.1, "shadow_min_votes": 3,
    "shadow_scope": "frame", "shadow_clip_min_votes": 20, "shadow_lead_px": 2, "shadow_diagonal_deg": 20.0,
    "lane_fill_rel": 0.0, "lane_fill_line": 0.6, "lane_fill_road_k": 3.0,
}


def _disk(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


class _Region:
    """Pixels of one candidate mover: flat indices into the frame, their coordinates and flows."""

    __slots__ = ("ys", "xs", "w")

    def __init__(self, ys: np.ndarray, xs: np.ndarray, w: np.ndarray):
        self.ys, self.xs, self.w = ys, xs, w

    @property
    def velocity(self) -> np.ndarray:
        return np.median(self.w, axis=0) if len(self.w) else np.zeros(2)

    def box(self) -> tuple[int, int, int, int]:
        return int(self.xs.min()), int(self.ys.min()), int(self.xs.max()), int(self.ys.max())

    def cores(self, rel: float, min_area_px: int) -> list[_Region]:
        """The 8-connected parts of the region's pixels at least ``rel`` times its 90th percentile speed.

        A flow window spreads a vehicle's motion onto the ground around it at a lower speed; that
        halo joins vehicles that follow each other closely at the same speed into one region, and
        leaving it out parts them again. Parts under ``min_area_px`` are dropped; with ``rel`` 0, or
        when no part is left, the whole region.
        """
        if rel <= 0 or len(self.w) == 0:
            return [self]
        speed = np.hypot(self.w[:, 0], self.w[:, 1])
        keep = speed >= rel * np.percentile(speed, 90)
        return _parts(self.ys[keep], self.xs[keep], self.w[keep], min_area_px) or [self]


def _parts(ys: np.ndarray, xs: np.ndarray, w: np.ndarray, min_px: float) -> list[_Region]:
    """The 8-connected parts of the pixels ``(ys, xs)`` (flows ``w``) that hold at least ``min_px`` of them."""
    if len(ys) == 0:
        return []
    x0, y0 = int(xs.min()), int(ys.min())
    img = np.zeros((int(ys.max()) - y0 + 1, int(xs.max()) - x0 + 1), np.uint8)
    img[ys - y0, xs - x0] = 1
    n, labels = cv2.connectedComponents(img, connectivity=8)
    lab = labels[ys - y0, xs - x0]
    parts = [_Region(ys[lab == j], xs[lab == j], w[lab == j]) for j in range(1, n)]
    return [q for q in parts if len(q.ys) >= min_px]


def _left_over(region: _Region, found, rel: float, min_area_px: int) -> list[_Region]:
    """The 8-connected parts of the pixels of ``region`` more than 2 px outside every box of ``found``
    ((x0, y0, x1, y1, u, v) each: a box and its motion) that hold at least ``rel`` of the region and
    ``min_area_px`` and whose centre lies in the lane of a box that overlaps the region's: on the line of its
    motion, within the box's half extent across it (``leftover_rel``: the vehicle ahead of or behind a mover found
    in the region, not what lies beside it)."""
    rx0, ry0, rx1, ry1 = region.box()
    found = [b for b in found if b[0] <= rx1 and b[2] >= rx0 and b[1] <= ry1 and b[3] >= ry0]
    if len(region.ys) < min_area_px or not found:
        return []
    out = np.ones(len(region.ys), bool)
    for x0, y0, x1, y1, _, _ in found:
        out &= (region.xs < x0 - 2) | (region.xs > x1 + 2) | (region.ys < y0 - 2) | (region.ys > y1 + 2)
    need = max(min_area_px, rel * len(region.ys))
    if out.sum() < need:
        return []

    def in_lane(q: _Region) -> bool:
        for bx0, by0, bx1, by1, u, v in found:
            ext = box_extents(bx1 - bx0 + 1, by1 - by0 + 1, u, v)
            if ext is None:
                continue
            speed = math.hypot(u, v)  # the part's centre from the box's, across the motion
            across = abs(-(q.xs.mean() - (bx0 + bx1) / 2) * v + (q.ys.mean() - (by0 + by1) / 2) * u) / speed
            if across <= ext[1] / 2:
                return True
        return False

    return [q for q in _parts(region.ys[out], region.xs[out], region.w[out], need) if in_lane(q)]


def _check_keys(params: dict) -> dict:
    unknown = sorted(set(params) - set(DETECTION_DEFAULTS))
    if unknown:
        raise ValueError(f"detection: unknown key(s) {unknown}; valid: {', '.join(DETECTION_DEFAULTS)}")
    p = {**DETECTION_DEFAULTS, **params}
    if p["ground_model"] not in ("affine", "quadratic", "none"):
        raise ValueError(f"ground_model: expected affine, quadratic or none, got {p['ground_model']!r}")
    for k, v in p.items():
        if k in ("ground_model", "shadow_scope") or (v is None and k in ("max_area_px", "min_area_m2", "max_area_m2",
                                                                          "min_box_m2")):
            continue
        if k in ("box_from_frames", "box_three_frames", "box_reach_parts", "gap_split_moved"):
            if not isinstance(v, bool):
                raise ValueError(f"{k}: expected true/false, got {v!r}")
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ValueError(f"{k}: expected a finite number >= 0, got {v!r}")
    for k in ("open_px", "close_px", "min_area_px", "border_px", "refine_px", "box_reach_px", "gap_split_width_px",
              "gap_split_length_px", "refine_wide_px", "shadow_lead_px"):
        if not isinstance(p[k], (int, np.integer)):
            raise ValueError(f"{k}: expected an integer >= 0, got {p[k]!r}")
    if not p["max_area_halo_rel"] >= 1:
        raise ValueError(f"max_area_halo_rel: expected a number >= 1, got {p['max_area_halo_rel']!r}")
    for k in ("min_explained", "box_join", "box_reach_join", "change_enough", "gap_split_valley", "shadow_vote",
              "shadow_ratio_hi", "leftover_rel", "nms_inside"):
        if not p[k] <= 1:
            raise ValueError(f"{k}: expected a fraction in [0, 1], got {p[k]!r}")
    if not p["shadow_trim_rel"] < 0.5:
        raise ValueError(f"shadow_trim_rel: expected a fraction in [0, 0.5), got {p['shadow_trim_rel']!r}")
    if not p["shadow_ratio_lo"] < p["shadow_ratio_hi"]:
        raise ValueError(f"shadow_ratio_lo: expected below shadow_ratio_hi ({p['shadow_ratio_hi']!r}), "
                         f"got {p['shadow_ratio_lo']!r}")
    for k in ("shadow_min_votes", "shadow_clip_min_votes"):
        if not isinstance(p[k], (int, np.integer)) or p[k] < 1:
            raise ValueError(f"{k}: expected an integer >= 1, got {p[k]!r}")
    if p["shadow_scope"] not in ("frame", "clip"):
        raise ValueError(f"shadow_scope: expected frame or clip, got {p['shadow_scope']!r}")
    if not 0 < p["lane_fill_line"] <= 1:
        raise ValueError(f"lane_fill_line: expected a fraction in (0, 1], got {p['lane_fill_line']!r}")
    if not p["shadow_diagonal_deg"] <= 45:
        raise ValueError(f"shadow_diagonal_deg: expected degrees in [0, 45], got {p['shadow_diagonal_deg']!r}")
    return p


def _split(region: _Region, p: dict, depth: int = 0) -> list[_Region]:
    """Split a region into parts of coherent velocity (recursive 2-means on the flow vectors, then 8-connectivity)."""
    n = len(region.w)
    if depth >= 3 or n < 2 * p["min_area_px"]:
        return [region]
    w = region.w.astype(np.float64)
    # coherent already (most regions): every velocity within the split distance of the median, no 2-means
    med = np.median(w[:: max(1, n // 2000)], axis=0)
    spread = float(np.percentile(np.hypot(*(w - med).T), 95))
    if spread <= 0.5 * (p["split_px"] + p["split_rel"] * math.hypot(*med)):
        return [region]
    # 2-means (on at most ~2000 of the vectors) started from the two farthest apart along the principal
    # direction of the spread
    sub = w[:: max(1, n // 2000)]
    d = sub - sub.mean(axis=0)
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    proj = d @ vt[0]
    c = np.stack([sub[np.argmin(proj)], sub[np.argmax(proj)]])
    for _ in range(6):
        lab_s = np.sum((sub - c[1]) ** 2, axis=1) < np.sum((sub - c[0]) ** 2, axis=1)
        if lab_s.all() or not lab_s.any():
            return [region]
        c = np.stack([sub[~lab_s].mean(axis=0), sub[lab_s].mean(axis=0)])
    lab = np.sum((w - c[1]) ** 2, axis=1) < np.sum((w - c[0]) ** 2, axis=1)
    if lab.all() or not lab.any():
        return [region]
    speed = max(float(np.hypot(*c[0])), float(np.hypot(*c[1])))
    if not float(np.hypot(*(c[0] - c[1]))) > p["split_px"] + p["split_rel"] * speed:
        return [region]
    parts = []
    x0, y0, x1, y1 = region.box()
    for k in (False, True):
        sel = lab == k
        img = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
        img[region.ys[sel] - y0, region.xs[sel] - x0] = 1
        n_lab, labels = cv2.connectedComponents(img, connectivity=8)
        lab_px = labels[region.ys[sel] - y0, region.xs[sel] - x0]
        ys, xs, ws = region.ys[sel], region.xs[sel], region.w[sel]
        for j in range(1, n_lab):
            s = lab_px == j
            if s.sum() >= p["min_area_px"]:
                parts.append(_Region(ys[s], xs[s], ws[s]))
    if len(parts) < 2:
        return [region]
    return [q for part in parts for q in _split(part, p, depth + 1)]


def _one_motion(vels: np.ndarray, vel, merge_px: float, merge_rel: float) -> np.ndarray:
    """``(n,)`` bool: which of the velocities ``vels`` ``(n, 2)`` agree with ``vel`` ``(u, v)`` as the regions of one
    mover do (``merge_px``, ``merge_rel``): they differ by at most ``merge_px + merge_rel`` times the faster speed."""
    dv = np.hypot(*(vels - vel).T)
    speed = np.maximum(np.hypot(*vels.T), math.hypot(*vel))
    return dv <= merge_px + merge_rel * speed


def _merge(regions: list[_Region], p: dict) -> list[_Region]:
    """Join regions whose boxes lie within merge_gap_px and whose velocities agree (union-find)."""
    n = len(regions)
    if n < 2:
        return regions
    boxes = np.array([r.box() for r in regions], dtype=np.float64)
    vel = np.array([r.velocity for r in regions])
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    gap = p["merge_gap_px"]
    for i in range(n):
        gx = np.maximum(boxes[i + 1:, 0] - boxes[i, 2], boxes[i, 0] - boxes[i + 1:, 2]) - 1
        gy = np.maximum(boxes[i + 1:, 1] - boxes[i, 3], boxes[i, 1] - boxes[i + 1:, 3]) - 1
        alike = _one_motion(vel[i + 1:], vel[i], p["merge_px"], p["merge_rel"])
        for j in np.flatnonzero((np.maximum(gx, gy) <= gap) & alike):
            parent[root(i + 1 + int(j))] = root(i)
    groups: dict[int, list[_Region]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(regions[i])
    return [g[0] if len(g) == 1 else _Region(np.concatenate([r.ys for r in g]), np.concatenate([r.xs for r in g]),
                                             np.concatenate([r.w for r in g])) for g in groups.values()]


def _overlapping(cores: list[_Region], iou: float) -> list[list[_Region]]:
    """Cores grouped greedily, largest first: each takes the cores not yet grouped whose boxes overlap its own by ``iou``.

    A vehicle that moves much more than the flow method can follow leaves parts of different
    speeds (the flow found part of its motion here, all of it there) and a region where the flow
    failed (the ground it uncovered); their boxes overlap. The largest part leads its group.
    """
    order = sorted(range(len(cores)), key=lambda i: -len(cores[i].ys))
    boxes = [cores[i].box() for i in order]
    used = [False] * len(order)
    groups = []
    for a in range(len(order)):
        if used[a]:
            continue
        used[a] = True
        members = [cores[order[a]]]
        for b in range(a + 1, len(order)):
            if not used[b] and iou_xyxy(boxes[a], boxes[b]) >= iou:
                used[b] = True
                members.append(cores[order[b]])
        groups.append(members)
    return groups


def iou_xyxy(a, b) -> float:
    """IoU of two inclusive pixel boxes ``(x0, y0, x1, y1)``."""
    iw = min(a[2], b[2]) - max(a[0], b[0]) + 1
    ih = min(a[3], b[3]) - max(a[1], b[1]) + 1
    if iw <= 0 or ih <= 0:
        return 0.0
    inter = iw * ih
    return inter / ((a[2] - a[0] + 1) * (a[3] - a[1] + 1) + (b[2] - b[0] + 1) * (b[3] - b[1] + 1) - inter)


def _motion(region: _Region, starts, frames, ground, p: dict):
    """The motion of a region that best explains the change between the frames: ``(u, v, margin)`` or None.

    Candidates: each start (the flow's median motion of each part of the region, relative to the
    ground) and, with ``refine_px``, the block matching's motion from it. Evidence that the
    region's texture moved by (u, v) over the ground: the change it explains (at least
    ``min_explained``), then its margin over the opposite motion (at least half ``min_explained``:
    a uniform roof moved less than its size matches itself either way). The best-explaining
    candidate that passes both is chosen; with ``min_explained`` 0 the best-explaining one. None
    when none passes. With ``refine_wide_px`` a region so found may take the motion of the coarse
    wide search (:func:`_wide_velocity`, refined within ``refine_px``) instead: where it lies beyond
    ``refine_px`` of every start (nearer, a start's refinement reaches it) and explains the change by at
    least ``min_explained`` more than the chosen motion, with its own margin. It corrects the motion of a
    mover the flow found (a car beyond the flow's reach at 2-3 frames a second, given a fraction of its
    motion or the reverse); it finds none the flow did not (repeated texture, another car of one look).
    """
    chosen = _best_motion(region, starts, frames, ground, p)
    if chosen is None or p["refine_wide_px"] <= p["refine_px"] or p["min_explained"] <= 0:
        return chosen
    wide = _wide_velocity(region, frames, p["refine_wide_px"], ground)
    if wide is None or not all(math.hypot(wide[0] - u, wide[1] - v) > p["refine_px"] for u, v in starts):
        return chosen
    better = _best_motion(region, [wide], frames, ground, p)
    if better is None:
        return chosen
    gain = _explained(region, frames, chosen[0], chosen[1], ground)
    if _explained(region, frames, better[0], better[1], ground) >= gain + p["min_explained"]:
        return better
    return chosen


def _best_motion(region: _Region, starts, frames, ground, p: dict):
    """:func:`_motion`'s choice among ``starts`` and their refinements: ``(u, v, margin)`` or None."""
    cands: list[tuple[float, float]] = []
    for u, v in starts:
        tries = [(u, v)]
        if p["refine_px"] > 0:
            tries.append(_refine_velocity(region, frames, u, v, p["refine_px"], ground))
        for a, b in tries:
            if all(math.hypot(a - a2, b - b2) > 0.25 for a2, b2 in cands):
                cands.append((a, b))
    options = sorted(((_explained(region, frames, a, b, ground), a, b) for a, b in cands), reverse=True)
    for gain, a, b in options:
        if p["min_explained"] > 0 and gain < p["min_explained"]:
            break
        margin = gain - _explained(region, frames, -a, -b, ground)
        if p["min_explained"] <= 0 or margin >= p["min_explained"] / 2:
            return a, b, margin
    if p["min_explained"] > 0:
        return None
    gain, a, b = options[0]
    return a, b, gain - _explained(region, frames, -a, -b, ground)


def _patch(img: np.ndarray, xa: int, ya: int, xb: int, yb: int) -> np.ndarray:
    return np.ascontiguousarray(img[ya:yb + 1, xa:xb + 1], dtype=np.float32)


def _shifted(img: np.ndarray, du: float, dv: float) -> np.ndarray:
    """``img(x + du, y + dv)`` sampled bilinearly (the border replicated)."""
    return cv2.warpAffine(img, np.float32([[1, 0, du], [0, 1, dv]]), (img.shape[1], img.shape[0]),
                          flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)


def _refine_velocity(region: _Region, frames, u: float, v: float, radius_px: int,
                     ground=(0.0, 0.0)) -> tuple[float, float]:
    """The region's motion over the ground by masked block matching around the flow's (u, v).

    Flow methods fall short of motions much larger than their window or finest pyramid level can
    see (a vehicle at 30 m/s moves 15 px a frame at 10 fps, 0.2 m/px); the region's own pixels of
    frame t, searched in the compensated frame t+1 within ``radius_px`` of the flow's prediction
    (``ground`` + (u, v): ``ground`` is the motion the compensation left the ground with there),
    are matched by the sum of squared differences over the region's pixels (``cv2.matchTemplate``
    with a mask), the minimum refined to sub-pixel by a parabola per axis. Returns the motion
    relative to the ground.
    """
    g0, g1 = frames
    h, w = g0.shape
    gu, gv = ground
    pu, pv = u + gu, v + gv
    x0, y0, x1, y1 = region.box()
    tpl = _patch(g0, x0, y0, x1, y1)
    mask = np.zeros(tpl.shape, np.float32)
    mask[region.ys - y0, region.xs - x0] = 1.0
    r = int(radius_px) + int(math.ceil(max(abs(pu), abs(pv))))
    xa, ya, xb, yb = max(0, x0 - r), max(0, y0 - r), min(w - 1, x1 + r), min(h - 1, y1 + r)
    area = _patch(g1, xa, ya, xb, yb)
    if area.shape[0] < tpl.shape[0] + 2 or area.shape[1] < tpl.shape[1] + 2:
        return u, v
    ssd = cv2.matchTemplate(area, tpl, cv2.TM_SQDIFF, mask=mask)
    # candidates: within radius_px of the flow's prediction (the ground's place is where the region's
    # ground halo matches, so it is no candidate unless the flow predicts it)
    dy, dx = np.mgrid[0:ssd.shape[0], 0:ssd.shape[1]]
    dx, dy = dx + xa - x0, dy + ya - y0
    ssd = np.where(np.hypot(dx - pu, dy - pv) <= radius_px, ssd, np.inf)
    iy, ix = np.unravel_index(int(np.argmin(ssd)), ssd.shape)
    if not np.isfinite(ssd[iy, ix]):
        return u, v

    def vertex(a, b, c):
        den = a - 2 * b + c
        return 0.0 if not (np.isfinite(a) and np.isfinite(c)) or den <= 0 else float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))

    ox = vertex(ssd[iy, ix - 1], ssd[iy, ix], ssd[iy, ix + 1]) if 0 < ix < ssd.shape[1] - 1 else 0.0
    oy = vertex(ssd[iy - 1, ix], ssd[iy, ix], ssd[iy + 1, ix]) if 0 < iy < ssd.shape[0] - 1 else 0.0
    return float(dx[iy, ix] + ox) - gu, float(dy[iy, ix] + oy) - gv


# _wide_velocity: the search runs on frames reduced this many times (a car of 20 x 10 px at KIT AIS's 0.15 m/px is
# 5 x 2.5 px there: still a template), the full-resolution refinement (refine_px) places it after
WIDE_STEP = 4


def _wide_velocity(region: _Region, frames, radius_px: int, ground=(0.0, 0.0)) -> tuple[float, float] | None:
    """The region's motion over the ground by masked block matching within ``radius_px`` of the ground's motion,
    on frames reduced :data:`WIDE_STEP` times (coarse: :func:`_refine_velocity` places it); None where the region
    is under 2 x 2 px reduced or the search area leaves no room.

    At 2-3 frames a second a car moves 10-50 px a frame, beyond what DIS or a pyramid follows on a 40 px car: the
    flow gives its region a fraction of the motion or the reverse of it (KIT AIS, dis: a fifth of the detections on a
    moving car pointed backwards at about a third of its speed), the refinement within ``refine_px`` of that
    cannot reach the true motion, and the box the frames give then covers the place the car left. The region's
    own pixels of frame t, sought in the compensated frame t+1 around the ground's motion, find it. Returns the
    motion relative to the ground, px.
    """
    g0, g1 = frames
    h, w = g0.shape
    gu, gv = ground
    s = WIDE_STEP
    x0, y0, x1, y1 = region.box()
    if (x1 - x0 + 1) < 2 * s or (y1 - y0 + 1) < 2 * s:
        return None
    r = int(radius_px) + int(math.ceil(max(abs(gu), abs(gv))))
    xa, ya, xb, yb = max(0, x0 - r), max(0, y0 - r), min(w - 1, x1 + r), min(h - 1, y1 + r)
    # one grid for both: the template's cells are cells of the search area (offsets multiples of s)
    tx0, ty0 = xa + ((x0 - xa) // s) * s, ya + ((y0 - ya) // s) * s
    tw, th = (x1 - tx0) // s + 1, (y1 - ty0) // s + 1
    aw, ah = (xb - xa + 1) // s, (yb - ya + 1) // s
    if aw < tw + 2 or ah < th + 2:
        return None
    small = lambda img, xs, ys, nw, nh: cv2.resize(_patch(img, xs, ys, xs + nw * s - 1, ys + nh * s - 1), (nw, nh),
                                                   interpolation=cv2.INTER_AREA)
    tpl = small(g0, tx0, ty0, tw, th)
    full = np.zeros((th * s, tw * s), np.float32)
    iy, ix = region.ys - ty0, region.xs - tx0
    ok = (iy >= 0) & (iy < th * s) & (ix >= 0) & (ix < tw * s)
    full[iy[ok], ix[ok]] = 1.0
    mask = (cv2.resize(full, (tw, th), interpolation=cv2.INTER_AREA) >= 0.5).astype(np.float32)
    if mask.sum() < 4:
        return None
    ssd = cv2.matchTemplate(small(g1, xa, ya, aw, ah), tpl, cv2.TM_SQDIFF, mask=mask)
    dy, dx = np.mgrid[0:ssd.shape[0], 0:ssd.shape[1]]
    dx, dy = dx * s + xa - tx0, dy * s + ya - ty0
    ssd = np.where(np.hypot(dx - gu, dy - gv) <= radius_px, ssd, np.inf)
    k = int(np.argmin(ssd))
    if not np.isfinite(ssd.flat[k]):
        return None
    return float(dx.flat[k]) - gu, float(dy.flat[k]) - gv


def _motion_gain(a: np.ndarray, b: np.ndarray, c: np.ndarray | None, u: float, v: float, ground) -> np.ndarray:
    """Grey levels by which the motion ``(u, v)`` over the ground's ``ground`` explains patch ``a`` of frame t from
    ``b`` (frame t+1) better than the ground's motion alone, averaged over 3 x 3 px; with ``c`` (frame t-1) the
    smaller of that and the same test backwards. Patches as :func:`_patch` cuts them, one shape."""
    gu, gv = ground
    gain = cv2.blur(np.abs(_shifted(b, gu, gv) - a) - np.abs(_shifted(b, u + gu, v + gv) - a), (3, 3))
    if c is not None:
        gain = np.minimum(gain, cv2.blur(np.abs(_shifted(c, -gu, -gv) - a) - np.abs(_shifted(c, -u - gu, -v - gv) - a),
                                         (3, 3)))
    return gain


def _moved_box(region: _Region, frames, u: float, v: float, ground=(0.0, 0.0), prev=None, *, join: float = 0.5,
               reach_px: int = 0, reach_join: float = 0.2, reach_parts: bool = False, road_k: float = 3.0,
               margin_px: int = 4,
               gain_grey: float = 2.0, others: list | None = None,
               other_rel: float = 0.5) -> tuple[int, int, int, int, int] | None:
    """The box of the pixels around the region that its motion explains better than the ground's.

    A flow region is larger than its vehicle: the flow window carries the vehicle's motion onto the
    ground around it. A pixel of the vehicle is where the compensated frame t+1 sampled at the
    vehicle's motion (``ground`` + (u, v)) matches frame t better than sampled at the ground's
    (``ground``: what the compensation left of the ground's motion there); with ``prev`` (frame
    t-1 compensated into frame t) also where frame t-1 sampled at the opposite motions does: the
    first test alone marks the vehicle and the ground it covers next, the second the vehicle and
    the ground it uncovered, both the vehicle at t alone, however far it moved (the intersection
    of the two change masks, each made motion-aware). The gain, averaged over 3 x 3 px, above
    ``gain_grey`` grey levels, closed over 2 px, within ``margin_px`` of the region's box: its
    8-connected part that holds most of the region's pixels, joined by the other parts that lie
    at least half in the region when at most ``join`` of the pixels between them (in the convex hull
    of the parts) are static texture (warping by the motion makes them worse by ``gain_grey``: ground between two
    vehicles that follow each other; a uniform roof between a car's front and rear edges changes
    neither way). With ``reach_px``, parts up to that far from the region's box join too when they
    lie in its lane (across the motion they overlap the box by half the narrower one) and at most
    ``reach_join`` of the pixels inside the convex hull of both that neither part marks are static texture:
    a long uniform roof (a bus) moving about a pixel a frame gives the flow its rear or front edge
    alone, and the other edge is the rest of the vehicle (see :func:`_join_in_lane`). Without
    ``prev`` the box reaches one motion ahead, taken off, unless the vehicle moved more than its
    length. Returns ``(x0, y0, x1, y1, n)``, the inclusive box and the number
    of marked pixels in its parts; None when no pixel qualifies. With a list ``others``, the parts
    that lie at least half in the region, did not join (static texture between) and hold at least
    ``other_rel`` times the pixels of the part chosen first are appended to it as ``(x0, y0, x1,
    y1, n)`` in frame pixels: a second vehicle that a smoothing flow joined to the first region.
    """
    g0, g1 = frames
    h, w = g0.shape
    gu, gv = ground
    x0, y0, x1, y1 = region.box()
    pad = margin_px + reach_px + int(math.ceil(max(abs(u + gu), abs(v + gv), abs(gu), abs(gv)))) + 2
    xa, ya, xb, yb = max(0, x0 - pad), max(0, y0 - pad), min(w - 1, x1 + pad), min(h - 1, y1 + pad)
    a, b = _patch(g0, xa, ya, xb, yb), _patch(g1, xa, ya, xb, yb)
    gain = _motion_gain(a, b, None if prev is None else _patch(prev, xa, ya, xb, yb), u, v, ground)
    marked = (gain > gain_grey).astype(np.uint8)
    inner = np.zeros_like(marked)  # within margin_px of the region's box
    inner[max(0, y0 - margin_px) - ya:min(h - 1, y1 + margin_px) - ya + 1,
          max(0, x0 - margin_px) - xa:min(w - 1, x1 + margin_px) - xa + 1] = 1
    moved = cv2.morphologyEx(marked & inner, cv2.MORPH_CLOSE, _disk(2))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(moved, connectivity=8)
    if n < 2:
        return None
    votes = np.bincount(labels[region.ys - ya, region.xs - xa], minlength=n)
    votes[0] = 0
    k = int(np.argmax(votes))
    if votes[k] == 0:
        return None
    left, top = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    right, bottom = left + stats[:, cv2.CC_STAT_WIDTH] - 1, top + stats[:, cv2.CC_STAT_HEIGHT] - 1
    bx0, by0, bx1, by1 = left[k], top[k], right[k], bottom[k]
    count = int(stats[k, cv2.CC_STAT_AREA])
    apart = []  # parts in the region that did not join: static texture between them and the box
    if join > 0:
        static = gain < -gain_grey
        inside = [j for j in np.argsort(-votes, kind="stable")
                  if j != k and votes[j] > 0 and 2 * votes[j] >= stats[j, cv2.CC_STAT_AREA]]
        (bx0, by0, bx1, by1), count, taken, apart = _join_parts(k, inside, labels, stats, moved, static, join)
        if reach_px > 0 and math.hypot(u, v) >= 0.25:
            zone = np.zeros_like(moved)
            zone[max(0, y0 - reach_px) - ya:min(h - 1, y1 + reach_px) - ya + 1,
                 max(0, x0 - reach_px) - xa:min(w - 1, x1 + reach_px) - xa + 1] = 1
            far = cv2.morphologyEx(marked & zone, cv2.MORPH_CLOSE, _disk(2))
            # the full motion explains the change better than half of it: the vehicle's own edge, not a slower one
            # ahead in a queue (whose change half the motion explains as well)
            half_off = np.abs(_shifted(b, 0.5 * u + gu, 0.5 * v + gv) - a)
            full = cv2.blur(half_off - np.abs(_shifted(b, u + gu, v + gv) - a), (3, 3)) > 0
            road = None
            if reach_parts and road_k > 0:
                # the road's grey value from the ring of ground around the box so far (its vehicle's marked pixels
                # left out): a line across the lane that is mostly road-coloured is a gap between two vehicles even
                # where the asphalt is too uniform to be static texture (the synthetic city's cars nose to tail)
                ring = np.zeros(moved.shape, bool)
                ring[max(0, by0 - GAP_SPLIT_RING_PX):by1 + GAP_SPLIT_RING_PX + 1,
                     max(0, bx0 - GAP_SPLIT_RING_PX):bx1 + GAP_SPLIT_RING_PX + 1] = True
                ring[by0:by1 + 1, bx0:bx1 + 1] = False
                model = _road_grey(a[ring & (marked == 0)])
                if model is not None:
                    road = np.abs(a - model[0]) <= road_k * model[1]
            bx0, by0, bx1, by1, extra = _join_in_lane(far, static, (bx0, by0, bx1, by1), u, v, reach_join, full,
                                                      parts=taken if reach_parts else None, road=road)
            count += extra
    if others is not None and apart:  # (apart only with join > 0, which made ``static``)
        for cx0, cy0, cx1, cy1, n_px in _joined_apart(apart, labels, stats, moved, static, join):
            if n_px >= other_rel * stats[k, cv2.CC_STAT_AREA] and not (
                    cx0 <= bx1 and cx1 >= bx0 and cy0 <= by1 and cy1 >= by0):
                # the 3 x 3 average widened the part by a pixel a side (as the box below)
                others.append((int(cx0 + xa + 1), int(cy0 + ya + 1), int(cx1 + xa - 1), int(cy1 + ya - 1), n_px))
    bx0, by0, bx1, by1 = bx0 + xa, by0 + ya, bx1 + xa, by1 + ya
    if prev is None:
        # the marked pixels are the vehicle and the ground it covers next: one motion ahead taken off, unless
        # the two places lie apart (extent under twice the motion: the part chosen is the vehicle alone)
        if bx1 - bx0 + 1 >= 2 * abs(u):
            bx0, bx1 = bx0 - min(u, 0.0), bx1 - max(u, 0.0)
        if by1 - by0 + 1 >= 2 * abs(v):
            by0, by1 = by0 - min(v, 0.0), by1 - max(v, 0.0)
    # the 3 x 3 average widened the box by a pixel a side
    bx0, bx1, by0, by1 = bx0 + 1, bx1 - 1, by0 + 1, by1 - 1
    if bx1 < bx0 or by1 < by0:
        return None
    return int(round(bx0)), int(round(by0)), int(round(bx1)), int(round(by1)), count


def _join_parts(seed: int, parts, labels: np.ndarray, stats: np.ndarray, moved: np.ndarray, static: np.ndarray,
                join: float) -> tuple[tuple[int, int, int, int], int, np.ndarray, list]:
    """Part ``seed`` of ``labels`` (connected components, ``stats`` theirs) joined by each of ``parts`` in turn when at
    most ``join`` of the pixels between them are static texture: inside the convex hull of the parts joined so far and
    the next, not ``moved`` (a box would add the ground beside a vehicle that drives diagonally, and a diagonal car's
    front and rear would never join; a uniform roof between a car's edges is neither moved nor static).
    ``((x0, y0, x1, y1), n, taken, rest)``: the joined parts' box, their marked pixels, their mask, the parts left."""
    left, top = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    right, bottom = left + stats[:, cv2.CC_STAT_WIDTH] - 1, top + stats[:, cv2.CC_STAT_HEIGHT] - 1
    x0, y0, x1, y1 = int(left[seed]), int(top[seed]), int(right[seed]), int(bottom[seed])
    n_px = int(stats[seed, cv2.CC_STAT_AREA])
    taken = labels == seed
    rest = []
    for j in parts:
        c0, r0, c1, r1 = min(x0, left[j]), min(y0, top[j]), max(x1, right[j]), max(y1, bottom[j])
        ys, xs = np.nonzero(taken[r0:r1 + 1, c0:c1 + 1] | (labels[r0:r1 + 1, c0:c1 + 1] == j))
        if _static_between(np.stack([xs, ys], axis=1), moved[r0:r1 + 1, c0:c1 + 1],
                           static[r0:r1 + 1, c0:c1 + 1]) <= join:
            x0, y0, x1, y1 = int(c0), int(r0), int(c1), int(r1)
            n_px += int(stats[j, cv2.CC_STAT_AREA])
            taken |= labels == j
        else:
            rest.append(j)
    return (x0, y0, x1, y1), n_px, taken, rest


def _joined_apart(parts, labels: np.ndarray, stats: np.ndarray, moved: np.ndarray, static: np.ndarray,
                  join: float) -> list[tuple[int, int, int, int, int]]:
    """The parts that did not join a region's box (labels of ``labels``, largest vote first), joined among themselves
    by the same rule (:func:`_join_parts`): a second vehicle whose front and rear the flow marked apart (a uniform
    roof between) is one box, not two halves. ``(x0, y0, x1, y1, n)`` each, in the masks' pixels; ``n`` the marked
    pixels of its parts."""
    out, free = [], list(parts)
    while free:
        box, n_px, _, free = _join_parts(free[0], free[1:], labels, stats, moved, static, join)
        out.append((*box, n_px))
    return out


# _gap_split: a part must hold a line (across the cut) of which at least this fraction is no road; the ring of ground
# around the box whose grey values tell the road's, px
GAP_SPLIT_PEAK = 0.4
GAP_SPLIT_RING_PX = 4
# _gap_split: each part must hold at least this share of the moving pixels its area would hold at the box's density
# (a part that holds none is ground or a kerb the box took in, not a vehicle)
GAP_SPLIT_MOVED_SHARE = 0.4
# _gap_split with by_motion: a part must hold a line across the motion that moves at least this fraction as much as
# the box's most moving line (a second vehicle, not a fringe of the first's edge)
GAP_SPLIT_MOVED_PEAK = 0.5


def _road_grey(ring: np.ndarray) -> tuple[float, float] | None:
    """The road's grey value and spread from the grey values ``ring`` of the ground around a box: the median and
    1.4826 MAD (at least 1 grey level); None under 16 values. A pixel is road when it lies within ``road_k`` spreads
    of the median (:func:`_gap_split`, :func:`_moved_box` with ``reach_parts``)."""
    ring = np.asarray(ring, np.float64).ravel()
    if ring.size < 16:
        return None
    road = float(np.median(ring))
    return road, max(1.0, 1.4826 * float(np.median(np.abs(ring - road))))


def _gap_split(frame: np.ndarray, box, u: float, v: float, *, width_px: int, length_px: int, road_k: float = 3.0,
               valley: float = 0.12, peak: float = GAP_SPLIT_PEAK, ring_px: int = GAP_SPLIT_RING_PX,
               moved: Callable[[], np.ndarray] | None = None, moved_share: float = GAP_SPLIT_MOVED_SHARE,
               by_motion: bool = False) -> list[tuple[int, int, int, int, int]]:
    """The vehicles of a box that a band of road parts: their boxes ``(x0, y0, x1, y1, n)``, or [] for one vehicle.

    Two or three vehicles that move together at one velocity (cars leaving a parking row or a queue side
    by side, a car close behind another) give one flow region and one box from the frames: nothing in
    their motion parts them. Their bodies do: between two cars lies a band of road from one side of the
    box to the other. A pixel of ``frame`` in the box is **road** when its grey value lies within
    ``road_k`` robust standard deviations (1.4826 MAD) of the median of the ring of ``ring_px`` around
    the box (the ground the vehicles stand on; at least 1 grey level). The box's pixels are binned by
    their coordinate across the motion ``(u, v)`` (1 px lines along it) and then, each part on its own,
    along it; a run of lines of which at most ``valley`` are no road, with lines of no road beyond it on
    both sides, is a cut where the parts it leaves each span at least ``width_px`` across (``length_px``
    along) between their first and last line over ``valley`` and each hold a line of which ``peak`` is
    no road (0: no cut that way). A bus or truck has no such band: its roof, however uniform, differs from
    the road on every line, and its windows and ends lie on the lines a road-coloured roof leaves. Each
    part's box spans its lines over ``valley`` both ways. Without a motion the image axes are taken.

    Parameters
    ----------
    frame : ndarray, (H, W)
        Gray frame t.
    box : (int, int, int, int)
        ``(x0, y0, x1, y1)``, inclusive px.
    u, v : float
        The box's motion, px/frame (its direction alone is used).
    moved : callable, optional
        Returns the box's pixels that its motion explains (:func:`_box_motion`; ``(y1 - y0 + 1, x1 - x0 + 1)``
        bool), called only when the box has parts (most boxes have none): with it, each part must hold at
        least ``moved_share`` of the moving pixels its area would hold at the box's density, else no cut
        (the part is ground, a kerb or a wall the box took in).
    by_motion : bool
        With ``moved``: where no band of road parts the box (or the parts it leaves fail ``moved_share``), a band of
        ground that the box's motion does not move is one too, judged the same way on the moving pixels as fractions
        of the box's most moving line (a band at most ``valley`` of it, each part holding a line of
        ``GAP_SPLIT_MOVED_PEAK``). Two cars abreast at one velocity with a zebra crossing, a marking or a shadow
        between them leave no band of road grey, yet nothing between them moves; across one vehicle its moving ends
        and windows span its whole width. Each part must reach further along the motion than across it (a vehicle
        drives along its length; the crowns of a flickering tree the flow joined are as wide as long).

    Returns
    -------
    list of (int, int, int, int, int)
        Inclusive boxes and the number of pixels in them that are no road; [] where no cut qualifies.
    """
    h, w = frame.shape
    x0, y0, x1, y1 = (int(round(c)) for c in box)
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w - 1, x1), min(h - 1, y1)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return []
    xa, ya, xb, yb = max(0, x0 - ring_px), max(0, y0 - ring_px), min(w - 1, x1 + ring_px), min(h - 1, y1 + ring_px)
    patch = _patch(frame, xa, ya, xb, yb)
    inside = np.zeros(patch.shape, bool)
    inside[y0 - ya:y1 - ya + 1, x0 - xa:x1 - xa + 1] = True
    model = _road_grey(patch[~inside])
    by_motion = by_motion and moved is not None
    if model is None and not by_motion:
        return []
    ys, xs = np.nonzero(inside)
    speed = math.hypot(u, v)
    du, dv = (u / speed, v / speed) if speed > 0 else (1.0, 0.0)
    xc, yc = xs - xs.mean(), ys - ys.mean()
    along, across = xc * du + yc * dv, -xc * dv + yc * du

    def cut(vehicle: np.ndarray, low: float, top: float) -> list[np.ndarray]:
        parts = [np.ones(len(xs), bool)]
        for coord, min_px in ((across, width_px), (along, length_px)):
            if min_px > 0:
                parts = [q for sel in parts for q in _cut_at_gaps(coord, vehicle, sel, min_px, low, top)]
        return parts

    m = None

    def moving() -> np.ndarray:  # the box's pixels that its motion explains, asked for once and only where needed
        nonlocal m
        if m is None:
            m = np.asarray(moved(), bool)[ys - (y0 - ya), xs - (x0 - xa)]
        return m

    def each_moves(parts: list[np.ndarray]) -> bool:  # no part is ground, a kerb or a wall the box took in
        if moved is None:
            return True
        density = moving().mean()
        return all(moving()[sel].sum() >= moved_share * density * sel.sum() for sel in parts)

    parts, low, lengthwise = [], valley, False
    if model is not None:
        vehicle = np.abs(patch[ys, xs] - model[0]) > road_k * model[1]
        parts = cut(vehicle, low, peak)
    held = len(parts) >= 2 and each_moves(parts)
    if not held and by_motion:
        # how much of a line moves depends on the vehicles' texture (a uniform roof moves at its ends alone): the
        # fractions are taken relative to the box's most moving line across
        most = float(_line_fractions(across, moving(), np.ones(len(xs), bool))[0].max())
        vehicle, low, lengthwise = moving(), valley * most, True
        parts = cut(vehicle, low, GAP_SPLIT_MOVED_PEAK * most) if most > 0 else []
        held = len(parts) >= 2 and each_moves(parts)
    if not held:
        return []
    out = []
    for sel in parts:
        for coord in (across, along):
            sel = sel & _over_valley(coord, vehicle, sel, low)
        if not sel.any() or (lengthwise and np.ptp(along[sel]) < np.ptp(across[sel])):
            return []  # a part cut by motion must drive along its length: no round crown of a tree's flicker
        out.append((int(xs[sel].min() + xa), int(ys[sel].min() + ya), int(xs[sel].max() + xa), int(ys[sel].max() + ya),
                    int(vehicle[sel].sum())))
    return out


def _box_motion(frames, box, u: float, v: float, ground=(0.0, 0.0), prev=None, *,
                gain_grey: float = 2.0) -> np.ndarray:
    """The pixels of the inclusive ``box`` that the motion ``(u, v)`` explains better than the ground's by
    ``gain_grey`` grey levels, averaged over 3 x 3 px (the test of :func:`_moved_box`, with ``prev`` over three
    frames): ``(y1 - y0 + 1, x1 - x0 + 1)`` bool."""
    g0, g1 = frames
    h, w = g0.shape
    gu, gv = ground
    x0, y0, x1, y1 = box
    pad = int(math.ceil(max(abs(u + gu), abs(v + gv), abs(gu), abs(gv)))) + 2
    xa, ya, xb, yb = max(0, x0 - pad), max(0, y0 - pad), min(w - 1, x1 + pad), min(h - 1, y1 + pad)
    a, b = _patch(g0, xa, ya, xb, yb), _patch(g1, xa, ya, xb, yb)
    gain = _motion_gain(a, b, None if prev is None else _patch(prev, xa, ya, xb, yb), u, v, ground)
    return gain[y0 - ya:y1 - ya + 1, x0 - xa:x1 - xa + 1] > gain_grey


def _line_fractions(coord: np.ndarray, vehicle: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per 1 px line of ``coord`` over the pixels ``sel``: the fraction that is ``vehicle``, and each pixel's line."""
    lo = math.floor(float(coord[sel].min()))
    line = np.floor(coord - lo).astype(np.int64)
    n = int(line[sel].max()) + 1
    total = np.bincount(line[sel], minlength=n)
    hit = np.bincount(line[sel], weights=vehicle[sel].astype(np.float64), minlength=n)
    return hit / np.maximum(total, 1), line


def _over_valley(coord: np.ndarray, vehicle: np.ndarray, sel: np.ndarray, valley: float) -> np.ndarray:
    """The pixels of ``sel`` between the first and last line of ``coord`` of which over ``valley`` is vehicle."""
    frac, line = _line_fractions(coord, vehicle, sel)
    over = np.flatnonzero(frac > valley)
    if len(over) == 0:
        return np.zeros_like(sel)
    return sel & (line >= over[0]) & (line <= over[-1])


def _cut_at_gaps(coord: np.ndarray, vehicle: np.ndarray, sel: np.ndarray, min_px: int, valley: float,
                 peak: float) -> list[np.ndarray]:
    """``sel`` cut at the runs of lines of ``coord`` that are road (:func:`_gap_split`), first to last."""
    frac, line = _line_fractions(coord, vehicle, sel)
    n = len(frac)
    gap = frac <= valley

    def fits(seg: np.ndarray) -> bool:
        over = np.flatnonzero(seg > valley)
        return len(over) > 0 and over[-1] - over[0] + 1 >= min_px and float(seg.max()) >= peak

    cuts, start, i = [], 0, 0
    while i < n:
        if not gap[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and gap[j + 1]:
            j += 1
        if i > start and j < n - 1 and fits(frac[start:i]) and fits(frac[j + 1:]):
            cuts.append((i + j) // 2)
            start = j + 1
        i = j + 1
    if not cuts:
        return [sel]
    edges = [-1] + cuts + [n]
    return [sel & (line > a) & (line <= b) for a, b in zip(edges[:-1], edges[1:])]


def _static_between(points_px: np.ndarray, moved: np.ndarray, static: np.ndarray, skip=None) -> float:
    """The fraction of ``static`` pixels among those inside the convex hull of ``points_px`` ((N, 2) x, y, in the
    masks' pixels) that ``moved`` does not mark, ``skip`` (an inclusive box x0, y0, x1, y1) left out; 0 when there
    are none. What lies between parts of a mover: a uniform roof is neither marked nor static, textured ground
    between two vehicles is static (:func:`_moved_box`, :func:`_join_in_lane`)."""
    hull = np.zeros(moved.shape, np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(np.asarray(points_px, dtype=np.int32)), 1)
    between = (hull == 1) & (moved == 0)
    if skip is not None:
        x0, y0, x1, y1 = skip
        between[y0:y1 + 1, x0:x1 + 1] = False
    return float(static[between].mean()) if between.any() else 0.0


# _static_band: the hull is eroded by this many px (its border runs over the ground beside a vehicle whose parts reach
# its sides: a cab wider than its trailer, the 3 x 3 average's widening), and its pixels are binned in lines this many
# px thick across the motion; a line with fewer hull pixels is not judged. _join_in_lane (box_reach_parts): a line
# more than BAND_STATIC static is ground between two vehicles (the city-wide world's road: 0.85-0.92 of the pixels of
# the patches around truck 202 are static, the truck's included; the most static line of the hull of each part judged
# there, 14 pairs: 0.15-0.41 for most, at most 0.52, the gap between cab and trailer included)
BAND_ERODE_PX = 2
BAND_LINE_PX = 2
BAND_MIN_PX = 4
BAND_STATIC = 0.5


def _static_band(points_px: np.ndarray, moved: np.ndarray, static: np.ndarray, du: float, dv: float, *,
                 erode_px: int = BAND_ERODE_PX, line_px: int = BAND_LINE_PX, min_px: int = BAND_MIN_PX,
                 road: np.ndarray | None = None) -> float:
    """The largest share of a line across the motion ``(du, dv)`` (a unit vector) inside the convex hull of
    ``points_px`` ((N, 2) x, y, in the masks' pixels) that is ``static`` and not ``moved``; 0 when no line holds
    ``min_px`` hull pixels. Ground between two vehicles that follow each other is a band of static texture
    from one side of the lane to the other; a long uniform roof (a trailer, a bus) is neither moved nor static on
    every line, whatever static pixels lie along its sides or in the gap between a cab and its trailer
    (:func:`_join_in_lane`). With ``road`` (bool, the pixels of the road's grey value, :func:`_road_grey`) a pixel
    that is road counts as ground too, ``moved`` or not: untextured asphalt between two cars close together is not
    static texture (warping it by the motion changes nothing, and next to a moving edge the motion explains it), but
    it is the road's colour, where a uniform trailer or bus roof (white, grey, not the asphalt's grey) is not."""
    hull = np.zeros(moved.shape, np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(np.asarray(points_px, dtype=np.int32)), 1)
    if erode_px > 0:
        hull = cv2.erode(hull, _disk(erode_px))
    ys, xs = np.nonzero(hull)
    if not len(xs):
        return 0.0
    along = xs * du + ys * dv
    line = np.floor((along - along.min()) / line_px).astype(np.int64)
    total = np.bincount(line)
    ground = static[ys, xs] & (moved[ys, xs] == 0)
    if road is not None:
        # road-coloured asphalt counts whether or not the motion marks it: untextured asphalt next to a moving edge
        # is explained by the motion (the edge moves onto it), so a gap of a few px between two cars is all marked
        ground = ground | road[ys, xs]
    hit = np.bincount(line, weights=ground.astype(np.float64), minlength=len(total))
    judged = total >= min_px
    return float((hit[judged] / total[judged]).max()) if judged.any() else 0.0


def _join_in_lane(moved: np.ndarray, static: np.ndarray, box, u: float, v: float, join: float,
                  full: np.ndarray | None = None, min_part_px: int = 9,
                  parts: np.ndarray | None = None, road: np.ndarray | None = None) -> tuple[int, int, int, int, int]:
    """``box`` grown by the parts of ``moved`` that lie in its lane, nearest first (:func:`_moved_box`).

    A part joins when, across the motion (u, v), its extent and the box's overlap by at least half
    the narrower of the two, and at most ``join`` of the pixels inside the convex hull of the box
    and the part that ``moved`` does not mark are ``static`` (texture that warping by the motion
    makes worse: ground between two vehicles that follow each other; a uniform roof is neither).
    Parts smaller than ``min_part_px`` (a 3 x 3 speck) and those the box already touches are left
    alone, and so are those of which ``full`` (where the motion explains the change better than half of
    it does) marks under half: the edge of a slower vehicle ahead in a queue. With ``parts`` (bool, the
    pixels of the parts the box was made of; ``box_reach_parts``) the hull is that of those pixels, and of
    each part joined so far, with the part's, not of the box's corners: the axis-aligned box of a vehicle
    that drives diagonally holds the ground beside it, which the hull of its corners and a part far along
    the lane sweeps over (a truck's cab and the rear edge of its uniform trailer at 34 degrees: 0.38 of the
    pixels between static, all of them ground beside the trailer); the part joins unless a line of that hull
    across the motion is more than ``BAND_STATIC`` static (:func:`_static_band`: the band of ground between
    two vehicles, where a uniform roof's hull holds static pixels along its sides alone, which ``join``'s
    fraction of the whole hull counts); and a part touching the grown box, not the first one, is judged as
    the others are (the next edge of the part just joined); with ``road`` (bool, the road's grey value) a line's
    road-coloured pixels count as ground as well (untextured asphalt between two cars nose to tail). Returns the
    grown box
    ``(x0, y0, x1, y1)`` (patch pixels, inclusive) and the number of pixels joined.
    """
    bx0, by0, bx1, by1 = box
    first = box
    hull_pts = None
    if parts is not None:
        ys0, xs0 = np.nonzero(parts)
        if len(xs0):
            hull_pts = cv2.convexHull(np.stack([xs0, ys0], axis=1).astype(np.int32)).reshape(-1, 2)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(moved, connectivity=8)
    speed = math.hypot(u, v)
    du, dv = u / speed, v / speed  # along the motion; (-dv, du) across it

    def across(xs, ys):
        t = -dv * np.asarray(xs, np.float64) + du * np.asarray(ys, np.float64)
        return float(t.min()), float(t.max())

    order = np.argsort(np.hypot(centroids[:, 0] - (bx0 + bx1) / 2, centroids[:, 1] - (by0 + by1) / 2))
    extra = 0
    for j in order:
        left, top = int(stats[j, cv2.CC_STAT_LEFT]), int(stats[j, cv2.CC_STAT_TOP])
        right, bottom = left + int(stats[j, cv2.CC_STAT_WIDTH]) - 1, top + int(stats[j, cv2.CC_STAT_HEIGHT]) - 1
        if j == 0 or stats[j, cv2.CC_STAT_AREA] < min_part_px:
            continue
        tx0, ty0, tx1, ty1 = first if hull_pts is not None else (bx0, by0, bx1, by1)
        if left <= tx1 + 1 and right >= tx0 - 1 and top <= ty1 + 1 and bottom >= ty0 - 1:
            continue  # touching the box: the box's own part or a neighbour the first pass judged
        ys, xs = np.nonzero(labels[top:bottom + 1, left:right + 1] == j)
        xs, ys = xs + left, ys + top
        if full is not None and 2 * int(full[ys, xs].sum()) < len(xs):
            continue
        a0, a1 = across([bx0, bx1, bx0, bx1], [by0, by0, by1, by1])
        p0, p1 = across(xs, ys)
        if min(a1, p1) - max(a0, p0) < 0.5 * min(a1 - a0, p1 - p0):
            continue
        base = hull_pts if hull_pts is not None else np.array([[bx0, by0], [bx1, by0], [bx0, by1], [bx1, by1]])
        pts = np.concatenate([base, np.stack([xs, ys], axis=1)])
        if hull_pts is not None:
            if _static_band(pts, moved, static, du, dv, road=road) > BAND_STATIC:
                continue
        elif _static_between(pts, moved, static, skip=(bx0, by0, bx1, by1)) > join:
            continue
        bx0, by0, bx1, by1 = min(bx0, left), min(by0, top), max(bx1, right), max(by1, bottom)
        extra += int(stats[j, cv2.CC_STAT_AREA])
        if hull_pts is not None:
            hull_pts = cv2.convexHull(pts.astype(np.int32)).reshape(-1, 2)
    return bx0, by0, bx1, by1, extra


def _explained(region: _Region, frames, u: float, v: float, ground=(0.0, 0.0)) -> float:
    """The fraction of the region's grey-value change that its motion (u, v) over the ground removes.

    The change is ``|I1'(x + g) - I0(x)|`` (``g``: ``ground``, the motion the compensation left the
    ground with there), the rest ``|I1'(x + g + w) - I0(x)|``.
    """
    g0, g1 = frames
    h, w = g0.shape
    gu, gv = ground
    x0, y0, x1, y1 = region.box()
    pad = int(math.ceil(max(abs(u + gu), abs(v + gv), abs(gu), abs(gv)))) + 2
    xa, ya, xb, yb = max(0, x0 - pad), max(0, y0 - pad), min(w - 1, x1 + pad), min(h - 1, y1 + pad)
    a, b = _patch(g0, xa, ya, xb, yb), _patch(g1, xa, ya, xb, yb)
    b0 = _shifted(b, gu, gv) if gu or gv else b
    bw = _shifted(b, u + gu, v + gv)
    step = max(1, len(region.ys) // 1500)  # a large region is judged on a sample of its pixels
    ys, xs = region.ys[::step] - ya, region.xs[::step] - xa
    # a change of brightness over the region (light, a cloud's shadow) is no motion: each difference is
    # taken about its median over the region
    d0, d1 = b0[ys, xs] - a[ys, xs], bw[ys, xs] - a[ys, xs]
    before, after = np.abs(d0 - np.median(d0)), np.abs(d1 - np.median(d1))
    # over the quarter of the pixels that changed most: the flow method's halo (ground around a vehicle that the flow
    # window carries along) did not change, and warping it by the vehicle's motion would count against it
    changed = (before >= np.percentile(before, 75)) & (before > 0)
    total = float(before[changed].sum())
    return 1.0 - float(after[changed].sum()) / total if total > 0 else 0.0


def explained_in_box(frames, box, motions_px, *, ground_px=(0.0, 0.0)) -> np.ndarray:
    """The fraction of the grey-value change in ``box`` that each motion removes (:func:`_explained` on the box).

    Parameters
    ----------
    frames : (ndarray, ndarray)
        Gray frame t and the other frame in frame t's pixels, (H, W).
    box : (float, float, float, float)
        ``(x0, y0, x1, y1)``, inclusive px; clipped to the frame.
    motions_px : sequence of (float, float)
        Motions over the ground, px (frame t's pixel x matches the other frame at ``x + ground_px + motion``).
    ground_px : (float, float)
        The motion the compensation left the ground with there, px.

    Returns
    -------
    ndarray, (len(motions_px),) float64
        ``1 - rest / change`` over the quarter of the box's pixels that changed most (at most 1; negative
        where the motion makes the match worse; 0 for a box with no change).
    """
    h, w = np.shape(frames[0])
    x0, y0, x1, y1 = (int(round(c)) for c in box)
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w - 1, x1), min(h - 1, y1)
    if x1 < x0 or y1 < y0:
        raise ValueError(f"box: expected (x0, y0, x1, y1) overlapping the {w} x {h} frame, got {tuple(box)}")
    ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1]
    region = _Region(ys.ravel(), xs.ravel(), np.zeros((ys.size, 2), np.float32))
    return np.array([_explained(region, frames, float(u), float(v), ground_px) for u, v in motions_px])


def ground_fit_at(flow: np.ndarray, valid: np.ndarray, points_px, *, model: str = "affine") -> np.ndarray:
    """The robust ground fit of :func:`ground_residual` evaluated at ``points_px``, ``(N, 2)`` float64 px.

    ``points_px``: ``(N, 2)`` pixel positions ``(x, y)``; zeros where the fit has too few grid pixels.
    """
    h, w = np.shape(flow)[:2]
    coef = _ground_fit(flow, np.asarray(valid, bool), model=model)
    return np.array([_fit_at(coef, float(x), float(y), h, w) for x, y in np.reshape(points_px, (-1, 2))],
                    dtype=np.float64).reshape(-1, 2)


def ground_fit_map(flow: np.ndarray, valid: np.ndarray) -> np.ndarray | None:
    """The robust affine ground fit of :func:`ground_residual` as a map, ``(3, 3)``: ``x -> x + F(x)``.

    ``F`` is the fitted flow (``u = a0 + a1 xn + a2 yn`` in the fit's coordinates ``xn = (x - W/2) / W``,
    ``yn = (y - H/2) / H``) written in pixels; None where the fit has too few grid pixels.
    """
    h, w = np.shape(flow)[:2]
    coef = _ground_fit(flow, np.asarray(valid, bool), model="affine")
    if coef is None:
        return None
    (a0, b0), (a1, b1), (a2, b2) = coef
    return np.array([[1.0 + a1 / w, a2 / h, a0 - a1 / 2 - a2 / 2],
                     [b1 / w, 1.0 + b2 / h, b0 - b1 / 2 - b2 / 2],
                     [0.0, 0.0, 1.0]])


def _difference_variance(a: np.ndarray, b: np.ndarray, *, step_px: int = 2, border_px: int = 8) -> float:
    """The robust variance of ``b - a`` over the frame, grey levels^2: what noise alone changes between two frames.

    Most of a frame is static ground, so the median absolute deviation of the difference on a grid
    (every ``step_px``-th pixel, ``border_px`` left out where the compensation brings in content) is
    that of the ground: sensor noise, compression, the registration's residual. For independent noise of
    standard deviation sigma in each frame it is ``2 sigma^2`` (``(1.4826 MAD)^2``).
    """
    d = (np.asarray(b, np.float32) - np.asarray(a, np.float32))[border_px:-border_px or None:step_px,
                                                                   border_px:-border_px or None:step_px]
    if d.size == 0:
        return 0.0
    mad = float(np.median(np.abs(d - np.median(d))))
    return (1.4826 * mad) ** 2


def _changed_at_rest(a: np.ndarray, b: np.ndarray, box, ground, diff_var: float) -> tuple[float, float] | None:
    """How much the patch ``box`` of frame ``a`` changed at its place in frame ``b``, and what noise alone would change.

    ``(1 - NCC(a[box], b[box + ground]), diff_var / (2 var(a[box])))``: ``b`` sampled at the motion the
    ground keeps there (``ground``, px). For a static patch of signal variance ``s^2`` under independent noise
    ``sigma`` in each frame, ``NCC = s^2 / (s^2 + sigma^2)``, so ``1 - NCC = sigma^2 / var(a[box])`` =
    ``diff_var / (2 var(a[box]))`` (``diff_var``: :func:`_difference_variance` of the pair). A patch whose
    content moved (a vehicle leaving its place) decorrelates towards ``1 - NCC = 1``. None where either
    patch is flat (no NCC: nothing to tell, e.g. a box on a uniform outline).
    """
    h, w = a.shape
    x0, y0, x1, y1 = (int(round(c)) for c in box)
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w - 1, x1), min(h - 1, y1)
    gu, gv = ground
    pad = int(math.ceil(max(abs(gu), abs(gv)))) + 2
    xa, ya, xb, yb = max(0, x0 - pad), max(0, y0 - pad), min(w - 1, x1 + pad), min(h - 1, y1 + pad)
    pb = _patch(b, xa, ya, xb, yb)
    q = (_shifted(pb, gu, gv) if gu or gv else pb)[y0 - ya:y1 - ya + 1, x0 - xa:x1 - xa + 1].astype(np.float64)
    pa = np.asarray(a[y0:y1 + 1, x0:x1 + 1], np.float64)
    pa, q = pa - pa.mean(), q - q.mean()
    var_a, var_q = float((pa * pa).mean()), float((q * q).mean())
    if not var_a > 0 or not var_q > 0:
        return None
    return 1.0 - float((pa * q).mean()) / math.sqrt(var_a * var_q), diff_var / (2.0 * var_a)


def _changed(d: Detection, ground, frame: np.ndarray, others, p: dict) -> bool:
    """Whether the content of ``d``'s box in ``frame`` (t) changed at its place beyond noise.

    ``others``: ``(frame, sign, difference variance)`` of frame t+1 (sign 1) and, where known, of frame
    t-1 (sign -1, the motion the ground keeps there taken as the same in both pairs). Each change must
    reach ``min(change_noise_k * noise change, change_enough)`` (:func:`_changed_at_rest`); a flat box
    is not judged.
    """
    for other, sign, dv in others:
        cn = _changed_at_rest(frame, other, (d.x0_px, d.y0_px, d.x1_px, d.y1_px), (sign * ground[0], sign * ground[1]),
                              dv)
        if cn is not None and cn[0] < min(p["change_noise_k"] * cn[1], p["change_enough"]):
            return False
    return True


def ground_residual(flow: np.ndarray, valid: np.ndarray, *, model: str = "affine", step_px: int = 8,
                    iterations: int = 3) -> np.ndarray:
    """The local flow minus a robust affine fit of it: what the global model left of the ground's motion removed.

    A shift model leaves the ground with a residual that varies over the image (the camera's
    roll, pitch and yaw jitter, a change of height, a tilted view); it is smooth and covers most
    of the image, a vehicle's motion is neither. ``u = a0 + a1 x + a2 y``, ``v = b0 + b1 x + b2 y``
    (``model="affine"``; ``"quadratic"`` adds ``x^2, x y, y^2`` terms: lens distortion and a
    rolling shutter bend the residual) is fitted by least squares on a grid of valid pixels (``step_px``), ``iterations`` times,
    each time on the pixels within 2.5 median absolute deviations (at least 0.3 px) of the last fit.

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
        Local flow, px.
    valid : ndarray, (H, W) bool

    Returns
    -------
    ndarray, (H, W, 2) float32
        ``flow`` minus the fitted field (``flow`` itself when fewer than 12 grid pixels are valid).
    """
    return _subtract_fit(flow, _ground_fit(flow, valid, model=model, step_px=step_px, iterations=iterations))


def _subtract_fit(flow: np.ndarray, coef: np.ndarray | None) -> np.ndarray:
    """``flow`` (float32) minus the ground fit of coefficients ``coef`` (affine: 3 rows, quadratic: 6)."""
    f = np.asarray(flow, dtype=np.float32)
    if coef is None:
        return f
    h, w = flow.shape[:2]
    X = ((np.arange(w) - w / 2) / w)[:, None]
    Y = ((np.arange(h) - h / 2) / h)[:, None]
    gx = (coef[0] + coef[1] * X).astype(np.float32)                              # (W, 2)
    gy = (coef[2] * Y).astype(np.float32)                                        # (H, 2)
    out = f - gx[None, :, :] - gy[:, None, :]
    if len(coef) == 6:
        out -= (coef[3] * X * X).astype(np.float32)[None, :, :] + (coef[5] * Y * Y).astype(np.float32)[:, None, :]
        out -= (X[None, :, :] * Y[:, None, :] * coef[4]).astype(np.float32)
    return out


def _ground_fit(flow: np.ndarray, valid: np.ndarray, *, model: str, step_px: int = 8,
                iterations: int = 3) -> np.ndarray | None:
    """The coefficients ``(3 or 6, 2)`` of :func:`ground_residual`'s fit, or None (fewer than 12 grid pixels)."""
    h, w = flow.shape[:2]
    ys, xs = np.mgrid[step_px // 2:h:step_px, step_px // 2:w:step_px]
    ok = valid[ys, xs]
    ys, xs = ys[ok].astype(np.float64), xs[ok].astype(np.float64)
    if model not in ("affine", "quadratic"):
        raise ValueError(f"model: expected affine or quadratic, got {model!r}")
    if len(xs) < 12:
        return None
    z = np.asarray(flow)[ys.astype(int), xs.astype(int)].astype(np.float64)
    # coordinates scaled to about [-1, 1]: the quadratic terms' least squares stay well conditioned
    xn, yn = (xs - w / 2) / w, (ys - h / 2) / h
    A = np.column_stack([np.ones_like(xs), xn, yn] + ([xn * xn, xn * yn, yn * yn] if model == "quadratic" else []))
    keep = np.ones(len(xs), bool)
    coef = np.zeros((A.shape[1], 2))
    for _ in range(iterations):
        if keep.sum() < 12:
            break
        coef = np.linalg.lstsq(A[keep], z[keep], rcond=None)[0]
        r = np.hypot(*(z - A @ coef).T)
        keep = r <= max(0.3, 2.5 * float(np.median(r[keep])))
    return coef


def _fit_at(coef: np.ndarray | None, x: float, y: float, h: int, w: int) -> tuple[float, float]:
    """The ground fit's flow at pixel (x, y), px ((0, 0) without a fit)."""
    if coef is None:
        return 0.0, 0.0
    xn, yn = (x - w / 2) / w, (y - h / 2) / h
    terms = [1.0, xn, yn, xn * xn, xn * yn, yn * yn][:len(coef)]
    g = np.asarray(terms) @ coef
    return float(g[0]), float(g[1])


def _too_large(area_px: float, p: dict, gsd_m_per_px: float | None) -> bool:
    """Whether ``area_px`` pixels exceed ``max_area_px`` or, with the ground sampling distance, ``max_area_m2``."""
    if p["max_area_px"] is not None and area_px > p["max_area_px"]:
        return True
    return gsd_m_per_px is not None and p["max_area_m2"] is not None and area_px * gsd_m_per_px**2 > p["max_area_m2"]


def _too_small_box(box, p: dict, gsd_m_per_px: float | None, h: int, w: int) -> bool:
    """Whether the inclusive box ``(x0, y0, x1, y1)`` covers less than ``min_box_m2`` (with the ground sampling
    distance and the key set; the box from the frames, not the flow region a smoothing method's halo enlarges). A box
    within ``border_px`` of the image's edge is a vehicle's part the frame cuts, and is not judged."""
    if gsd_m_per_px is None or p["min_box_m2"] is None:
        return False
    x0, y0, x1, y1 = box
    b = p["border_px"]
    if x0 <= b or y0 <= b or x1 >= w - 1 - b or y1 >= h - 1 - b:
        return False
    return (x1 - x0 + 1) * (y1 - y0 + 1) * gsd_m_per_px**2 < p["min_box_m2"]


def _box_iou(a: Detection, b: Detection) -> float:
    """IoU of two detections' inclusive pixel boxes."""
    return iou_xyxy((a.x0_px, a.y0_px, a.x1_px, a.y1_px), (b.x0_px, b.y0_px, b.x1_px, b.y1_px))


def drop_parts_inside(detections: list[Detection], share: float, *, merge_px: float = DETECTION_DEFAULTS["merge_px"],
                      merge_rel: float = DETECTION_DEFAULTS["merge_rel"]) -> list[Detection]:
    """``detections`` without those whose box lies ``share`` or more inside a larger detection's box and whose motion
    agrees with that one's as the regions of one mover agree (within ``merge_px + merge_rel`` times the faster
    speed, :func:`_one_motion`): a part of that mover (``nms_inside``). A box inside a larger one of another motion
    (a car in a region a wrong flow joined to it) stays.

    Of two boxes of one area (two parts of a roof grown over it by the lane fill end as the same box), the later
    goes. A box inside a larger one that was itself dropped still goes. Order is kept.
    """
    if not detections:
        return []
    b = np.array([(d.x0_px, d.y0_px, d.x1_px, d.y1_px) for d in detections], dtype=np.float64)
    vel = np.array([(d.u_px, d.v_px) for d in detections], dtype=np.float64)
    area = (b[:, 2] - b[:, 0] + 1) * (b[:, 3] - b[:, 1] + 1)
    order = np.arange(len(b))
    keep = []
    for i, d in enumerate(detections):
        iw = np.minimum(b[:, 2], b[i, 2]) - np.maximum(b[:, 0], b[i, 0]) + 1
        ih = np.minimum(b[:, 3], b[i, 3]) - np.maximum(b[:, 1], b[i, 1]) + 1
        larger = (area > area[i]) | ((area == area[i]) & (order < i))
        inside = (iw > 0) & (ih > 0) & (iw * ih >= share * area[i])
        keep.append(not (larger & inside & _one_motion(vel, vel[i], merge_px, merge_rel)).any())
    return [d for d, k in zip(detections, keep) if k]


def _along(d: Detection, gv, bound: float, p: dict) -> bool:
    """Whether the motion of ``d`` lies along ``gv`` in its sense, up to ``bound`` px, within the tolerance."""
    gn = math.hypot(*gv)
    if not gn > 0:
        return False
    along = (d.u_px * gv[0] + d.v_px * gv[1]) / gn
    perp = abs(-d.u_px * gv[1] + d.v_px * gv[0]) / gn
    return 0 <= along <= bound and perp <= p["parallax_perp_px"] + p["parallax_perp_rel"] * math.hypot(d.u_px, d.v_px)


def box_extents(w: float, h: float, u: float, v: float) -> tuple[float, float] | None:
    """How far an axis-aligned ``w`` x ``h`` px box reaches along the motion ``(u, v)`` and across it: ``w |e_x| +
    h |e_y|`` and ``w |e_y| + h |e_x|`` for the unit motion ``e``; None without motion. A bus driving along its length
    up the image, 15 x 59 px: 59 along, 15 across."""
    s = math.hypot(u, v)
    if not s > 0:
        return None
    ex, ey = abs(u) / s, abs(v) / s
    return w * ex + h * ey, w * ey + h * ex


def moves_lengthwise(d: Detection, rel: float) -> bool:
    """Whether ``d``'s box (its inclusive width and height) reaches at least ``rel`` times as far along its motion
    ``(u_px, v_px)`` as across it (:func:`box_extents`): a bus driving along its length up the image, 15 x 59 px,
    3.9 times; a square box, 1. False for ``rel`` 0 (off) or no motion.
    """
    ext = box_extents(d.x1_px - d.x0_px + 1, d.y1_px - d.y0_px + 1, d.u_px, d.v_px) if rel > 0 else None
    return ext is not None and ext[0] >= rel * ext[1]


def _parallax(d: Detection, g, p: dict, h: int, w: int) -> bool:
    """The residual of ``d`` is the parallax of a static point under the global motion ``g`` (and ``d`` does not
    move along its length, ``parallax_lengthwise_rel``)."""
    if g is None or not p["parallax_max_ratio"] > 0 or moves_lengthwise(d, p["parallax_lengthwise_rel"]):
        return False
    gv = g if g.ndim == 1 else g[min(h - 1, round(d.y_px)), min(w - 1, round(d.x_px))]
    return _along(d, gv, p["parallax_max_ratio"] * math.hypot(*gv), p)


def _common_parallax(dets: list[Detection], p: dict, image_area: int):
    """The direction shared by most of the moving area, when that area is a parallax field's and not traffic's.

    Where the frames were registered before they came (an orthophoto sequence, a stabilised
    video) the global motion left is not the camera's translation, and the parallax of roofs and
    tree crowns points along the translation that was removed. The static structures of a pair all
    share that direction and sense (the epipole's, far off for a nadir view); traffic does not. A
    direction within ``parallax_angle_deg`` of which lie at least three regions covering at least
    ``parallax_min_fraction`` of the image and half of all moving area is taken as parallax (vehicles
    cover a few per cent of a frame: 26 cars of 300 px are 1.5 % of 960 x 540), and the
    regions along it no faster than ``parallax_speed_rel`` times their area-weighted median speed
    are rejected. Returns ``(direction, speed bound)`` or None.
    """
    if p["parallax_min_fraction"] <= 0 or len(dets) < 3:
        return None
    v = np.array([[d.u_px, d.v_px] for d in dets])
    a = np.array([d.area_px for d in dets], dtype=np.float64)
    speed = np.hypot(v[:, 0], v[:, 1])
    ok = speed > 0
    if ok.sum() < 3:
        return None
    unit = v[ok] / speed[ok, None]
    cos = unit @ unit.T
    close = cos >= math.cos(math.radians(p["parallax_angle_deg"]))
    support = close @ a[ok]
    i = int(np.argmax(support))
    if support[i] < max(p["parallax_min_fraction"] * image_area, 0.5 * a.sum()) or close[i].sum() < 3:
        return None
    members = close[i]
    e = (unit[members] * a[ok][members, None]).sum(axis=0)
    order = np.argsort(speed[ok][members])
    cum = np.cumsum(a[ok][members][order])
    median_speed = float(speed[ok][members][order][np.searchsorted(cum, cum[-1] / 2)])
    return e / np.hypot(*e), p["parallax_speed_rel"] * median_speed


def shadow_bands(gray: np.ndarray, box, *, max_rel: float = 0.35, ratio_lo: float = 0.2, ratio_hi: float = 0.8,
                 min_frac: float = 0.3, ground_px: int = 3, lead_px: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """How much of each side of ``box`` is as dark as a cast shadow on the ground around it.

    A cast shadow keeps the ground's texture and darkens it by a ratio (the ground's irradiance in and out
    of the sun: the brightness test of shadow detection in background subtraction, Horprasert et al. 1999,
    Cucchiara et al. 2003). The ground is the median grey of the ring of ``ground_px`` px around the box, 2 px
    out (its nearest pixel may be the vehicle's or the shadow's blur); a pixel is dark when its grey lies
    within ``[ratio_lo, ratio_hi]`` times it. A side's band is the run of strips (columns for left and
    right, rows for top and bottom) from the side, or from up to ``lead_px`` in (the blurred edge; the ground
    a box from the frames holds beyond the shadow, where the shadow lay at t-1 or lies at t+1), in which at
    least ``min_frac`` of the pixels are dark (a shadow beside a vehicle that lies diagonally in its box
    covers part of each strip), at most ``max_rel`` of the box's width (height). A dark vehicle body is
    dark too: :func:`trim_cast_shadows` tells shadows from it by the frame's vote on the outer fractions.

    Parameters
    ----------
    gray : ndarray, (H, W) float or uint8
        Frame t, grey levels (any scale with black at 0: the test is a ratio).
    box : (x0, y0, x1, y1)
        Inclusive pixel box.
    max_rel, ratio_lo, ratio_hi, min_frac, ground_px, lead_px
        As above.

    Returns
    -------
    widths : ndarray, (4,) int64
        Band widths, px, of the left, top, right and bottom sides, the lead included (0: none).
    outer : ndarray, (4,) float64
        The fraction of dark pixels in the ``max_rel`` of the box next to each side (NaN without a ring of
        ground: the box at the image's edge, or the ring black).
    """
    g = np.asarray(gray)
    h, w = g.shape
    x0, y0, x1, y1 = (int(round(float(c))) for c in box)
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w - 1, x1), min(h - 1, y1)
    widths, outer = np.zeros(4, np.int64), np.full(4, np.nan)
    if x1 < x0 or y1 < y0 or x0 < ground_px + 1 or y0 < ground_px + 1 or x1 + ground_px + 2 > w \
            or y1 + ground_px + 2 > h:
        return widths, outer
    ring = np.concatenate([g[y0:y1 + 1, x0 - 1 - ground_px:x0 - 1].ravel(),
                           g[y0:y1 + 1, x1 + 2:x1 + 2 + ground_px].ravel(),
                           g[y0 - 1 - ground_px:y0 - 1, x0:x1 + 1].ravel(),
                           g[y1 + 2:y1 + 2 + ground_px, x0:x1 + 1].ravel()])
    ground = float(np.median(ring))
    if not ground > 0:
        return widths, outer
    patch = g[y0:y1 + 1, x0:x1 + 1].astype(np.float32)
    dark = (patch >= ratio_lo * ground) & (patch <= ratio_hi * ground)
    for side in range(4):
        frac = dark.mean(axis=0 if side in (0, 2) else 1)  # per strip, left to right or top to bottom
        frac, opposite = (frac[::-1], frac) if side >= 2 else (frac, frac[::-1])
        k_max = max(1, int(max_rel * len(frac)))
        outer[side] = float(frac[:k_max].mean())
        # a vehicle seen from above is about as dark at its front as at its rear, at its left as at its right: a
        # band darker than the same depth from the opposite side is what lies beside the body, its shadow
        run = frac[:k_max] - opposite[:k_max] >= min_frac
        start = int(np.argmax(run)) if run.any() else k_max
        if start <= lead_px:  # the box may hold the blurred edge, and ground, before the shadow: trimmed with it
            stop = np.flatnonzero(~run[start:])
            widths[side] = start + (int(stop[0]) if len(stop) else k_max - start)
    return widths, outer


def trim_cast_shadows(gray: np.ndarray, detections: list[Detection], *, max_rel: float = 0.35,
                      ratio_lo: float = 0.2, ratio_hi: float = 0.8, vote: float = 0.1,
                      min_votes: int = 3, lead_px: int = 2) -> list[Detection]:
    """``detections`` with the cast shadow taken off their boxes, on the side the frame's detections agree on.

    A vehicle's shadow moves with it, so the flow and the frames' change give it the vehicle's motion and
    the box holds it (2-6.5 px past the body on the synthetic scenes' sun side); annotators box the body.
    One sun casts every shadow of a frame the same way, onto one or two adjacent sides of the boxes, and
    which way is not known (real footage does not say; an overcast sky casts none). A side is a shadow side
    when, over at least ``min_votes`` detections, the mean fraction of dark pixels next to it exceeds that
    next to the opposite side by ``vote`` (:func:`shadow_bands`, ``outer``): a dark body is as dark on both
    sides, a shadow on one; and so it does among the detections moving each way along that axis (those moving
    across it count for both): a box grown along the motion (KIT AIS, 2-3 frames a second) holds a dark body
    at one end, the same end for every vehicle driving one way. On a shadow side each box loses its own
    band, at most 1.5 times the median band of the detections that have one there (a dark car on the
    shadow's side would lose more than its shadow). The centre ``x_px, y_px`` becomes the new box's; the other fields stay.

    Parameters
    ----------
    gray : ndarray, (H, W)
        Frame t, grey levels (black at 0).
    detections : list of Detection
        The pair's detections (frame t pixels).
    max_rel, ratio_lo, ratio_hi, lead_px
        :func:`shadow_bands`.
    vote : float
        The margin, a fraction in [0, 1], of the dark fraction next to a side over the opposite side's.
    min_votes : int
        The fewest detections (with a ring of ground) that decide a frame's shadow sides.

    Returns
    -------
    list of Detection
        In the order given.
    """
    if not 0 <= vote <= 1:
        raise ValueError(f"vote: expected a fraction in [0, 1], got {vote!r}")
    if np.ndim(gray) != 2:
        raise ValueError(f"gray: expected an (H, W) frame, got shape {np.shape(gray)}")
    if not detections or max_rel <= 0:
        return list(detections)
    found = [shadow_bands(gray, (d.x0_px, d.y0_px, d.x1_px, d.y1_px), max_rel=max_rel, ratio_lo=ratio_lo,
                          ratio_hi=ratio_hi, lead_px=lead_px) for d in detections]
    bands, outer = np.array([b for b, _ in found]), np.array([o for _, o in found])
    seen = np.isfinite(outer[:, 0])
    if seen.sum() < min_votes:
        return list(detections)
    motion = np.nan_to_num(np.array([(d.u_px, d.v_px) for d in detections], dtype=np.float64))
    cut = np.zeros(4)  # the cap of each side; 0 where it is no shadow side
    for side in range(4):
        axis = side % 2  # 0: left / right, x; 1: top / bottom, y
        along = np.abs(motion[:, axis]) >= np.abs(motion[:, 1 - axis])
        sense = np.where(along, np.sign(motion[:, axis]), 0.0)
        diff = outer[:, side] - outer[:, (side + 2) % 4]
        # a box grown along the motion (the ground a fast vehicle covers next) holds the body at one end, dark at
        # that end for every vehicle that drives that way: the side must be darker for movers either way
        groups = [seen & (sense >= 0), seen & (sense <= 0)]
        with_band = bands[:, side] > 0
        if all(gr.any() and diff[gr].mean() >= vote for gr in groups) and with_band.any():
            cut[side] = 1.5 * np.median(bands[with_band, side])
    return _trimmed(detections, bands, cut)


def _trimmed(detections: list[Detection], bands: np.ndarray, cut: np.ndarray) -> list[Detection]:
    """Each box less its own band on each side (left, top, right, bottom), at most ``cut`` there; centre follows."""
    if not cut.any():
        return list(detections)
    out = []
    for d, b in zip(detections, bands):
        t = np.floor(np.minimum(b, cut))
        x0, y0, x1, y1 = d.x0_px + t[0], d.y0_px + t[1], d.x1_px - t[2], d.y1_px - t[3]
        out.append(d._replace(x_px=(x0 + x1) / 2, y_px=(y0 + y1) / 2, x0_px=float(x0), y0_px=float(y0),
                              x1_px=float(x1), y1_px=float(y1)))
    return out


def shadow_lean(gray: np.ndarray, detections: list[Detection], *, max_rel: float = 0.35, ratio_lo: float = 0.2,
                ratio_hi: float = 0.8, lead_px: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Each detection's shadow bands and the way its dark pixels lean: a frame's votes for the clip's sun.

    Parameters
    ----------
    gray : ndarray, (H, W)
        Frame t, grey levels (black at 0).
    detections : list of Detection
        The pair's detections (frame t pixels).
    max_rel, ratio_lo, ratio_hi, lead_px
        :func:`shadow_bands`.

    Returns
    -------
    bands : ndarray, (N, 4) int64
        :func:`shadow_bands` ``widths`` of each detection (left, top, right, bottom), px.
    lean : ndarray, (N, 2) float64
        The dark fraction next to the right side less that next to the left, and next to the bottom less that
        next to the top (:func:`shadow_bands` ``outer``; in [-1, 1], x right and y down: the image direction the
        box's dark pixels lie towards); NaN where the box has no ring of ground.
    """
    if np.ndim(gray) != 2:
        raise ValueError(f"gray: expected an (H, W) frame, got shape {np.shape(gray)}")
    bands, lean = np.zeros((len(detections), 4), np.int64), np.full((len(detections), 2), np.nan)
    for i, d in enumerate(detections):
        b, o = shadow_bands(gray, (d.x0_px, d.y0_px, d.x1_px, d.y1_px), max_rel=max_rel, ratio_lo=ratio_lo,
                            ratio_hi=ratio_hi, lead_px=lead_px)
        bands[i], lean[i] = b, (o[2] - o[0], o[3] - o[1])
    return bands, lean


def clip_shadow_direction(lean: np.ndarray, motion_px: np.ndarray, *, vote: float = 0.1,
                          min_votes: int = 20) -> np.ndarray:
    """The way the clip's cast shadows fall, from the leans of its detections so far; zero: no shadow.

    One sun casts every shadow of a clip the same way on the ground (it moves 0.25 degrees a minute), so the
    detections of all the clip's pairs vote together, each in one ground-fixed frame (the caller turns each
    pair's ``lean`` and motion by the camera's yaw since the clip's first frame; the image axes turn with the
    camera). Along each axis the detections are grouped as in :func:`trim_cast_shadows`, by the way they move
    along it (those moving across it count for both). What the body puts at its front or rear (a dark
    windscreen, a dark body at one end of a box grown along the motion, KIT AIS at 2-3 frames a second) leans
    one way for the vehicles driving one way and the other way for those driving back: ``lean+ = s + b``,
    ``lean- = s - b``; the shadow ``s`` leans the same way for both. The axis's shadow lean is the mean of the
    two groups' mean leans, ``s``; it must reach ``vote``. (The frame's rule, both groups past ``vote``, gives
    up the shadow wherever the body's lean is the larger: the synthetic city's dark windscreens lean 0.16, its
    shadows 0.13.) An overcast sky casts no shadow: the leans scatter about zero and no axis passes, so
    nothing is trimmed; an axis along which the vehicles drive one way only says nothing (``b`` and ``s``
    cannot be told apart).

    Parameters
    ----------
    lean : ndarray, (N, 2) float
        :func:`shadow_lean` of the detections so far, in the reference frame's axes (NaN rows: no vote).
    motion_px : ndarray, (N, 2) float
        Their motion (u, v), px/frame, in the same axes (NaN: unknown, taken as 0: across both axes).
    vote : float
        The least mean lean, a fraction in [0, 1], of both groups along an axis.
    min_votes : int
        The fewest detections with a lean in each group of an axis that decide its shadow (until then: none).

    Returns
    -------
    ndarray, (2,) float64
        The shadow's lean (x, y) in the reference frame's axes: per axis ``s``, 0 where the axis does not
        pass; both 0 when no shadow is decided.
    """
    if not 0 <= vote <= 1:
        raise ValueError(f"vote: expected a fraction in [0, 1], got {vote!r}")
    lean = np.asarray(lean, dtype=np.float64).reshape(-1, 2)
    motion = np.nan_to_num(np.asarray(motion_px, dtype=np.float64).reshape(-1, 2))
    if len(motion) != len(lean):
        raise ValueError(f"motion_px: expected {len(lean)} rows (one per lean), got {len(motion)}")
    out = np.zeros(2)
    seen = np.isfinite(lean).all(axis=1)
    for axis in (0, 1):
        along = np.abs(motion[:, axis]) >= np.abs(motion[:, 1 - axis])
        sense = np.where(along, np.sign(motion[:, axis]), 0.0)
        groups = [seen & (sense >= 0), seen & (sense <= 0)]
        if any(gr.sum() < min_votes for gr in groups):
            continue
        shadow = float(np.mean([lean[gr, axis].mean() for gr in groups]))
        if abs(shadow) >= vote:
            out[axis] = shadow
    return out


def image_yaw_rad(matrix) -> float:
    """The turn of the image content from frame t to frame t+1 of a pair's global model, rad.

    ``matrix`` (3, 3) maps frame t's pixels to frame t+1's (the pipeline's pair model; a shift: 0). A
    direction ``d`` on the ground seen in frame t is ``R(angle) d`` in frame t+1 (x right, y down, so a positive
    angle turns x towards y, clockwise on the screen); the angle is that of the nearest rotation to the
    model's linear part (its similarity part: ``atan2(a21 - a12, a11 + a22)``).
    """
    M = np.asarray(matrix, dtype=np.float64)
    if M.shape != (3, 3):
        raise ValueError(f"matrix: expected a (3, 3) model, got shape {M.shape}")
    return float(math.atan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1]))


def turn(vectors, angle_rad: float) -> np.ndarray:
    """``vectors`` (N, 2) or (2,) (x right, y down) turned by ``angle_rad`` (x towards y), float64, same shape."""
    v = np.asarray(vectors, dtype=np.float64)
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def fill_lane(gray: np.ndarray, detections: list[Detection], *, next_gray: np.ndarray | None = None,
              max_rel: float = 3.0, line_frac: float = 0.6, road_k: float = 3.0, ring_px: int = GAP_SPLIT_RING_PX,
              gain_grey: float = 2.0) -> list[Detection]:
    """``detections`` with each box grown along its motion over the body its flow could not see.

    A vehicle's uniform roof moving along itself changes neither the flow nor the frames inside it: the box of
    the region holds the front or the rear edge (the aperture problem). Its body shows in the frame all the same:
    it is no road. Of a box, the pixels whose grey lies more than ``road_k`` robust spreads from the road (the
    median and 1.4826 MAD of the ring of ``ring_px`` px of ground 2 px around the box, :func:`_road_grey`) are its
    body; their extents along the motion ``(u, v)`` and across it are its length and its lane. The lane is binned
    in 1 px lines across the motion, and from each end of the body outwards the box takes in lines of which at
    least ``line_frac`` is body, up to a length of ``max_rel`` times the body's length or width, whichever is
    larger. Road between two vehicles ends it, and so does the road behind a car, whose box holds its whole body
    already. With ``next_gray`` (frame t+1 compensated into frame t) the new end must be the vehicle's: around the
    last lines taken in (2 px either side, the lane's width), frame t+1 sampled at the box's motion must match frame
    t better than unmoved, by ``gain_grey`` grey levels on average (the far edge of a roof moves with it; a
    crosswalk or a stop line painted ahead of a car, no road either, does not), else that side keeps its extent.
    A box without a motion, at the image's border, or with under 10 body pixels is left as it is.

    Parameters
    ----------
    gray : ndarray, (H, W)
        Frame t, grey levels.
    detections : list of Detection
        Frame t's detections (inclusive boxes; ``u_px, v_px`` their motion).
    next_gray : ndarray, (H, W), optional
        Frame t+1 compensated into frame t's pixels (without it the new ends are not checked).
    max_rel, line_frac, road_k, ring_px, gain_grey
        As above (``lane_fill_rel``, ``lane_fill_line``, ``lane_fill_road_k``).

    Returns
    -------
    list of Detection
        In the order given; a grown box's centre is the new box's.
    """
    g = np.asarray(gray)
    if g.ndim != 2:
        raise ValueError(f"gray: expected an (H, W) frame, got shape {g.shape}")
    nxt = None if next_gray is None else np.asarray(next_gray)
    if nxt is not None and nxt.shape != g.shape:
        raise ValueError(f"next_gray: expected the shape of gray {g.shape}, got {nxt.shape}")
    if not max_rel >= 0:
        raise ValueError(f"max_rel: expected a number >= 0, got {max_rel!r}")
    out = []
    for d in detections:
        grown = None if max_rel == 0 else _lane_box(
            g, nxt, (d.x0_px, d.y0_px, d.x1_px, d.y1_px), d.u_px, d.v_px, max_rel=max_rel, line_frac=line_frac,
            road_k=road_k, ring_px=ring_px, gain_grey=gain_grey)
        if grown is None:
            out.append(d)
            continue
        x0, y0, x1, y1 = grown
        out.append(d._replace(x_px=(x0 + x1) / 2, y_px=(y0 + y1) / 2, x0_px=float(x0), y0_px=float(y0),
                              x1_px=float(x1), y1_px=float(y1)))
    return out


def _lane_box(g: np.ndarray, nxt: np.ndarray | None, box, u: float, v: float, *, max_rel: float, line_frac: float,
              road_k: float, ring_px: int, gain_grey: float) -> tuple[int, int, int, int] | None:
    """:func:`fill_lane` of one box: the grown inclusive box, or None where it stays as it is."""
    h, w = g.shape
    speed = math.hypot(u, v)
    if not speed > 0:
        return None
    x0, y0, x1, y1 = (int(round(float(c))) for c in box)
    if x0 < ring_px + 2 or y0 < ring_px + 2 or x1 + ring_px + 3 > w or y1 + ring_px + 3 > h or x1 < x0 or y1 < y0:
        return None
    du, dv = u / speed, v / speed
    ring = np.ones((y1 - y0 + 5 + 2 * ring_px, x1 - x0 + 5 + 2 * ring_px), bool)
    ring[ring_px:-ring_px, ring_px:-ring_px] = False
    road = _road_grey(g[y0 - 2 - ring_px:y1 + 3 + ring_px, x0 - 2 - ring_px:x1 + 3 + ring_px][ring])
    if road is None:
        return None
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2

    def along_across(xa, ya, xb, yb):  # a window's pixels: body or not, and their coordinates along and across
        ys, xs = np.mgrid[ya:yb + 1, xa:xb + 1]
        body = np.abs(g[ya:yb + 1, xa:xb + 1].astype(np.float32) - road[0]) > road_k * road[1]
        return body, (xs - cx) * du + (ys - cy) * dv, -(xs - cx) * dv + (ys - cy) * du, xs, ys

    body, s, t, _, _ = along_across(x0, y0, x1, y1)
    if body.sum() < 10:
        return None
    t_lo, t_hi = np.percentile(t[body], [5, 95])
    s_lo, s_hi = np.percentile(s[body], [2, 98])
    max_len = max_rel * max(s_hi - s_lo, t_hi - t_lo)
    reach = int(math.ceil(max_len))
    xa, ya = max(0, int(math.floor(x0 - reach * abs(du)))), max(0, int(math.floor(y0 - reach * abs(dv))))
    xb, yb = min(w - 1, int(math.ceil(x1 + reach * abs(du)))), min(h - 1, int(math.ceil(y1 + reach * abs(dv))))
    body, s, t, xs, ys = along_across(xa, ya, xb, yb)
    lane = (t >= t_lo) & (t <= t_hi)
    lines = np.floor(s).astype(np.int64)
    first = int(lines[lane].min())
    lines -= first  # each pixel's line across the motion, 0 the lane's first
    total = np.bincount(lines[lane])
    share = np.bincount(lines[lane], weights=body[lane].astype(np.float64), minlength=len(total))
    share /= np.maximum(total, 1)
    lo, hi = int(math.floor(s_lo)) - first, int(math.ceil(s_hi)) - first
    end = hi
    while end + 1 < len(share) and share[end + 1] >= line_frac and end + 1 - lo <= max_len:
        end += 1
    start = lo
    while start - 1 >= 0 and share[start - 1] >= line_frac and end - (start - 1) <= max_len:
        start -= 1
    if start == lo and end == hi:
        return None
    if nxt is not None:
        # the new end must move with the vehicle: frame t+1 at the motion explains the lines around it better
        a = g[ya:yb + 1, xa:xb + 1].astype(np.float32)
        b = nxt[ya:yb + 1, xa:xb + 1].astype(np.float32)
        gain = np.abs(b - a) - np.abs(_shifted(b, u, v) - a)

        def moves(at: int) -> bool:
            near = lane & (np.abs(lines - at) <= 2)
            return bool(near.any()) and float(gain[near].mean()) > gain_grey

        end = end if end == hi or moves(end) else hi
        start = start if start == lo or moves(start) else lo
    if start == lo and end == hi:
        return None
    taken = lane & body & (lines >= start) & (lines <= end)
    return (min(x0, int(xs[taken].min())), min(y0, int(ys[taken].min())), max(x1, int(xs[taken].max())),
            max(y1, int(ys[taken].max())))


def trim_toward(detections: list[Detection], bands: np.ndarray, direction, *,
                min_cos: float = 0.5, diagonal_deg: float = 0.0) -> list[Detection]:
    """``detections`` with their cast shadow taken off the sides that face ``direction``.

    A side faces the shadow when its outward normal lies within ``arccos(min_cos)`` of ``direction`` (60
    degrees: a shadow that falls along a diagonal of the image reaches out of two adjacent sides, one along an
    axis out of one). There each box loses its own band, at most 1.5 times the median band of the detections
    that have one on that side (:func:`trim_cast_shadows`). A detection whose motion ``(u_px, v_px)`` lies more
    than ``diagonal_deg`` off both image axes keeps its box (``shadow_diagonal_deg``: a vehicle driving
    diagonally does not fill its axis-aligned box, whose edge bands hold a corner of it; 0: every box trimmed).

    Parameters
    ----------
    detections : list of Detection
        The pair's detections (frame t pixels).
    bands : ndarray, (N, 4) int
        Their :func:`shadow_lean` ``bands``.
    direction : array-like, (2,)
        The shadow's direction in frame t's axes (x right, y down); zero: no shadow, nothing trimmed.
    min_cos : float
        In (0, 1].
    diagonal_deg : float
        In [0, 45].

    Returns
    -------
    list of Detection
        In the order given.
    """
    b = np.asarray(bands).reshape(-1, 4)
    if len(b) != len(detections):
        raise ValueError(f"bands: expected {len(detections)} rows (one per detection), got {len(b)}")
    if not 0 < min_cos <= 1:
        raise ValueError(f"min_cos: expected a number in (0, 1], got {min_cos!r}")
    if not 0 <= diagonal_deg <= 45:
        raise ValueError(f"diagonal_deg: expected degrees in [0, 45], got {diagonal_deg!r}")
    s = np.asarray(direction, dtype=np.float64).reshape(2)
    norm = math.hypot(*s)
    cut = np.zeros(4)
    if not detections or not norm > 0:
        return list(detections)
    if diagonal_deg > 0:
        # each motion's angle off the x axis, folded into [0, 90]: diagonal between diagonal_deg and 90 - it; such
        # a box's bands are no shadow's, neither trimmed nor counted in the median
        u, v = np.array([d.u_px for d in detections]), np.array([d.v_px for d in detections])
        off_x = np.degrees(np.arctan2(np.abs(v), np.abs(u)))
        diagonal = (np.hypot(u, v) > 0) & (off_x > diagonal_deg) & (off_x < 90 - diagonal_deg)
        b = np.where(diagonal[:, None], 0, b)
    for side, normal in enumerate(((-1, 0), (0, -1), (1, 0), (0, 1))):
        with_band = b[:, side] > 0
        if (normal[0] * s[0] + normal[1] * s[1]) / norm >= min_cos and with_band.any():
            cut[side] = 1.5 * np.median(b[with_band, side])
    return _trimmed(detections, b, cut)


@register_stage("detection")
def detect_vehicles(flow: np.ndarray, valid: np.ndarray, *, global_flow_px=None, frames=None, prev_frame=None,
                    gsd_m_per_px: float | None = None, parallax_exempt: Callable[[Detection], bool] | None = None,
                    **params) -> list[Detection]:
    """Moving vehicles of a pair: regions of independent local motion, one per rigid mover (module docstring).

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
        Local flow (u, v) of pair t -> t+1 after global compensation, px; frame t pixels.
    valid : ndarray, (H, W) bool
        Where the flow is defined.
    global_flow_px : array-like, (2,) or (H, W, 2), optional
        The global (camera) motion of the pair, px: the shift, or the global model's field.
        Without it the parallax test is off.
    frames : (ndarray, ndarray), optional
        Gray frame t and the compensated frame t+1, (H, W): for the ``min_explained`` test,
        the refinement, the box and the change at rest (off without them).
    prev_frame : ndarray, (H, W), optional
        Gray frame t-1 compensated into frame t's pixels (``I_{t-1}(M^-1 x)``, ``M`` the global
        model of pair t-1): the box test of ``box_three_frames`` and the change at rest from t-1 (frames
        t, t+1 alone without it).
    gsd_m_per_px : float, optional
        Ground sampling distance, m/px: fills ``area_m2`` and applies ``min_area_m2``, ``max_area_m2``.
    parallax_exempt : callable, optional
        Called with each detection the parallax test (``parallax_max_ratio``) rejects; one it returns True for
        is kept (the long pair's chains over frames, :class:`algorithms.long_baseline.ParallaxChains`).
    **params
        Keys of ``DETECTION_DEFAULTS`` (module docstring); an unknown key raises ValueError naming it.

    Returns
    -------
    list of Detection
        Largest first; ``u_px, v_px`` the region's median local flow, px/frame.
    """
    p = _check_keys(params)
    f = np.asarray(flow)
    if f.ndim != 3 or f.shape[2] != 2:
        raise ValueError(f"flow: expected (H, W, 2), got {tuple(f.shape)}")
    val = np.asarray(valid)
    if val.shape != f.shape[:2] or val.dtype != bool:
        raise ValueError(f"valid: expected {f.shape[:2]} bool, got {tuple(val.shape)} {val.dtype}")
    if gsd_m_per_px is not None and not (math.isfinite(gsd_m_per_px) and gsd_m_per_px > 0):
        raise ValueError(f"gsd_m_per_px: expected None or a finite number > 0, got {gsd_m_per_px!r}")
    h, w = f.shape[:2]
    coef = None
    if p["ground_model"] != "none":
        coef = _ground_fit(f, val, model=p["ground_model"])
        f = _subtract_fit(f, coef)
    mag2 = f[..., 0].astype(np.float32) ** 2 + f[..., 1].astype(np.float32) ** 2
    thr = float(p["min_magnitude_px"])
    if p["noise_k"] > 0:
        # the flow's noise on the ground: the median residual speed on a grid of valid pixels (for 2-D
        # Gaussian noise 1.18 sigma; 3 medians are 3.5 sigma, which 0.2 % of the ground exceeds)
        grid = mag2[4::8, 4::8][val[4::8, 4::8]]
        if grid.size:
            thr = max(thr, p["noise_k"] * math.sqrt(float(np.median(grid))))
    mask = (val & (mag2 >= np.float32(thr) ** 2)).view(np.uint8)
    b = p["border_px"]
    if b:  # a flow window clipped by the border, content that enters: the flow there is unreliable
        mask[:b], mask[-b:], mask[:, :b], mask[:, -b:] = 0, 0, 0, 0
    if p["open_px"]:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _disk(p["open_px"]))
    if p["close_px"]:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _disk(p["close_px"]))
    n, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(mask, 8, cv2.CV_32S, cv2.CCL_BBDT)
    # a region under the smallest detection's area in m^2 gives none (its parts are smaller still): not split
    min_px = p["min_area_px"]
    if gsd_m_per_px is not None and p["min_area_m2"] is not None:
        min_px = max(min_px, int(p["min_area_m2"] / gsd_m_per_px**2))
    regions = []
    for i in range(1, n):
        if stats[i, cv2.CC_STAT_AREA] < min_px:
            continue
        x0, y0 = stats[i, cv2.CC_STAT_LEFT], stats[i, cv2.CC_STAT_TOP]
        sub = labels[y0:y0 + stats[i, cv2.CC_STAT_HEIGHT], x0:x0 + stats[i, cv2.CC_STAT_WIDTH]] == i
        ys, xs = np.nonzero(sub)
        ys, xs = ys + y0, xs + x0
        regions.append(_Region(ys, xs, f[ys, xs].astype(np.float32)))
    regions = [q for r in regions for q in _split(r, p)]
    regions = _merge(regions, p)

    g = None if global_flow_px is None else np.asarray(global_flow_px, dtype=np.float64)
    if g is not None and g.shape not in ((2,), (h, w, 2)):
        raise ValueError(f"global_flow_px: expected (2,) or {(h, w, 2)}, got {tuple(g.shape)}")
    if frames is not None and (len(frames) != 2 or any(np.shape(a) != (h, w) for a in frames)):
        raise ValueError(f"frames: expected two gray frames of shape {(h, w)}")
    if prev_frame is not None and np.shape(prev_frame) != (h, w):
        raise ValueError(f"prev_frame: expected a gray frame of shape {(h, w)}, got {np.shape(prev_frame)}")
    out, evidence_of, late_of = [], [], []
    ground_of = []
    cores = [c for r in regions if len(r.ys) >= p["min_area_px"] for c in r.cores(p["core_rel"], p["min_area_px"])]
    cores = _merge(cores, p) if len(cores) > len(regions) else cores
    found: list = []  # the boxes of the cores' movers (leftover_rel)

    def candidates():
        """(group of regions, late): the cores' groups, then (late) what they left of each region (leftover_rel)."""
        yield from ((group, False) for group in _overlapping(cores, p["nms_iou"]))
        if p["leftover_rel"] > 0 and frames is not None and p["box_from_frames"]:
            # outside every box found: a slower vehicle close behind a faster one, whose pixels fell under core_rel
            # of its region's speed, looked at once at its own motion
            yield from (([q], True) for r in regions for q in _left_over(r, found, p["leftover_rel"], p["min_area_px"]))

    for group, late in candidates():
        # without the frames the largest part alone (nothing tells which part's flow is right)
        c = group[0] if frames is None or len(group) == 1 else _Region(
            np.concatenate([q.ys for q in group]), np.concatenate([q.xs for q in group]),
            np.concatenate([q.w for q in group]))
        area = len(c.ys)
        boxed = frames is not None and p["box_from_frames"]
        # with the box from the frames the upper limits judge that box: a flow halo (a smoothing window
        # that spreads a fast car's motion over two to three times its area) is no larger vehicle; a region
        # beyond max_area_halo_rel times them is rejected before its costly box (roofs, a parallax field)
        if _too_large(area / p["max_area_halo_rel"] if boxed else area, p, gsd_m_per_px):
            continue
        area_m2 = area * gsd_m_per_px**2 if gsd_m_per_px is not None else math.nan
        if gsd_m_per_px is not None and p["min_area_m2"] is not None and area_m2 < p["min_area_m2"]:
            continue
        cx, cy = float(c.xs.mean()), float(c.ys.mean())
        u, v = (float(a) for a in group[0].velocity)
        margin = float(area)  # what ranks overlapping regions without frames
        # the motion the compensation left the ground with here: the frames are compared about it
        ground = _fit_at(coef, cx, cy, h, w)
        if frames is not None and (p["refine_px"] > 0 or p["min_explained"] > 0):
            chosen = _motion(c, [tuple(float(a) for a in q.velocity) for q in group], frames, ground, p)
            if chosen is None:
                continue
            u, v, margin = chosen
        x0, y0, x1, y1 = c.box()
        if frames is not None and p["box_from_frames"]:
            prev = prev_frame if p["box_three_frames"] else None
            # a motion beyond the region only with frame t-1: its test leaves out the places the vehicle moves to
            # and comes from, which frames t, t+1 alone would join to it
            reach = 4 + (int(math.ceil(p["box_margin_rel"] * max(abs(u), abs(v)))) if prev is not None else 0)
            apart: list = []
            box = _moved_box(c, frames, u, v, ground, prev, join=p["box_join"], reach_px=p["box_reach_px"],
                             reach_join=p["box_reach_join"], reach_parts=p["box_reach_parts"],
                             road_k=p["box_reach_road_k"], margin_px=reach,
                             others=apart if p["box_split_rel"] > 0 else None, other_rel=p["box_split_rel"])
            # the evidence of a mover: at least min_area_px pixels that its motion explains better than the
            # ground's (a region of flow noise, or of an edge the registration left, holds a few)
            if box is None or box[4] < p["min_area_px"]:
                continue
            x0, y0, x1, y1 = box[:4]
            if not late:
                found.append((x0, y0, x1, y1, u, v))
            if _too_large((x1 - x0 + 1) * (y1 - y0 + 1), p, gsd_m_per_px) \
                    or _too_small_box((x0, y0, x1, y1), p, gsd_m_per_px, h, w):
                continue
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
            # a second vehicle at about the same velocity that the flow's smoothing joined to this region, static
            # texture between the two: its own detection at this one's motion, ranked after it
            for ax0, ay0, ax1, ay1, n_px in apart:
                if n_px < p["min_area_px"] or _too_large((ax1 - ax0 + 1) * (ay1 - ay0 + 1), p, gsd_m_per_px) \
                        or _too_small_box((ax0, ay0, ax1, ay1), p, gsd_m_per_px, h, w):
                    continue
                a_m2 = n_px * gsd_m_per_px**2 if gsd_m_per_px is not None else math.nan
                out.append(Detection((ax0 + ax1) / 2, (ay0 + ay1) / 2, n_px, float(ax0), float(ay0), float(ax1),
                                     float(ay1), u, v, a_m2))
                evidence_of.append(margin * n_px / box[4])
                late_of.append(late)
                ground_of.append(ground)
            # two or three vehicles at one velocity, a band of road between them: one detection each
            cut = _gap_split(frames[0], (x0, y0, x1, y1), u, v, width_px=p["gap_split_width_px"],
                             length_px=p["gap_split_length_px"], road_k=p["gap_split_road_k"],
                             valley=p["gap_split_valley"], by_motion=p["gap_split_moved"],
                             moved=lambda: _box_motion(frames, (x0, y0, x1, y1), u, v, ground, prev)) \
                if p["gap_split_width_px"] > 0 or p["gap_split_length_px"] > 0 else []
            if cut and not any(_too_small_box(q[:4], p, gsd_m_per_px, h, w) for q in cut):
                n_all = sum(q[4] for q in cut) or 1
                for qx0, qy0, qx1, qy1, n_px in cut:
                    share = n_px / n_all
                    out.append(Detection((qx0 + qx1) / 2, (qy0 + qy1) / 2, max(1, round(area * share)), float(qx0),
                                         float(qy0), float(qx1), float(qy1), u, v, area_m2 * share))
                    evidence_of.append(margin * share)
                    late_of.append(late)
                    ground_of.append(ground)
                continue
        out.append(Detection(cx, cy, area, float(x0), float(y0), float(x1), float(y1), u, v, area_m2))
        evidence_of.append(margin)
        late_of.append(late)
        ground_of.append(ground)
    # one detection per mover: a vehicle that moves more than its size leaves a second region where the
    # flow method failed (the ground it uncovered or covered); of regions whose boxes overlap by nms_iou,
    # the one whose motion explains the change best stays; a leftover part's (leftover_rel) only where it overlaps
    # none of the cores' detections
    kept: list[Detection] = []
    kept_ground = []
    for i in np.lexsort((-np.asarray(evidence_of, dtype=np.float64), np.asarray(late_of, dtype=bool))):
        d = out[i]
        if not any(_box_iou(d, k) >= p["nms_iou"] for k in kept):
            kept.append(d)
            kept_ground.append(ground_of[i])
    out = [(d, gr) for d, gr in zip(kept, kept_ground)
           if not _parallax(d, g, p, h, w) or (parallax_exempt is not None and parallax_exempt(d))]
    parallax_dir = _common_parallax([d for d, _ in out], p, h * w)
    if parallax_dir is not None:
        e, bound = parallax_dir
        out = [(d, gr) for d, gr in out if not _along(d, e, bound, p)]
    if frames is not None and p["change_noise_k"] > 0 and out:
        # a mover's content left its place from t to t+1 and arrived there since t-1; static texture that the flow
        # saw move (aliasing of markings, compression, flickering crowns) changed there as noise does. Last: the
        # parts a rejected detection stood for are the same texture, and the common parallax is judged on all
        others = [(o, sign, _difference_variance(frames[0], o))
                  for o, sign in ((frames[1], 1), (prev_frame, -1)) if o is not None]
        out = [(d, gr) for d, gr in out if _changed(d, gr, frames[0], others, p)]
    out = [d for d, _ in out]
    if frames is not None and p["shadow_trim_rel"] > 0 and p["shadow_scope"] == "frame":
        out = trim_cast_shadows(frames[0], out, max_rel=p["shadow_trim_rel"], ratio_lo=p["shadow_ratio_lo"],
                                ratio_hi=p["shadow_ratio_hi"], vote=p["shadow_vote"], min_votes=p["shadow_min_votes"],
                                lead_px=p["shadow_lead_px"])
    return sorted(out, key=lambda d: -d.area_px)
