"""CarRacing's 96 x 96 observation from spans, without the 1000 x 800 picture.

Gymnasium's ``CarRacing`` draws a 1000 x 800 picture at every step and shrinks it with
``pygame.transform.smoothscale``; the observation is the shrunk picture. Here the drawing
(``envs.pygame_raster``, pygame's own polygon algorithms) records what it would write as spans,
row by row, and the shrinking is computed row by row from those spans:

- pygame-ce 2.5's ``smoothscale`` (``src_c/transform.c``: ``scalesmooth``) shrinks along x, then
  along y, with the fixed-point box filter of its SSE2 backend (``src_c/simd_transform_sse2.c``:
  ``filter_shrink_X_SSE2``, ``filter_shrink_Y_SSE2``; ARM's NEON backend runs the same code through
  sse2neon). An output pixel is the 16-bit sum of the source pixels wholly inside it, plus the two
  pixels it shares with its neighbours, each weighted ``(4 v * w) >> 16``, times a reciprocal,
  ``>> 16``, saturated (``_mm_mulhi_epu16``, ``_mm_packus_epi16``). ``shrink_schedule`` walks the
  C loop once to find which pixels are shared and with which weights;
- a row is painted in a 1000-pixel buffer (spans in drawing order, blends as pygame blends them);
  two neighbouring pixels can differ only at a span's end, so an output pixel in which no span
  ends between two pixels that differ in the painted row is of one colour, and is copied from a
  palette of rows of one colour, computed once per colour; the others are summed in loops
  of fixed length, blue and red in the 16-bit lanes of one integer, green in another (no lane
  carries: eleven pixels of 255 at most), without a branch that depends on the column: the
  mispredicted branches of a loop of 9 or 10 pixels had cost more than the sums;
- a row whose spans are the previous row's is that row; an anti-aliased edge's pixels that the
  polygon's own fill covers right after are never recorded.

The result is ``np.array_equal`` to smoothscale of pygame's picture (``tests/test_car_racing.py``:
random polygons, random pictures, and the environment side by side with Gymnasium's).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import overload

from envs.pygame_raster import SPAN_BITS, append, blend, draw_polygon, gfx_aapolygon, gfx_filled_polygon, span_record

_FLAGS = {"cache": True, "nogil": True}
_ONE = 0x4000  # the SSE2 filter's unit: a source pixel is 0x4000
_LANE = 0xFFFF
_PALETTE = 64  # colours whose uniform output rows are kept (a frame has about a dozen)
_FEWEST = 9  # whole source pixels of most output pixels from 1000 to 96 (observe: a constant)
_RECENT = 32  # colours whose palette rows are found without the table (a power of two)


def shrink_schedule(source: int, target: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """The SSE2 filter's walk along one axis, as its C loop makes it.

    Returns the reciprocal, and per output pixel the source pixel it shares with the next one
    (its last), that pixel's weight in it (``xcounter``) and the remainder carried into the next
    (``xfrac``). Source pixels between two shared ones are summed whole.
    """
    space = _ONE * source // target  # "must be > 1": a shrink
    reciprocal = (0x40000000 // space) & _LANE  # _mm_set1_epi16 keeps 16 bits
    counter, shared, weights, carried = space, [], [], []
    for position in range(source):
        if counter > _ONE:
            counter -= _ONE
        else:
            fraction = _ONE - counter
            shared.append(position)
            weights.append(counter)
            carried.append(fraction)
            counter = space - fraction
    if len(shared) != target:
        raise ValueError(f"smoothscale's walk from {source} to {target} writes {len(shared)} pixels")
    return tuple([reciprocal] + [np.array(values, dtype=np.int64) for values in (shared, weights, carried)])


@njit(**_FLAGS)
def _spread(pixel):
    """XRGB8888 -> blue, green, red in 16-bit lanes 0, 1, 2 of one integer."""
    pixel = np.int64(pixel)
    return (pixel & 0xFF) | ((pixel & 0xFF00) << 8) | ((pixel & 0xFF0000) << 16)


@njit(**_FLAGS)
def _lane(spread, lane):
    return (spread >> (16 * lane)) & _LANE


@njit(inline="always")
def _output(accumulated, value, weight, reciprocal):
    """One channel of a written pixel: ``mulhi(4 v, w) + acc``, ``mulhi(., recip)``, packus."""
    total = (((4 * value * weight) >> 16) + accumulated) & _LANE
    return min((total * reciprocal) >> 16, 255)


@njit(**_FLAGS)
def _pixel_of(spread, previous, column, sums, x_schedule):
    """One output pixel of ``filter_shrink_X_SSE2`` (spread lanes): ``sums`` of its whole source
    pixels, the carry from ``previous`` (the pixel shared with the output pixel before), and the
    part of ``spread`` (the pixel it shares with the next)."""
    reciprocal, _, weights, carried, _ = x_schedule
    result = 0
    for lane in range(3):
        carry = ((4 * _lane(previous, lane) * carried[column - 1]) >> 16) if column > 0 else 0
        accumulated = (_lane(sums, lane) + carry) & _LANE
        result |= _output(accumulated, _lane(spread, lane), weights[column], reciprocal) << (16 * lane)
    return result


@njit(**_FLAGS)
def _uniform_row(color, x_schedule, out):
    """Every output pixel of a row of one colour (spread)."""
    shared = x_schedule[1]
    spread = _spread(color)
    for column in range(shared.shape[0]):
        whole = shared[column] - (shared[column - 1] + 1 if column > 0 else 0)
        out[column] = _pixel_of(spread, spread, column, spread * whole, x_schedule)


@njit(**_FLAGS)
def _palette_row(color, palette, rows, x_schedule):
    """Which of ``rows`` holds the output pixels of a row of uniform ``color`` (computed when new);
    -1 when the palette is full. ``palette``: its size, then (colour, row) pairs in a table hashed
    by colour, colour -1 for a free slot."""
    slots = (palette.shape[0] - 1) // 2
    slot = (np.int64(color) * 40503) % slots
    for _ in range(slots):
        key = palette[1 + 2 * slot]
        if key == color:
            return palette[2 + 2 * slot]
        if key < 0:
            used = palette[0]
            if used >= rows.shape[0]:
                return -1
            palette[0] = used + 1
            palette[1 + 2 * slot], palette[2 + 2 * slot] = color, used
            _uniform_row(color, x_schedule, rows[used])
            return used
        slot = (slot + 1) % slots
    return -1


@njit(inline="never", **_FLAGS)
def _exact_pixel(row, column, x_schedule):
    """One output pixel of ``filter_shrink_X_SSE2`` from its source pixels, for any column."""
    shared = x_schedule[1]
    first = shared[column - 1] + 1 if column > 0 else 0
    sums = 0
    for x in range(first, shared[column]):
        sums += _spread(row[x])
    previous = _spread(row[first - 1]) if column > 0 else 0
    return _pixel_of(_spread(row[shared[column]]), previous, column, sums, x_schedule)


@njit(inline="always")
def _channel(sums, carry, value, weight, reciprocal):
    """``_output`` of one channel whose carried part is ``carry``."""
    return _output((sums + carry) & _LANE, value, weight, reciprocal)


@njit(inline="always")
def _mixed_pixel(row, first, last, fewest, weight, carried, reciprocal):
    """``_exact_pixel`` of a column past the first, its whole pixels ``first..last - 1`` being
    ``fewest`` or one more: a loop of fixed length and the last pixel masked, so that no branch
    depends on the column (their mispredictions were most of the cost). Blue and red are summed in
    the lanes of one integer, green in another (ten pixels of 255 fit 16 bits)."""
    blue_red, green_sum = 0, 0
    start = np.uint64(first)  # (unsigned indices: no check for negative ones)
    for x in range(start, start + np.uint64(fewest)):
        pixel = np.int64(row[x])
        blue_red += pixel & 0xFF00FF
        green_sum += pixel & 0xFF00
    pixel = np.int64(row[start + np.uint64(fewest)]) * (last - first - fewest)  # (shared, times 0, if not whole)
    blue_red += pixel & 0xFF00FF
    green_sum += pixel & 0xFF00
    value, previous = np.int64(row[np.uint64(last)]), np.int64(row[start - np.uint64(1)])
    blue = _channel(blue_red & _LANE, (4 * (previous & 0xFF) * carried) >> 16, value & 0xFF, weight, reciprocal)
    green = _channel(green_sum >> 8, (4 * ((previous >> 8) & 0xFF) * carried) >> 16, (value >> 8) & 0xFF, weight,
                     reciprocal)
    red = _channel(blue_red >> 16, (4 * ((previous >> 16) & 0xFF) * carried) >> 16, (value >> 16) & 0xFF, weight,
                   reciprocal)
    return blue | (green << 16) | (red << 32)


@njit(inline="always")
def _recent_slot(color):
    """Where ``color`` (24 bits) is kept in the cache of recent colours: Fibonacci hashing, the
    high bits of a 32-bit product. A hash of the low bits had put white with black and blue with
    purple (the dashboard's colours), and missed about once per row."""
    return 2 * (((color * 2654435769) >> 27) & (_RECENT - 1))


@njit(inline="never", **_FLAGS)
def _missed_entry(color, palette, rows, x_schedule, cache):
    """``_palette_row`` for a colour the cache of recent colours lacks, then kept in the cache."""
    entry = _palette_row(color, palette, rows, x_schedule)
    slot = _recent_slot(color)
    cache[slot], cache[slot + 1] = color, entry
    return entry


@njit(inline="always", **_FLAGS)  # (called per record: as a call, 3-6 % of observe's time)
def _unpack(record):
    """(x1, x2, colour, alpha) of ``pygame_raster.span_record``."""
    mask = (1 << SPAN_BITS) - 1
    return record & mask, (record >> SPAN_BITS) & mask, (record >> 28) & 0xFFFFFF, (record >> 20) & 0xFF


def _text_pixel(value):
    """A pixel of the text block: uint32 as it is, a uint8 grey as that byte in each channel."""


@overload(_text_pixel, jit_options=_FLAGS)
def _text_pixel_overload(value):
    if value == types.uint8:
        return lambda value: np.uint32(value) * np.uint32(0x010101)
    return lambda value: value


@njit(**_FLAGS)
def observe(records, counts, background, text, text_x, text_y, x_schedule, y_schedule, work, out):
    """The (rows, columns, RGB) observation of a height x width picture given as span records, the text
    block ``text`` (uint32 pixels, or uint8 greys: ``_text_pixel``) over them at (``text_x``, ``text_y``).

    ``work``: (row buffer uint32 (width), mixed flags bool (columns, then a flag set for good past
    them, padded to a multiple of 8), the same flags as uint64 words (a view), x-shrunk row int64
    (columns), palette int64 (see ``_palette_row``), its rows int64 (entries, columns), a cache of
    recent colours int64 (``_RECENT`` pairs colour, entry), ``_write_row``'s planes uint32 (3, columns),
    the fewest whole source pixels of an output pixel along x).

    Along x (``filter_shrink_X_SSE2``), the flags are read eight at a time: between two flagged
    columns the row is of one colour, and those columns are copied from the palette's row for that
    colour (found in the cache of recent colours first); a flagged one is summed (``_mixed_pixel``).
    Written in one loop: this is the observation's hot path, and the same code as helper functions
    ran 25 % slower. A row's painting and flags are written out here too, not in a helper inlined
    by numba: an inlined function's array arguments are new references, and where its body has
    loops numba does not prune their counts, so each row paid an atomic increment and decrement per
    array (0.9x the time without them). Uniform columns are copied with unsigned indices, which
    need no check for negative ones, so that the copy is vectorised.
    """
    row, mixed, words, shrunk, palette, rows, cache, planes, fewest = work
    height, column_of, columns, width = records.shape[0], x_schedule[4], shrunk.shape[0], row.shape[0]
    x_reciprocal, x_shared, x_weights, x_carried = x_schedule[0], x_schedule[1], x_schedule[2], x_schedule[3]
    reciprocal, shared, weights, carried, _ = y_schedule
    sums = np.zeros(columns, dtype=np.int64)
    output_row = 0
    for y in range(height):
        # a row drawn as the previous one was is the same row: its shrunk pixels are there already
        text_row = text.shape[0] > 0 and text_y <= y <= text_y + text.shape[0]  # (or the row after it)
        same = y > 0 and not text_row and counts[y] == counts[y - 1]  # (the same records, in the same order)
        if same:
            for k in range(counts[y]):
                if records[y, k] != records[y - 1, k]:
                    same = False
                    break
        if not same:  # paint the row's spans over the background, then the text
            row[:] = background  # (a slice's fill: 0.97x observe's time of a loop's here)
            for k in range(counts[y]):
                x1, x2, color, alpha = _unpack(records[y, k])
                if alpha == 255:
                    for x in range(x1, x2 + 1):
                        row[x] = color
                else:
                    at = np.uint64(x1)  # (unsigned: no check for a negative index)
                    row[at] = blend(row[at], color, alpha)
            # flag the output pixels in which two neighbouring source pixels differ: only at a span's
            # end (x1, or x2 + 1), and not where a later span hides it or the colours are the same,
            # which the painted row tells (about 4.6 flagged output pixels per row instead of 7.9)
            for k in range(counts[y]):
                x1, x2, _, _ = _unpack(records[y, k])
                start, end = np.uint64(x1), np.uint64(x2 + 1)  # (unsigned: no checks for negative indices)
                if x1 > 0 and row[start] != row[start - np.uint64(1)]:
                    mixed[np.uint64(column_of[start])] = True  # pixels x1 - 1 and x1 are in the output pixel of x1
                if x2 + 1 < width and row[end] != row[end - np.uint64(1)]:
                    mixed[np.uint64(column_of[end])] = True
            line = y - text_y
            if 0 <= line < text.shape[0]:
                for x in range(max(text_x, 0), min(text_x + text.shape[1], width)):
                    row[x] = _text_pixel(text[line, x - text_x])
                    mixed[column_of[x]] = True
                if text_x + text.shape[1] < width:
                    mixed[column_of[max(text_x + text.shape[1], 0)]] = True
            start = 0
            for index in range(words.shape[0]):
                word = words[index]
                if word == 0:
                    continue
                words[index] = 0
                while word != 0:  # (the flags are bytes 0 or 1: one set bit per flagged column)
                    column = 8 * index + (np.int64(trailing_zeros(word)) >> 3)
                    word &= word - np.uint64(1)
                    if column > start:  # start..column - 1: one colour
                        color = np.int64(row[x_shared[start]])
                        slot = _recent_slot(color)
                        entry = cache[slot + 1]
                        if cache[slot] != color:
                            entry = _missed_entry(color, palette, rows, x_schedule, cache)
                        if entry >= 0:  # (unsigned indices: a copy without negative-index checks, vectorised)
                            for uniform in range(np.uint64(start), np.uint64(column)):
                                shrunk[uniform] = rows[entry, uniform]
                        else:  # the palette is full
                            for uniform in range(start, column):
                                shrunk[uniform] = _exact_pixel(row, uniform, x_schedule)
                    if column == columns:  # the flag past the last column
                        break
                    if column == 0:
                        shrunk[0] = _exact_pixel(row, 0, x_schedule)
                    else:
                        first, last = x_shared[column - 1] + 1, x_shared[column]
                        weight, carry = x_weights[column], x_carried[column - 1]
                        if fewest == _FEWEST:  # (a constant: the summing loop is unrolled)
                            shrunk[column] = _mixed_pixel(row, first, last, _FEWEST, weight, carry, x_reciprocal)
                        else:
                            shrunk[column] = _mixed_pixel(row, first, last, fewest, weight, carry, x_reciprocal)
                    start = column + 1
            mixed[columns] = True
        if output_row < shared.shape[0] and y == shared[output_row]:
            _write_row(shrunk, sums, weights[output_row], carried[output_row], reciprocal, out[output_row], planes)
            output_row += 1
        else:
            for column in range(columns):
                sums[column] += shrunk[column]


@njit(**_FLAGS)
def _write_row(shrunk, sums, weight, carried, reciprocal, out, planes):
    """``filter_shrink_Y_SSE2`` at a shared row: the output row, and the sums restarted with the carry.

    Each channel is computed over the whole row into ``planes`` (uint32 (3, columns)), then the row is
    interleaved into ``out``: loops the compiler vectorises, where stores three bytes apart are not
    (0.67x the time of the same arithmetic written into ``out``). The channels are ``_output``'s
    arithmetic written out in uint32, which vectorises wider: through ``_output`` itself, in int64,
    the same loops took 1.5x as long. Every product fits 32 bits: a pixel's channel is at most 255
    (``4 * 255 * weight < 2**24``), a sum at most ``_LANE`` (``_LANE * reciprocal < 2**32``)."""
    weight4, carried4, scale = np.uint32(4 * weight), np.uint32(4 * carried), np.uint32(reciprocal)
    columns, half, lane_mask = shrunk.shape[0], np.uint32(16), np.uint32(_LANE)
    for lane in range(3):
        for column in range(columns):
            value = np.uint32(_lane(shrunk[column], lane))
            total = (((value * weight4) >> half) + np.uint32(_lane(sums[column], lane))) & lane_mask
            planes[lane, column] = min((total * scale) >> half, np.uint32(255))
    for column in range(columns):
        pixel, remainder = shrunk[column], 0
        for lane in range(3):
            remainder |= np.int64((np.uint32(_lane(pixel, lane)) * carried4) >> half) << (16 * lane)
        sums[column] = remainder
    for column in range(columns):
        out[column, 0], out[column, 1], out[column, 2] = planes[2, column], planes[1, column], planes[0, column]


def full_schedule(source: int, target: int) -> tuple:
    """``shrink_schedule`` plus, per source pixel, the output pixel it is summed into (or shared by)."""
    reciprocal, shared, weights, carried = shrink_schedule(source, target)
    owner = np.searchsorted(shared, np.arange(source), side="left").astype(np.int64)
    return reciprocal, shared, weights, carried, owner


class SpanObservation:
    """Buffers and schedules for one picture size and observation size, reused from step to step."""

    def __init__(self, width: int, height: int, columns: int, rows: int, capacity: int = 48):
        self.size = (width, height)
        self.x_schedule = full_schedule(width, columns)
        self.y_schedule = full_schedule(height, rows)
        self.counts = np.zeros(height, dtype=np.int64)
        if width > 1 << SPAN_BITS:
            raise ValueError(f"span records hold x up to {(1 << SPAN_BITS) - 1}, the picture is {width} wide")
        self.records = np.empty((height, capacity), dtype=np.int64)
        whole = np.diff(self.x_schedule[1], prepend=-1)[1:] - 1  # whole source pixels of columns 1, 2, ...
        if len(whole) and whole.max() - whole.min() > 1:
            raise ValueError(f"smoothscale's walk from {width} to {columns} sums {set(whole.tolist())} whole pixels")
        mixed = np.zeros((columns // 8 + 1) * 8, dtype=np.bool_)
        mixed[columns] = True  # (observe: the end of the last run of uniform columns)
        self._work = (np.empty(width, dtype=np.uint32), mixed, mixed.view(np.uint64), np.empty(columns, dtype=np.int64),
                      np.full(1 + 4 * _PALETTE, -1, dtype=np.int64),  # a table twice the palette's size
                      np.empty((_PALETTE, columns), dtype=np.int64),
                      np.full(2 * _RECENT, -1, dtype=np.int64), np.empty((3, columns), dtype=np.uint32),
                      int(whole.min()) if len(whole) else 0)
        self._work[4][0] = 0
        self._cover = np.empty((3, height), dtype=np.int64)  # record_polygons' scratch: one polygon's fill

    def target(self) -> tuple:
        """An empty span list for ``envs.pygame_raster``'s drawing functions."""
        self.counts[:] = 0
        return (self.records, self.counts, self.size[1], self.size[0])

    def record_polygons(self, target: tuple, flip: bool, *polygons) -> None:
        """``pygame_raster.draw_polygons``'s arguments after the target and flip."""
        record_polygons(target, flip, *polygons, self._cover)

    def overflowed(self) -> bool:
        """True (and the list grown) if the last drawing recorded more spans in a row than it could keep."""
        most = _fullest(self.counts)
        if most <= self.records.shape[1]:
            return False
        self.records = np.empty((self.size[1], 2 * most), dtype=np.int64)
        return True

    def observe(self, background: int, text: np.ndarray, text_x: int, text_y: int) -> np.ndarray:
        out = np.empty((len(self.y_schedule[1]), len(self.x_schedule[1]), 3), dtype=np.uint8)
        observe(self.records, self.counts, background, text, text_x, text_y, self.x_schedule, self.y_schedule,
                self._work, out)
        return out


@njit(**_FLAGS)
def _fullest(counts) -> int:
    """``counts.max()``: compiled, it costs a few microseconds inside the training loop, where numpy's
    reduction of 800 integers cost 25."""
    return counts.max()


@njit(**_FLAGS)
def record_polygons(spans, flip, xs, ys, starts, colors, antialiased, cover):
    """``pygame_raster.draw_polygons`` into a span list, less what cannot show.

    An anti-aliased polygon's edge pixels that its own fill, drawn right after them, covers are
    never seen. The fill is drawn first into ``cover`` (int64 (3, height): per row the last span's
    x1 and x2 and how many spans; ``pygame_raster``'s cover target); where it has at most one span
    per row, those spans are the cover behind which the edge is drawn, which leaves those pixels
    out, and then they are recorded. Otherwise the edge and the fill are recorded in order, and the
    hidden pixels removed (``_drop_covered``). A row whose last record is then an opaque span over
    the whole width keeps only that one (``_keep_whole_rows``).
    """
    records, counts, height, width = spans
    for k in range(colors.shape[0]):
        polygon_xs, polygon_ys = xs[starts[k]:starts[k + 1]], ys[starts[k]:starts[k + 1]]
        low, high = max(polygon_ys.min() - 1, 0), min(polygon_ys.max() + 1, height - 1)  # the edge's rows
        if flip:  # the rows of the records
            low, high = height - 1 - high, height - 1 - low
        if not antialiased[k]:
            draw_polygon(spans, flip, polygon_xs, polygon_ys, colors[k])
        elif low <= high:
            _record_antialiased(spans, flip, polygon_xs, polygon_ys, colors[k], low, high, cover)
        _keep_whole_rows(records, counts, low, high, width)


@njit(inline="always", **_FLAGS)
def _record_antialiased(spans, flip, xs, ys, color, low, high, cover):
    """One anti-aliased polygon whose edge touches rows low..high of the records (``record_polygons``)."""
    records, counts, height, width = spans
    cover[2, low:high + 1] = 0
    gfx_filled_polygon((cover, height, width), flip, xs, ys, color)
    if cover[2, low:high + 1].max() <= 1:
        for row in range(low, high + 1):
            if cover[2, row] == 0:  # (an empty row covers nothing)
                cover[0, row], cover[1, row] = width, -1
        gfx_aapolygon((records, counts, height, width, cover), flip, xs, ys, color)
        for row in range(low, high + 1):
            if cover[2, row]:
                append(records, counts, row, span_record(cover[0, row], cover[1, row], color, 255))
        return
    before, between = cover[0], cover[1]  # (the cover's rows, unused on this path, as scratch)
    before[low:high + 1] = counts[low:high + 1]
    gfx_aapolygon(spans, flip, xs, ys, color)
    between[low:high + 1] = counts[low:high + 1]
    gfx_filled_polygon(spans, flip, xs, ys, color)
    for row in range(low, high + 1):
        _drop_covered(records, counts, row, before[row], between[row])


@njit(**_FLAGS)
def _keep_whole_rows(records, counts, low, high, width):
    """Rows low..high whose last record is an opaque span over the whole width keep only that
    record: it hides everything recorded before it in its row. (The dashboard's black bar hides the
    world in the picture's last 100 rows: they then hold the bar and the indicators, and most of
    them are the row above, which ``observe`` does not compute again.)"""
    for row in range(low, high + 1):
        last = counts[row] - 1
        if 0 < last < records.shape[1]:
            x1, x2, _, alpha = _unpack(records[row, last])
            if x1 == 0 and x2 == width - 1 and alpha == 255:
                records[row, 0] = records[row, last]
                counts[row] = 1


@njit(**_FLAGS)
def _drop_covered(records, counts, row, first, fills):
    """Remove row ``row``'s records first..fills - 1 (edge pixels) that lie inside one of the
    records fills..counts[row] - 1 (the polygon's own fill, opaque, drawn after them)."""
    end = min(counts[row], records.shape[1])
    if fills >= end or first >= fills:
        return
    kept = first
    for index in range(first, end):
        x1, x2, _, _ = _unpack(records[row, index])
        covered = False
        if index < fills:
            for fill in range(fills, end):
                fill_x1, fill_x2, _, _ = _unpack(records[row, fill])
                if fill_x1 <= x1 and x2 <= fill_x2:
                    covered = True
                    break
        if not covered:
            records[row, kept] = records[row, index]
            kept += 1
    counts[row] = kept + (counts[row] - end)  # (past the capacity: still counted)
