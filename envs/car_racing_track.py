"""Gymnasium's CarRacing track, generated with the same arithmetic at a fraction of the cost.

Gymnasium's ``CarRacing._create_track`` (O. Klimov; ``gymnasium/envs/box2d/car_racing.py``, v3)
costs most of a reset: a Python loop of ``math`` calls that steers from checkpoint to checkpoint
(up to 2500 steps), then about 300 Box2D static bodies, each made through pybox2d's keyword-argument
wrappers. This module keeps what it draws and in which order (the 24 ``np_random`` draws of the
checkpoints are made by the caller, exactly as the stock method makes them) and does the rest:

- the steering loop, the search of the closed lap, the glue test, the red-white border and the
  tiles' corners in one numba function, with the stock expressions in the stock order. numba calls
  the C library's ``atan2``, ``cos`` and ``sin``, as CPython's ``math`` does, and contracts no
  multiply-add (no fastmath), so every double is the stock's: ``tests/test_car_racing.py`` compares
  ``track`` and ``road_poly`` with Gymnasium's on many seeds, float for float;
- the tile bodies are made by the calls pybox2d's wrappers end in (``b2World.__CreateBody`` with
  one reused body definition, ``b2Body.__CreateFixture`` with the stock fixture definition whose
  shape gets its four corners through ``set_vertex``), in the stock order, with the stock
  attributes, so the world, its contacts and the reward are the stock's; the colours, rows of one
  array, are computed before the loop in one pass (``_tile_colors``: setting them row by row inside
  it had cost a sixth of this function's time).
"""

from __future__ import annotations

import math

import numpy as np
from Box2D import b2_staticBody, b2Body, b2BodyDef
from gymnasium.envs.box2d import car_racing as stock
from numba import njit

_CHECKPOINTS = 12
_NO_FREEZE = 2500
# track rows: alpha, beta, x, y (the stock's tuples); tile rows: the 4 road corners, then the border's
_TILE_WIDTH = 16


@njit(cache=True, nogil=True)
def _steer(checkpoints: np.ndarray) -> np.ndarray:
    """The stock ``while True`` loop that drives from checkpoint to checkpoint: its track rows."""
    track = np.empty((_NO_FREEZE, 4))
    n = 0
    x, y, beta = 1.5 * stock.TRACK_RAD, 0.0, 0.0
    dest_i = 0
    laps = 0
    no_freeze = _NO_FREEZE
    visited_other_side = False
    count = checkpoints.shape[0]
    while True:
        alpha = math.atan2(y, x)
        if visited_other_side and alpha > 0:
            laps += 1
            visited_other_side = False
        if alpha < 0:
            visited_other_side = True
            alpha += 2 * math.pi
        while True:  # the destination among the checkpoints
            failed = True
            while True:
                dest_alpha = checkpoints[dest_i % count, 0]
                dest_x = checkpoints[dest_i % count, 1]
                dest_y = checkpoints[dest_i % count, 2]
                if alpha <= dest_alpha:
                    failed = False
                    break
                dest_i += 1
                if dest_i % count == 0:
                    break
            if not failed:
                break
            alpha -= 2 * math.pi
        r1x = math.cos(beta)
        r1y = math.sin(beta)
        p1x = -r1y
        p1y = r1x
        dest_dx = dest_x - x
        dest_dy = dest_y - y
        proj = r1x * dest_dx + r1y * dest_dy
        while beta - alpha > 1.5 * math.pi:
            beta -= 2 * math.pi
        while beta - alpha < -1.5 * math.pi:
            beta += 2 * math.pi
        prev_beta = beta
        proj *= stock.SCALE
        if proj > 0.3:
            beta -= min(stock.TRACK_TURN_RATE, abs(0.001 * proj))
        if proj < -0.3:
            beta += min(stock.TRACK_TURN_RATE, abs(0.001 * proj))
        x += p1x * stock.TRACK_DETAIL_STEP
        y += p1y * stock.TRACK_DETAIL_STEP
        track[n, 0] = alpha
        track[n, 1] = prev_beta * 0.5 + beta * 0.5
        track[n, 2] = x
        track[n, 3] = y
        n += 1
        if laps > 4:
            break
        no_freeze -= 1
        if no_freeze == 0:
            break
    return track[:n]


@njit(cache=True, nogil=True)
def _closed_lap(track: np.ndarray, start_alpha: float) -> tuple[int, int]:
    """The stock's i1..i2: the second-to-last and last passes through the start; (-1, -1) if none."""
    i1, i2 = -1, -1
    i = track.shape[0]
    while True:
        i -= 1
        if i == 0:
            return -1, -1
        through = track[i, 0] > start_alpha and track[i - 1, 0] <= start_alpha
        if through and i2 == -1:
            i2 = i
        elif through and i1 == -1:
            i1 = i
            return i1, i2


@njit(cache=True, nogil=True)
def _borders(track: np.ndarray) -> np.ndarray:
    """The stock's red-white border flags on hard turns (negative indices wrap, as in Python)."""
    n = track.shape[0]
    border = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        good = True
        oneside = 0.0
        for neg in range(stock.BORDER_MIN_COUNT):
            beta1 = track[(i - neg) % n, 1]
            beta2 = track[(i - neg - 1) % n, 1]
            good &= abs(beta1 - beta2) > stock.TRACK_TURN_RATE * 0.2
            oneside += np.sign(beta1 - beta2)
        good &= abs(oneside) == stock.BORDER_MIN_COUNT
        border[i] = good
    for i in range(n):
        for neg in range(stock.BORDER_MIN_COUNT):
            border[(i - neg) % n] |= border[i]
    return border


@njit(cache=True, nogil=True)
def _put(target: np.ndarray, values: tuple) -> None:
    for k in range(len(values)):
        target[k] = values[k]


@njit(cache=True, nogil=True)
def _tiles(track: np.ndarray, border: np.ndarray) -> np.ndarray:
    """Each tile's road corners (l1, r1, r2, l2) and, where ``border``, the border's (same order)."""
    n = track.shape[0]
    width, outer = stock.TRACK_WIDTH, stock.TRACK_WIDTH + stock.BORDER
    tiles = np.full((n, _TILE_WIDTH), np.nan)
    for i in range(n):
        beta1, x1, y1 = track[i, 1], track[i, 2], track[i, 3]
        beta2, x2, y2 = track[(i - 1) % n, 1], track[(i - 1) % n, 2], track[(i - 1) % n, 3]
        c1, s1, c2, s2 = math.cos(beta1), math.sin(beta1), math.cos(beta2), math.sin(beta2)
        _put(tiles[i, 0:8], (x1 - width * c1, y1 - width * s1, x1 + width * c1, y1 + width * s1,
                             x2 + width * c2, y2 + width * s2, x2 - width * c2, y2 - width * s2))
        if border[i]:
            side = np.sign(beta2 - beta1)
            _put(tiles[i, 8:16], (x1 + side * width * c1, y1 + side * width * s1,
                                  x1 + side * outer * c1, y1 + side * outer * s1,
                                  x2 + side * outer * c2, y2 + side * outer * s2,
                                  x2 + side * width * c2, y2 + side * width * s2))
    return tiles


@njit(cache=True, nogil=True)
def track_and_tiles(checkpoints: np.ndarray, start_alpha: float) -> tuple[int, int, bool, np.ndarray, np.ndarray]:
    """The stock ``_create_track``'s geometry: (i1, i2, glued, track rows, tile corners).

    ``checkpoints`` holds the stock's (alpha, x, y) rows. On failure (no closed lap, or head and
    tail too far apart: ``glued`` false) the arrays are empty: the stock method would return False.
    """
    empty = np.empty((0, 4)), np.empty((0, _TILE_WIDTH))
    track = _steer(checkpoints)
    i1, i2 = _closed_lap(track, start_alpha)
    if i1 == -1:
        return -1, -1, False, empty[0], empty[1]
    track = track[i1:i2 - 1]
    first_perp_x = math.cos(track[0, 1])
    first_perp_y = math.sin(track[0, 1])
    glue = np.sqrt(np.square(first_perp_x * (track[0, 2] - track[-1, 2]))
                   + np.square(first_perp_y * (track[0, 3] - track[-1, 3])))
    if glue > stock.TRACK_DETAIL_STEP:
        return i1, i2, False, empty[0], empty[1]
    return i1, i2, True, track, _tiles(track, _borders(track))


def checkpoints(env: stock.CarRacing) -> np.ndarray:
    """The stock's 12 checkpoints, drawing from ``env.np_random`` as it does; sets ``start_alpha``."""
    rows = np.empty((_CHECKPOINTS, 3))
    for c in range(_CHECKPOINTS):
        noise = env.np_random.uniform(0, 2 * math.pi * 1 / _CHECKPOINTS)
        alpha = 2 * math.pi * c / _CHECKPOINTS + noise
        rad = env.np_random.uniform(stock.TRACK_RAD / 3, stock.TRACK_RAD)
        if c == 0:
            alpha = 0
            rad = 1.5 * stock.TRACK_RAD
        if c == _CHECKPOINTS - 1:
            alpha = 2 * math.pi * c / _CHECKPOINTS
            env.start_alpha = 2 * math.pi * (-0.5) / _CHECKPOINTS
            rad = 1.5 * stock.TRACK_RAD
        rows[c] = alpha, rad * math.cos(alpha), rad * math.sin(alpha)
    return rows


_BORDER = ((255, 255, 255), (255, 0, 0))  # the stock border's colours: tile i's is _BORDER[i % 2]


def _tile_colors(road_color: np.ndarray, tiles: np.ndarray) -> np.ndarray:
    """``road_poly``'s colours as rows (K, 3), in its order: each tile's road, the stock's
    ``road_color + 0.01 * (i % 3) * 255``, then its border if it has one."""
    bordered = ~np.isnan(tiles[:, 8])
    tile = np.arange(len(tiles))
    road_row = tile + np.cumsum(bordered) - bordered  # a tile's road comes after the polygons before it
    colors = np.empty((len(tiles) + int(np.count_nonzero(bordered)), 3))
    shades = np.array([road_color + 0.01 * shade * 255 for shade in range(3)])
    colors[road_row] = shades[tile % 3]
    colors[road_row[bordered] + 1] = np.array(_BORDER)[tile[bordered] % 2]
    return colors


def create_track(env: stock.CarRacing, body_def: b2BodyDef) -> tuple[np.ndarray, np.ndarray] | None:
    """The stock ``_create_track`` on ``env``: the same track, ``road_poly``, bodies and draws.

    ``body_def`` is a static body definition reused for every tile (the stock makes one per tile).
    Returns ``road_poly``'s corners (K, 4, 2) and colours (K, 3), or None where the stock method
    returns False. A tile's ``color`` (the array ``road_poly`` holds, which the contact listener
    changes in place) is a row of those colours: the colours read there are always the tiles'.
    """
    env.road = []
    i1, i2, glued, track, tiles = track_and_tiles(checkpoints(env), env.start_alpha)
    if i1 == -1:
        return None
    if env.verbose:
        print(f"Track generation: {i1}..{i2} -> {i2 - i1}-tiles track")
    if not glued:
        return None
    fixture_def, shape = env.fd_tile, env.fd_tile.shape
    # what world.CreateStaticBody, body.CreateFixture and shape.vertices = ... end in
    create_body, create_fixture = env.world._b2World__CreateBody, b2Body._b2Body__CreateFixture
    set_vertex, set_shape = shape.set_vertex, shape._b2PolygonShape__set_vertices_internal
    road, road_poly = env.road, env.road_poly
    colors = _tile_colors(env.road_color, tiles)
    rows = list(colors)  # views, one per polygon: what the tiles hold and the contact listener recolours
    k = 0
    for i, row in enumerate(tiles.tolist()):
        l1, r1, r2, l2 = (row[0], row[1]), (row[2], row[3]), (row[4], row[5]), (row[6], row[7])
        set_vertex(0, row[0], row[1])
        set_vertex(1, row[2], row[3])
        set_vertex(2, row[4], row[5])
        set_vertex(3, row[6], row[7])
        shape.vertexCount = 4
        set_shape()
        body = create_body(body_def)
        fixture = create_fixture(body, fixture_def)
        body.userData = body
        body.color = color = rows[k]
        body.road_visited = False
        body.road_friction = 1.0
        body.idx = i
        fixture.sensor = True
        road_poly.append(([l1, r1, r2, l2], color))
        road.append(body)
        k += 1
        if row[8] == row[8]:  # a border (NaN otherwise)
            border = [(row[8], row[9]), (row[10], row[11]), (row[12], row[13]), (row[14], row[15])]
            road_poly.append((border, _BORDER[i % 2]))
            k += 1
    env.track = [tuple(row) for row in track.tolist()]
    corners = tiles.reshape(-1, 8)  # each tile's road, then its border (NaN where none)
    return corners[~np.isnan(corners[:, 0])].reshape(-1, 4, 2), colors


def static_body_def() -> b2BodyDef:
    """The body definition ``world.CreateStaticBody(fixtures=...)`` builds, to be reused."""
    return b2BodyDef(type=b2_staticBody)
