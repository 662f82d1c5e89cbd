"""NumPy rasteriser of the cart-pole scene (no OpenGL, no matplotlib).

Used by :meth:`pilco.envs.CartPoleSwingUp.render`; kept apart from the dynamics.
"""
from __future__ import annotations

import numpy as np

__all__ = ["draw_cartpole"]

_GREY = (120, 120, 120)
_RED = (220, 30, 30)
_BLUE = (40, 90, 200)
_ORANGE = (200, 130, 40)
_DARK = (30, 30, 30)
_BROWN = (110, 60, 10)


class _Canvas:
    """An RGB image of ``height x width`` pixels with masks of simple shapes."""

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height = width, height
        self.cols = np.arange(width, dtype=np.float64)[None, :] + 0.5
        self.rows = np.arange(height, dtype=np.float64)[:, None] + 0.5
        self.img = np.full((height, width, 3), 250, dtype=np.uint8)

    def fill(self, mask: np.ndarray, color: tuple[int, int, int]) -> None:
        self.img[np.broadcast_to(mask, (self.height, self.width))] = color

    def disk(self, px: float, py: float, radius: float) -> np.ndarray:
        return (self.cols - px) ** 2 + (self.rows - py) ** 2 <= radius**2

    def segment(self, p0: tuple[float, float], p1: tuple[float, float], width: float) -> np.ndarray:
        ax, ay = p0
        dx, dy = p1[0] - ax, p1[1] - ay
        length2 = dx * dx + dy * dy
        if length2 == 0.0:
            return self.disk(ax, ay, width / 2)
        cols, rows = self.cols, self.rows
        t = np.clip(((cols - ax) * dx + (rows - ay) * dy) / length2, 0.0, 1.0)
        return (cols - ax - t * dx) ** 2 + (rows - ay - t * dy) ** 2 <= (width / 2) ** 2


def draw_cartpole(
    cart_x: float,
    tip: np.ndarray,
    target_tip: np.ndarray,
    pole_length: float,
    width: int,
    height: int,
) -> np.ndarray:
    """Draw rail, target tip marker, cart and pole.

    Args:
        cart_x: cart position [m].
        tip: pendulum tip position ``(x, y)`` [m], shape ``(2,)``.
        target_tip: target tip position ``(x, y)`` [m], shape ``(2,)``.
        pole_length: pole length [m] (sets the visible range: at least 4 m).
        width, height: image size in pixels.

    Returns:
        ``uint8`` image of shape ``(height, width, 3)``.
    """
    canvas = _Canvas(width, height)
    cols, rows = canvas.cols, canvas.rows
    view_width = max(4.0, 8.0 * pole_length)  # metres visible horizontally
    scale = width / view_width  # pixels per metre
    cy = 0.5 * height  # rail row
    cx = 0.5 * width  # x = 0 column

    def to_px(xw: float, yw: float) -> tuple[float, float]:
        return cx + xw * scale, cy - yw * scale

    # Rail and tick marks every metre.
    canvas.fill(np.abs(rows - cy) <= 1.0, _GREY)
    for xm in np.arange(np.ceil(-view_width / 2), np.floor(view_width / 2) + 1):
        px, _ = to_px(xm, 0.0)
        canvas.fill((np.abs(cols - px) <= 0.75) & (np.abs(rows - cy - 6) <= 5), _GREY)

    # Target tip marker: red ring with a cross.
    tx, ty = to_px(*target_tip)
    r_t = max(4.0, 0.06 * scale)
    canvas.fill(canvas.disk(tx, ty, r_t) & ~canvas.disk(tx, ty, r_t - 2.5), _RED)
    canvas.fill(canvas.segment((tx - r_t, ty), (tx + r_t, ty), 1.5), _RED)
    canvas.fill(canvas.segment((tx, ty - r_t), (tx, ty + r_t), 1.5), _RED)

    # Cart.
    cart_w, cart_h = 0.4 * scale, 0.2 * scale
    px, py = to_px(float(cart_x), 0.0)
    canvas.fill((np.abs(cols - px) <= cart_w / 2) & (np.abs(rows - py) <= cart_h / 2), _BLUE)

    # Pole and tip.
    tip_px = to_px(*tip)
    pole_w = max(3.0, 0.04 * scale)
    canvas.fill(canvas.segment((px, py), tip_px, pole_w), _ORANGE)
    canvas.fill(canvas.disk(px, py, pole_w * 0.8), _DARK)
    canvas.fill(canvas.disk(tip_px[0], tip_px[1], pole_w), _BROWN)
    return canvas.img
