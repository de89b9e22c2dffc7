"""Rendering of a race: RGB frames drawn with PIL, an optional matplotlib window, animation files.

Imported lazily by :meth:`SOfARRaceEnv.render` and the demo, never at package import.

A frame shows, around a camera that follows the ego (north up, ``view_width`` = 180 m
across, centred 36 m ahead of the ego along its heading): grass, the tarmac between the
track edges (the edges of the off-track test, ``n = +width_left(s)`` and
``n = -width_right(s)``), the raceline, the barrier ellipses of the opponents (the zero
level set ``h = 0`` of the velocity-aware barrier: an ellipse in the Frenet frame mapped
to Cartesian coordinates, drawn with the longitudinal semi-axis of the side the ego would
approach from), the MIQP lateral plan (orange dots), the MPC prediction (cyan line), the
opponents (red; in the interactive world purple while a car makes or holds a defensive move and
pink while it lifts) and the ego (blue) as their 4.9 m x 1.9 m footprints, with a sensor
the opponents where the controller sees them (white outlines), and a text panel
with time, speed, gamma and overtakes (top left). A legend strip along the bottom of the frame, below
the view of the track, names the marks that appear in the world drawn (the defending and lifting colours
only where opponents defend or lift, the sensed positions only with a sensor; ``Renderer(legend=False)``
leaves it out and gives the whole frame to the view). Frames are drawn with PIL (~5-8 ms at 640 x 480).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from .control.barrier import BarrierParams, semi_axis_s
from .geometry import footprint_corners
from .vehicle import AV21, VehicleParams

__all__ = ["LEGEND", "Renderer", "legend_entries", "write_animation"]

_GRASS = (62, 112, 58)
_TARMAC = (92, 92, 98)
_EDGE = (235, 235, 235)
_RACELINE = (150, 150, 160)
_EGO = (40, 110, 230)
_OPPONENT = (215, 50, 45)
_DEFENDING = (150, 40, 200)
_LIFTING = (245, 150, 170)
_SEEN = (250, 250, 250)
_BARRIER = (255, 200, 60)
_PLAN = (255, 140, 0)
_MPC = (0, 230, 230)
_PANEL = (20, 20, 24)
_TEXT = (240, 240, 240)
_THETA = np.linspace(0.0, 2.0 * np.pi, 48)
_GIF_COLOURS = 127
"""Colours of an animation's palette; index 127 is the transparent "unchanged" colour of the delta frames."""
LEGEND = (
    ("ego", "car", _EGO),
    ("opponent", "car", _OPPONENT),
    ("defending", "car", _DEFENDING),
    ("lifting", "car", _LIFTING),
    ("sensed position", "outline", _SEEN),
    ("barrier h = 0", "ring", _BARRIER),
    ("MIQP lateral plan", "dots", _PLAN),
    ("MPC prediction", "line", _MPC),
    ("raceline", "line", _RACELINE),
    ("track edge", "line", _EDGE),
)
"""The legend of a frame: (label, mark, colour) of everything :meth:`Renderer.draw` draws (a frame's legend
shows those that appear in its world: :func:`legend_entries`)."""
_ROW, _MARK_W, _PAD, _GAP = 15, 22, 6, 14
"""Legend layout [px]: row height, mark width, padding, space between two entries of a row."""


def legend_entries(race, seen: bool) -> tuple[tuple[str, str, tuple[int, int, int]], ...]:
    """The entries of :data:`LEGEND` that can appear in ``race``'s world: defending and lifting only where the
    opponents defend or lift, the sensed positions only with a sensor (``seen``)."""
    config = getattr(getattr(race, "opponents", None), "config", None)
    defends = bool(config is not None and config.defence.active)
    lifts = bool(config is not None and config.pace.lift_rate > 0.0 and config.pace.lift_depth < 1.0)
    drop = {"defending": not defends, "lifting": not lifts, "sensed position": not seen}
    return tuple(entry for entry in LEGEND if not drop.get(entry[0], False))


def _font(size: int):
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: fixed-size bitmap font
        return ImageFont.load_default()


def _legend_image(font, entries, width: int) -> Image.Image:
    """The legend strip of ``entries``, ``width`` px wide: the entries left to right in as many rows as they
    need (drawn once, pasted into every frame)."""
    probe = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    places, x, row = [], _PAD, 0
    for label, _, _ in entries:
        w = _MARK_W + 6 + int(math.ceil(probe.textlength(label, font=font)))
        if x > _PAD and x + w > width - _PAD:
            x, row = _PAD, row + 1
        places.append((x, row))
        x += w + _GAP
    img = Image.new("RGB", (width, 2 * _PAD + _ROW * (row + 1) - 3), _PANEL)
    d = ImageDraw.Draw(img)
    for (label, mark, colour), (x0, i) in zip(entries, places):
        y = _PAD + _ROW * i + _ROW // 2 - 1
        x1 = x0 + _MARK_W
        if mark == "car":
            d.rectangle((x0 + 4, y - 3, x1 - 4, y + 3), fill=colour, outline=(0, 0, 0))
        elif mark == "outline":
            d.rectangle((x0 + 4, y - 3, x1 - 4, y + 3), outline=colour)
        elif mark == "ring":
            d.ellipse((x0, y - 4, x1, y + 4), outline=colour, width=1)
        elif mark == "dots":
            for x in range(x0 + 2, x1, 6):
                d.ellipse((x - 2, y - 2, x + 2, y + 2), fill=colour)
        else:
            d.line((x0, y, x1, y), fill=colour, width=2)
        d.text((x1 + 6, y - 7), label, fill=_TEXT, font=font)
    return img


class Renderer:
    """Draws frames of one track; keeps the static geometry between frames."""

    def __init__(self, track, vehicle: VehicleParams = AV21, barrier: BarrierParams = BarrierParams(),
                 width: int = 640, height: int = 480, view_width: float = 180.0, fps: int = 10,
                 legend: bool = True):
        self.track = track
        self.vehicle = vehicle
        self.barrier = barrier
        self.width = int(width)
        self.height = int(height)
        self.scale = self.width / float(view_width)
        """Pixels per metre."""
        self.fps = fps
        # the track surface as the Frenet edges of the off-track test, n = +width_left(s) and
        # n = -width_right(s), sampled every ~2 m; drawn per frame only where it is in view
        s = np.linspace(0.0, track.length, max(16, int(track.length / 2.0)), endpoint=False)
        self._mid = np.column_stack(track.to_cartesian(s, np.zeros_like(s)))
        self._left = np.column_stack(track.to_cartesian(s, np.asarray(track.width_left(s), float)))
        self._right = np.column_stack(track.to_cartesian(s, -np.asarray(track.width_right(s), float)))
        self._reach = float(max(np.max(track.width_left(s)), np.max(track.width_right(s))))
        self.look_ahead = 0.2 * float(view_width)
        """The camera centre is this far ahead of the ego along its heading [m]."""
        self._font = _font(14)
        self.legend = bool(legend)
        self._legend = None
        """The legend strip, drawn on the first frame (its entries depend on the world)."""
        self._figure = None
        self._image = None

    # ------------------------------------------------------------------ drawing
    @property
    def view_height(self) -> int:
        """Height of the view of the track [px]: the frame above the legend strip."""
        return self.height - (self._legend.size[1] if self._legend is not None else 0)

    def _to_px(self, xy: np.ndarray, centre: np.ndarray) -> list[tuple[float, float]]:
        p = (np.asarray(xy, float).reshape(-1, 2) - centre) * self.scale
        px = p[:, 0] + 0.5 * self.width
        py = 0.5 * self.view_height - p[:, 1]
        return list(zip(px.tolist(), py.tolist()))

    def _visible(self, xy: np.ndarray, centre: np.ndarray, margin: float = 1.2) -> np.ndarray:
        half = margin * 0.5 * np.array([self.width, self.view_height]) / self.scale
        return np.all(np.abs(np.asarray(xy, float).reshape(-1, 2) - centre) <= half, axis=1)

    def _visible_runs(self, centre: np.ndarray) -> list[np.ndarray]:
        """Index arrays of the contiguous stretches of track samples near the view."""
        half = 0.5 * np.array([self.width, self.view_height]) / self.scale + self._reach + 5.0
        idx = np.flatnonzero(np.all(np.abs(self._mid - centre) <= half, axis=1))
        if idx.size == 0:
            return []
        runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
        k = len(self._mid)
        if len(runs) > 1 and runs[0][0] == 0 and runs[-1][-1] == k - 1:  # a stretch across s = 0
            runs = [np.concatenate([runs[-1], runs[0]])] + runs[1:-1]
        # one more sample at both ends so that consecutive frames join seamlessly
        return [np.concatenate([[(r[0] - 1) % k], r, [(r[-1] + 1) % k]]) for r in runs]

    def barrier_ellipse(self, opp: np.ndarray, ego_v: float) -> np.ndarray:
        """Cartesian points (48, 2) of the zero level set of h around one opponent row (s, n, v)."""
        s_o, n_o, v_o = (float(x) for x in opp)
        c = np.cos(_THETA)
        # points behind the opponent (c < 0) are where an ego approaching from behind would be
        a = semi_axis_s(-10.0 * c, ego_v, v_o, self.barrier)
        x, y = self.track.to_cartesian(s_o + a * c, n_o + self.barrier.b * np.sin(_THETA))
        return np.column_stack([x, y])

    def draw(self, race, output=None, gamma: float | None = None, car: int = 0,
             seen: np.ndarray | None = None) -> np.ndarray:
        """One frame (height, width, 3) uint8 centred on controlled car ``car``; ``seen``: rows (s, n, v) of
        the opponents as the car's sensor reports them (drawn as outlines), None without a sensor."""
        if self.legend and self._legend is None:
            self._legend = _legend_image(_font(12), legend_entries(race, seen is not None), self.width)
        img = Image.new("RGB", (self.width, self.height), _GRASS)
        d = ImageDraw.Draw(img)
        ego = race.states[car]
        centre = ego[:2] + self.look_ahead * np.array([math.cos(ego[2]), math.sin(ego[2])])
        for run in self._visible_runs(centre):
            left, right = self._to_px(self._left[run], centre), self._to_px(self._right[run], centre)
            d.polygon(left + right[::-1], fill=_TARMAC)
            d.line(left, fill=_EDGE, width=2)
            d.line(right, fill=_EDGE, width=2)
            d.line(self._to_px(self._mid[run], centre), fill=_RACELINE, width=1)

        # barrier ellipses of everything the car must avoid
        ego_f = race.frenet[car]
        opponents = race.opponent_frenet(car)
        if opponents.shape[0]:
            gaps = np.abs(np.asarray(self.track.gap(opponents[:, 0], ego_f[0]), float))
            for row in opponents[gaps < 0.75 * self.width / self.scale]:
                pts = self._to_px(self.barrier_ellipse(row, float(ego_f[3])), centre)
                d.line(pts + pts[:1], fill=_BARRIER, width=1)

        if output is not None:
            if output.plan is not None:
                plan = output.plan
                s_abs = output.plan_s + np.asarray(plan.s, float)
                x, y = self.track.to_cartesian(s_abs, np.asarray(plan.d, float))
                for px, py in self._to_px(np.column_stack([x, y]), centre):
                    d.ellipse((px - 2, py - 2, px + 2, py + 2), fill=_PLAN)
            xp = np.asarray(output.mpc.x_pred, float)
            x, y = self.track.to_cartesian(output.ego_s + xp[:, 0], xp[:, 1])
            d.line(self._to_px(np.column_stack([x, y]), centre), fill=_MPC, width=2)

        # cars
        p = self.vehicle
        corners = race.obstacle_corners(car)
        colours = (_OPPONENT, _DEFENDING, _LIFTING)
        doing = race.opponents.behaviour()  # the scripted field comes first among the obstacles
        for k, quad in enumerate(corners):
            if self._visible(quad.mean(axis=0), centre).all():
                fill = colours[doing[k]] if k < doing.size else _OPPONENT
                d.polygon(self._to_px(quad, centre), fill=fill, outline=(0, 0, 0))
        if seen is not None and len(seen):
            s_seen, n_seen = np.asarray(seen, float)[:, 0], np.asarray(seen, float)[:, 1]
            x, y = self.track.to_cartesian(s_seen, n_seen)
            psi = np.asarray(self.track.heading(s_seen), float)
            for quad in footprint_corners(np.asarray(x, float), np.asarray(y, float), psi, p):
                if self._visible(quad.mean(axis=0), centre).all():
                    pts = self._to_px(quad, centre)
                    d.line(pts + pts[:1], fill=_SEEN, width=1)
        ego_quad = footprint_corners(ego[0], ego[1], ego[2], p)
        d.polygon(self._to_px(ego_quad, centre), fill=_EGO, outline=(255, 255, 255))

        # text panel
        lines = [
            f"t      {race.time:6.1f} s",
            f"speed  {float(ego[3]):6.1f} m/s",
            f"gamma  {gamma:6.2f}" if gamma is not None else "gamma     -",
            f"overt. {int(race.overtakes[car]):6d}",
        ]
        d.rectangle((6, 6, 170, 12 + 18 * len(lines)), fill=_PANEL)
        for i, text in enumerate(lines):
            d.text((12, 9 + 18 * i), text, fill=_TEXT, font=self._font)
        if self._legend is not None:
            img.paste(self._legend, self.legend_box[:2])
        return np.asarray(img, dtype=np.uint8)

    @property
    def legend_box(self) -> tuple[int, int, int, int] | None:
        """(left, top, right, bottom) of the legend strip in a frame [px], below the view of the track; None
        without a legend (or before the first frame)."""
        if self._legend is None:
            return None
        w, h = self._legend.size
        return 0, self.height - h, w, self.height

    # ------------------------------------------------------------------ window
    def show(self, frame: np.ndarray) -> None:
        """Display a frame in a matplotlib window (``render_mode="human"``)."""
        import matplotlib.pyplot as plt

        if self._figure is None or not plt.fignum_exists(self._figure.number):
            self._figure = plt.figure("SOfAR", figsize=(self.width / 100, self.height / 100))
            ax = self._figure.add_axes((0, 0, 1, 1))
            ax.set_axis_off()
            self._image = ax.imshow(frame)
            plt.show(block=False)
        else:
            self._image.set_data(frame)
        self._figure.canvas.draw_idle()
        plt.pause(1.0 / self.fps)

    def close(self) -> None:
        if self._figure is not None:
            import matplotlib.pyplot as plt

            plt.close(self._figure)
            self._figure = None


def write_animation(frames: Sequence[np.ndarray], path: str | os.PathLike, fps: float = 10.0,
                    progress: bool = False) -> str:
    """Write RGB frames to ``path``: a GIF (PIL) for ``.gif``, else a video through imageio's ffmpeg plugin.

    Returns the path written. An MP4 needs the ``imageio-ffmpeg`` package. ``progress`` shows a
    progress bar over the frames (tqdm, on stderr).
    """
    path = os.fspath(path)
    if not frames:
        raise ValueError("no frames to write")
    from tqdm import tqdm

    bar = tqdm(frames, desc=f"writing {os.path.basename(path)}", unit="frame", disable=not progress, leave=False)
    if path.lower().endswith(".gif"):
        # one palette for the whole animation, from a few frames spread over it: mapping onto a
        # fixed palette is ~10x faster than PIL's per-frame quantisation and does not flicker
        picks = np.linspace(0, len(frames) - 1, min(len(frames), 8)).astype(int)
        sample = Image.fromarray(np.concatenate([np.asarray(frames[i], np.uint8) for i in picks], axis=0))
        palette = sample.quantize(colors=_GIF_COLOURS, method=Image.Quantize.MEDIANCUT)
        colours = palette.getpalette()[: 3 * _GIF_COLOURS]
        colours += [0] * (3 * 256 - len(colours))  # index _GIF_COLOURS (transparent) and the unused rest
        images, previous = [], None
        for f in bar:
            index = np.asarray(Image.fromarray(np.asarray(f, np.uint8)).quantize(palette=palette,
                                                                              dither=Image.Dither.NONE))
            # a pixel unchanged since the previous frame is transparent (the previous frame shows through):
            # what PIL's optimize=True does, with numpy instead of its ~20 ms-a-frame pixel loop
            delta = index if previous is None else np.where(index == previous, _GIF_COLOURS, index).astype(np.uint8)
            previous = index
            image = Image.frombytes("P", (delta.shape[1], delta.shape[0]), np.ascontiguousarray(delta).tobytes())
            image.putpalette(colours)
            images.append(image)
        duration_ms = int(round(1000.0 / fps))
        images[0].save(path, save_all=True, append_images=images[1:], duration=duration_ms, loop=0, optimize=False,
                       transparency=_GIF_COLOURS, disposal=1)
        return path
    import imageio.v2 as imageio

    with imageio.get_writer(path, fps=fps) as writer:
        for f in bar:
            writer.append_data(np.asarray(f, np.uint8))
    return path
