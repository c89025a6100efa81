"""The per-frame picture of a run: what the cameras saw, what was detected, which track each
detection joined, and the global map so far.

Layout, left to right: the camera images (nuScenes order: front row FRONT_LEFT FRONT FRONT_RIGHT,
back row BACK_LEFT BACK BACK_RIGHT; other rigs in their own order, three per row) with the frame's
predictions projected onto the ground through the frame's camera geometry (``vis.overlay``),
coloured by class and labelled by track id; a bird's-eye panel around the ego (x forward up, y
left to the left) with the frame's ground truth (wide pale bands), the global map so far (thin)
and the predictions (after fusion: the points the run stores, labelled by track id; those the
method did not track are only counted in the header, the viewer draws them); and an overview
of the whole drive with the map so far, the path driven and the path ahead. See ``vis.replay``
for what "the map so far" is.

Drawn with Pillow (the BEV panels supersampled for smooth lines). No I/O except ``write_png``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw

from icmapper.atomic import atomic_path
from icmapper.data.types import CLASS_NAMES, PerceptionRange, world_to_ego
from icmapper.vis.overlay import (
    Overlay,
    draw_camera_overlays,
    middle_out,
    place_labels,
)
from icmapper.vis.replay import FrameView, MapItem, RunReplay
from icmapper.vis.style import (
    BACKGROUND_RGB,
    CLASS_RGB,
    EGO_RGB,
    PATH_RGB,
    TEXT_RGB,
    font,
    tint,
)

#: Track ids from here on are predictions the method did not track (``mapping.mapper``'s
#: UNTRACKED_ID_BASE; the run writer's fresh ids are larger still).
UNTRACKED_FROM = 1 << 40
_FRONT = ("CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT")
_BACK = ("CAM_BACK_LEFT", "CAM_BACK", "CAM_BACK_RIGHT")
_GAP = 4  # pixels between panels
_TITLE = 16  # pixels of a panel title strip
_HEADER = 26  # pixels of the picture's header
_SS = 2  # supersampling of the BEV panels
_EGO_SIZE = (4.8, 1.9)  # m, length and width of the ego box
_BEV_MARGIN = 10.0  # m of context around the perception range in the ego panel


def camera_order(names: tuple[str, ...]) -> list[list[int]]:
    """Rows of camera indices: the nuScenes layout when the rig has its six cameras, else the
    rig's order three per row."""
    if all(n in names for n in _FRONT + _BACK):
        return [[names.index(n) for n in _FRONT], [names.index(n) for n in _BACK]]
    idx = list(range(len(names)))
    return [idx[i : i + 3] for i in range(0, len(idx), 3)]


def is_tracked(track_id: int) -> bool:
    return int(track_id) < UNTRACKED_FROM


def prediction_overlays(view: FrameView) -> list[Overlay]:
    """The frame's tracked predictions as camera overlays, labelled with their track id (those
    the method did not track are left out of the cameras: low scores, mostly clutter)."""
    p = view.predictions
    return [
        Overlay(pts, int(cls), cls == 0, str(tid), 3)
        for cls, pts, tid in zip(p.classes.tolist(), p.points, p.track_ids.tolist(), strict=True)
        if is_tracked(tid)
    ]


class _Canvas:
    """A supersampled drawing surface mapping metres to pixels by ``to_px``."""

    def __init__(self, size: tuple[int, int]) -> None:
        self.size = size
        self.img = Image.new("RGB", (size[0] * _SS, size[1] * _SS), (255, 255, 255))
        self.draw = ImageDraw.Draw(self.img)

    def to_px(self, pts: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover
        raise NotImplementedError

    def line(self, pts: NDArray, rgb: tuple[int, int, int], width: float, closed: bool) -> None:
        p = np.asarray(pts, dtype=np.float64)
        if closed and p.shape[0] > 2:
            p = np.vstack([p, p[:1]])
        px = self.to_px(p)  # (n, 2)
        if px.shape[0] >= 2:
            w = max(1, int(round(width * _SS)))
            self.draw.line([tuple(q) for q in px.tolist()], fill=rgb, width=w, joint="curve")

    def polygon(self, pts: NDArray, fill: tuple[int, int, int] | None, outline: tuple) -> None:
        px = self.to_px(np.asarray(pts, dtype=np.float64))
        self.draw.polygon([tuple(q) for q in px.tolist()], fill=fill, outline=outline, width=_SS)

    def dots(self, pts: NDArray, rgb: tuple[int, int, int], radius: float) -> None:
        r = radius * _SS
        for x, y in self.to_px(np.asarray(pts, dtype=np.float64)).tolist():
            self.draw.ellipse((x - r, y - r, x + r, y + r), fill=rgb)

    def image(self) -> Image.Image:
        return self.img.resize(self.size, Image.Resampling.LANCZOS)


class _EgoCanvas(_Canvas):
    """Ego frame: x forward (up), y left (left); centred on the ego."""

    def __init__(self, size: tuple[int, int], scale: float) -> None:
        super().__init__(size)
        self.scale = scale * _SS
        self.cx, self.cy = size[0] * _SS / 2, size[1] * _SS / 2

    def to_px(self, pts: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.stack([self.cx - pts[:, 1] * self.scale, self.cy - pts[:, 0] * self.scale], 1)


class _WorldCanvas(_Canvas):
    """World frame, north up, fitted to the box lo..hi (m)."""

    def __init__(self, size: tuple[int, int], lo: NDArray, hi: NDArray) -> None:
        super().__init__(size)
        span = np.maximum(hi - lo, 1.0)
        self.scale = float(min(size[0] / span[0], size[1] / span[1])) * _SS
        self.centre = (lo + hi) / 2
        self.cx, self.cy = size[0] * _SS / 2, size[1] * _SS / 2

    def to_px(self, pts: NDArray[np.float64]) -> NDArray[np.float64]:
        d = pts - self.centre
        return np.stack([self.cx + d[:, 0] * self.scale, self.cy - d[:, 1] * self.scale], 1)


def _ego_box(pose: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(4, 2) corners of the ego box (ego frame, or world with a pose)."""
    ln, wd = _EGO_SIZE
    box = np.array([[ln / 2, wd / 2], [ln / 2, -wd / 2], [-ln / 2, -wd / 2], [-ln / 2, wd / 2]])
    box[:, 0] -= 0.9  # the ego origin sits on the rear axle, the box reaches ahead of it
    box[:, 0] += ln / 2 - 1.0
    if pose is None:
        return box
    return box @ pose[:2, :2].T + pose[:2, 3]


def _range_box(rng: PerceptionRange) -> NDArray[np.float64]:
    hx, hy = rng.half_x, rng.half_y
    return np.array([[hx, hy], [hx, -hy], [-hx, -hy], [-hx, hy]], dtype=np.float64)


def _title(img: Image.Image, text: str, size: int = 12) -> None:
    d = ImageDraw.Draw(img)
    d.rectangle((0, 0, img.width, _TITLE - 1), fill=(235, 235, 235))
    d.text((4, 1), text, fill=TEXT_RGB, font=font(size))


def bev_panel(view: FrameView, rng: PerceptionRange, height: int) -> Image.Image:
    """The ego-centred bird's-eye panel of a frame (see the module docstring)."""
    hx, hy = rng.half_x + _BEV_MARGIN, rng.half_y + _BEV_MARGIN
    scale = (height - _TITLE) / (2 * hx)
    width = int(round(2 * hy * scale))
    cv = _EgoCanvas((width, height - _TITLE), scale)
    cv.line(_range_box(rng), (200, 200, 200), 1, True)
    if view.gt is not None:
        for cls, pts in zip(view.gt.classes.tolist(), view.gt.points, strict=True):
            cv.line(pts, tint(CLASS_RGB[cls], 0.7), 6, cls == 0)
    for m in view.map_so_far:
        ego = world_to_ego(m.points, view.pose)  # (n, 2)
        if np.any((np.abs(ego[:, 0]) < hx + 5) & (np.abs(ego[:, 1]) < hy + 5)):
            cv.line(ego, tint(CLASS_RGB[m.cls], 0.35), 1.2, m.closed)
    p = view.predictions
    labels = []
    for cls, pts, tid in zip(p.classes.tolist(), p.points, p.track_ids.tolist(), strict=True):
        if not is_tracked(tid):
            continue  # counted in the header; the viewer draws them (dashed)
        cv.line(pts, (255, 255, 255), 4.5, cls == 0)  # a halo: predictions over the map
        cv.line(pts, CLASS_RGB[cls], 2.2, cls == 0)
        cv.dots(pts, CLASS_RGB[cls], 1.5)
        places = middle_out(cv.to_px(np.asarray(pts, np.float64)) / _SS)
        labels.append((places, str(tid), CLASS_RGB[cls]))
    cv.polygon(_ego_box(), EGO_RGB, EGO_RGB)
    img = cv.image()
    d = ImageDraw.Draw(img)
    place_labels(d, labels, 10)
    out = Image.new("RGB", (width, height), (255, 255, 255))
    out.paste(img, (0, _TITLE))
    _title(out, f"BEV, ego frame ({rng.name} m range)")
    return out


def overview_bounds(replay: RunReplay) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World box (lo (2,), hi (2,)) around the drive's path, map and ground truth."""
    parts = [np.asarray(replay.seq.poses)[:, :2, 3]]
    parts += [m.points for m in replay.map_items]
    gg = replay.global_gt if replay.source is not None else None
    parts += [g.points for g in gg or []]
    xy = np.concatenate(parts)  # (n, 2)
    reach = max(replay.rng.half_x, replay.rng.half_y)
    return xy.min(0) - reach / 2, xy.max(0) + reach / 2


def overview_panel(
    replay: RunReplay, view: FrameView, size: tuple[int, int], bounds: tuple[NDArray, NDArray]
) -> Image.Image:
    """The whole drive: map so far, ground truth, path driven and ahead, the ego now."""
    w, h = size
    cv = _WorldCanvas((w, h - _TITLE), *bounds)
    px_per_m = cv.scale / _SS
    for g in replay.global_gt or [] if replay.source is not None else []:
        cv.line(g.points, tint(CLASS_RGB[int(g.cls)], 0.75), max(2.0, 1.0 * px_per_m), g.closed)
    path = np.asarray(replay.seq.poses)[:, :2, 3]  # (T, 2)
    cv.line(path[view.t :], tint(PATH_RGB, 0.4), 1, False)
    for m in view.map_so_far:
        cv.line(m.points, CLASS_RGB[m.cls], 1.3, m.closed)
    cv.line(path[: view.t + 1], EGO_RGB, 1.5, False)
    rect = _range_box(replay.rng) @ view.pose[:2, :2].T + view.pose[:2, 3]  # (4, 2) world
    cv.line(rect, (120, 120, 120), 1, True)
    cv.polygon(_ego_box(view.pose), EGO_RGB, EGO_RGB)
    out = Image.new("RGB", size, (255, 255, 255))
    out.paste(cv.image(), (0, _TITLE))
    n = len(view.map_so_far)
    _title(out, f"global map so far: {n} instance{'s' * (n != 1)} (final shapes)")
    return out


def _legend_entries(ground_truth: bool) -> list[tuple[str, tuple[int, int, int], int]]:
    """(text, swatch colour, swatch width): the class colours, and the ground truth's pale band
    where the picture draws it."""
    out = [(name, CLASS_RGB[cls], 3) for cls, name in enumerate(CLASS_NAMES)]
    if ground_truth:
        out.append(("ground truth", tint(CLASS_RGB[1], 0.7), 6))
    return out


def _legend_width(d: ImageDraw.ImageDraw, ground_truth: bool) -> int:
    return sum(
        30 + int(d.textlength(t, font=font(12))) for t, _, _ in _legend_entries(ground_truth)
    )


def _legend(d: ImageDraw.ImageDraw, x: int, y: int, ground_truth: bool) -> None:
    f = font(12)
    for text, rgb, w in _legend_entries(ground_truth):
        d.line((x, y + 8, x + 18, y + 8), fill=rgb, width=w)
        d.text((x + 22, y), text, fill=TEXT_RGB, font=f)
        x += 30 + int(d.textlength(text, font=f))


def frame_picture(
    replay: RunReplay, t: int, bounds: tuple[NDArray, NDArray] | None = None
) -> Image.Image:
    """The picture of the run's frame t (module docstring). bounds: the overview's world box
    (``overview_bounds``; pass it when drawing many frames so it is computed once)."""
    view = replay.frame(t)
    panels: list[Image.Image] = []
    if view.images is not None and view.rig is not None:
        cams = draw_camera_overlays(view.images, view.rig, prediction_overlays(view))
        rows = camera_order(view.rig.names)
        ch, cw = view.rig.image_size
        ncol = max(len(r) for r in rows)
        grid = Image.new(
            "RGB",
            (ncol * cw + (ncol - 1) * _GAP, len(rows) * (ch + _TITLE) + (len(rows) - 1) * _GAP),
            BACKGROUND_RGB,
        )
        for r, row in enumerate(rows):
            for c, cam in enumerate(row):
                tile = Image.new("RGB", (cw, ch + _TITLE), (255, 255, 255))
                tile.paste(cams[cam], (0, _TITLE))
                _title(tile, view.rig.names[cam])
                grid.paste(tile, (c * (cw + _GAP), r * (ch + _TITLE + _GAP)))
        panels.append(grid)
    height = panels[0].height if panels else 440
    panels.append(bev_panel(view, replay.rng, height))
    b = bounds if bounds is not None else overview_bounds(replay)
    span = np.maximum(b[1] - b[0], 1.0)
    ow = int(np.clip(height * span[0] / span[1], height * 0.6, height * 1.6))
    panels.append(overview_panel(replay, view, (ow, height), b))
    width = sum(p.width for p in panels) + _GAP * (len(panels) + 1)
    p = view.predictions
    tracked = sum(is_tracked(i) for i in p.track_ids.tolist())
    head = (
        f"{replay.run.method} on {replay.name}   frame {view.t}/{len(replay) - 1}   "
        f"t = {view.timestamp - float(replay.seq.timestamps[0]):.1f} s   "
        f"{len(p)} predictions ({tracked} tracked)"
    )
    gt = view.gt is not None
    probe = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    head_end = _GAP + 2 + int(probe.textlength(head, font=font(14))) + 20
    legend_w = _legend_width(probe, gt)
    one_line = head_end + legend_w <= width - _GAP  # else the legend on a line of its own
    header = _HEADER if one_line else 2 * _HEADER - 6
    pic = Image.new("RGB", (width, height + header + _GAP), BACKGROUND_RGB)
    x = _GAP
    for panel in panels:
        pic.paste(panel, (x, header))
        x += panel.width + _GAP
    d = ImageDraw.Draw(pic)
    d.text((_GAP + 2, 5), head, fill=TEXT_RGB, font=font(14))
    if one_line:
        _legend(d, width - _GAP - legend_w, 6, gt)
    else:
        _legend(d, _GAP + 2, _HEADER - 2, gt)
    return pic


def write_png(img: Image.Image, path: str | os.PathLike) -> Path:
    """Writes ``img`` to ``path`` atomically (PNG); returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        img.save(tmp, format="PNG", optimize=True)
    return out


def map_item_count(items: list[MapItem]) -> dict[str, int]:
    """Instances per class name."""
    counts = dict.fromkeys(CLASS_NAMES, 0)
    for m in items:
        counts[CLASS_NAMES[m.cls]] += 1
    return counts
