"""Pygame renderer for formation frames (2D top view, 3D oblique view).

A *frame* is a plain dict produced by the environment once per render call; the
renderer knows nothing else about the env. Its keys (exactly these; world units
are metres, ``n`` agents in ``d`` dimensions):

========================  =================  ==============================================
key                       shape / type       meaning
========================  =================  ==============================================
``positions``             (n, d) float, m    current agent positions
``leaders``               (n_l,) int         indices of leader agents (others are followers)
``edges``                 (m, 2) int         communication edges (drawn if m <= max_edges)
``targets``               (n, d) or None     affine-target ghost positions
``obstacles``             dict               ``segments`` (k, 2, d) walls, ``circles``
                                             (c, d + 1) centre + radius; either may be empty
``goal``                  (n, d) or None     goal-pose ghost positions
``trail``                 (T, n, d)          recent positions, oldest first; T may be 0
``bounds``                (2, d)             world min (row 0) and max (row 1)
``agent_radius``          float, m           agent disc radius (drawn at least 2 px)
``text``                  str                status line (top left)
``time``                  float, s           simulation time
========================  =================  ==============================================

``rgb_array`` mode draws on an off-screen ``pygame.Surface`` and never touches the
display, so it runs headless (``SDL_VIDEODRIVER=dummy`` or no display at all).
``human`` mode opens a window with ``pygame.display`` and ticks a clock at ``fps``.

3D frames use a fixed orthographic camera: the world is rotated about z by
``yaw`` (30 degrees) and viewed from ``elevation`` (25 degrees) above the
horizontal; agents are sorted by depth, shaded as spheres and scaled by +-15 %
with depth. The camera frames the team and what it must pass, not the whole world
box (:meth:`Renderer.view_box`): the agents, their goal, targets and trail and the
obstacles reaching into that region, padded and kept within the world box; the floor
grid and the wireframe drawn are that box. Within an episode (frame times not
decreasing) the view only grows, so an animation does not zoom back and forth.
Large swarms (n > ``large_n``) are painted as small squares straight into the
pixel array, so a 10,000-agent frame stays well under 0.5 s.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import numpy as np
import pygame
from numpy.typing import NDArray

from formation_env.core.errors import ControlDimension, FormationError
from formation_env.core.validation import check_shape

__all__ = ["FRAME_KEYS", "PALETTE", "RENDER_MODES", "Renderer"]

RENDER_MODES: tuple[str, ...] = ("human", "rgb_array")

FRAME_KEYS: frozenset[str] = frozenset(
    {
        "positions",
        "leaders",
        "edges",
        "targets",
        "obstacles",
        "goal",
        "trail",
        "bounds",
        "agent_radius",
        "text",
        "time",
    }
)

Colour = tuple[int, int, int]

PALETTE: Mapping[str, Colour] = {
    "background": (250, 250, 248),
    "frame": (205, 205, 205),
    "grid": (232, 232, 232),
    "edge": (175, 175, 175),
    "wall": (55, 55, 60),
    "obstacle": (120, 120, 130),
    "goal": (30, 160, 60),
    "target": (150, 140, 200),
    "leader": (230, 85, 25),
    "follower": (40, 105, 215),
    "outline": (35, 35, 40),
    "shadow": (215, 215, 215),
    "text": (25, 25, 30),
    "note": (180, 40, 40),
}
"""RGB colours of every drawn element (leaders orange-red, followers blue, goal green)."""


def _mix(colour: Colour, other: Colour, t: float) -> Colour:
    """Blend ``colour`` toward ``other`` by ``t`` in [0, 1]."""
    return (
        round(colour[0] + (other[0] - colour[0]) * t),
        round(colour[1] + (other[1] - colour[1]) * t),
        round(colour[2] + (other[2] - colour[2]) * t),
    )


def _nice_length(target: float) -> float:
    """Largest 1, 2 or 5 times a power of ten not above ``target`` (> 0)."""
    base = 10.0 ** math.floor(math.log10(target))
    for mult in (5.0, 2.0, 1.0):
        if mult * base <= target:
            return mult * base
    return base


class Renderer:
    """Draw formation frames with pygame, off-screen (``rgb_array``) or in a window (``human``).

    Args:
        d: spatial dimension of the frames, 2 or 3.
        render_mode: ``"rgb_array"`` (``draw`` returns an (height, width, 3) uint8 array)
            or ``"human"`` (``draw`` shows the frame in a window and returns None).
        width, height: image size in pixels.
        fps: frame rate of the ``human`` window clock (frames per second).

    Raises:
        ValueError: unknown ``render_mode``, ``d`` not 2 or 3, a size under 64 px, or fps <= 0.

    Attributes:
        max_edges: edges are drawn only when m <= max_edges (else a note is shown).
        large_n: above this many agents, agents, ghosts and trails are painted as
            small squares/pixels with numpy instead of pygame circles (leaders stay discs).
        max_trail_segments: above n * T trail segments, trails are painted as pixels.
        max_shadows: 3D floor shadows and drop lines are drawn for n <= max_shadows.
        yaw, elevation: 3D camera angles in degrees.
        view_pad: 3D view margin around the team's region, a fraction of its largest side.
        min_view: 3D view's smallest side (m), so a small or resting team is not blown up to the frame.
    """

    max_edges: int = 20_000
    large_n: int = 2_000
    max_trail_segments: int = 20_000
    max_shadows: int = 200
    yaw: float = 30.0
    elevation: float = 25.0
    view_pad: float = 0.25
    min_view: float = 2.0

    def __init__(self, d: int, render_mode: str, width: int = 640, height: int = 640, fps: int = 20) -> None:
        if render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be one of {list(RENDER_MODES)}, got {render_mode!r}")
        if d not in (2, 3):
            raise ValueError(f"Renderer d must be 2 or 3, got {d}")
        if width < 64 or height < 64:
            raise ValueError(f"Renderer size must be at least 64 x 64 pixels, got {width} x {height}")
        if fps <= 0:
            raise ValueError(f"Renderer fps must be positive, got {fps}")
        self.d = int(d)
        self.render_mode = render_mode
        self.width = int(width)
        self.height = int(height)
        self.fps = int(fps)

        # Camera matrix: rows are screen-right, screen-up and toward-camera in world axes.
        yaw, elev = math.radians(self.yaw), math.radians(self.elevation)
        rz = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
        view = np.array(
            [
                [1.0, 0.0, 0.0],
                [0.0, math.sin(elev), math.cos(elev)],
                [0.0, -math.cos(elev), math.sin(elev)],
            ]
        )
        self._camera: NDArray[np.float64] = view @ rz

        self._font_px = max(12, round(min(self.width, self.height) / 36))
        self._line_px = self._font_px + 3
        self._margin = max(8, round(0.04 * min(self.width, self.height)))
        self._top = self._margin + 2 * self._line_px
        self._bottom = self._margin + self._line_px + 4

        self._surface: pygame.Surface | None = None
        self._window: pygame.Surface | None = None
        self._clock: pygame.time.Clock | None = None
        self._font: pygame.font.Font | None = None
        self._font_tried = False
        # World-to-screen transform, set from a frame's bounds.
        self._bounds: NDArray[np.float64] | None = None
        self._scale = 1.0
        self._centre_plane = np.zeros(2)
        self._centre_px = np.array([self.width / 2.0, self.height / 2.0])
        self._depth_range = (0.0, 1.0)
        # 3D view of the current episode: its box (2, 3), the world box and the time of the frame it was grown by.
        self._view: NDArray[np.float64] | None = None
        self._view_world: NDArray[np.float64] | None = None
        self._view_time = -math.inf

    # ------------------------------------------------------------------ transform

    def view_box(self, frame: Mapping[str, Any]) -> NDArray[np.float64]:
        """The 3D view of ``frame``: min and max corners (2, 3), metres.

        The box of the agents, goal, affine targets and trail, grown by every obstacle (circle, wall segment) that
        reaches into it padded by ``view_pad`` of its largest side, then padded by that margin plus the agent radius,
        widened to at least ``min_view`` per side and cut to the world box (``frame["bounds"]``) where it holds the
        team. Within an episode (a frame time not below the last one, the same world box) it is the union with the
        previous view; an earlier time starts afresh (:meth:`reset_view` does too). 2D frames: the world box.
        """
        return self._view_box(self._check_frame(frame))

    def _view_box(self, f: dict[str, Any]) -> NDArray[np.float64]:
        """:meth:`view_box` of a checked frame (``_check_frame``)."""
        world = self._checked_bounds(f["bounds"])
        if self.d == 2:
            return world
        parts = [f["positions"], f["trail"].reshape(-1, 3)]
        parts += [p for p in (f["goal"], f["targets"]) if p is not None]
        pts = np.concatenate(parts)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if pts.shape[0] == 0:
            return world
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        margin = self.view_pad * max(float(np.max(hi - lo)), self.min_view)
        reach_lo, reach_hi = lo - margin, hi + margin
        circles, segments = f["circles"], f["segments"]
        if circles.shape[0]:
            c, rad = circles[:, :3], circles[:, 3]
            ok = np.all(np.isfinite(circles), axis=1)
            ok &= np.linalg.norm(np.clip(c, reach_lo, reach_hi) - c, axis=1) <= rad
            if ok.any():
                lo = np.minimum(lo, (c[ok] - rad[ok, None]).min(axis=0))
                hi = np.maximum(hi, (c[ok] + rad[ok, None]).max(axis=0))
        if segments.shape[0]:
            ok = np.all(np.isfinite(segments), axis=(1, 2))
            ok &= np.all(segments.min(axis=1) <= reach_hi, axis=1) & np.all(segments.max(axis=1) >= reach_lo, axis=1)
            if ok.any():
                lo = np.minimum(lo, segments[ok].min(axis=(0, 1)))
                hi = np.maximum(hi, segments[ok].max(axis=(0, 1)))
        pad = self.view_pad * max(float(np.max(hi - lo)), self.min_view) + f["agent_radius"]
        lo, hi = lo - pad, hi + pad
        short = hi - lo < self.min_view
        mid = (lo + hi) / 2.0
        lo, hi = np.where(short, mid - self.min_view / 2, lo), np.where(short, mid + self.min_view / 2, hi)
        inside = (lo < world[1]) & (hi > world[0])  # cut to the world box on the axes where the region meets it
        lo, hi = np.where(inside, np.maximum(lo, world[0]), lo), np.where(inside, np.minimum(hi, world[1]), hi)
        same = self._view is not None and self._view_world is not None and np.array_equal(self._view_world, world)
        if same and f["time"] >= self._view_time and self._view is not None:
            lo, hi = np.minimum(lo, self._view[0]), np.maximum(hi, self._view[1])
        self._view, self._view_world, self._view_time = np.stack([lo, hi]), world, f["time"]
        return self._view.copy()

    def reset_view(self) -> None:
        """Forget the 3D view of the episode drawn so far: the next frame is framed afresh."""
        self._view, self._view_world, self._view_time = None, None, -math.inf

    def _checked_bounds(self, bounds: Any) -> NDArray[np.float64]:
        """``bounds`` as a (2, d) float array: finite, max >= min per axis (FormationError otherwise)."""
        b = np.asarray(bounds, dtype=np.float64)
        check_shape(b, (2, self.d), "frame['bounds']")
        if not np.all(np.isfinite(b)):
            raise FormationError("frame['bounds'] holds non-finite values")
        if np.any(b[1] < b[0]):
            raise FormationError(f"frame['bounds'] max must be >= min per axis, got min {b[0]} and max {b[1]}")
        return b

    def set_bounds(self, bounds: Any) -> None:
        """Fit the box ``bounds`` ((2, d), metres: min row, max row) into the image.

        Keeps the aspect ratio and leaves a margin plus bands for the status text (top)
        and legend (bottom). ``draw`` calls this with each frame's ``bounds`` (2D) or :meth:`view_box` (3D).
        """
        b = self._checked_bounds(bounds)
        self._bounds = b
        if self.d == 2:
            corners = b
        else:
            corners = np.array([[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        plane = self._project(corners)
        lo, hi = plane.min(axis=0), plane.max(axis=0)
        extent = hi - lo
        floor = max(float(extent.max()) * 1e-3, 1e-9)
        extent = np.where(extent > floor, extent, max(float(extent.max()), 1.0))
        avail_w = self.width - 2 * self._margin
        avail_h = self.height - self._top - self._bottom
        self._scale = float(min(avail_w / extent[0], avail_h / extent[1]))
        self._centre_plane = (lo + hi) / 2.0
        self._centre_px = np.array([self.width / 2.0, self._top + avail_h / 2.0])
        if self.d == 3:
            depth = corners @ self._camera[2]
            self._depth_range = (float(depth.min()), float(max(depth.max(), depth.min() + 1e-12)))

    @property
    def pixels_per_metre(self) -> float:
        """Scale of the current transform in pixels per metre (in the view plane for 3D)."""
        return self._scale

    def _project(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """World (..., d) to view-plane (..., 2) metres (identity for 2D)."""
        if self.d == 2:
            return points
        return points @ self._camera[:2].T

    def depth(self, points: Any) -> NDArray[np.float64]:
        """Distance toward the 3D camera of world points (..., d) -> (...,) metres (zeros in 2D).

        Larger is closer to the viewer; ``draw`` paints in increasing depth order.
        """
        p = np.asarray(points, dtype=np.float64)
        if self.d == 2:
            return np.zeros(p.shape[:-1])
        return p @ self._camera[2]

    def world_to_screen(self, points: Any) -> NDArray[np.float64]:
        """Map world points (..., d) in metres to pixel coordinates (..., 2) (x right, y down).

        Uses the transform of the last ``set_bounds`` (or ``draw``) call.

        Raises:
            FormationError: no bounds have been set yet.
            ControlDimension: the last axis is not d.
        """
        self._require_bounds()
        p = np.asarray(points, dtype=np.float64)
        if p.ndim == 0 or p.shape[-1] != self.d:
            raise ControlDimension(f"points must have shape (..., {self.d}), got {p.shape}")
        plane = self._project(p) - self._centre_plane
        out = np.empty(plane.shape, dtype=np.float64)
        out[..., 0] = self._centre_px[0] + plane[..., 0] * self._scale
        out[..., 1] = self._centre_px[1] - plane[..., 1] * self._scale
        return out

    # ------------------------------------------------------------------ frame checks

    def _check_frame(self, frame: Mapping[str, Any]) -> dict[str, Any]:
        """Validate ``frame`` and return a dict of float/int arrays with the documented shapes."""
        if not isinstance(frame, Mapping):
            raise TypeError(f"frame must be a dict, got {type(frame).__name__}")
        missing = FRAME_KEYS - set(frame)
        unknown = set(frame) - FRAME_KEYS
        if missing or unknown:
            raise FormationError(
                f"frame keys must be {sorted(FRAME_KEYS)}; missing {sorted(missing)}, unknown {sorted(unknown)}"
            )
        d = self.d
        pos = np.asarray(frame["positions"], dtype=np.float64)
        if pos.ndim != 2 or pos.shape[1] != d:
            raise ControlDimension(f"frame['positions'] must have shape (n, {d}), got {pos.shape}")
        n = pos.shape[0]

        leaders = np.asarray(frame["leaders"])
        if leaders.dtype == np.bool_:
            check_shape(leaders, (n,), "frame['leaders'] (boolean mask)")
            leaders = np.flatnonzero(leaders)
        leaders = leaders.reshape(-1)
        if leaders.size and not np.issubdtype(leaders.dtype, np.integer):
            raise FormationError(f"frame['leaders'] must hold integer indices, got dtype {leaders.dtype}")
        leaders = leaders.astype(np.int64)
        if leaders.size and (leaders.min() < 0 or leaders.max() >= n):
            raise FormationError(f"frame['leaders'] indices must lie in [0, {n}), got {leaders.min()}..{leaders.max()}")

        edges = np.asarray(frame["edges"])
        edges = np.zeros((0, 2), dtype=np.int64) if edges.size == 0 else edges.astype(np.int64)
        check_shape(edges, (None, 2), "frame['edges']")
        if edges.size and (edges.min() < 0 or edges.max() >= n):
            raise FormationError(f"frame['edges'] indices must lie in [0, {n}), got {edges.min()}..{edges.max()}")

        def optional_poses(key: str) -> NDArray[np.float64] | None:
            if frame[key] is None:
                return None
            arr = np.asarray(frame[key], dtype=np.float64)
            check_shape(arr, (n, d), f"frame[{key!r}]")
            return arr

        obstacles = frame["obstacles"] or {}
        if not isinstance(obstacles, Mapping):
            raise TypeError(f"frame['obstacles'] must be a dict, got {type(obstacles).__name__}")
        extra = set(obstacles) - {"segments", "circles"}
        if extra:
            raise FormationError(
                f"frame['obstacles'] keys must be 'segments' and 'circles', got unknown {sorted(extra)}"
            )
        segments = np.asarray(obstacles.get("segments", np.zeros((0, 2, d))), dtype=np.float64)
        segments = segments.reshape(0, 2, d) if segments.size == 0 else segments
        check_shape(segments, (None, 2, d), "frame['obstacles']['segments']")
        circles = np.asarray(obstacles.get("circles", np.zeros((0, d + 1))), dtype=np.float64)
        circles = circles.reshape(0, d + 1) if circles.size == 0 else circles
        check_shape(circles, (None, d + 1), "frame['obstacles']['circles']")

        trail = frame["trail"]
        trail = np.zeros((0, n, d)) if trail is None else np.asarray(trail, dtype=np.float64)
        trail = trail.reshape(0, n, d) if trail.size == 0 else trail
        check_shape(trail, (None, n, d), "frame['trail']")

        radius = float(frame["agent_radius"])
        if not (radius >= 0.0 and math.isfinite(radius)):
            raise FormationError(f"frame['agent_radius'] must be finite and >= 0, got {radius}")
        return {
            "positions": pos,
            "leaders": leaders,
            "edges": edges,
            "targets": optional_poses("targets"),
            "goal": optional_poses("goal"),
            "segments": segments,
            "circles": circles,
            "trail": trail,
            "bounds": frame["bounds"],
            "agent_radius": radius,
            "text": str(frame["text"]),
            "time": float(frame["time"]),
        }

    # ------------------------------------------------------------------ drawing

    def draw(self, frame: Mapping[str, Any]) -> NDArray[np.uint8] | None:
        """Draw one frame (see the module docstring for its keys and shapes).

        Returns:
            ``rgb_array``: an (height, width, 3) uint8 image. ``human``: None, after showing
            the frame in the window and waiting on the clock to keep ``fps``.

        Raises:
            FormationError / ControlDimension (both ValueError): missing or unknown keys,
            wrong shapes, out-of-range indices, bad bounds or radius.
        """
        f = self._check_frame(frame)
        self.set_bounds(self._view_box(f) if self.d == 3 else f["bounds"])
        surf = self._get_surface()
        surf.fill(PALETTE["background"])
        n = f["positions"].shape[0]
        large = n > self.large_n
        notes: list[str] = []

        world_clip = pygame.Rect(
            0, self._top - self._margin // 2, self.width, self.height - self._top - self._bottom + self._margin
        )
        surf.set_clip(world_clip)
        self._draw_box(surf)
        if self.d == 3 and n <= self.max_shadows:
            self._draw_shadows(surf, f["positions"], f["agent_radius"])
        self._draw_obstacles(surf, f["segments"], f["circles"])
        m = f["edges"].shape[0]
        if m <= self.max_edges:
            self._draw_edges(surf, f["positions"], f["edges"])
        else:
            notes.append(f"edges hidden (m = {m} > {self.max_edges})")
        is_leader = np.zeros(n, dtype=bool)
        is_leader[f["leaders"]] = True
        self._draw_trail(surf, f["trail"], f["positions"], is_leader)
        self._draw_ghosts(surf, f["goal"], f["targets"], f["agent_radius"], large)
        self._draw_agents(surf, f["positions"], is_leader, f["agent_radius"], large)
        surf.set_clip(None)

        status = f"t = {f['time']:.2f} s   n = {n}   leaders = {int(is_leader.sum())}   edges = {m}"
        self._draw_text(surf, f["text"], status, notes)
        self._draw_legend(surf, f)

        if self.render_mode == "human":
            self._show(surf)
            return None
        return (
            np.frombuffer(pygame.image.tobytes(surf, "RGB"), dtype=np.uint8).reshape(self.height, self.width, 3).copy()
        )

    def close(self) -> None:
        """Close the window (``human``) and drop the off-screen surface; ``draw`` may reopen them."""
        if self._window is not None:
            pygame.display.quit()
            self._window = None
            self._clock = None
        self._surface = None

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ helpers

    def _require_bounds(self) -> NDArray[np.float64]:
        if self._bounds is None:
            raise FormationError("Renderer needs bounds: call set_bounds() or draw() first")
        return self._bounds

    def _get_surface(self) -> pygame.Surface:
        if self._surface is None:
            self._surface = pygame.Surface((self.width, self.height), 0, 32)
        return self._surface

    def _get_font(self) -> pygame.font.Font | None:
        """The status/legend font, or None when pygame's font module is unavailable."""
        if not self._font_tried:
            self._font_tried = True
            try:
                if not pygame.font.get_init():
                    pygame.font.init()
                self._font = pygame.font.Font(None, self._font_px)
            except (pygame.error, NotImplementedError, OSError, ImportError, AttributeError):
                self._font = None
        return self._font

    def _show(self, surf: pygame.Surface) -> None:
        if self._window is None:
            pygame.display.init()
            self._window = pygame.display.set_mode((self.width, self.height))
            pygame.display.set_caption("formation_env")
            self._clock = pygame.time.Clock()
        pygame.event.pump()
        self._window.blit(surf, (0, 0))
        pygame.display.flip()
        if self._clock is not None:
            self._clock.tick(self.fps)

    def _screen(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """``world_to_screen`` clipped to a safe int range (non-finite rows become NaN)."""
        return np.clip(self.world_to_screen(points), -30_000.0, 30_000.0)

    def _depth_t(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Depth normalised to [0, 1] over the bounds box (1 = nearest); 0.5 in 2D."""
        if self.d == 2:
            return np.full(points.shape[:-1], 0.5)
        lo, hi = self._depth_range
        return np.clip((self.depth(points) - lo) / (hi - lo), 0.0, 1.0)

    def _radius_px(self, radius_m: float) -> float:
        return max(2.0, radius_m * self._scale)

    def _draw_box(self, surf: pygame.Surface) -> None:
        """2D: the bounds rectangle. 3D: a floor grid and the wireframe of the bounds box."""
        b = self._require_bounds()
        if self.d == 2:
            corners = self.world_to_screen(
                np.array([[b[0, 0], b[0, 1]], [b[1, 0], b[0, 1]], [b[1, 0], b[1, 1]], [b[0, 0], b[1, 1]]])
            )
            pygame.draw.lines(surf, PALETTE["frame"], True, corners.tolist(), 1)
            return
        z0 = b[0, 2]
        for t in np.linspace(0.0, 1.0, 6)[1:-1]:
            x = b[0, 0] + t * (b[1, 0] - b[0, 0])
            y = b[0, 1] + t * (b[1, 1] - b[0, 1])
            for p, q in (([x, b[0, 1], z0], [x, b[1, 1], z0]), ([b[0, 0], y, z0], [b[1, 0], y, z0])):
                a, c = self.world_to_screen(np.array([p, q]))
                pygame.draw.line(surf, PALETTE["grid"], a.tolist(), c.tolist(), 1)
        lo, hi = b[0], b[1]
        for axis in range(3):
            others = [k for k in range(3) if k != axis]
            for u in (0, 1):
                for v in (0, 1):
                    start = np.empty(3)
                    start[others[0]] = b[u, others[0]]
                    start[others[1]] = b[v, others[1]]
                    start[axis] = lo[axis]
                    end = start.copy()
                    end[axis] = hi[axis]
                    a, c = self.world_to_screen(np.array([start, end]))
                    pygame.draw.line(surf, PALETTE["frame"], a.tolist(), c.tolist(), 1)
        font = self._get_font()
        if font is not None:
            for axis, name in enumerate("xyz"):
                p = lo.copy()
                p[axis] = hi[axis] + 0.04 * (hi[axis] - lo[axis] + 1e-9)
                label = font.render(name, True, PALETTE["edge"])
                xy = self.world_to_screen(p)
                surf.blit(label, label.get_rect(center=(float(xy[0]), float(xy[1]))))

    def _draw_shadows(self, surf: pygame.Surface, pos: NDArray[np.float64], radius_m: float) -> None:
        """3D depth cue: a floor shadow under each agent and a faint drop line."""
        b = self._require_bounds()
        ok = np.all(np.isfinite(pos), axis=1)
        floor = pos[ok].copy()
        floor[:, 2] = b[0, 2]
        top = self._screen(pos[ok])
        bottom = self._screen(floor)
        r = self._radius_px(radius_m)
        squash = math.sin(math.radians(self.elevation))
        for (x0, y0), (x1, y1) in zip(top.tolist(), bottom.tolist(), strict=True):
            pygame.draw.line(surf, PALETTE["grid"], (x0, y0), (x1, y1), 1)
            rect = pygame.Rect(0, 0, max(2, round(2 * r)), max(1, round(2 * r * squash)))
            rect.center = (round(x1), round(y1))
            pygame.draw.ellipse(surf, PALETTE["shadow"], rect)

    def _draw_obstacles(
        self, surf: pygame.Surface, segments: NDArray[np.float64], circles: NDArray[np.float64]
    ) -> None:
        """Walls as thick dark lines, circular (2D) / spherical (3D) obstacles filled."""
        wall_px = max(3, min(self.width, self.height) // 140)
        if segments.shape[0]:
            ends = self._screen(segments)
            for (x0, y0), (x1, y1) in ends.tolist():
                if all(math.isfinite(v) for v in (x0, y0, x1, y1)):
                    pygame.draw.line(surf, PALETTE["wall"], (x0, y0), (x1, y1), wall_px)
                    for x, y in ((x0, y0), (x1, y1)):  # round caps
                        pygame.draw.circle(surf, PALETTE["wall"], (x, y), wall_px / 2)
        if circles.shape[0]:
            centres, radii = circles[:, : self.d], circles[:, self.d]
            order = np.argsort(self.depth(centres)) if self.d == 3 else np.arange(len(circles))
            xy = self._screen(centres)
            for i in order.tolist():
                x, y = xy[i]
                r = max(2.0, float(radii[i]) * self._scale)
                if not (math.isfinite(x) and math.isfinite(y)):
                    continue
                pygame.draw.circle(surf, PALETTE["obstacle"], (x, y), r)
                if self.d == 3 and r >= 6:
                    self._sphere_highlight(surf, PALETTE["obstacle"], x, y, r)
                pygame.draw.circle(surf, PALETTE["wall"], (x, y), r, max(1, wall_px // 2))

    def _draw_edges(self, surf: pygame.Surface, pos: NDArray[np.float64], edges: NDArray[np.int64]) -> None:
        if edges.shape[0] == 0:
            return
        xy = self._screen(pos)
        p, q = xy[edges[:, 0]], xy[edges[:, 1]]
        ok = np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(q), axis=1)
        colour = PALETTE["edge"]
        line = pygame.draw.aaline if edges.shape[0] <= 2_000 else pygame.draw.line
        for a, c in zip(p[ok].tolist(), q[ok].tolist(), strict=True):
            line(surf, colour, a, c)

    def _draw_trail(
        self, surf: pygame.Surface, trail: NDArray[np.float64], pos: NDArray[np.float64], is_leader: NDArray[np.bool_]
    ) -> None:
        """Faded polyline per agent, oldest segments palest; joined to the current position."""
        if trail.shape[0] == 0:
            return
        path = np.concatenate([trail, pos[None]], axis=0)  # (T + 1, n, d)
        n_steps, n = path.shape[0] - 1, path.shape[1]
        xy = self._screen(path)  # (T + 1, n, 2)
        bg = PALETTE["background"]
        lead_c, foll_c = PALETTE["leader"], PALETTE["follower"]
        if n_steps * n <= self.max_trail_segments:
            for t in range(n_steps):
                strength = 0.12 + 0.45 * (t + 1) / n_steps
                cl, cf = _mix(bg, lead_c, strength), _mix(bg, foll_c, strength)
                a, c = xy[t], xy[t + 1]
                ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(c), axis=1)
                for i in np.flatnonzero(ok).tolist():
                    pygame.draw.line(surf, cl if is_leader[i] else cf, a[i].tolist(), c[i].tolist(), 2)
            return
        # Many segments: paint trail points as single pixels, oldest first.
        strength = 0.12 + 0.45 * (np.arange(n_steps + 1) + 1) / (n_steps + 1)  # (T + 1,)
        base = np.where(is_leader[:, None], np.array(lead_c, float), np.array(foll_c, float))  # (n, 3)
        bgv = np.array(bg, float)
        cols = bgv + strength[:, None, None] * (base[None] - bgv)  # (T + 1, n, 3)
        self._paint(surf, xy.reshape(-1, 2), cols.reshape(-1, 3), 0)

    def _draw_ghosts(
        self,
        surf: pygame.Surface,
        goal: NDArray[np.float64] | None,
        targets: NDArray[np.float64] | None,
        radius_m: float,
        large: bool,
    ) -> None:
        """Goal ghosts as hollow green circles, affine-target ghosts as faint hollow circles."""
        r = self._radius_px(radius_m)
        for arr, key, grow, width in ((goal, "goal", 4.0, 2), (targets, "target", 2.0, 1)):
            if arr is None or arr.shape[0] == 0:
                continue
            if large:
                self._paint(surf, self._screen(arr), np.array(PALETTE[key], float), 0 if key == "target" else 1)
                continue
            xy = self._screen(arr)
            scale = 0.85 + 0.3 * self._depth_t(arr)
            for (x, y), s in zip(xy.tolist(), scale.tolist(), strict=True):
                if math.isfinite(x) and math.isfinite(y):
                    pygame.draw.circle(surf, PALETTE[key], (x, y), (r + grow) * s, width)

    def _draw_agents(
        self, surf: pygame.Surface, pos: NDArray[np.float64], is_leader: NDArray[np.bool_], radius_m: float, large: bool
    ) -> None:
        """Filled discs (2D) or shaded spheres sorted by depth (3D); leaders drawn over followers in 2D."""
        n = pos.shape[0]
        if n == 0:
            return
        xy = self._screen(pos)
        dt = self._depth_t(pos)
        base = np.where(is_leader[:, None], np.array(PALETTE["leader"], float), np.array(PALETTE["follower"], float))
        if self.d == 3:
            order = np.argsort(dt, kind="stable")  # far first
            fog = 0.35 * (1.0 - dt)[:, None]
            cols = base + fog * (np.array(PALETTE["background"], float) - base)
        else:
            order = np.argsort(is_leader, kind="stable")  # followers first, leaders on top
            cols = base
        r = self._radius_px(radius_m)
        if large:
            # Swarm as small squares; leaders (usually few) then as outlined discs on top.
            half = int(min(2, max(0, round(r) - 1)))
            self._paint(surf, xy[order], cols[order], half)
            r_lead = max(r, 4.0)
            for i in np.flatnonzero(is_leader[order]).tolist():
                x, y = xy[order[i]]
                if math.isfinite(x) and math.isfinite(y):
                    pygame.draw.circle(surf, PALETTE["leader"], (x, y), r_lead)
                    pygame.draw.circle(surf, PALETTE["outline"], (x, y), r_lead, 1)
            return
        sizes = r * (0.85 + 0.3 * dt) if self.d == 3 else np.full(n, r)
        outline = PALETTE["outline"]
        for i in order.tolist():
            x, y = xy[i]
            if not (math.isfinite(x) and math.isfinite(y)):
                continue
            c: Colour = (round(cols[i, 0]), round(cols[i, 1]), round(cols[i, 2]))
            rad = float(sizes[i])
            pygame.draw.circle(surf, c, (x, y), rad)
            if self.d == 3 and rad >= 5:
                self._sphere_highlight(surf, c, x, y, rad)
            if rad >= 4:
                pygame.draw.circle(surf, outline, (x, y), rad, 1)

    @staticmethod
    def _sphere_highlight(surf: pygame.Surface, colour: Colour, x: float, y: float, r: float) -> None:
        """Fake sphere shading: a lighter disc toward the upper left."""
        pygame.draw.circle(surf, _mix(colour, (255, 255, 255), 0.25), (x - 0.2 * r, y - 0.2 * r), 0.6 * r)
        pygame.draw.circle(surf, _mix(colour, (255, 255, 255), 0.55), (x - 0.35 * r, y - 0.35 * r), 0.25 * r)

    def _paint(self, surf: pygame.Surface, xy: NDArray[np.float64], colours: NDArray[np.float64], half: int) -> None:
        """Paint (2 half + 1)-pixel squares at screen points ``xy`` (k, 2); colours (k, 3) or (3,).

        Later points overwrite earlier ones. Respects the surface clip rectangle.
        """
        ok = np.all(np.isfinite(xy), axis=1)
        pix = np.rint(xy[ok]).astype(np.int64)
        cols = np.asarray(colours, dtype=np.float64)
        cols = np.broadcast_to(cols, (xy.shape[0], 3))[ok] if cols.ndim == 1 else cols[ok]
        cols = np.clip(np.rint(cols), 0, 255).astype(np.uint8)
        clip = surf.get_clip()
        arr = pygame.surfarray.pixels3d(surf)  # (W, H, 3) view; locks the surface
        try:
            for dx in range(-half, half + 1):
                for dy in range(-half, half + 1):
                    x, y = pix[:, 0] + dx, pix[:, 1] + dy
                    inside = (x >= clip.left) & (x < clip.right) & (y >= clip.top) & (y < clip.bottom)
                    arr[x[inside], y[inside]] = cols[inside]
        finally:
            del arr

    def _draw_text(self, surf: pygame.Surface, text: str, status: str, notes: list[str]) -> None:
        font = self._get_font()
        if font is None:
            return
        x, y = self._margin, self._margin // 2
        if text:
            surf.blit(font.render(text, True, PALETTE["text"]), (x, y))
        y += self._line_px
        line = font.render(status, True, PALETTE["text"])
        surf.blit(line, (x, y))
        if notes:
            surf.blit(font.render("   " + "; ".join(notes), True, PALETTE["note"]), (x + line.get_width(), y))

    def _draw_legend(self, surf: pygame.Surface, f: dict[str, Any]) -> None:
        """One legend row in the bottom band, plus a metre scale bar in 2D."""
        font = self._get_font()
        if font is None:
            return
        y = self.height - self._margin // 2 - self._line_px // 2
        r = max(4, self._font_px // 3)
        x = self._margin
        entries: list[tuple[str, str]] = [("leader", "leader"), ("follower", "follower")]
        if f["goal"] is not None:
            entries.append(("goal", "goal"))
        if f["targets"] is not None:
            entries.append(("target", "affine target"))
        if f["segments"].shape[0] or f["circles"].shape[0]:
            entries.append(("obstacle", "obstacle"))
        for key, label in entries:
            img = font.render(label, True, PALETTE["text"])
            if x + 2 * r + 5 + img.get_width() > self.width - self._margin:
                break  # no room left on the legend row
            if key in ("leader", "follower"):
                pygame.draw.circle(surf, PALETTE[key], (x + r, y), r)
                pygame.draw.circle(surf, PALETTE["outline"], (x + r, y), r, 1)
            elif key == "goal":
                pygame.draw.circle(surf, PALETTE[key], (x + r, y), r + 1, 2)
            elif key == "target":
                pygame.draw.circle(surf, PALETTE[key], (x + r, y), r + 1, 1)
            else:
                pygame.draw.circle(surf, PALETTE["obstacle"], (x + r, y), r)
                pygame.draw.circle(surf, PALETTE["wall"], (x + r, y), r, 1)
            surf.blit(img, img.get_rect(midleft=(x + 2 * r + 5, y)))
            x += 2 * r + 5 + img.get_width() + 16
        if self.d == 2:
            target_px = 0.18 * self.width
            length = _nice_length(target_px / self._scale)
            bar = length * self._scale
            x1 = self.width - self._margin
            x0 = x1 - bar
            img = font.render(f"{length:g} m", True, PALETTE["text"])
            if x0 - img.get_width() - 6 > x:
                col = PALETTE["text"]
                pygame.draw.line(surf, col, (x0, y), (x1, y), 2)
                for xe in (x0, x1):
                    pygame.draw.line(surf, col, (xe, y - 4), (xe, y + 4), 2)
                surf.blit(img, img.get_rect(midright=(x0 - 6, y)))
