"""The DAVIS family's runtime op ``davis_areas``: an event frame's filtered areas (numpy only)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from slipkit.runtime._schema import Fields
from slipkit.runtime.preprocessing import Array, Op, register_op

# -- DAVIS event frames: opening, closing, area filter, areas --------------------------------
# The DAVIS detector (slipkit.families.davis.polarity.clean_frame) uses scipy.ndimage for the
# morphology and the connected-component labelling. scipy is not installed on the
# gripper PC (the runtime imports only numpy and onnxruntime) and ONNX has no
# connected-component op, so they are written here by hand in vectorised numpy; the
# tests check them against scipy.ndimage on random frames.


def _shifted(img: NDArray[np.bool_], shift: int, axis: int) -> NDArray[np.bool_]:
    """``out[i] = img[i + shift]`` along ``axis``, False outside the frame."""
    out = np.zeros_like(img)
    n = img.shape[axis]
    src = [slice(None)] * img.ndim
    dst = [slice(None)] * img.ndim
    if shift >= 0:
        src[axis], dst[axis] = slice(shift, n), slice(0, max(n - shift, 0))
    else:
        src[axis], dst[axis] = slice(0, n + shift), slice(-shift, n)
    out[tuple(dst)] = img[tuple(src)]
    return out


def _erode(img: NDArray[np.bool_], size: int) -> NDArray[np.bool_]:
    """Binary erosion by a ``size`` square, border False (scipy's default origin)."""
    for axis in (0, 1):
        out = np.ones_like(img)
        for k in range(size):
            out &= _shifted(img, k - size // 2, axis)
        img = out
    return img


def _dilate(img: NDArray[np.bool_], size: int) -> NDArray[np.bool_]:
    """Binary dilation by a ``size`` square (scipy's default origin)."""
    for axis in (0, 1):
        out = np.zeros_like(img)
        for k in range(size):
            out |= _shifted(img, size // 2 - k, axis)
        img = out
    return img


def label_components(img: NDArray[np.bool_]) -> tuple[NDArray[np.intp], int]:
    """8-connected components of a binary image: labels 1..n (0: background), n.

    Hand-written because ``scipy.ndimage.label`` is not available on the gripper PC
    (see above). Vectorised over the set pixels only, in raster order: each pixel's
    label is the position (in that order) of a pixel of its component. Labels start
    as the first pixel of the pixel's horizontal run; then, until nothing changes,
    each pixel takes the smallest label among itself and its six neighbours in the
    rows above and below, each run takes the smallest label of its pixels, and each
    label follows ``label[label]`` (pointer jumping, which halves the chains). Each
    component ends labelled with its first pixel in raster order, so the components
    are numbered 1..n in that order, as ``scipy.ndimage.label`` numbers them.

    Parameters
    ----------
    img : ndarray of bool (height, width)

    Returns
    -------
    labels : ndarray of int (height, width)
    n : int
        Number of components.
    """
    img = np.asarray(img, dtype=bool)
    h, w = img.shape
    out = np.zeros((h, w), dtype=np.intp)
    # A one-pixel False border: flat neighbours never wrap into the next row.
    wp = w + 2
    pad = np.zeros((h + 2, wp), dtype=bool)
    pad[1:-1, 1:-1] = img
    pix = np.flatnonzero(pad)
    n = len(pix)
    if n == 0:
        return out, 0
    starts = np.flatnonzero(np.diff(pix, prepend=-2) != 1)  # first pixel of each run
    run_of = np.cumsum(np.diff(pix, prepend=-2) != 1) - 1
    where = np.full(pad.size, n, dtype=np.intp)  # flat index -> position (n: unset)
    where[pix] = np.arange(n)
    offsets = np.array([-wp - 1, -wp, -wp + 1, wp - 1, wp, wp + 1])
    nb = where[pix[:, None] + offsets]  # (n, 6) positions of the vertical neighbours
    lab = np.append(starts[run_of], n)  # sentinel n: an unset neighbour
    while True:
        new = np.minimum(lab[:n], lab[nb].min(axis=1))
        new = np.minimum.reduceat(new, starts)[run_of]
        new = new[new]  # pointer jumping: labels are positions of pixels
        if np.array_equal(new, lab[:n]):
            break
        lab[:n] = new
    lab = lab[:n]
    roots = np.flatnonzero(lab == np.arange(n))
    rows, cols = np.divmod(pix, wp)
    out[rows - 1, cols - 1] = np.searchsorted(roots, lab) + 1
    return out, len(roots)


def clean_event_frame(
    img: NDArray[np.bool_],
    *,
    opening_px: int,
    opening_shape: str,
    closing_px: int,
    min_area_px: int,
) -> NDArray[np.bool_]:
    """:func:`slipkit.families.davis.polarity.clean_frame` in numpy: opening, closing, area filter."""
    img = np.asarray(img, dtype=bool)
    if not img.any():
        return img
    if opening_px > 1:
        if opening_shape == "square":
            img = _dilate(_erode(img, opening_px), opening_px)
        else:  # "lines": union of the openings with a horizontal and a vertical line
            img = _line_opening(img, opening_px, 1) | _line_opening(img, opening_px, 0)
    if not img.any():
        return img
    # Closing and labelling only on the bounding box of what the opening kept (the
    # opening removes the scattered noise events, so the box is usually small): a
    # closing adds pixels only within closing_px of a set one, and padding the box
    # by closing_px keeps the erosion off the border, as the detector does.
    p = max(closing_px, 0)
    rows, cols = np.flatnonzero(img.any(axis=1)), np.flatnonzero(img.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    box = np.pad(img[r0:r1, c0:c1], p)
    if closing_px > 1:
        box = _erode(_dilate(box, p), p)
    if min_area_px > 1:
        labels, n = label_components(box)
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        keep = sizes >= min_area_px
        keep[0] = False
        box = keep[labels]
    # Back into the box only, as the detector (a closing by a square never sets a
    # pixel outside the bounding box of the set ones).
    out = np.zeros_like(img)
    out[r0:r1, c0:c1] = box[p : p + r1 - r0, p : p + c1 - c0]
    return out


def _line_opening(img: NDArray[np.bool_], size: int, axis: int) -> NDArray[np.bool_]:
    """Opening by a ``size`` line along ``axis`` (1: horizontal, 0: vertical)."""
    ero = np.ones_like(img)
    for k in range(size):
        ero &= _shifted(img, k - size // 2, axis)
    out = np.zeros_like(img)
    for k in range(size):
        out |= _shifted(ero, size // 2 - k, axis)
    return out


class _DavisAreas:
    """Event frames ``(1, 2, H, W)`` (positive, negative counts) -> filtered areas ``(1, 2)``."""

    def __init__(self, params: dict[str, Any], in_shape: tuple[int, ...]) -> None:
        self.params = params
        self.out_shape: tuple[int, ...] = (1, 2)
        self._buf = np.empty(self.out_shape)

    def __call__(self, x: Array) -> Array:
        for i in (0, 1):
            kept = clean_event_frame(x[-1, i] > 0, **self.params)
            self._buf[0, i] = np.count_nonzero(kept)
        return self._buf


#: largest opening / closing element of ``davis_areas`` (px)
MAX_MORPHOLOGY_PX = 32


@register_op("davis_areas")
def _davis_areas(f: Fields, in_shape: tuple[int, ...]) -> Op:
    f.only(("op", "opening_px", "opening_shape", "closing_px", "min_area_px"))
    if len(in_shape) != 4 or in_shape[0] != 1 or in_shape[1] != 2:
        raise f.error(
            "op",
            "needs one event frame of shape (1, 2, height, width) (positive then "
            f"negative event counts per pixel); the step's input is {list(in_shape)}",
        )
    params = {
        "opening_px": f.integer("opening_px", minimum=0, maximum=MAX_MORPHOLOGY_PX),
        "opening_shape": f.string(
            "opening_shape", "square", choices=("square", "lines")
        ),
        "closing_px": f.integer("closing_px", minimum=0, maximum=MAX_MORPHOLOGY_PX),
        "min_area_px": f.integer(
            "min_area_px", minimum=0, maximum=in_shape[2] * in_shape[3]
        ),
    }
    return _DavisAreas(params, in_shape)
