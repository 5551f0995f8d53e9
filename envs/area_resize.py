"""OpenCV's ``cv2.resize(frame, size, interpolation=cv2.INTER_AREA)`` of a uint8 RGB frame, value for value,
compiled and fused with the pixel policy's conversion to float32 planes.

A downscale by a factor that is not a whole number on both axes (CarRacing's 96 x 96 to 84 x 84) takes
OpenCV's general area path (``modules/imgproc/src/resize.cpp``): ``computeResizeAreaTab`` lists, per
output column, the source columns it covers and their float32 weights (computed in double, the first
and last partial); ``ResizeArea_Invoker`` sums each source row over those columns in float32, then the
rows of each output row, and rounds half to even into uint8. This module builds the same tables once per
shape and sums in the same order, with each column's and row's terms padded to a fixed count by terms
of weight 0: a pixel times 0 is +0, and a non-negative float32 plus +0 is itself, so the sums keep
their bits. Each source row is summed across once, where OpenCV sums it again for every output row it
touches; the sums are the same. Along a row, outputs whose terms read consecutive source values (from
96 to 84, stretches of 7 pixels: 21 values) are summed a stretch at a time, which vectorises where a
gathered load per term did not (a CarRacing frame's resize 118 -> 81 us here); with two terms per output,
both in one loop, and the planes written four rows at a time (81 -> 54 us).

``PixelObservation`` uses it where it applies (``takes_area_path``) and ``cv2.resize`` otherwise.
No ``fastmath``: the sums must round as OpenCV's do. ``tests/test_area_resize.py`` compares it with
``cv2.resize`` on CarRacing's frames and random images of many shapes.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit


def _scale(source: int, size: int) -> float:
    return 1.0 / (size / source)  # OpenCV's scale_x = 1./inv_scale_x, inv_scale_x = (double)dsize/ssize


def takes_area_path(source: tuple[int, int], size: tuple[int, int]) -> bool:
    """Whether OpenCV's INTER_AREA resizes ``source`` (height, width) to ``size`` (height, width)
    through the area tables: a downscale on both axes (an upscale is a bilinear variant) whose factors
    are not both whole numbers (``resizeAreaFast``), as ``cv::resize`` decides it."""
    if min(*source, *size) < 1:
        return False  # nothing to resize: OpenCV's own error
    scales = [_scale(source[axis], size[axis]) for axis in (0, 1)]
    if min(scales) < 1.0:
        return False
    return not all(abs(scale - round(scale)) < np.finfo(np.float64).eps for scale in scales)


def _area_terms(source: int, size: int) -> list[tuple[int, int, np.float32]]:
    """``computeResizeAreaTab`` for one channel: (output index, source index, weight) in OpenCV's order."""
    scale = _scale(source, size)
    terms = []
    for out in range(size):
        start = out * scale
        end = start + scale
        cell = min(scale, source - start)
        first, last = math.ceil(start), math.floor(end)
        last = min(last, source - 1)
        first = min(first, last)
        if first - start > 1e-3:
            terms.append((out, first - 1, np.float32((first - start) / cell)))
        terms.extend((out, index, np.float32(1.0 / cell)) for index in range(first, last))
        if end - last > 1e-3:
            terms.append((out, last, np.float32(min(min(end - last, 1.0), cell) / cell)))
    return terms


def _padded(terms: list[tuple[int, int, np.float32]], size: int, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """The terms as (count, size * channels) indices and weights into a row of ``channels``-interleaved
    values, each output's in OpenCV's order, padded with terms of weight 0."""
    per_output: list[list[tuple[int, np.float32]]] = [[] for _ in range(size)]
    for out, index, weight in terms:
        per_output[out].append((index, weight))
    count = max(len(entries) for entries in per_output)
    indices = np.empty((count, size), dtype=np.int64)
    weights = np.zeros((count, size), dtype=np.float32)
    for out, entries in enumerate(per_output):
        for term, (index, weight) in enumerate(entries):
            indices[term, out], weights[term, out] = index, weight
        indices[len(entries):, out] = entries[-1][0]  # any pixel of the row: its weight is 0
    channel = np.arange(channels)
    return ((indices[:, :, None] * channels + channel).reshape(count, size * channels),
            np.repeat(weights, channels, axis=1))


def _stretches(indices: np.ndarray) -> np.ndarray:
    """(first output, length) of each maximal stretch of outputs along which every term's source index
    steps by one, from (terms, outputs) indices."""
    steps = np.all(np.diff(indices, axis=1) == 1, axis=0)  # between output i and i + 1
    breaks = np.flatnonzero(~steps) + 1
    starts = np.concatenate([[0], breaks])
    return np.stack([starts, np.diff(np.append(starts, indices.shape[1]))], axis=1).astype(np.int64)


@functools.lru_cache(maxsize=8)
def area_tables(source: tuple[int, int], size: tuple[int, int], channels: int) -> tuple[np.ndarray, ...]:
    """(column indices, column weights, their stretches, row indices, row weights) of a resize of a
    ``channels``-channel frame from ``source`` to ``size`` (both (height, width)), for ``area_planes``."""
    (height, width), (out_height, out_width) = source, size
    row_indices, row_weights = _padded(_area_terms(height, out_height), out_height, 1)
    columns, column_weights = _padded(_area_terms(width, out_width), out_width, channels)
    tables = (columns, column_weights, _stretches(columns), row_indices, row_weights)
    for table in tables:
        table.flags.writeable = False
    return tables


class AreaResize:
    """``cv2.resize(frame, size, interpolation=cv2.INTER_AREA)`` of uint8 frames of one shape, as the
    float32 planes (C, width, height) of ``swapaxes(resized / 255.0, 0, 2)``; the scratch is its own."""

    def __init__(self, shape: tuple[int, int, int], size: tuple[int, int]):
        height, width, channels = shape
        self.shape, self.size = shape, size
        self._tables = area_tables((height, width), size, channels)
        self._across = np.empty((height, size[1] * channels), dtype=np.float32)
        self._rows = np.empty((size[0], size[1] * channels), dtype=np.float32)

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        height, width, channels = self.shape
        out = np.empty((channels, self.size[1], self.size[0]), dtype=np.float32)
        flat = np.ascontiguousarray(frame).reshape(height, width * channels)
        area_planes(flat, *self._tables, self._across, self._rows, out)
        return out


@njit(cache=True, nogil=True)
def area_planes(frame, columns, column_weights, stretches, rows, row_weights, across, resized, out) -> None:
    """out[c, x, y] = float32(``cv2.resize(frame, INTER_AREA)[y, x, c]``) / 255 for a frame of (H, W * C)
    uint8 and out (C, w, h); scratch: across (H, w * C), each source row summed across, and resized
    (h, w * C).

    Where every output has two terms (a downscale by less than 2, as CarRacing's), both are summed in
    one loop, ``(0 + first) + second``: OpenCV's two steps from a sum of 0, rounded as it rounds them,
    in 0.6x the time of a loop per term. The planes are written four output rows at a time, so that
    each write into a plane is four consecutive floats (0.5x the time of one at a time)."""
    zero = np.float32(0.0)
    for source_row in range(frame.shape[0]):
        pixels, sums = frame[source_row], across[source_row]
        for stretch in range(stretches.shape[0]):
            first, length = stretches[stretch, 0], stretches[stretch, 1]
            part = sums[first:first + length]
            if columns.shape[0] == 2:
                one, two = pixels[columns[0, first]:], pixels[columns[1, first]:]
                weights_one = column_weights[0, first:first + length]
                weights_two = column_weights[1, first:first + length]
                for index in range(length):
                    part[index] = ((zero + np.float32(one[index]) * weights_one[index])
                                   + np.float32(two[index]) * weights_two[index])
                continue
            part[:] = zero
            for term in range(columns.shape[0]):  # OpenCV's order: buf[dx] += S[sx] * alpha, term by term
                start, weights = columns[term, first], column_weights[term, first:first + length]
                source = pixels[start:start + length]
                for index in range(length):
                    part[index] += np.float32(source[index]) * weights[index]
    for y in range(rows.shape[1]):
        sums = resized[y]
        if rows.shape[0] == 2:
            weight_one, one = row_weights[0, y], across[rows[0, y]]
            weight_two, two = row_weights[1, y], across[rows[1, y]]
            for index in range(sums.size):
                sums[index] = (zero + weight_one * one[index]) + weight_two * two[index]
        else:
            sums[:] = zero
            for term in range(rows.shape[0]):  # sum += beta * buf, row by row
                weight, summed = row_weights[term, y], across[rows[term, y]]
                for index in range(sums.size):
                    sums[index] += weight * summed[index]
        for index in range(sums.size):  # saturate_cast<uchar>: cvRound, clamped; then numpy's uint8 / 255.0
            sums[index] = min(max(np.rint(sums[index]), zero), np.float32(255.0)) / np.float32(255.0)
    channels, height = out.shape[0], out.shape[2]
    whole = height - height % 4
    for y in range(0, whole, 4):
        first, second, third, fourth = resized[y], resized[y + 1], resized[y + 2], resized[y + 3]
        for x in range(out.shape[1]):
            for channel in range(channels):
                index, plane = x * channels + channel, out[channel, x]
                plane[y], plane[y + 1] = first[index], second[index]
                plane[y + 2], plane[y + 3] = third[index], fourth[index]
    for channel in range(channels):
        for x in range(out.shape[1]):
            for y in range(whole, height):
                out[channel, x, y] = resized[y, x * channels + channel]
