"""The flow convention of aerobench: one home for layouts, input checks and colours.

Conventions (see ``docs/architecture.md``):

* A frame is ``(H, W)`` gray or ``(H, W, 3)`` RGB, of an integer or real dtype.
  :func:`as_gray` converts it once to ``(H, W)`` float32 in the input's own
  units (uint8 stays 0..255, float stays as it is): every method takes frames
  through it.
* A flow field is ``(H, W, 2)`` float32 in pixels, ``[..., 0] = u`` (+x, right),
  ``[..., 1] = v`` (+y, down), forward from frame t to frame t+1::

      I_{t+1}(x + u, y + v) ~ I_t(x, y)

  Pixel centres sit at integer coordinates.
* A global shift is the displacement ``(dx, dy)`` of the ground's image content
  from t to t+1, not the correction that undoes it.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = [
    "FLOW_DTYPE",
    "as_gray",
    "check_frame_pair",
    "check_flow",
    "endpoint_error",
    "warp_backward",
    "flow_to_color",
    "color_wheel_image",
]

FLOW_DTYPE = np.float32

# ITU-R BT.601 luma weights, the ones cv2.COLOR_RGB2GRAY uses.
_LUMA_RGB = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def _describe(a: np.ndarray) -> str:
    return f"{tuple(a.shape)} {a.dtype}"


def as_gray(frame: np.ndarray, *, name: str = "frame") -> np.ndarray:
    """Return ``frame`` as ``(H, W)`` float32 gray, in the input's own units.

    Parameters
    ----------
    frame : ndarray, (H, W) or (H, W, 3) or (H, W, 1)
        Integer (uint8, uint16, ...) or real dtype. RGB is converted with the
        BT.601 weights (0.299, 0.587, 0.114); values are not rescaled, so uint8
        input gives 0..255.
    name : str
        Used in error messages.

    Raises
    ------
    TypeError
        For bool, complex, object or other non-numeric dtypes.
    ValueError
        For a wrong number of dimensions or channels, an empty image, or a
        non-finite pixel.
    """
    a = np.asarray(frame)
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise TypeError(
            f"{name}: expected an integer or real image (uint8, float32, ...), got dtype {a.dtype}"
        )
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 3 and a.shape[2] == 3:
        g = (a.astype(np.float32, copy=False) @ _LUMA_RGB).astype(np.float32, copy=False)
    elif a.ndim == 2:
        g = a.astype(np.float32, copy=True)
    else:
        raise ValueError(f"{name}: expected (H, W) gray or (H, W, 3) RGB, got {_describe(a)}")
    if g.size == 0 or min(g.shape) < 2:
        raise ValueError(f"{name}: expected an image of at least 2x2 pixels, got {_describe(a)}")
    if not np.isfinite(g).all():
        bad = int(np.count_nonzero(~np.isfinite(g)))
        raise ValueError(f"{name}: {bad} pixel(s) are NaN or infinite")
    return g


def check_frame_pair(frame0: np.ndarray, frame1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convert both frames with :func:`as_gray` and check that their sizes match."""
    g0 = as_gray(frame0, name="frame0")
    g1 = as_gray(frame1, name="frame1")
    if g0.shape != g1.shape:
        raise ValueError(f"frame0 and frame1 differ in size: {g0.shape} vs {g1.shape}")
    return g0, g1


def check_flow(flow: np.ndarray, *, name: str = "flow", shape: tuple[int, int] | None = None,
               allow_nan: bool = False) -> np.ndarray:
    """Check a flow field's layout and return it as float32 ``(H, W, 2)``.

    ``shape`` pins ``(H, W)``. Non-finite values are an error unless
    ``allow_nan`` (for fields whose unknown pixels are NaN, such as ground truth
    read from a file).
    """
    a = np.asarray(flow)
    if not np.issubdtype(a.dtype, np.floating):
        raise TypeError(f"{name}: expected (H, W, 2) float32, got {_describe(a)}")
    if a.ndim != 3 or a.shape[2] != 2:
        hint = " (channels first? flow is (H, W, 2))" if a.ndim == 3 and a.shape[0] == 2 else ""
        raise ValueError(f"{name}: expected (H, W, 2) float32, got {_describe(a)}{hint}")
    if shape is not None and a.shape[:2] != tuple(shape):
        raise ValueError(f"{name}: expected size {tuple(shape)}, got {a.shape[:2]}")
    if not allow_nan and not np.isfinite(a).all():
        raise ValueError(f"{name}: {int(np.count_nonzero(~np.isfinite(a)))} value(s) are NaN or infinite")
    return a.astype(FLOW_DTYPE, copy=False)


def endpoint_error(flow_est: np.ndarray, flow_true: np.ndarray) -> np.ndarray:
    """Endpoint error ``sqrt((u_e - u_t)^2 + (v_e - v_t)^2)`` per pixel, ``(...)`` float64 px.

    The one home of EPE: metrics, reports and benchmarks import it. Both fields
    are ``(..., 2)`` (u, v), taken to float64 before the difference, so the value
    does not depend on the fields' dtypes; NaN in either gives NaN.
    """
    d = np.asarray(flow_est, np.float64) - np.asarray(flow_true, np.float64)
    if d.shape[-1:] != (2,):
        raise ValueError(f"flow: expected (..., 2) (u, v) fields, got {np.shape(flow_est)} and {np.shape(flow_true)}")
    return np.hypot(d[..., 0], d[..., 1])


def warp_backward(image: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``image`` at ``(x + u, y + v)``: bring frame t+1 back onto frame t.

    With the true forward flow, ``warp_backward(frame1, flow) ~ frame0``.

    Returns
    -------
    warped : ndarray, same shape and float32
        Bilinear samples; outside the image the border is replicated.
    inside : ndarray, (H, W) bool
        Where the sample point lies inside the image.
    """
    f = check_flow(flow, shape=np.asarray(image).shape[:2])
    h, w = f.shape[:2]
    map_x, map_y = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
    inside = np.empty((h, w), bool)
    target_points(f, map_x, map_y, inside)
    src = np.asarray(image).astype(np.float32, copy=False)
    warped = cv2.remap(src, map_x, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return warped, inside


def target_points(flow: np.ndarray, map_x: np.ndarray | None, map_y: np.ndarray | None,
                  inside: np.ndarray) -> None:
    """Where each pixel's flow points, ``(x + u, y + v)``, and whether that lies inside the frame, in one pass.

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float32
        Checked (see :func:`check_flow`).
    map_x, map_y : ndarray, (H, W) float32, or None
        Filled with ``x + u`` and ``y + v`` in float32 (the sums of
        ``np.arange(W, dtype=float32)[None, :] + flow[..., 0]`` and its y twin); None: not wanted.
    inside : ndarray, (H, W) bool
        Filled with ``0 <= x + u <= W - 1 and 0 <= y + v <= H - 1`` (False for NaN).
    """
    from algorithms._point_kernels import target_inside_kernel, target_points_kernel  # numba, on first use

    f = np.ascontiguousarray(flow, dtype=np.float32)
    if map_x is None or map_y is None:
        target_inside_kernel(f, inside)
    else:
        target_points_kernel(f, map_x, map_y, inside)


def _middlebury_wheel() -> np.ndarray:
    """The colour wheel of Baker et al. (IJCV 2011): 55 hues, (ncols, 3) float in 0..255.

    Segments red-yellow 15, yellow-green 6, green-cyan 4, cyan-blue 11,
    blue-magenta 13, magenta-red 6, as the Middlebury flow colour coding defines.
    """
    segments = [(15, (255, 0, 0), (255, 255, 0)), (6, (255, 255, 0), (0, 255, 0)),
                (4, (0, 255, 0), (0, 255, 255)), (11, (0, 255, 255), (0, 0, 255)),
                (13, (0, 0, 255), (255, 0, 255)), (6, (255, 0, 255), (255, 0, 0))]
    rows = []
    for n, start, end in segments:
        t = np.arange(n, dtype=np.float64)[:, None] / n
        rows.append(np.asarray(start, float) + t * (np.asarray(end, float) - np.asarray(start, float)))
    return np.concatenate(rows, axis=0)


_WHEEL = _middlebury_wheel()


def flow_to_color(flow: np.ndarray, *, max_magnitude: float | None = None,
                  valid: np.ndarray | None = None) -> np.ndarray:
    """Colour-code a flow field in the Middlebury convention: hue = direction, saturation = magnitude.

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
        Our layout; NaN marks unknown pixels (drawn black).
    max_magnitude : float, optional
        Magnitude, in px, that maps to full saturation; default the largest
        finite magnitude in ``flow`` (at least 1e-6). Pass the same value for
        fields that should be compared side by side.
    valid : ndarray, (H, W) bool, optional
        Pixels outside it are drawn black.

    Returns
    -------
    ndarray, (H, W, 3) uint8 RGB
    """
    f = check_flow(flow, allow_nan=True).astype(np.float64)
    known = np.isfinite(f[..., 0]) & np.isfinite(f[..., 1])
    if valid is not None:
        known &= np.asarray(valid, bool)
    if max_magnitude is None:
        mag = np.hypot(np.where(known, f[..., 0], 0.0), np.where(known, f[..., 1], 0.0))
        max_magnitude = float(mag.max()) if mag.size else 0.0
    scale = max(float(max_magnitude), 1e-6)
    rgb = np.empty(f.shape[:2] + (3,), np.uint8)
    from algorithms._color_kernel import color_code  # numba: compiled on first use, not on import

    color_code(np.ascontiguousarray(f), np.ascontiguousarray(known), scale, _WHEEL, rgb)
    return rgb


def color_wheel_image(size: int = 101) -> np.ndarray:
    """A legend: the flow colour of every displacement in a disc, ``(size, size, 3)`` uint8.

    The disc's edge is full saturation; directions are image directions
    (+x right, +y down).
    """
    if size < 3:
        raise ValueError(f"size: expected at least 3, got {size}")
    c = (size - 1) / 2.0
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float32)
    field = np.stack([(xs - c) / c, (ys - c) / c], axis=-1)
    outside = np.hypot(field[..., 0], field[..., 1]) > 1.0
    rgb = flow_to_color(field, max_magnitude=1.0)
    rgb[outside] = 255
    return rgb
