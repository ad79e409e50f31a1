"""Work that pipelines running on the same frames compute once: gray frames, pass-1 shifts, compensation.

The pipelines of one scene read the same frames, and most of them measure the same
global shifts (``global_motion`` method and parameters) and compensate the same pair by
the same matrix. A :class:`SharedWork` made for one sequence and passed to each
:meth:`algorithms.pipeline.Pipeline.run` on it (``shared=``) computes each of these once;
the results are the values a pipeline would have computed alone, bit for bit (the same
function on the same inputs). Frames and compensated pairs are handed out as read-only
views of the one array kept (no copy per caller: 7 pipelines x 3 arrays a pair were 1281
copies of 1.2 MB a scene), so a method that writes into its input raises numpy's
"read-only" error instead of changing what another pipeline sees; the built-in flow
methods take their frames through :func:`algorithms.flow.as_gray`, which copies.

Memory is bounded by ``max_bytes`` whatever the sequence length: gray frames are kept
least recently used first out (a sequence whose gray frames fit is decoded once for all
its pipelines and both passes; a longer one is decoded again where it no longer fits),
compensated frames only for the last ``pairs_kept`` pairs (pipelines run in lock-step
ask for the same pair one after the other), and shifts (two numbers a pair) always.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from collections.abc import Callable, Hashable, Mapping, Sequence
from typing import Any

import numpy as np

from algorithms.flow import as_gray

__all__ = ["SharedWork", "DEFAULT_MAX_BYTES"]

# gray frames kept per sequence: 60 frames of 640x480 float32 are 74 MB, 300 of 1920x1080 2.5 GB
DEFAULT_MAX_BYTES = 512 * 1024 * 1024


class SharedWork:
    """What the pipelines run on ``frames`` share; one per sequence (see the module docstring).

    Parameters
    ----------
    frames : indexable of (H, W) or (H, W, 3) arrays
        The sequence's frames (``len`` and ``frames[i]``), read on demand.
    max_bytes : int
        Most bytes of gray frames held at once (at least one pair's are always held).
    pairs_kept : int
        Compensated pairs held (the lock-step window).
    """

    def __init__(self, frames: Sequence, *, max_bytes: int = DEFAULT_MAX_BYTES, pairs_kept: int = 2):
        if max_bytes < 0:
            raise ValueError(f"max_bytes: expected >= 0, got {max_bytes}")
        if pairs_kept < 1:
            raise ValueError(f"pairs_kept: expected >= 1, got {pairs_kept}")
        self.frames = frames
        self.max_bytes = int(max_bytes)
        self.pairs_kept = int(pairs_kept)
        self._gray: OrderedDict[int, np.ndarray] = OrderedDict()
        self._gray_bytes = 0
        self._shifts: dict[Hashable, tuple] = {}
        self._compensated: OrderedDict[Hashable, tuple] = OrderedDict()
        self.hits = {"gray": 0, "shifts": 0, "compensated": 0}
        self.misses = {"gray": 0, "shifts": 0, "compensated": 0}

    def __len__(self) -> int:
        return len(self.frames)

    def gray(self, i: int) -> np.ndarray:
        """Frame ``i`` as :func:`algorithms.flow.as_gray` gives it: ``(H, W)`` float32, a read-only view."""
        g = self._gray.get(i)
        if g is not None:
            self._gray.move_to_end(i)
            self.hits["gray"] += 1
            return _read_only(g)
        self.misses["gray"] += 1
        g = as_gray(self.frames[i], name=f"frames[{i}]")
        g.flags.writeable = False
        self._gray[i] = g
        self._gray_bytes += g.nbytes
        while self._gray_bytes > self.max_bytes and len(self._gray) > 2:
            _, old = self._gray.popitem(last=False)
            self._gray_bytes -= old.nbytes
        return _read_only(g)

    def global_shifts(self, method: str, params: Mapping[str, Any], correction: np.ndarray | None,
                      compute: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]]
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pass 1 of a pipeline: ``compute()`` once per (method, params, correction); copies of its arrays.

        ``compute`` returns (shifts (N-1, 2), valid (N-1,), times_ms (N-1,)).
        """
        key = (method, json.dumps(params, sort_keys=True, default=str),
               None if correction is None else np.ascontiguousarray(correction, np.float64).tobytes())
        if key in self._shifts:
            self.hits["shifts"] += 1
        else:
            self.misses["shifts"] += 1
            self._shifts[key] = tuple(np.array(a, copy=True) for a in compute())
        return tuple(a.copy() for a in self._shifts[key])

    def compensated(self, t: int, model: str, matrix: np.ndarray,
                    compute: Callable[[], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
        """Frame ``t + 1`` compensated by ``matrix`` (``compute()`` once per pair, model and matrix); read-only
        views."""
        key = (int(t), model, np.ascontiguousarray(matrix, np.float64).tobytes())
        hit = self._compensated.get(key)
        if hit is not None:
            self.hits["compensated"] += 1
            self._compensated.move_to_end(key)
        else:
            self.misses["compensated"] += 1
            hit = tuple(_read_only(np.asarray(a)) for a in compute())
            self._compensated[key] = hit
            # keep the last ``pairs_kept`` pairs, whatever models and matrices they were asked with
            while len({k[0] for k in self._compensated}) > self.pairs_kept:
                self._compensated.popitem(last=False)
        return tuple(_read_only(a) for a in hit)


def _read_only(a: np.ndarray) -> np.ndarray:
    """A view of ``a`` that cannot be written (nor made writeable, since the view owns no data)."""
    v = a.view()
    v.flags.writeable = False
    return v
