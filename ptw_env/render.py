"""Pictures of an environment's current state: rear view of lean and steer, top view of the path.

Drawn with Pillow (a matplotlib dependency) so that a frame costs about a
millisecond; ``human`` mode shows the frames in a matplotlib window.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image, ImageDraw

if TYPE_CHECKING:  # pragma: no cover
    from .env import PTWRollEnv

WIDTH, HEIGHT = 640, 320
_BG = (250, 250, 247)
_INK = (30, 30, 30)
_REF = (40, 120, 220)
_BIKE = (200, 60, 40)
_GRID = (215, 215, 210)


def _rear_view(d: ImageDraw.ImageDraw, phi: float, phi_ref: float, delta: float, box: tuple[int, int, int, int]) -> None:
    x0, y0, x1, y1 = box
    cx, ground = (x0 + x1) // 2, y1 - 40
    d.line([(x0 + 10, ground), (x1 - 10, ground)], fill=_INK, width=2)
    length = (ground - y0) * 0.75

    def tip(angle: float, frac: float = 1.0) -> tuple[float, float]:
        # rear view, looking forward: +y (the lean direction of phi > 0) is drawn to the left
        return cx - frac * length * math.sin(angle), ground - frac * length * math.cos(angle)

    d.line([(cx, ground), tip(phi_ref)], fill=_REF, width=2)
    d.line([(cx, ground), tip(phi)], fill=_BIKE, width=9)
    d.ellipse([cx - 7, ground - 7, cx + 7, ground + 7], fill=_INK)
    # handlebar, perpendicular to the frame, its length shortened by the steer angle (seen from behind)
    hx, hy = tip(phi)
    half = 28 * max(0.2, math.cos(min(abs(delta) * 8.0, 1.4)))
    ux, uy = math.cos(phi), -math.sin(phi)
    d.line([(hx - half * ux, hy + half * uy), (hx + half * ux, hy - half * uy)], fill=_INK, width=4)
    # steering gauge
    gx, gy = cx, y1 - 14
    d.line([(gx - 60, gy), (gx + 60, gy)], fill=_GRID, width=3)
    d.line([(gx, gy - 5), (gx, gy + 5)], fill=_INK, width=1)
    sx = gx - max(-60.0, min(60.0, math.degrees(delta) * 12.0))
    d.ellipse([sx - 4, gy - 4, sx + 4, gy + 4], fill=_BIKE)
    d.text((x0 + 8, y0 + 6), f"roll {math.degrees(phi):6.1f} deg", fill=_BIKE)
    d.text((x0 + 8, y0 + 20), f"ref  {math.degrees(phi_ref):6.1f} deg", fill=_REF)
    d.text((x0 + 8, y1 - 30), f"steer {math.degrees(delta):5.2f} deg", fill=_INK)


def _top_view(d: ImageDraw.ImageDraw, env: "PTWRollEnv", box: tuple[int, int, int, int]) -> None:
    x0, y0, x1, y1 = box
    X, Y = env.profile.X, env.profile.Y
    trace = env.trace if len(env.trace) else np.zeros((1, 3))
    allx = np.concatenate([X, trace[:, 0]])
    ally = np.concatenate([Y, trace[:, 1]])
    span = max(np.ptp(allx), np.ptp(ally), 1.0)
    scale = (min(x1 - x0, y1 - y0) - 30) / span
    mx, my = (allx.max() + allx.min()) / 2, (ally.max() + ally.min()) / 2
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2

    def p(x: float, y: float) -> tuple[float, float]:
        return cx + (x - mx) * scale, cy - (y - my) * scale  # +Y drawn upward

    step = max(1, len(X) // 400)
    d.line([p(a, b) for a, b in zip(X[::step], Y[::step])], fill=_REF, width=2)
    if len(trace) > 1:
        st = max(1, len(trace) // 400)
        d.line([p(a, b) for a, b in zip(trace[::st, 0], trace[::st, 1])], fill=_BIKE, width=2)
    px, py = p(env.pose[0], env.pose[1])
    psi = env.pose[2]
    d.ellipse([px - 5, py - 5, px + 5, py + 5], fill=_BIKE)
    d.line([(px, py), (px + 18 * math.cos(psi), py - 18 * math.sin(psi))], fill=_INK, width=2)
    t = env.step_index * env.dt
    d.text((x0 + 8, y0 + 6), f"{env.scenario.name}  t {t:5.1f} s  v {3.6 * env.profile.vx[env.step_index]:5.1f} km/h", fill=_INK)
    d.text((x0 + 8, y1 - 18), "top view: reference (blue), ridden (red)", fill=_INK)


def draw_frame(env: "PTWRollEnv") -> np.ndarray:
    """An RGB frame (HEIGHT x WIDTH x 3, uint8) of the environment's current state."""
    img = Image.new("RGB", (WIDTH, HEIGHT), _BG)
    d = ImageDraw.Draw(img)
    half = WIDTH // 2
    d.line([(half, 8), (half, HEIGHT - 8)], fill=_GRID, width=1)
    x = env.state
    _rear_view(d, float(x[0]), float(env.profile.phi_ref[env.step_index]), float(x[1]), (0, 0, half, HEIGHT))
    _top_view(d, env, (half, 0, WIDTH, HEIGHT))
    return np.asarray(img, dtype=np.uint8)


def show_frame(frame: np.ndarray, fig=None):
    """Show a frame in a matplotlib window (``render_mode="human"``); returns the figure."""
    import matplotlib.pyplot as plt

    if fig is None:
        plt.ion()
        fig, ax = plt.subplots(figsize=(WIDTH / 100, HEIGHT / 100))
        ax.set_axis_off()
        fig._ptw_im = ax.imshow(frame)
    else:
        fig._ptw_im.set_data(frame)
    fig.canvas.draw_idle()
    plt.pause(0.001)
    return fig
