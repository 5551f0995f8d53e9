"""CarRacing whose frames are Gymnasium's, bit for bit, computed several times faster.

Gymnasium's ``CarRacing`` (O. Klimov; ``gymnasium/envs/box2d/car_racing.py``, v3) draws the whole
picture at every step, because the observation is that picture. Most of its time goes to
``_render_road``: about 800 road and grass polygons are rotated vertex by vertex with
``pygame.math.Vector2.rotate_rad``, tested for visibility in Python, and about 60 of them drawn.
``FastCarRacing`` keeps the physics, the track generation and their random-number use (it changes
none of their numbers) and computes the same picture with less work:

- the car's ``gas`` and ``step`` run ``Car``'s arithmetic without numpy's scalar functions
  (``_Car``, the same double operations in the same order);
- the polygons are transformed in numpy with pygame's own arithmetic (``rotate_like_pygame``), so
  every vertex is the same double as pygame's, and culled with the same inclusive bounds; those
  that pass that generous test but lie wholly beyond one side of the screen are not drawn (pygame
  would clip every one of their pixels away);
- the playfield polygon, when it covers the screen with its edges out of sight, is a fill of the
  pixel pygame would write;
- for observations (``state_pixels``), no picture is drawn: the road, the grass, the
  car and the dashboard are recorded as spans by ``envs.pygame_raster`` (pygame's own polygon
  algorithms compiled with numba) in the stock order, flipped as the stock flips its picture, the
  score's pixels are those its blit writes, and ``envs.car_racing_observation`` computes
  ``smoothscale``'s 96 x 96 result from the spans; the car's corners come from Box2D's transform
  computed in float32 as Box2D does (``box2d_transform``). ``self.surf`` is then not updated;
- per frame, the culling, the car's corners (``_car_screen``), the playfield test and the arrays
  handed to the drawing are one numba call (``_scene``), with the same double and float32
  operations;
- where ``smoothscale``'s backend is not SSE2 or NEON, the world is drawn by the same compiled
  functions straight into the flipped frame, the dashboard and score by pygame, and the picture
  shrunk by ``smoothscale`` itself;
- video frames (``rgb_array``, ``human``), which also draw the skid marks, and any frame the
  compiled drawing cannot promise to reproduce (a coordinate beyond +-16383, a colour that is not
  plain RGB, a surface that is not 32-bit XRGB), go through pygame's own drawing calls, fewer of
  them, on reused surfaces;
- the font and the rendered score text are made once instead of at every frame;
- resets generate the stock track (same doubles, same random draws, same bodies in the same order)
  with its loops compiled by numba and the tile bodies made with fewer wrapper calls
  (``envs.car_racing_track``).

Observations and ``render()`` frames are ``np.array_equal`` to the stock class's:
``tests/test_car_racing.py`` checks the environment side by side with Gymnasium's class and each
compiled function against pygame on random polygons, and ``benchmarks/car_racing.py --identity``
runs longer episodes. Visited tiles change colour in place (``road_poly`` holds a reference to each
tile's colour array), so colours are read at every frame, never copied.
"""

from __future__ import annotations

import math

import numpy as np
import pygame
from gymnasium.envs.box2d import car_dynamics
from gymnasium.envs.box2d import car_racing as stock
from numba import njit
from pygame import gfxdraw

from envs import car_racing_track, pygame_raster
from envs.car_racing_observation import SpanObservation

_W, _H = stock.WINDOW_W, stock.WINDOW_H
_CULL_MARGIN = stock.MAX_SHAPE_DIM
# pygame's Vector2 (src_c/math.c, _vector2_rotate_helper): its default epsilon for right angles
_PYGAME_VECTOR_EPSILON = 1e-6
# the playfield is a fill only if the screen, grown by this many pixels, is inside it: the edges'
# anti-aliased pixels and the scanline rounding stay within one pixel of the edge
_FILL_MARGIN = 3
# |coordinate| below this: its integer is within what envs.pygame_raster reproduces
_COMPILED_BOUND = pygame_raster.LARGEST_COORDINATE + 1
_STATE_MODES = ("state_pixels", "state_pixels_list")
# smoothscale's backends whose arithmetic envs.car_racing_observation reproduces (NEON runs the SSE2
# code through sse2neon); with another (GENERIC: pygame's plain C filter), pygame shrinks the picture
_SPAN_BACKENDS = ("SSE2", "NEON")
# score texts whose pixels are kept: every text an environment's rewards write (from -100 to a lap's 1000 and
# some, about 1,100), grey at one byte a pixel (4.4 kB each), so at most 18 MB per environment. With the first
# 256 kept, a trained agent's scores, past 256, had been rendered again at most steps (a tenth of a step)
_SCORES_KEPT = 4096


def _rotated(x: np.ndarray, y: np.ndarray, angle: float) -> tuple[np.ndarray, np.ndarray]:
    angle = math.fmod(angle, 2 * math.pi)
    if angle < 0:
        angle += 2 * math.pi
    epsilon = _PYGAME_VECTOR_EPSILON
    if math.fmod(angle + epsilon, math.pi / 2) < 2 * epsilon:
        quarter_turns = int((angle + epsilon) / (math.pi / 2)) % 4
        return [(x, y), (-y, x), (-x, -y), (y, -x)][quarter_turns]
    sine, cosine = math.sin(angle), math.cos(angle)
    return cosine * x - sine * y, sine * x + cosine * y


def _rotation(angle: float) -> tuple[int, float, float]:
    """``_rotated``'s case: (quarter turns, 0, 0) at a multiple of pi/2, else (-1, sine, cosine)."""
    angle = math.fmod(angle, 2 * math.pi)
    if angle < 0:
        angle += 2 * math.pi
    epsilon = _PYGAME_VECTOR_EPSILON
    if math.fmod(angle + epsilon, math.pi / 2) < 2 * epsilon:
        return int((angle + epsilon) / (math.pi / 2)) % 4, 0.0, 0.0
    return -1, math.sin(angle), math.cos(angle)


@njit(cache=True, nogil=True)
def _screen_point(x: float, y: float, quarter: int, sine: float, cosine: float, zoom: float, tx: float,
                  ty: float) -> tuple[float, float]:
    """``to_screen`` of one point, ``_rotation``'s case given: the same operations on the same doubles
    (no fastmath: nothing is fused or reordered)."""
    if quarter == 0:
        rx, ry = x, y
    elif quarter == 1:
        rx, ry = -y, x
    elif quarter == 2:
        rx, ry = -x, -y
    elif quarter == 3:
        rx, ry = y, -x
    else:
        rx, ry = cosine * x - sine * y, sine * x + cosine * y
    return rx * zoom + tx, ry * zoom + ty


@njit(cache=True, nogil=True)
def _cull(corners: np.ndarray, reach: np.ndarray, quarter: int, sine: float, cosine: float, zoom: float, tx: float,
          ty: float) -> tuple[np.ndarray, np.ndarray]:
    """``to_screen`` of polygons (K, 4, 2), then ``_visible_polygons``' two tests, in one pass.

    A polygon whose circle (``reach``) lies on the screen wholly beyond the stock margin test's
    bounds, by a pixel more than rounding could move a corner, has no corner within them: its
    corners are not transformed (their rows of the screen corners are left unwritten)."""
    count = corners.shape[0]
    screen = np.empty(corners.shape)
    near = np.zeros(count, dtype=np.bool_)
    representable = True  # pygame_pixels: every drawn coordinate's int() reproducible
    for k in range(count):
        cx, cy = _screen_point(reach[k, 0], reach[k, 1], quarter, sine, cosine, zoom, tx, ty)
        slack = _CULL_MARGIN + reach[k, 2] * abs(zoom) * (1 + 1e-9) + 1.0
        if cx < -slack or cx > _W + slack or cy < -slack or cy > _H + slack:  # (NaN: False, then tested)
            continue
        for j in range(4):
            sx, sy = _screen_point(corners[k, j, 0], corners[k, j, 1], quarter, sine, cosine, zoom, tx, ty)
            screen[k, j, 0], screen[k, j, 1] = sx, sy
            if sx >= -_CULL_MARGIN and sx <= _W + _CULL_MARGIN and sy >= -_CULL_MARGIN and sy <= _H + _CULL_MARGIN:
                near[k] = True
    drawn = np.flatnonzero(near)
    for k in drawn:
        for j in range(4):
            for axis in range(2):
                if not abs(screen[k, j, axis]) < 2.0 ** 31:
                    representable = False
    if not representable:
        return drawn, screen
    kept = np.zeros(drawn.shape[0], dtype=np.bool_)
    for index in range(drawn.shape[0]):
        low_x, low_y, high_x, high_y = 1 << 20, 1 << 20, -(1 << 20), -(1 << 20)
        for j in range(4):  # pygame_pixels then touches_screen
            px = np.int64(np.int16(np.int64(screen[drawn[index], j, 0])))
            py = np.int64(np.int16(np.int64(screen[drawn[index], j, 1])))
            low_x, high_x = min(low_x, px), max(high_x, px)
            low_y, high_y = min(low_y, py), max(high_y, py)
        kept[index] = high_x >= 0 and low_x <= _W - 1 and high_y >= 0 and low_y <= _H - 1
    return drawn[kept], screen


def polygon_reach(corners: np.ndarray) -> np.ndarray:
    """Per polygon (K, 4, 2): its corners' mean and the largest distance from it to a corner (K, 3)."""
    center = corners.mean(axis=1)
    radius = np.sqrt(((corners - center[:, None, :]) ** 2).sum(axis=2).max(axis=1))
    return np.concatenate([center, radius[:, None]], axis=1)


def rotate_like_pygame(points: np.ndarray, angle: float) -> np.ndarray:
    """``Vector2(p).rotate_rad(angle)`` for every row ``p`` of ``points`` (..., 2), bit for bit.

    pygame-ce (``src_c/math.c``) reduces the angle with ``fmod`` to [0, 2 pi), swaps coordinates
    exactly at multiples of pi/2 (within 1e-6), and otherwise computes ``cos*x - sin*y``,
    ``sin*x + cos*y`` in doubles; ``math.sin``/``math.cos`` call the same C library.
    """
    return np.stack(_rotated(points[..., 0], points[..., 1], angle), axis=-1)


def to_screen(corners: np.ndarray, zoom: float, translation, angle: float) -> np.ndarray:
    """The stock ``_draw_colored_polygon``'s pixel coordinates: rotated, then ``c * zoom + t``."""
    rotated_x, rotated_y = _rotated(corners[..., 0], corners[..., 1], angle)
    screen = np.empty(corners.shape)
    screen[..., 0] = rotated_x * zoom + translation[0]
    screen[..., 1] = rotated_y * zoom + translation[1]
    return screen


def pygame_pixels(screen: np.ndarray) -> np.ndarray | None:
    """The Sint16 vertices pygame's gfxdraw makes of these coordinates (``int()``, then a cast).

    None when a coordinate is not finite or too large for that conversion to be reproduced here;
    the caller then leaves every decision to pygame.
    """
    if not np.all(np.abs(screen) < 2.0 ** 31):  # also False for NaN
        return None
    return np.trunc(screen).astype(np.int64).astype(np.int16).astype(np.int64)


def touches_screen(pixels: np.ndarray) -> np.ndarray:
    """Per polygon (..., corners, 2): can gfxdraw's filled or anti-aliased polygon write a pixel?

    Both clip to the surface: a polygon whose integer bounding box lies wholly beyond one side of
    the screen writes nothing (every scanline is outside, every edge is rejected by the line clip).
    """
    low, high = pixels.min(axis=-2), pixels.max(axis=-2)
    return (high[..., 0] >= 0) & (low[..., 0] <= _W - 1) & (high[..., 1] >= 0) & (low[..., 1] <= _H - 1)


def covers_screen(pixels: np.ndarray) -> bool:
    """Does this convex quadrilateral (4, 2) of integer vertices contain the screen with a margin?"""
    return _covers(np.asarray(pixels, dtype=np.int64))


@njit(cache=True, nogil=True)
def _covers(pixels: np.ndarray) -> bool:
    """``covers_screen``: every corner of the grown screen strictly on the same side of every edge."""
    low, high = -_FILL_MARGIN, _FILL_MARGIN
    corners = ((low, low), (_W - 1 + high, low), (_W - 1 + high, _H - 1 + high), (low, _H - 1 + high))
    positive, negative = False, False
    for index in range(4):
        previous = index - 1 if index > 0 else 3
        x1, y1, x2, y2 = pixels[previous, 0], pixels[previous, 1], pixels[index, 0], pixels[index, 1]
        for x, y in corners:
            cross = (x2 - x1) * (y - y1) - (y2 - y1) * (x - x1)
            if cross == 0:
                return False
            positive, negative = positive or cross > 0, negative or cross < 0
    return not (positive and negative)


@njit(cache=True, nogil=True)
def _playfield(corners, quarter, sine, cosine, zoom, tx, ty) -> tuple[np.ndarray, bool]:
    """The playfield's screen corners (``to_screen``) and whether it covers the screen
    (``covers_screen`` of ``pygame_pixels``: False when those are not reproducible)."""
    screen, pixels = np.empty((4, 2)), np.empty((4, 2), dtype=np.int64)
    representable = True
    for j in range(4):
        screen[j, 0], screen[j, 1] = _screen_point(corners[j, 0], corners[j, 1], quarter, sine, cosine, zoom, tx, ty)
        for axis in range(2):
            if not abs(screen[j, axis]) < 2.0 ** 31:  # also for NaN
                representable = False
            else:
                pixels[j, axis] = ((np.int64(screen[j, axis]) + 32768) & 0xFFFF) - 32768  # int(), then Sint16
    return screen, representable and _covers(pixels)


@njit(cache=True, nogil=True)
def _scene_arrays(playfield, covered, world, world_colors, car_corners, car_counts, car_colors, background):
    """``_compiled_scene``'s polygons in drawing order: the playfield unless it is a fill, the world
    (K, 4, 2), the car; as (fits, xs, ys, starts, pixel values, anti-aliased), ``fits`` False
    where a coordinate is beyond what ``envs.pygame_raster`` reproduces (or NaN)."""
    smooth = world.shape[0] + (0 if covered else 1)
    polygons = smooth + car_counts.shape[0]
    points = 4 * smooth + car_corners.shape[0]
    xs, ys = np.empty(points, dtype=np.int64), np.empty(points, dtype=np.int64)
    starts, colors = np.zeros(polygons + 1, dtype=np.int64), np.empty(polygons, dtype=np.int64)
    antialiased = np.zeros(polygons, dtype=np.bool_)
    antialiased[:smooth] = True
    corners = np.concatenate((world.reshape(-1, 2), car_corners)) if covered else np.concatenate(
        (playfield, world.reshape(-1, 2), car_corners))
    for point in range(points):
        x, y = corners[point, 0], corners[point, 1]
        if not (abs(x) < _COMPILED_BOUND and abs(y) < _COMPILED_BOUND):
            return False, xs, ys, starts, colors, antialiased
        xs[point], ys[point] = np.int64(x), np.int64(y)  # truncation, as pygame
    first = 0 if covered else 1
    colors[0] = background
    colors[first:first + world.shape[0]] = world_colors
    colors[smooth:] = car_colors
    for polygon in range(polygons):
        starts[polygon + 1] = starts[polygon] + (4 if polygon < smooth else car_counts[polygon - smooth])
    return True, xs, ys, starts, colors, antialiased


@njit(cache=True, nogil=True)
def _scene(world, reach, grass_count, grass, road_rows, playfield_corners, quarter, sine, cosine, zoom, tx, ty, owners,
           starts, vertices, poses, phased, phases, car_colors, white, background):
    """``_compiled_scene`` in one call: the playfield (``_playfield``), the world culled
    (``_cull``) with its pixel values (``_road_pixels``), the car (``_car_screen``), handed to
    ``_scene_arrays``. Returns (drawable, playfield covers the screen, xs, ys, starts, pixel
    values, anti-aliased); drawable is False where pygame must draw the frame."""
    playfield, covered = _playfield(playfield_corners, quarter, sine, cosine, zoom, tx, ty)
    drawn, screen = _cull(world, reach, quarter, sine, cosine, zoom, tx, ty)
    world_colors = np.empty(drawn.shape[0], dtype=np.int64)
    drawable = _road_pixels(drawn, grass_count, grass, road_rows, world_colors)
    car_corners, car_counts, car_values = _car_screen(owners, starts, vertices, poses, phased, phases, car_colors,
                                                      white, quarter, sine, cosine, zoom, tx, ty)
    drawable = drawable and (car_counts.shape[0] == 0 or car_counts.min() >= 4)  # (pygame draws triangles otherwise)
    fits, xs, ys, polygon_starts, colors, antialiased = _scene_arrays(playfield, covered, screen[drawn], world_colors,
                                                                      car_corners, car_counts, car_values, background)
    return drawable and fits, covered, xs, ys, polygon_starts, colors, antialiased


def box2d_transform(cos_sin_position: np.ndarray, local: np.ndarray) -> np.ndarray:
    """``b2Transform * b2Vec2`` of pybox2d for rows of (cos, sin, x, y) and of local points, bit for bit.

    Box2D's ``b2Mul(T, v)`` (``Box2D/Common/b2Math.h``) is ``(c vx - s vy) + px``, ``(s vx + c vy)
    + py`` in float32, one rounding per operation, which is what float32 numpy arrays do.
    """
    c, s, px, py = (cos_sin_position[:, i] for i in range(4))
    vx, vy = local[:, 0], local[:, 1]
    return np.stack(((c * vx - s * vy) + px, (s * vx + c * vy) + py), axis=-1).astype(np.float64)


_MARK_X = car_dynamics.WHEEL_W * car_dynamics.SIZE
_MARK_Y = car_dynamics.WHEEL_R


@njit(cache=True, nogil=True)
def _wheel_mark(phase: float, mark: np.ndarray) -> bool:
    """The white mark of a wheel turned by ``phase``, in the wheel's frame, into ``mark`` (4, 2)
    float32; False when hidden. ``Car.draw``'s own expressions (numpy's sign included), rounded to
    float32 as pybox2d rounds the tuples it is given."""
    a1, a2 = phase, phase + 1.2  # radians
    s1, s2, c1, c2 = math.sin(a1), math.sin(a2), math.cos(a1), math.cos(a2)
    if s1 > 0 and s2 > 0:
        return False
    if s1 > 0:
        c1 = np.sign(c1)
    if s2 > 0:
        c2 = np.sign(c2)
    size = car_dynamics.SIZE
    for corner, (x, c) in enumerate(((-_MARK_X, c1), (_MARK_X, c1), (_MARK_X, c2), (-_MARK_X, c2))):
        mark[corner, 0], mark[corner, 1] = np.float32(x), np.float32(+_MARK_Y * c * size)
    return True


@njit(cache=True, nogil=True)
def _place(local, pose, screen, points, quarter, sine, cosine, zoom, tx, ty) -> int:
    """Corners ``local`` (n, 2) float32 of a body at ``pose`` (cos, sin, x, y) float32 into
    ``screen[points:]``: Box2D's ``b2Mul`` in float32 (``box2d_transform``), then ``to_screen``."""
    c, s, px, py = pose[0], pose[1], pose[2], pose[3]
    for v in range(local.shape[0]):
        x, y = (c * local[v, 0] - s * local[v, 1]) + px, (s * local[v, 0] + c * local[v, 1]) + py
        screen[points + v, 0], screen[points + v, 1] = _screen_point(np.float64(x), np.float64(y), quarter, sine,
                                                                     cosine, zoom, tx, ty)
    return points + local.shape[0]


@njit(cache=True, nogil=True)
def _car_screen(owners, starts, vertices, poses, phased, phases, colors, white, quarter, sine, cosine, zoom, tx,
                ty) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Car.draw``'s polygons on the screen: fixture ``f`` (of body ``owners[f]``, local corners
    ``vertices[starts[f]:starts[f + 1]]``), then, for a body with a phase, its wheel's mark.
    ``poses``: per body (cos, sin, x, y) float32. Returns the corners (n, 2), the corner count and
    the pixel value of each polygon."""
    fixtures = owners.shape[0]
    screen = np.empty((vertices.shape[0] + 4 * fixtures, 2))
    counts, values = np.empty(2 * fixtures, dtype=np.int64), np.empty(2 * fixtures, dtype=np.int64)
    mark = np.empty((4, 2), dtype=np.float32)
    points, polygons = 0, 0
    for f in range(fixtures):
        body = owners[f]
        local = vertices[starts[f]:starts[f + 1]]
        points = _place(local, poses[body], screen, points, quarter, sine, cosine, zoom, tx, ty)
        counts[polygons], values[polygons] = local.shape[0], colors[body]
        polygons += 1
        if phased[body] and _wheel_mark(phases[body], mark):
            points = _place(mark, poses[body], screen, points, quarter, sine, cosine, zoom, tx, ty)
            counts[polygons], values[polygons] = 4, white
            polygons += 1
    return screen[:points], counts[:polygons], values[:polygons]


@njit(cache=True, nogil=True)
def _road_pixels(drawn, grass_count, grass, rows, values) -> bool:
    """``values``: the pixel of each polygon ``drawn`` of grass-then-road, ``grass`` or the tile's
    colour row as the stock's ``int(c)`` packed in XRGB8888; False if a colour is not within 0..255
    (or a grass polygon is drawn and ``grass`` is -1)."""
    for index in range(drawn.shape[0]):
        if drawn[index] < grass_count:
            if grass < 0:  # (the grass colour is not a plain pixel)
                return False
            values[index] = grass
            continue
        pixel = 0
        for channel in range(3):
            color = rows[drawn[index] - grass_count, channel]
            if not (color > -1 and color < 256):  # NaN too
                return False
            pixel = (pixel << 8) | np.int64(color)  # truncation toward zero: int(c)
        values[index] = pixel
    return True


# the dashboard's polygons (the stock _render_indicators): their colours' pixels, in its order
_DASHBOARD_COLORS = np.array([0x000000, 0xFFFFFF, 0x0000FF, 0x0000FF, 0x3300FF, 0x3300FF, 0x00FF00, 0xFF0000],
                             dtype=np.int64)


@njit(cache=True, nogil=True)
def _dashboard(vx, vy, omega0, omega1, omega2, omega3, angle, spin):
    """The stock ``_render_indicators``'s polygons from its readings (the hull's velocity, the
    wheels' omegas, wheel 0's joint angle, the hull's spin), with its double expressions: the
    ``render_if_min`` test, the corners, pygame's truncation to integers. Returns (fits, xs, ys,
    starts, colours, anti-aliased flags); fits is False where a corner is beyond the compiled
    drawing's bound (or NaN)."""
    s, h = _W / 40.0, _H / 40.0
    true_speed = math.sqrt(vx * vx + vy * vy)  # np.sqrt(np.square(vx) + np.square(vy))
    values = (1.0, true_speed, omega0, omega1, omega2, omega3, angle, spin)
    corners = np.empty((8, 8), dtype=np.float64)  # per shown polygon: x, y of its 4 corners in order
    colors = np.empty(8, dtype=np.int64)
    kept = 0
    for index in range(8):
        value = values[index]
        if not abs(value) > 1e-4:  # the stock render_if_min (NaN is not shown either)
            continue
        if index == 0:  # [(W, H), (W, H - 5 h), (0, H - 5 h), (0, H)]
            left, right, top, bottom = 0.0, float(_W), _H - 5 * h, float(_H)
            corners[kept] = (right, bottom, right, top, left, top, left, bottom)
            colors[kept] = _DASHBOARD_COLORS[index]
            kept += 1
            continue
        if index < 6:  # vertical(place, scaled value)
            place = 5 if index == 1 else index + 5
            scaled = 0.02 * value if index == 1 else 0.01 * value
            left, right, top, bottom = place * s, (place + 1) * s, _H - (h + h * scaled), _H - h
        else:  # horizontal(place, scaled value)
            place = 20 if index == 6 else 30
            scaled = -10.0 * value if index == 6 else -0.8 * value
            left, right, top, bottom = (place + 0) * s, (place + scaled) * s, _H - 4 * h, _H - 2 * h
        corners[kept] = (left, top, right, top, right, bottom, left, bottom)
        colors[kept] = _DASHBOARD_COLORS[index]
        kept += 1
    xs, ys = np.empty(4 * kept, dtype=np.int64), np.empty(4 * kept, dtype=np.int64)
    fits = True
    for polygon in range(kept):
        for corner in range(4):
            x, y = corners[polygon, 2 * corner], corners[polygon, 2 * corner + 1]
            if not (abs(x) < _COMPILED_BOUND and abs(y) < _COMPILED_BOUND):  # NaN too
                fits = False
                x, y = 0.0, 0.0
            xs[4 * polygon + corner], ys[4 * polygon + corner] = int(x), int(y)  # truncation, as pygame
    return fits, xs, ys, np.arange(kept + 1) * 4, colors[:kept], np.zeros(kept, dtype=np.bool_)


def _grass_corners() -> np.ndarray:
    """The stock ``_render_road``'s grass squares, with its own float expressions."""
    dim = stock.GRASS_DIM
    return np.array([[(dim * x + dim, dim * y + 0), (dim * x + 0, dim * y + 0),
                      (dim * x + 0, dim * y + dim), (dim * x + dim, dim * y + dim)]
                     for x in range(-20, 20, 2) for y in range(-20, 20, 2)], dtype=np.float64)


def _playfield_corners() -> np.ndarray:
    bound = stock.PLAYFIELD
    return np.array([(bound, bound), (bound, -bound), (-bound, -bound), (-bound, bound)], dtype=np.float64)


_DOUBLES = (float, np.float64)  # what CarRacing.step hands the car's controls (it casts an action to float64)


def _sign(x: float) -> float:
    """``np.sign`` of a double: 1.0, -1.0, 0.0 for either zero, NaN as it is."""
    return 1.0 if x > 0 else -1.0 if x < 0 else 0.0 if x == 0 else x


class _Car(car_dynamics.Car):
    """Gymnasium's ``Car`` whose ``gas`` and ``step`` run its arithmetic without numpy's scalar
    functions, which cost most of its time: ``np.clip``, ``np.sign``, ``np.square`` and ``np.sqrt``
    of a double are comparisons, a product and IEEE's square root, so the same double operations
    in the same order give the same doubles (as Python floats where the stock has numpy's float64).
    ``step`` also reads the controls as Python floats once per wheel, whose arithmetic costs a
    fraction of numpy scalars', and a wheel's directions from one read of its rotation (Box2D's
    proxies cost about a microsecond each): 0.6x its time. Any control that is not a double (the
    car's methods called from outside) takes the stock methods. ``FastCarRacing.step`` gives the
    car Gymnasium's reset makes this class."""

    def gas(self, gas):
        if type(gas) not in _DOUBLES:
            return super().gas(gas)
        gas = 0.0 if gas < 0 else 1.0 if gas > 1 else gas  # np.clip(gas, 0, 1): -0.0 and NaN as they are
        for w in self.wheels[2:4]:
            diff = gas - w.gas
            if diff > 0.1:
                diff = 0.1  # gradually increase, but stop immediately
            w.gas += diff

    def step(self, dt):
        wheels = self.wheels
        for w in wheels:  # (a loop, not a generator: a fifth of its time)
            if not (type(w.steer) in _DOUBLES and type(w.gas) in _DOUBLES and type(w.brake) in _DOUBLES
                    and type(w.omega) in _DOUBLES):
                return super().step(dt)
        friction, power, inertia = car_dynamics.FRICTION_LIMIT, car_dynamics.ENGINE_POWER, \
            car_dynamics.WHEEL_MOMENT_OF_INERTIA
        scale = 205000 * car_dynamics.SIZE * car_dynamics.SIZE
        for w in wheels:
            joint = w.joint
            # the controls as Python floats (the same doubles): numpy's scalar arithmetic costs several
            # times Python's, and would carry on into every expression below
            steer, gas, brake, omega = float(w.steer), float(w.gas), float(w.brake), float(w.omega)
            turn = steer - joint.angle  # (the stock reads the angle twice: the same float)
            joint.motorSpeed = _sign(turn) * min(50.0 * abs(turn), 3.0)
            grass = True
            friction_limit = friction * 0.6  # grass, unless on a tile
            for tile in w.tiles:
                friction_limit = max(friction_limit, friction * tile.road_friction)
                grass = False
            # GetWorldVector((0, 1)) and ((1, 0)): Box2D's b2Mul(q, v) in float32, whose products by 0
            # and 1 and sums with a zero are exact, and so are the same in doubles (NaN and the sign
            # of zero included); one proxy for the rotation instead of two vectors indexed six times
            rotation, v = w.transform.q, w.linearVelocity
            c, s, vx, vy = rotation.c, rotation.s, v.x, v.y
            forw_x, forw_y = c * 0.0 - s * 1.0, s * 0.0 + c * 1.0
            side_x, side_y = c * 1.0 - s * 0.0, s * 1.0 + c * 0.0
            vf = forw_x * vx + forw_y * vy  # forward speed
            vs = side_x * vx + side_y * vy  # side speed
            omega += dt * power * gas / inertia / (abs(omega) + 5.0)
            self.fuel_spent += dt * power * gas
            if brake >= 0.9:
                omega = 0
            elif brake > 0:
                direction = -_sign(omega)
                val = 15 * brake  # BRAKE_FORCE, radians per second
                if abs(val) > abs(omega):
                    val = abs(omega)  # low speed => same as = 0
                omega += direction * val
            w.phase += omega * dt
            vr = omega * w.wheel_rad  # rotating wheel speed
            f_force = -vf + vr
            p_force = -vs
            f_force *= scale
            p_force *= scale
            force = math.sqrt(f_force * f_force + p_force * p_force)
            if abs(force) > 2.0 * friction_limit:  # skid trace
                if w.skid_particle and w.skid_particle.grass == grass and len(w.skid_particle.poly) < 30:
                    w.skid_particle.poly.append((w.position[0], w.position[1]))
                elif w.skid_start is None:
                    w.skid_start = w.position
                else:
                    w.skid_particle = self._create_particle(w.skid_start, w.position, grass)
                    w.skid_start = None
            else:
                w.skid_start = None
                w.skid_particle = None
            if abs(force) > friction_limit:
                f_force /= force
                p_force /= force
                force = friction_limit
                f_force *= force
                p_force *= force
            w.omega = omega - dt * f_force * w.wheel_rad / inertia
            w.ApplyForceToCenter((p_force * side_x + f_force * forw_x, p_force * side_y + f_force * forw_y), True)


class FastCarRacing(stock.CarRacing):
    """Gymnasium's CarRacing with the same observations and frames, drawn with less work.

    Every constructor argument, ``reset`` option and attribute is the stock class's; only the
    drawing methods are replaced. ``self.surf`` is, as in the stock class, the last frame at full
    size (here a surface reused from frame to frame). Observations are C-contiguous arrays (the
    stock class returns a transposed view); their values are the same.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._frame: pygame.Surface | None = None  # the picture, flipped: stock's self.surf
        self._canvas: pygame.Surface | None = None  # the pygame path's unflipped picture
        self._probe: pygame.Surface | None = None
        self._scaled: dict[tuple[int, int], pygame.Surface] = {}
        self._compiled_drawing = False
        self._spans: SpanObservation | None = None  # the observation without the full picture
        self._score_pixels: dict[str, tuple[np.ndarray, int, int]] = {}  # per score text, up to _SCORES_KEPT
        self._font: pygame.font.Font | None = None
        self._score_text: tuple[str, pygame.Surface, pygame.Rect] | None = None
        self._road_source: list | None = None
        self._world_corners = np.empty((0, 4, 2))
        self._world_reach = np.empty((0, 3))  # polygon_reach of the world corners
        self._road_colors: list = []
        self._road_color_rows: np.ndarray | None = None  # the same colours as rows, when made so
        self._car_source: car_dynamics.Car | None = None
        self._car_fixtures: tuple = ()  # owners, starts, local corners (_car_screen)
        self._car_phased: tuple = ()  # which bodies are wheels, as a list and as an array
        self._car_colors: tuple | None = None  # (the colours, their pixel values): _car_pixel_values
        self._grass_corners = _grass_corners()
        self._playfield = _playfield_corners()
        self._tile_body = car_racing_track.static_body_def()

    def step(self, action):
        if type(self.car) is car_dynamics.Car:  # the car Gymnasium's reset made: the same, with less numpy
            self.car.__class__ = _Car
        return super().step(action)

    def _create_track(self) -> bool:
        """The stock track, ``road_poly`` and tile bodies, generated in numba (``envs.car_racing_track``)."""
        made = car_racing_track.create_track(self, self._tile_body)
        if made is None:
            return False
        road, self._road_color_rows = made
        # _world_polygons' cache, from the same doubles road_poly holds
        self._set_world(np.concatenate([self._grass_corners, road]))
        self._road_colors = [color for _, color in self.road_poly]
        self._road_source = self.road_poly
        return True

    # --- one frame ---------------------------------------------------------------------------

    def _render(self, mode: str):
        assert mode in self.metadata["render_modes"]
        pygame.font.init()
        if self.screen is None and mode == "human":
            pygame.display.init()
            self.screen = pygame.display.set_mode((_W, _H))
        if self.clock is None:
            self.clock = pygame.time.Clock()
        if "t" not in self.__dict__:
            return None  # reset() not called yet
        self._make_surfaces()
        camera = self._camera()
        if mode == "state_pixels" and (observation := self._observe_from_spans(camera)) is not None:
            return observation
        if mode not in _STATE_MODES or not self._draw_compiled(*camera):
            self._draw_with_pygame(*camera, draw_particles=mode not in _STATE_MODES)
        self.surf = self._frame
        self._render_indicators(_W, _H)
        self._draw_score()
        if mode == "human":
            pygame.event.pump()
            self.clock.tick(self.metadata["render_fps"])
            assert self.screen is not None
            self.screen.fill(0)
            self.screen.blit(self.surf, (0, 0))
            pygame.display.flip()
            return None
        if mode == "rgb_array":
            return self._create_image_array(self.surf, (stock.VIDEO_W, stock.VIDEO_H))
        if mode == "state_pixels":
            return self._create_image_array(self.surf, (stock.STATE_W, stock.STATE_H))
        return self.isopen

    def _make_surfaces(self) -> None:
        if self._frame is not None:
            return
        self._frame = pygame.Surface((_W, _H))
        self._canvas = pygame.Surface((_W, _H))
        self._probe = pygame.Surface((1, 1))
        # the compiled drawing writes 32-bit XRGB pixels into rows of exactly the surface's width
        self._compiled_drawing = (self._frame.get_bitsize() == 32 and self._frame.get_pitch() == 4 * _W
                                  and self._frame.get_masks() == (0xFF0000, 0xFF00, 0xFF, 0)
                                  and self._frame.map_rgb((1, 2, 3)) == 0x010203)
        if self._compiled_drawing and pygame.transform.get_smoothscale_backend() in _SPAN_BACKENDS:
            self._spans = SpanObservation(_W, _H, stock.STATE_W, stock.STATE_H)

    def _camera(self) -> tuple[float, tuple[float, float], float]:
        """Zoom, translation and angle of the stock ``_render``, computed as it does."""
        assert self.car is not None
        angle = -self.car.hull.angle
        # animating the first second's zoom
        zoom = 0.1 * stock.SCALE * max(1 - self.t, 0) + stock.ZOOM * stock.SCALE * min(self.t, 1)
        position = self.car.hull.position  # (one proxy: the stock reads it twice, the same floats)
        scroll_x = -(position.x) * zoom
        scroll_y = -(position.y) * zoom
        trans = pygame.math.Vector2((scroll_x, scroll_y)).rotate_rad(angle)
        return zoom, (_W / 2 + trans[0], _H / 4 + trans[1]), angle

    def _draw_score(self) -> None:
        """The stock score text, rendered once per distinct string with one Font."""
        if self._font is None:
            self._font = pygame.font.Font(pygame.font.get_default_font(), 42)
        text = f"{self.reward:04.0f}"
        if self._score_text is None or self._score_text[0] != text:
            image = self._font.render(text, True, (255, 255, 255), (0, 0, 0))
            rect = image.get_rect()
            rect.center = (60, _H - _H * 2.5 / 40.0)
            self._score_text = (text, image, rect)
        self.surf.blit(self._score_text[1], self._score_text[2])

    def _create_image_array(self, screen, size):
        """The stock ``smoothscale`` into a reused surface; its pixels read as (height, width, RGB)."""
        scaled = self._scaled.get(size)
        if scaled is None:
            scaled = self._scaled[size] = pygame.Surface(size)
        pygame.transform.smoothscale(screen, size, scaled)
        rgb = bytearray(pygame.image.tobytes(scaled, "RGB"))
        return np.frombuffer(rgb, dtype=np.uint8).reshape(size[1], size[0], 3)

    # --- what is drawn -------------------------------------------------------------------------

    def _world_polygons(self) -> np.ndarray:
        """Grass then road corners (K, 4, 2); ``self._road_colors`` the road's colours, live references."""
        road_poly = self.road_poly
        if self._road_source is not road_poly or len(self._world_corners) != len(self._grass_corners) + len(road_poly):
            road = np.array([poly for poly, _ in road_poly], dtype=np.float64).reshape(-1, 4, 2)
            self._set_world(np.concatenate([self._grass_corners, road]))
            self._road_colors = [color for _, color in road_poly]  # never copies: visited tiles change
            self._road_color_rows = None
            self._road_source = road_poly
        return self._world_corners

    def _set_world(self, corners: np.ndarray) -> None:
        self._world_corners, self._world_reach = corners, polygon_reach(corners)

    def _visible_polygons(self, zoom, translation, angle) -> tuple[np.ndarray, np.ndarray]:
        """Indices into grass-then-road of the polygons to draw, and their screen corners (n, 4, 2).

        The stock test first (some corner within ``MAX_SHAPE_DIM`` of the screen), then the exact
        one: pygame would clip away every pixel of a polygon wholly beyond one side of the screen.
        """
        drawn, screen = _cull(self._world_polygons(), self._world_reach, *_rotation(angle), zoom, *translation)
        return drawn, screen[drawn]

    def _polygon_color(self, index: int):
        """The colour the stock ``_render_road`` passes for polygon ``index`` of grass-then-road."""
        grass = len(self._grass_corners)
        if index < grass:
            return self.grass_color
        return [int(c) for c in self._road_colors[index - grass]]

    def _gfx_pixel(self, color) -> int:
        """The pixel value gfxdraw writes for ``color``, as it parses it (arrays of floats included)."""
        self._probe.fill(0)
        gfxdraw.hline(self._probe, 0, 0, 0, color)
        return self._probe.get_at_mapped((0, 0))

    # --- pygame's drawing ----------------------------------------------------------------------

    def _draw_with_pygame(self, zoom, translation, angle, draw_particles: bool) -> None:
        """The stock drawing calls, fewer of them, on the canvas; then flipped into the frame."""
        self.surf = self._canvas
        self._render_road(zoom, translation, angle)
        self.car.draw(self._canvas, zoom, translation, angle, draw_particles)
        source = pygame.surfarray.pixels2d(self._canvas)
        target = pygame.surfarray.pixels2d(self._frame)
        target[...] = source[:, ::-1]  # pygame.transform.flip(canvas, False, True), without a new surface
        del source, target  # release the surfaces' locks before anything blits onto them

    def _render_road(self, zoom, translation, angle):
        self._draw_playfield(zoom, translation, angle)
        drawn, screen = self._visible_polygons(zoom, translation, angle)
        for index, points in zip(drawn.tolist(), screen.tolist()):
            color = self._polygon_color(index)
            gfxdraw.aapolygon(self.surf, points, color)
            gfxdraw.filled_polygon(self.surf, points, color)

    def _draw_playfield(self, zoom, translation, angle) -> None:
        """The background: a fill when the playfield polygon covers the screen, else pygame's polygon."""
        screen = to_screen(self._playfield, zoom, translation, angle)
        pixels = pygame_pixels(screen)
        if pixels is not None and covers_screen(pixels):
            self.surf.fill(self._gfx_pixel(self.bg_color))
            return
        self.surf.fill(0)  # a new stock surface is black
        points = screen.tolist()
        gfxdraw.aapolygon(self.surf, points, self.bg_color)
        gfxdraw.filled_polygon(self.surf, points, self.bg_color)

    # --- the compiled drawing ------------------------------------------------------------------

    def _draw_compiled(self, zoom, translation, angle) -> bool:
        """The world straight into the flipped frame by ``envs.pygame_raster``; False, having drawn
        nothing, where that cannot be guaranteed to match pygame (then pygame draws it)."""
        scene = self._compiled_scene(zoom, translation, angle)
        if scene is None:
            return False
        background, *polygons = scene
        self._frame.fill(background)
        frame = pygame.surfarray.pixels2d(self._frame).T  # (height, width) view of the frame's pixels
        pygame_raster.draw_polygons(frame, True, *polygons)
        del frame  # release the surface's lock before anything blits onto it
        return True

    def _compiled_scene(self, zoom, translation, angle) -> tuple | None:
        """The background pixel and the world's polygons for ``pygame_raster.draw_polygons``
        (xs, ys, starts, pixel values, anti-aliased); None where the compiled drawing cannot be
        guaranteed to match pygame."""
        if not self._compiled_drawing:
            return None
        world = self._world_polygons()
        road_rows = self._road_rows()
        car = self._car_state()
        background, grass = self._plain_pixel(self.bg_color), self._plain_pixel(self.grass_color)
        if road_rows is None or car is None or background is None:
            return None
        drawable, covered, *polygons = _scene(world, self._world_reach, len(self._grass_corners),
                                              -1 if grass is None else grass, road_rows, self._playfield,
                                              *_rotation(angle), zoom, *translation, *car, background)
        if not drawable:
            return None
        return (background if covered else 0, *polygons)  # (a new stock surface is black)

    # --- the observation without the picture -------------------------------------------------

    def _observe_from_spans(self, camera) -> np.ndarray | None:
        """The observation from spans (``envs.car_racing_observation``): the world, the dashboard
        and the score as the stock class draws them, none of them on a surface; None where the
        compiled drawing cannot promise pygame's pixels (then the picture is drawn)."""
        if self._spans is None:
            return None
        scene = self._compiled_scene(*camera)
        indicators = self._indicator_polygons()
        if scene is None or indicators is None:
            return None
        background, *polygons = scene
        while True:
            target = self._spans.target()
            self._spans.record_polygons(target, True, *polygons)  # the world, flipped as the stock flips it
            self._spans.record_polygons(target, False, *indicators)  # the dashboard, on the flipped picture
            if not self._spans.overflowed():
                break
        return self._spans.observe(background, *self._score_image())

    def _indicator_polygons(self) -> tuple | None:
        """The stock ``_render_indicators``'s polygons, its expressions, as ``record_polygons``'
        arguments (pygame's integer corners, pixel values, none anti-aliased: ``pygame.draw.polygon``);
        None if a corner is beyond what the compiled drawing reproduces."""
        car, wheels = self.car, self.car.wheels
        velocity = car.hull.linearVelocity
        fits, *polygons = _dashboard(velocity.x, velocity.y, *[float(wheel.omega) for wheel in wheels],
                                     wheels[0].joint.angle, car.hull.angularVelocity)
        return tuple(polygons) if fits else None

    def _score_image(self) -> tuple[np.ndarray, int, int]:
        """The score's pixels as the stock blit writes them, and where: made once per distinct text and
        kept, the first ``_SCORES_KEPT`` texts of this environment (an episode's scores recur in the next:
        a text is rendered in about 60 us, and changes every few steps). White on black, the pixels are
        grey: kept as one byte each (uint8, the pixel being that byte in each channel), else as they are
        (uint32); ``envs.car_racing_observation.observe`` reads either."""
        text = f"{self.reward:04.0f}"
        kept = self._score_pixels.get(text)
        if kept is not None:
            return kept
        if self._font is None:
            self._font = pygame.font.Font(pygame.font.get_default_font(), 42)
        image = self._font.render(text, True, (255, 255, 255), (0, 0, 0))
        rect = image.get_rect()
        rect.center = (60, _H - _H * 2.5 / 40.0)
        copy = pygame.Surface(image.get_size())  # the frame's pixel format
        copy.blit(image, (0, 0))
        pixels = np.ascontiguousarray(pygame.surfarray.array2d(copy).T)
        grey = (pixels & 0xFF).astype(np.uint8)
        if np.array_equal(pixels, grey.astype(pixels.dtype) * 0x010101):
            pixels = grey
        kept = (pixels, rect.x, rect.y)
        if len(self._score_pixels) < _SCORES_KEPT:
            self._score_pixels[text] = kept
        return kept

    def _plain_pixel(self, color) -> int | None:
        """The pixel gfxdraw writes for ``color`` if it is an opaque RGB colour; None if it would blend."""
        return self._gfx_pixel(color) if len(color) == 3 else None

    def _road_rows(self) -> np.ndarray | None:
        """The tiles' colours as rows (K, 3) of doubles, read now (visited tiles change colour):
        ``envs.car_racing_track``'s rows, which the tiles' colours are views of, or made from
        ``road_poly``'s colours; None where those are not three numbers each."""
        if self._road_color_rows is not None:
            return self._road_color_rows
        if not self._road_colors:
            return np.empty((0, 3))
        try:
            rows = np.array(self._road_colors, dtype=np.float64).reshape(len(self._road_colors), -1)
        except (TypeError, ValueError):
            return None
        return rows if rows.shape[1] == 3 else None

    def _car_state(self) -> tuple | None:
        """``_car_screen``'s arguments before the camera: the car's fixtures (owners, starts,
        local corners), the bodies' poses, which are wheels and their phases, and the pixel values
        of the bodies and of the wheel mark; drawn in ``Car.draw``'s order
        (``gymnasium/envs/box2d/car_dynamics.py``; no skid marks): each body's fixtures, a wheel's
        white mark right after it. None if a colour is not plain RGB."""
        bodies = self.car.drawlist
        if self._car_source is not self.car:
            fixtures = [(index, np.array(fixture.shape.vertices, dtype=np.float32))
                        for index, body in enumerate(bodies) for fixture in body.fixtures]
            self._car_fixtures = (np.array([index for index, _ in fixtures], dtype=np.int64),
                                  np.cumsum([0] + [len(corners) for _, corners in fixtures]),
                                  np.concatenate([corners for _, corners in fixtures]).reshape(-1, 2))
            phased = ["phase" in body.__dict__ for body in bodies]  # the wheels: Car.__init__ gives them a phase
            self._car_phased = (phased, np.array(phased))
            self._car_source = self.car
        poses = np.array([(rotation.c, rotation.s, position.x, position.y)
                          for rotation, position in ((t.q, t.position) for t in (body.transform for body in bodies))],
                         dtype=np.float32)
        phased, is_wheel = self._car_phased
        phases = np.array([body.phase if wheel else 0.0 for body, wheel in zip(bodies, phased)], dtype=np.float64)
        colors = self._car_pixel_values(tuple(tuple(body.color) for body in bodies), car_dynamics.WHEEL_WHITE)
        if colors is None:
            return None
        return (*self._car_fixtures, poses, is_wheel, phases, *colors)

    def _car_pixel_values(self, colors: tuple, white) -> tuple[np.ndarray, int] | None:
        """The bodies' pixels and the wheel mark's, as ``Car.draw`` makes them (``int(c * 255)``)
        of these colours, or None; made again only when a colour changes."""
        if self._car_colors is None or self._car_colors[0] != (colors, white):
            pixels = [self._draw_pixel([int(c * 255) for c in color]) for color in colors]
            white_pixel = self._draw_pixel(list(white))
            values = None if None in pixels or white_pixel is None else (np.array(pixels, dtype=np.int64), white_pixel)
            self._car_colors = ((colors, white), values)
        return self._car_colors[1]

    @staticmethod
    def _draw_pixel(color: list) -> int | None:
        """The pixel ``pygame.draw`` writes for a colour of three ints (XRGB8888), None for others."""
        if len(color) == 3 and all(isinstance(c, int) and 0 <= c <= 255 for c in color):
            return (color[0] << 16) | (color[1] << 8) | color[2]
        return None

    def close(self):
        self._font = None  # a Font must not outlive pygame.quit(), which the stock close() may call
        self._score_text = None
        super().close()
