"""CarRacing whose frames are Gymnasium's, bit for bit, computed several times faster (issue 9).

Gymnasium's ``CarRacing`` (O. Klimov; ``gymnasium/envs/box2d/car_racing.py``, v3) draws the whole
picture at every step, because the observation is that picture. Most of its time goes to
``_render_road``: about 800 road and grass polygons are rotated vertex by vertex with
``pygame.math.Vector2.rotate_rad``, tested for visibility in Python, and about 60 of them drawn.
``FastCarRacing`` keeps the physics, the track generation and their random-number use (it does not
touch them) and computes the same picture with less work:

- the polygons are transformed in numpy with pygame's own arithmetic (``rotate_like_pygame``), so
  every vertex is the same double as pygame's, and culled with the same inclusive bounds;
- polygons that pass that (generous) test but whose pixels all lie off the screen are not drawn:
  pygame would clip every one of their pixels away;
- the playfield polygon, when it covers the screen with its edges out of sight, becomes a fill of
  the colour pygame would write;
- the 1000 x 800 surfaces, the font and the rendered score text are reused instead of being made
  again at every frame.

Everything that reaches a pixel still goes through pygame's own drawing functions with the same
coordinates and colours in the same order, so observations and ``render()`` frames are
``np.array_equal`` to the stock class's; ``tests/test_car_racing.py`` checks it on the real
environment and ``benchmarks/car_racing.py`` on longer runs. Visited tiles change colour in place
(``road_poly`` holds a reference to each tile's colour array), so colours are read at every frame,
never copied.
"""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pygame
from gymnasium.envs.box2d import car_racing as stock
from pygame import gfxdraw

_W, _H = stock.WINDOW_W, stock.WINDOW_H
_CULL_MARGIN = stock.MAX_SHAPE_DIM
# pygame's Vector2 (src_c/math.c, _vector2_rotate_helper): its default epsilon for right angles
_PYGAME_VECTOR_EPSILON = 1e-6
# the playfield is a fill only if the screen, grown by this many pixels, is inside it: the edges'
# anti-aliased pixels and the scanline rounding stay within one pixel of the edge
_FILL_MARGIN = 3
_INT16 = 1 << 15


def rotate_like_pygame(points: np.ndarray, angle: float) -> np.ndarray:
    """``Vector2(p).rotate_rad(angle)`` for every row ``p`` of ``points`` (..., 2), bit for bit.

    pygame-ce (``src_c/math.c``) reduces the angle with ``fmod`` to [0, 2 pi), swaps coordinates
    exactly at multiples of pi/2 (within 1e-6), and otherwise computes ``cos*x - sin*y``,
    ``sin*x + cos*y`` in doubles; ``math.sin``/``math.cos`` call the same C library.
    """
    angle = math.fmod(angle, 2 * math.pi)
    if angle < 0:
        angle += 2 * math.pi
    x, y = points[..., 0], points[..., 1]
    epsilon = _PYGAME_VECTOR_EPSILON
    if math.fmod(angle + epsilon, math.pi / 2) < 2 * epsilon:
        quarter_turns = int((angle + epsilon) / (math.pi / 2)) % 4
        rotated = [(x, y), (-y, x), (-x, -y), (y, -x)][quarter_turns]
        return np.stack(rotated, axis=-1)
    sine, cosine = math.sin(angle), math.cos(angle)
    return np.stack((cosine * x - sine * y, sine * x + cosine * y), axis=-1)


def _grass_corners() -> np.ndarray:
    """The stock ``_render_road``'s grass squares, with its own float expressions."""
    dim = stock.GRASS_DIM
    return np.array([[(dim * x + dim, dim * y + 0), (dim * x + 0, dim * y + 0),
                      (dim * x + 0, dim * y + dim), (dim * x + dim, dim * y + dim)]
                     for x in range(-20, 20, 2) for y in range(-20, 20, 2)], dtype=np.float64)


def _playfield_corners() -> np.ndarray:
    bound = stock.PLAYFIELD
    return np.array([(bound, bound), (bound, -bound), (-bound, -bound), (-bound, bound)], dtype=np.float64)


def to_screen(corners: np.ndarray, zoom: float, translation, angle: float) -> np.ndarray:
    """The stock ``_draw_colored_polygon``'s pixel coordinates: rotate, then ``c * zoom + t``."""
    rotated = rotate_like_pygame(corners, angle)
    screen = np.empty_like(rotated)
    screen[..., 0] = rotated[..., 0] * zoom + translation[0]
    screen[..., 1] = rotated[..., 1] * zoom + translation[1]
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
    low, high = -_FILL_MARGIN, _FILL_MARGIN
    corners = ((low, low), (_W - 1 + high, low), (_W - 1 + high, _H - 1 + high), (low, _H - 1 + high))
    signs = set()
    for index in range(4):
        (x1, y1), (x2, y2) = pixels[index - 1].tolist(), pixels[index].tolist()
        for x, y in corners:
            cross = (x2 - x1) * (y - y1) - (y2 - y1) * (x - x1)
            if cross == 0:
                return False
            signs.add(cross > 0)
    return len(signs) == 1


class FastCarRacing(stock.CarRacing):
    """Gymnasium's CarRacing with the same observations and frames, drawn with less work.

    Every constructor argument, ``reset`` option and attribute is the stock class's; only
    ``_render`` and ``_render_road`` are replaced. ``self.surf`` is, as in the stock class, the
    last frame at full size (a surface reused from frame to frame).
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._canvas: pygame.Surface | None = None
        self._flipped: pygame.Surface | None = None
        self._probe: pygame.Surface | None = None
        self._font: pygame.font.Font | None = None
        self._score_text: tuple[str, pygame.Surface, pygame.Rect] | None = None
        self._road_source: list | None = None
        self._road_corners = np.empty((0, 4, 2))
        self._grass_corners = _grass_corners()
        self._playfield = _playfield_corners()

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
        self._draw_world(draw_particles=mode not in ["state_pixels_list", "state_pixels"])
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

    def _draw_world(self, draw_particles: bool) -> None:
        """Road, grass and car seen from the car's camera, flipped into ``self.surf`` (as the stock)."""
        if self._canvas is None:
            self._canvas = pygame.Surface((_W, _H))
            self._flipped = pygame.Surface((_W, _H))
            self._probe = pygame.Surface((1, 1))
        assert self.car is not None
        angle = -self.car.hull.angle
        zoom = 0.1 * stock.SCALE * max(1 - self.t, 0) + stock.ZOOM * stock.SCALE * min(self.t, 1)
        scroll_x = -(self.car.hull.position[0]) * zoom
        scroll_y = -(self.car.hull.position[1]) * zoom
        trans = pygame.math.Vector2((scroll_x, scroll_y)).rotate_rad(angle)
        trans = (_W / 2 + trans[0], _H / 4 + trans[1])
        self.surf = self._canvas
        self._render_road(zoom, trans, angle)
        self.car.draw(self._canvas, zoom, trans, angle, draw_particles)
        self._flip_canvas()

    def _flip_canvas(self) -> None:
        """``pygame.transform.flip(canvas, False, True)`` into the reused second surface."""
        source = pygame.surfarray.pixels2d(self._canvas)
        target = pygame.surfarray.pixels2d(self._flipped)
        target[...] = source[:, ::-1]
        del source, target  # release the surfaces' locks before anything blits onto them
        self.surf = self._flipped

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

    # --- the road ------------------------------------------------------------------------------

    def _render_road(self, zoom, translation, angle):
        self._draw_playfield(zoom, translation, angle)
        corners, colors = self._world_polygons()
        screen = to_screen(corners, zoom, translation, angle)
        inside = ((screen[..., 0] >= -_CULL_MARGIN) & (screen[..., 0] <= _W + _CULL_MARGIN)
                  & (screen[..., 1] >= -_CULL_MARGIN) & (screen[..., 1] <= _H + _CULL_MARGIN))
        drawn = np.flatnonzero(inside.any(axis=1))  # the stock test: some corner in the grown box
        pixels = pygame_pixels(screen[drawn])
        if pixels is not None:
            drawn = drawn[touches_screen(pixels)]
        grass = len(self._grass_corners)
        for index, points in zip(drawn.tolist(), screen[drawn].tolist()):
            color = self.grass_color if index < grass else [int(c) for c in colors[index - grass]]
            gfxdraw.aapolygon(self.surf, points, color)
            gfxdraw.filled_polygon(self.surf, points, color)

    def _draw_playfield(self, zoom, translation, angle) -> None:
        """The background: a fill when the playfield polygon covers the screen, else pygame's polygon."""
        screen = to_screen(self._playfield, zoom, translation, angle)
        pixels = pygame_pixels(screen)
        if pixels is not None and covers_screen(pixels):
            self._probe.fill(0)
            gfxdraw.hline(self._probe, 0, 0, 0, self.bg_color)  # the pixel value gfxdraw writes
            self.surf.fill(self._probe.get_at_mapped((0, 0)))
            return
        self.surf.fill(0)  # a new stock surface is black
        points = screen.tolist()
        gfxdraw.aapolygon(self.surf, points, self.bg_color)
        gfxdraw.filled_polygon(self.surf, points, self.bg_color)

    def _world_polygons(self) -> tuple[np.ndarray, list]:
        """Grass then road corners (K, 4, 2), and the road colours (live references, never copies)."""
        road_poly = self.road_poly
        if self._road_source is not road_poly or len(self._road_corners) != len(self._grass_corners) + len(road_poly):
            road = np.array([poly for poly, _ in road_poly], dtype=np.float64).reshape(-1, 4, 2)
            self._road_corners = np.concatenate([self._grass_corners, road])
            self._road_colors = [color for _, color in road_poly]
            self._road_source = road_poly
        return self._road_corners, self._road_colors

    def close(self):
        self._font = None  # a Font must not outlive pygame.quit(), which the stock close() may call
        self._score_text = None
        super().close()


STOCK_ID = "CarRacingStock-v3"


def register() -> None:
    """``CarRacing-v3`` (so also the retired ``CarRacing-v0``) makes ``FastCarRacing``; ``STOCK_ID`` Gymnasium's class.

    Idempotent. The stock id keeps every setting of Gymnasium's spec (time limit, reward threshold),
    so a result can be checked against Gymnasium's own class with ``--environment CarRacingStock-v3``.
    """
    spec = gym.registry.get("CarRacing-v3")
    if spec is None or STOCK_ID in gym.registry:
        return
    gym.registry[STOCK_ID] = dataclasses.replace(spec, id=STOCK_ID)
    gym.registry["CarRacing-v3"] = dataclasses.replace(spec, entry_point=f"{__name__}:{FastCarRacing.__name__}")


register()
