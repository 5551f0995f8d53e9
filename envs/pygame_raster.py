"""pygame-ce's polygon drawing, reproduced pixel for pixel in numba, for the fast CarRacing.

CarRacing draws its picture with three pygame-ce 2.5 functions; this module computes the same
pixels with the same integer and float32 arithmetic, without crossing the interpreter per polygon:

- ``pygame.gfxdraw.filled_polygon``: SDL_gfx's ``filledPolygonColorMT`` (``src_c/SDL_gfx/
  SDL_gfxPrimitives.c``), a scanline fill whose crossings are 16.16 fixed point;
- ``pygame.gfxdraw.aapolygon``: SDL_gfx's ``aapolygonColor``, one ``_aalineColor`` per edge: the line
  clipped to the surface (``_clipLine``, float32 slopes), then Wu's algorithm, each pixel blended
  by ``_putPixelAlpha`` (the ``DEFAULT_ALPHA_PIXEL_ROUTINE``, 32-bit unsigned arithmetic);
- ``pygame.draw.polygon`` (filled): pygame's ``draw_fillpoly`` (``src_c/draw.c``), a scanline fill
  with float32 crossings and a second pass for horizontal edges.

Pixels are written into a (height, width) uint32 array of an XRGB8888 surface (a no-alpha 32-bit
surface, the kind ``pygame.Surface((w, h))`` makes), with the surface as the clipping rectangle;
``flip`` writes row ``height - 1 - y`` instead of ``y``, which is ``pygame.transform.flip(surface,
False, True)`` of what pygame would have drawn. Vertices are the integers pygame makes of float
coordinates (truncation), and must lie within +-16383 so that no 32-bit intermediate overflows;
colours are mapped pixel values. No ``fastmath``: float32 operations must round as pygame's do.
``tests/test_car_racing.py`` compares every function with pygame itself on random polygons.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import overload

_FLAGS = {"cache": True, "nogil": True}
_U32 = 0xFFFFFFFF
_RED, _GREEN, _BLUE = 0xFF0000, 0x00FF00, 0x0000FF
LARGEST_COORDINATE = 16383  # 65536 * (x2 - x1) stays within a C int


@njit(**_FLAGS)
def _row(height, flip, y):
    return height - 1 - y if flip else y


@njit(**_FLAGS)
def _blend_channel(old, new, mask, shift, alpha):
    """One channel of SDL_gfx's ``_putPixelAlpha`` on a 32-bit surface, unsigned wrap-around included."""
    difference = ((new & mask) - (old & mask)) & _U32
    change = ((((difference >> shift) * alpha) & _U32) >> 8 << shift) & _U32
    return ((old & mask) + change) & mask


@njit(**_FLAGS)
def _blend_pixel(pixels, flip, x, y, color, alpha):
    """``_putPixelAlpha``: clipped; written as is at alpha 255, blended below (the surface has no alpha)."""
    height, width = _size(pixels)
    if x < 0 or x >= width or y < 0 or y >= height:
        return
    if alpha == 255:
        _put_span(pixels, flip, y, x, x, color)
    else:
        _put_blend(pixels, flip, x, y, color, alpha)


@njit(**_FLAGS)
def blend(old, color, alpha):
    """The pixel ``_putPixelAlpha`` makes of ``old`` under ``color`` at ``alpha`` < 255."""
    old = np.int64(old)
    return (_blend_channel(old, color, _RED, 16, alpha) | _blend_channel(old, color, _GREEN, 8, alpha)
            | _blend_channel(old, color, _BLUE, 0, alpha))


# --- the targets -------------------------------------------------------------------------------
# A target is one of:
# - a (height, width) uint32 array of pixels, written at once;
# - a span list ``(records, counts, height, width)``: row y's writes, in order, are
#   ``records[y, :counts[y]]``, each one int64 (``span_record``; width at most 1024, colours of 24
#   bits). Past a row's capacity writes are counted, not stored, so that the caller can grow the
#   list and draw again;
# - a span list behind a cover ``(records, counts, height, width, cover)``: the same, less the
#   writes that lie wholly within ``cover[0, y]..cover[1, y]`` (int64, (3, height)), which the caller
#   knows an opaque span it records after them hides;
# - a cover ``(cover, height, width)``: row y's last write is ``cover[0, y]..cover[1, y]`` and
#   ``cover[2, y]`` counts the writes (opaque spans only: what a fill makes).
# The drawing code is the same for all.

SPAN_BITS = 10  # bits of x1 and of x2 in a span record


@njit(**_FLAGS)
def span_record(x1, x2, color, alpha):
    """One span in an int64: x1 and x2 (10 bits each), alpha (8 bits, 255: opaque), colour (24 bits)."""
    return np.int64(x1) | (np.int64(x2) << 10) | (np.int64(alpha) << 20) | ((np.int64(color) & 0xFFFFFF) << 28)


def _size(target):
    """(height, width) of a target."""


def _put_span(target, flip, y, x1, x2, color):
    """Opaque pixels x1..x2 (clipped, ordered) of row y."""


def _put_blend(target, flip, x, y, color, alpha):
    """One pixel (clipped) blended at alpha < 255."""


def _put_record(target, row, x1, x2, color, alpha):
    """A write into row ``row`` of a span list (with or without a cover) or of a cover."""


@overload(_size, jit_options=_FLAGS)
def _size_overload(target):
    if isinstance(target, types.Array):
        return lambda target: (target.shape[0], target.shape[1])
    if len(target) == 3:
        return lambda target: (target[1], target[2])
    return lambda target: (target[2], target[3])


@overload(_put_span, jit_options=_FLAGS)
def _put_span_overload(target, flip, y, x1, x2, color):
    if isinstance(target, types.Array):
        def write(target, flip, y, x1, x2, color):
            target[_row(target.shape[0], flip, y), x1:x2 + 1] = color
        return write

    def record(target, flip, y, x1, x2, color):
        _put_record(target, _row(_size(target)[0], flip, y), x1, x2, color, 255)
    return record


@overload(_put_blend, jit_options=_FLAGS)
def _put_blend_overload(target, flip, x, y, color, alpha):
    if isinstance(target, types.Array):
        def write(target, flip, x, y, color, alpha):
            row = _row(target.shape[0], flip, y)
            target[row, x] = blend(target[row, x], color, alpha)
        return write

    def record(target, flip, x, y, color, alpha):
        _put_record(target, _row(_size(target)[0], flip, y), x, x, color, alpha)
    return record


@overload(_put_record, jit_options=_FLAGS)
def _put_record_overload(target, row, x1, x2, color, alpha):
    if len(target) == 3:
        return lambda target, row, x1, x2, color, alpha: _cover(target[0], row, x1, x2)
    if len(target) == 5:
        return lambda target, row, x1, x2, color, alpha: _record_behind(target[0], target[1], target[4], row, x1,
                                                                        x2, color, alpha)
    return lambda target, row, x1, x2, color, alpha: _record(target[0], target[1], row, x1, x2, color, alpha)


@njit(**_FLAGS)
def _record(records, counts, row, x1, x2, color, alpha):
    append(records, counts, row, span_record(x1, x2, color, alpha))


@njit(**_FLAGS)
def append(records, counts, row, record, counted=1):
    """Add ``record`` to row ``row`` of a span list (past its capacity, only counted); with
    ``counted`` 0 it is written where the next record will overwrite it, and not counted."""
    index = counts[row]
    counts[row] = index + counted
    if index < records.shape[1]:
        records[row, index] = record


@njit(**_FLAGS)
def _cover(cover, row, x1, x2):
    """A span into a cover: the row's last span, and one more counted."""
    cover[0, row], cover[1, row] = x1, x2
    cover[2, row] += 1


@njit(**_FLAGS)
def _record_behind(records, counts, cover, row, x1, x2, color, alpha):
    """``_record`` unless ``cover`` holds x1..x2 in this row. Without a branch on that: an early
    return here keeps LLVM from inlining the drawing's calls, which then cost ten times as much."""
    hidden = (cover[0, row] <= x1) & (x2 <= cover[1, row])
    append(records, counts, row, span_record(x1, x2, color, alpha), 1 - hidden)


@njit(**_FLAGS)
def _gfx_hline(pixels, flip, x1, x2, y, color):
    """SDL_gfx's ``hlineColor`` at alpha 255: ends in either order, both included, clipped."""
    if x1 > x2:
        x1, x2 = x2, x1
    height, width = _size(pixels)
    if x2 < 0 or x1 > width - 1 or y < 0 or y > height - 1:
        return
    _put_span(pixels, flip, y, max(x1, 0), min(x2, width - 1), color)


@njit(**_FLAGS)
def _gfx_vline(pixels, flip, x, y1, y2, color):
    """SDL_gfx's ``vlineColor`` at alpha 255."""
    if y1 > y2:
        y1, y2 = y2, y1
    height, width = _size(pixels)
    if x < 0 or x > width - 1 or y2 < 0 or y1 > height - 1:
        return
    for y in range(max(y1, 0), min(y2, height - 1) + 1):
        _put_span(pixels, flip, y, x, x, color)


@njit(**_FLAGS)
def _sort(values, count):
    """Sort ``values[:count]`` in place (a handful of crossings: insertion sort, no allocation)."""
    for i in range(1, count):
        value, j = values[i], i - 1
        while j >= 0 and values[j] > value:
            values[j + 1] = values[j]
            j -= 1
        values[j + 1] = value


@njit(**_FLAGS)
def _row_crossings(xs, ys, y, high, crossings):
    """Where row ``y`` crosses the polygon's edges in pygame's ``draw_fillpoly``, sorted, in
    ``crossings``; their number.

    Both scanline fills (this and SDL_gfx's, ``gfx_filled_polygon``) take an edge from its upper
    corner, skip horizontal ones, count an edge for y1 <= y < y2 and, on the last row, for y == y2.
    pygame divides in float32 and rounds alternately down and up.
    """
    found = 0
    for i in range(xs.shape[0]):
        previous = xs.shape[0] - 1 if i == 0 else i - 1
        x1, y1, x2, y2 = xs[previous], ys[previous], xs[i], ys[i]
        if y1 > y2:
            x1, y1, x2, y2 = x2, y2, x1, y1
        if y1 == y2 or not ((y1 <= y < y2) or (y == high and y == y2)):
            continue
        crossing = np.float32((y - y1) * (x2 - x1)) / np.float32(y2 - y1)
        crossings[found] = (math.floor(crossing) if found % 2 == 0 else math.ceil(crossing)) + x1
        found += 1
    _sort(crossings, found)
    return found


@njit(**_FLAGS)
def gfx_filled_polygon(pixels, flip, xs, ys, color):
    """``pygame.gfxdraw.filled_polygon`` (SDL_gfx ``filledPolygonColorMT``) of integer vertices.

    Its edges are counted on the rows ``_row_crossings`` says, and SDL_gfx computes each crossing in
    16.16 fixed point as ``(65536 (y - y1)) / (y2 - y1) * (x2 - x1) + 65536 x1``; here each edge
    walks its rows carrying that quotient and its remainder (adding ``65536 // d`` and
    ``65536 % d``): the same integers without a division per row. The crossings are gathered edge
    by edge, then each row's are sorted and filled between, as SDL_gfx does row by row.
    """
    count = xs.shape[0]
    low, high = ys.min(), ys.max()
    first, last = max(low, 0), min(high, _size(pixels)[0] - 1)
    if first > last:
        return  # rows off the surface draw nothing: they are not scanned
    crossings = np.empty((last - first + 1, count), dtype=np.int64)  # per row from ``first``
    found = np.zeros(last - first + 1, dtype=np.int64)
    for i in range(count):  # each edge from its upper corner, over the rows it is counted on
        previous = count - 1 if i == 0 else i - 1
        x1, y1, x2, y2 = xs[previous], ys[previous], xs[i], ys[i]
        if y1 > y2:
            x1, y1, x2, y2 = x2, y2, x1, y1
        if y1 == y2:
            continue
        start, stop = max(y1, first), min(y2 if y2 == high else y2 - 1, last)
        origin, run, rise = 65536 * x1, x2 - x1, y2 - y1
        quotient, remainder = divmod(65536 * (start - y1), rise)
        step, carry = divmod(65536, rise)
        for y in range(start - first, stop - first + 1):
            crossings[y, found[y]] = quotient * run + origin
            found[y] += 1
            remainder += carry
            wraps = remainder >= rise  # (no branch: it would be mispredicted)
            quotient += step + wraps
            remainder -= rise * wraps
    for y in range(last - first + 1):
        row = crossings[y]
        if found[y] == 2:  # a convex polygon's row
            left, right = row[0], row[1]
            row[0], row[1] = min(left, right), max(left, right)
        else:
            _sort(row, found[y])
        for i in range(0, found[y] - 1, 2):
            left = row[i] + 1
            left = (left >> 16) + ((left & 32768) >> 15)
            right = row[i + 1] - 1
            right = (right >> 16) + ((right & 32768) >> 15)
            _gfx_hline(pixels, flip, left, right, first + y, color)


@njit(**_FLAGS)
def _outcode(x, y, right, bottom):
    code = 0
    if x < 0:
        code |= 1
    elif x > right:
        code |= 2
    if y < 0:
        code |= 8
    elif y > bottom:
        code |= 4
    return code


@njit(**_FLAGS)
def _short(value):
    """C's conversion of an int to Sint16 (two's complement wrap)."""
    return ((value + 32768) & 0xFFFF) - 32768


@njit(**_FLAGS)
def _clip_line(x1, y1, x2, y2, right, bottom):
    """SDL_gfx's ``_clipLine`` (Cohen-Sutherland with a float32 slope): (draw, x1, y1, x2, y2)."""
    while True:
        code1 = _outcode(x1, y1, right, bottom)
        code2 = _outcode(x2, y2, right, bottom)
        if code1 | code2 == 0:
            return True, x1, y1, x2, y2
        if code1 & code2:
            return False, x1, y1, x2, y2
        if code1 == 0:
            x1, y1, x2, y2, code1 = x2, y2, x1, y1, code2
        slope = np.float32(y2 - y1) / np.float32(x2 - x1) if x2 != x1 else np.float32(1.0)
        if code1 & 1:
            y1, x1 = _short(y1 + int(np.float32(0 - x1) * slope)), 0
        elif code1 & 2:
            y1, x1 = _short(y1 + int(np.float32(right - x1) * slope)), right
        elif code1 & 4:
            if x2 != x1:
                x1 = _short(x1 + int(np.float32(bottom - y1) / slope))
            y1 = bottom
        elif code1 & 8:
            if x2 != x1:
                x1 = _short(x1 + int(np.float32(0 - y1) / slope))
            y1 = 0


@njit(**_FLAGS)
def _gfx_aaline(pixels, flip, x1, y1, x2, y2, color):
    """SDL_gfx's ``_aalineColor`` without its end point, at alpha 255 (``color``: a mapped pixel)."""
    height, width = _size(pixels)
    draw, x1, y1, x2, y2 = _clip_line(x1, y1, x2, y2, width - 1, height - 1)
    if not draw:
        return
    x0, y0, x_end, y_end = x1, y1, x2, y2
    if y0 > y_end:
        x0, y0, x_end, y_end = x2, y2, x1, y1
    dx, dy = x_end - x0, y_end - y0
    if dx == 0:
        if dy > 0:
            _gfx_vline(pixels, flip, x1, y0, y0 + dy, color)
        else:
            _blend_pixel(pixels, flip, x1, y1, color, 255)
        return
    if dy == 0:
        _gfx_hline(pixels, flip, x0, x0 + dx, y1, color)
        return
    step = 1
    if dx < 0:
        step, dx = -1, -dx
    _blend_pixel(pixels, flip, x1, y1, color, 255)
    error = 0
    if dy > dx:  # y-major: y advances every pixel, x when the 32-bit error accumulator wraps
        adjust = (((dx << 16) // dy) << 16) & _U32
        x_next = x0 + step
        for _ in range(dy - 1):
            previous, error = error, (error + adjust) & _U32
            if error <= previous:
                x0, x_next = x_next, x_next + step
            y0 += 1
            weight = (error >> 24) & 255
            _blend_pixel(pixels, flip, x0, y0, color, (255 * (255 - weight)) >> 8)
            _blend_pixel(pixels, flip, x_next, y0, color, (255 * weight) >> 8)
    else:  # x-major
        adjust = (((dy << 16) // dx) << 16) & _U32
        y_next = y0 + 1
        for _ in range(dx - 1):
            previous, error = error, (error + adjust) & _U32
            if error <= previous:
                y0, y_next = y_next, y_next + 1
            x0 += step
            weight = (error >> 24) & 255
            _blend_pixel(pixels, flip, x0, y0, color, (255 * (255 - weight)) >> 8)
            _blend_pixel(pixels, flip, x0, y_next, color, (255 * weight) >> 8)


@njit(**_FLAGS)
def gfx_aapolygon(pixels, flip, xs, ys, color):
    """``pygame.gfxdraw.aapolygon``: each edge in order, the closing one last."""
    count = xs.shape[0]
    for i in range(1, count):
        _gfx_aaline(pixels, flip, xs[i - 1], ys[i - 1], xs[i], ys[i], color)
    _gfx_aaline(pixels, flip, xs[count - 1], ys[count - 1], xs[0], ys[0], color)


@njit(**_FLAGS)
def _draw_hline(pixels, flip, x1, y, x2, color):
    """pygame's ``drawhorzlineclipbounding``."""
    height, width = _size(pixels)
    if y < 0 or y >= height:
        return
    if x2 < x1:
        x1, x2 = x2, x1
    x1, x2 = max(x1, 0), min(x2, width - 1)
    if x2 < 0 or x1 >= width:
        return
    _put_span(pixels, flip, y, x1, x2, color)


@njit(**_FLAGS)
def draw_polygon(pixels, flip, xs, ys, color):
    """``pygame.draw.polygon`` filled, of four or more integer vertices (pygame's ``draw_fillpoly``)."""
    count = xs.shape[0]
    low, high = ys.min(), ys.max()
    if low == high:
        _draw_hline(pixels, flip, xs.min(), low, xs.max(), color)
        return
    crossings = np.empty(count, dtype=np.int64)
    for y in range(max(low, 0), min(high, _size(pixels)[0] - 1) + 1):
        found = _row_crossings(xs, ys, y, high, crossings)
        for i in range(0, found - 1, 2):
            _draw_hline(pixels, flip, crossings[i], y, crossings[i + 1], color)
    for i in range(count):
        previous = count - 1 if i == 0 else i - 1
        y = ys[i]
        if low < y < high and ys[previous] == y:
            _draw_hline(pixels, flip, xs[i], y, xs[previous], color)


@njit(**_FLAGS)
def draw_polygons(pixels, flip, xs, ys, starts, colors, antialiased):
    """Polygons in order, polygon ``k`` being ``xs[starts[k]:starts[k + 1]]`` (and ``ys``):
    ``gfxdraw.aapolygon`` then ``gfxdraw.filled_polygon`` where ``antialiased[k]`` (road, grass),
    else ``draw.polygon`` (the car)."""
    for k in range(colors.shape[0]):
        polygon_xs, polygon_ys = xs[starts[k]:starts[k + 1]], ys[starts[k]:starts[k + 1]]
        if antialiased[k]:
            gfx_aapolygon(pixels, flip, polygon_xs, polygon_ys, colors[k])
            gfx_filled_polygon(pixels, flip, polygon_xs, polygon_ys, colors[k])
        else:
            draw_polygon(pixels, flip, polygon_xs, polygon_ys, colors[k])
