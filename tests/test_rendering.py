"""Tests of the pygame renderer and the animation writer (headless, SDL dummy driver)."""

from __future__ import annotations

import importlib.util
import os
import time
from pathlib import Path
from typing import Any

os.environ["SDL_VIDEODRIVER"] = "dummy"
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import imageio.v3 as iio
import numpy as np
import pytest

from formation_env.env.rendering import PALETTE, Renderer
from formation_env.env.video import save_animation

W, H = 320, 240


def make_frame(d: int = 2, n: int = 5, **overrides: Any) -> dict[str, Any]:
    """A small valid frame: agents on a circle of radius 3 m inside a 10 m box."""
    ang = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    pos = np.zeros((n, d))
    pos[:, 0], pos[:, 1] = 3.0 * np.cos(ang), 3.0 * np.sin(ang)
    if d == 3:
        pos[:, 2] = 2.0
    frame: dict[str, Any] = {
        "positions": pos,
        "leaders": np.array([0, 1]),
        "edges": np.array([(i, (i + 1) % n) for i in range(n)]),
        "targets": None,
        "obstacles": {"segments": np.zeros((0, 2, d)), "circles": np.zeros((0, d + 1))},
        "goal": None,
        "trail": np.zeros((0, n, d)),
        "bounds": np.array([[-5.0] * d, [5.0] * d]),
        "agent_radius": 0.3,
        "text": "test",
        "time": 1.5,
    }
    frame.update(overrides)
    return frame


def pixel(img: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """RGB at screen point ``xy`` = (x, y) pixels."""
    x, y = np.rint(xy).astype(int)
    return img[y, x]


def near(img: np.ndarray, xy: np.ndarray, colour: tuple[int, int, int], box: int = 12, tol: int = 30) -> int:
    """Number of pixels within ``box`` px of ``xy`` whose colour is within ``tol`` of ``colour``."""
    x, y = np.rint(xy).astype(int)
    patch = img[max(0, y - box) : y + box + 1, max(0, x - box) : x + box + 1].astype(int)
    return int(np.sum(np.all(np.abs(patch - np.array(colour)) <= tol, axis=-1)))


def test_rgb_array_shape_dtype() -> None:
    img = Renderer(2, "rgb_array", width=W, height=H).draw(make_frame())
    assert img is not None
    assert img.shape == (H, W, 3)
    assert img.dtype == np.uint8


def test_leaders_and_followers_in_distinct_colours_at_their_positions() -> None:
    r = Renderer(2, "rgb_array", width=W, height=H)
    frame = make_frame()
    img = r.draw(frame)
    assert img is not None
    xy = r.world_to_screen(frame["positions"])
    assert xy.shape == (5, 2)
    assert PALETTE["leader"] != PALETTE["follower"]
    for i in range(5):
        expected = PALETTE["leader"] if i in (0, 1) else PALETTE["follower"]
        assert tuple(pixel(img, xy[i])) == expected, f"agent {i}"


def test_world_to_screen_keeps_aspect_ratio() -> None:
    r = Renderer(2, "rgb_array", width=W, height=H)
    r.set_bounds(np.array([[0.0, 0.0], [4.0, 2.0]]))
    a, b, c = r.world_to_screen(np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 2.0]]))
    assert (b[0] - a[0]) == pytest.approx(2.0 * (a[1] - c[1]))  # y up on screen is down in pixels
    assert 0 < a[0] < b[0] < W and 0 < c[1] < a[1] < H


def test_world_to_screen_needs_bounds() -> None:
    with pytest.raises(ValueError, match="needs bounds"):
        Renderer(2, "rgb_array").world_to_screen(np.zeros((1, 2)))


def test_obstacles_and_goal_are_drawn() -> None:
    r = Renderer(2, "rgb_array", width=W, height=H)
    goal = make_frame()["positions"] * 0.3  # ghosts near the centre, away from agents
    frame = make_frame(
        goal=goal,
        obstacles={
            "segments": np.array([[[-4.5, -4.0], [4.5, -4.0]]]),
            "circles": np.array([[-3.5, 3.5, 0.8]]),
        },
    )
    img = r.draw(frame)
    assert img is not None
    wall_mid, circle_c = r.world_to_screen(np.array([[0.0, -4.0], [-3.5, 3.5]]))
    assert tuple(pixel(img, wall_mid)) == PALETTE["wall"]
    assert tuple(pixel(img, circle_c)) == PALETTE["obstacle"]
    for g in r.world_to_screen(goal):
        assert near(img, g, PALETTE["goal"]) > 3
    blank = r.draw(make_frame())
    assert blank is not None
    assert near(blank, r.world_to_screen(goal[0]), PALETTE["goal"]) == 0


def test_targets_and_trail_are_drawn() -> None:
    r = Renderer(2, "rgb_array", width=W, height=H)
    frame = make_frame()
    trail = frame["positions"][None] + np.linspace(-2.0, -0.5, 4)[:, None, None] * np.array([1.0, 0.0])
    with_extras = r.draw(make_frame(targets=frame["positions"] * 0.5, trail=trail))
    plain = r.draw(frame)
    assert with_extras is not None and plain is not None
    changed = np.any(with_extras != plain, axis=-1)
    tx = r.world_to_screen(frame["positions"][2] * 0.5)
    assert changed[int(tx[1]) - 10 : int(tx[1]) + 11, int(tx[0]) - 10 : int(tx[0]) + 11].any()
    mid = r.world_to_screen(trail[1, 3])
    assert changed[int(mid[1]) - 2 : int(mid[1]) + 3, int(mid[0]) - 2 : int(mid[0]) + 3].any()


def test_3d_projection_draws_something() -> None:
    r = Renderer(3, "rgb_array", width=W, height=H)
    frame = make_frame(
        d=3,
        goal=make_frame(d=3)["positions"] + 0.5,
        obstacles={
            "segments": np.array([[[-4.0, 4.0, 0.0], [4.0, 4.0, 0.0]]]),
            "circles": np.array([[0.0, 0.0, 4.0, 1.0]]),
        },
    )
    img = r.draw(frame)
    assert img is not None and img.shape == (H, W, 3)
    xy = r.world_to_screen(frame["positions"])
    assert np.all((xy > 0) & (xy < np.array([W, H])))
    assert len({tuple(p) for p in np.rint(xy).astype(int)}) == 5  # a genuine projection, no collapse
    assert near(img, xy[0], PALETTE["leader"], box=4, tol=80) > 0
    assert near(img, xy[3], PALETTE["follower"], box=4, tol=80) > 0
    # Depth: the camera looks from -y, so a point at smaller y is closer (larger depth).
    assert r.depth(np.array([0.0, -1.0, 0.0])) > r.depth(np.array([0.0, 1.0, 0.0]))


def _share(r: Renderer, points: np.ndarray) -> float:
    """The larger of the width and height shares of the picture that ``points`` (k, 3) span on screen."""
    xy = r.world_to_screen(points)
    return float(np.max((xy.max(axis=0) - xy.min(axis=0)) / np.array([r.width, r.height])))


def _inside(r: Renderer, points: np.ndarray) -> bool:
    xy = r.world_to_screen(points)
    return bool(np.all((xy > 0) & (xy < np.array([r.width, r.height]))))


@pytest.mark.parametrize("seed", range(5))
def test_3d_camera_frames_the_team_and_what_it_must_pass(seed: int) -> None:
    """``maneuver_3d``'s team (a 20 m world box) spans at least a fifth of the picture, not 5 %; on
    ``obstacle_field`` in 3D the team, its goal and the obstacles on the way between them are all in the picture."""
    from formation_env.env.engine import Engine

    eng = Engine("maneuver_3d")
    state = eng.reset(np.random.default_rng(seed), 1)
    r = Renderer(3, "rgb_array")
    img = r.draw(eng.frame(state, 0))
    assert img is not None and _inside(r, state.pos[0]) and _share(r, state.pos[0]) >= 0.2
    field = Engine("obstacle_field", framework="bipyramid_3d")
    state = field.reset(np.random.default_rng(seed), 1)
    frame = field.frame(state, 0)
    r = Renderer(3, "rgb_array")
    r.draw(frame)
    circles = frame["obstacles"]["circles"]
    lo, hi = (
        np.minimum(state.pos[0].min(0), state.goal[0].min(0)),
        np.maximum(state.pos[0].max(0), state.goal[0].max(0)),
    )
    between = np.all((circles[:, :3] >= lo) & (circles[:, :3] <= hi), axis=1)  # centres in the team-goal box
    assert _inside(r, state.pos[0]) and _inside(r, state.goal[0]) and _inside(r, circles[between, :3])


def test_3d_view_grows_within_an_episode_and_starts_afresh_at_an_earlier_time() -> None:
    r = Renderer(3, "rgb_array", width=W, height=H)
    first = make_frame(d=3, time=0.0)
    v0 = r.view_box(first)
    assert np.all(v0[0] >= -5.0) and np.all(v0[1] <= 5.0)  # within the world box
    assert np.all(v0[0] <= first["positions"].min(0)) and np.all(v0[1] >= first["positions"].max(0))
    moved = make_frame(d=3, time=1.0, positions=first["positions"] * 0.2)
    v1 = r.view_box(moved)  # the same episode: the union, no zoom in
    assert np.all(v1[0] <= v0[0]) and np.all(v1[1] >= v0[1]) and np.all(v1[0] <= moved["positions"].min(0))
    fresh = r.view_box(make_frame(d=3, time=0.0, positions=first["positions"] * 0.2))
    assert np.all(fresh[1] - fresh[0] < v0[1] - v0[0])  # an earlier time: a new episode, framed afresh
    r.reset_view()
    np.testing.assert_array_equal(r.view_box(moved), fresh)


def test_human_mode_under_dummy_driver() -> None:
    r = Renderer(2, "human", width=W, height=H, fps=1000)
    try:
        assert r.draw(make_frame()) is None
        assert r.draw(make_frame(time=2.0)) is None
    finally:
        r.close()
    r.close()  # idempotent


def test_invalid_render_mode_raises() -> None:
    with pytest.raises(ValueError, match=r"render_mode must be one of \['human', 'rgb_array'\]"):
        Renderer(2, "ansi")


def test_invalid_dimension_raises() -> None:
    with pytest.raises(ValueError, match="d must be 2 or 3"):
        Renderer(4, "rgb_array")


def test_bad_frames_raise() -> None:
    r = Renderer(2, "rgb_array", width=W, height=H)
    bad_key = make_frame()
    del bad_key["goal"]
    with pytest.raises(ValueError, match=r"missing \['goal'\]"):
        r.draw(bad_key)
    with pytest.raises(ValueError, match=r"unknown \['colour'\]"):
        r.draw(make_frame(colour=1))
    with pytest.raises(ValueError, match=r"positions.*shape \(n, 2\)"):
        r.draw(make_frame(positions=np.zeros((5, 3))))
    with pytest.raises(ValueError, match=r"edges.*indices must lie in \[0, 5\)"):
        r.draw(make_frame(edges=np.array([[0, 5]])))
    with pytest.raises(ValueError, match=r"bounds.*max must be >= min"):
        r.draw(make_frame(bounds=np.array([[1.0, 1.0], [0.0, 2.0]])))


def test_non_finite_positions_do_not_crash() -> None:
    pos = make_frame()["positions"].copy()
    pos[2] = np.nan
    pos[3] = 1e12
    img = Renderer(2, "rgb_array", width=W, height=H).draw(make_frame(positions=pos))
    assert img is not None and img.shape == (H, W, 3)


@pytest.mark.parametrize("d", [2, 3])
def test_ten_thousand_agents(d: int) -> None:
    n = 10_000
    rng = np.random.default_rng(0)
    pos = rng.uniform(-4.0, 4.0, size=(n, d))
    frame = make_frame(
        d=d,
        n=n,
        positions=pos,
        leaders=np.arange(d + 1),
        edges=rng.integers(0, n, size=(30_000, 2)),
        targets=pos + 0.1,
        goal=pos - 0.1,
        trail=pos[None] + rng.normal(0.0, 0.05, size=(3, n, d)),
        agent_radius=0.01,
    )
    r = Renderer(d, "rgb_array")
    t0 = time.perf_counter()
    img = r.draw(frame)
    elapsed = time.perf_counter() - t0
    assert img is not None and img.shape == (640, 640, 3)
    assert elapsed < 2.0  # generous for CI; ~0.05 s typical
    # Followers are painted (fogged with depth in 3D), leaders drawn on top as discs.
    follower_like = np.all(np.abs(img.astype(int) - np.array(PALETTE["follower"])) <= (0 if d == 2 else 90), axis=-1)
    assert follower_like.sum() > 5_000
    for i in range(d + 1):
        assert near(img, r.world_to_screen(pos[i]), PALETTE["leader"], box=2, tol=0) > 0


def test_hidden_edges_are_noted_in_the_status_line() -> None:
    n = 50
    rng = np.random.default_rng(1)
    frame = make_frame(n=n, edges=rng.integers(0, n, size=(40, 2)))
    r = Renderer(2, "rgb_array")
    shown = r.draw(frame)
    r.max_edges = 10
    hidden = r.draw(frame)
    assert shown is not None and hidden is not None
    top = r._top  # the status band above the world area
    assert near(shown[:top], np.array([320, top // 2]), PALETTE["note"], box=320, tol=40) == 0
    assert near(hidden[:top], np.array([320, top // 2]), PALETTE["note"], box=320, tol=40) > 10
    world = slice(top, 640 - r._bottom)
    assert np.sum(np.any(shown[world] != hidden[world], axis=-1)) > 50  # edges are gone


def test_draws_without_fonts(monkeypatch: pytest.MonkeyPatch) -> None:
    import pygame

    def no_font(*args: Any, **kwargs: Any) -> None:
        raise pygame.error("font not available")

    monkeypatch.setattr(pygame.font, "Font", no_font)
    r = Renderer(2, "rgb_array", width=W, height=H)
    img = r.draw(make_frame())
    assert img is not None and img.shape == (H, W, 3)
    assert tuple(pixel(img, r.world_to_screen(make_frame()["positions"][0]))) == PALETTE["leader"]


def test_save_animation_gif_roundtrip(tmp_path: Path) -> None:
    r = Renderer(2, "rgb_array", width=W, height=H)
    frames = [r.draw(make_frame(time=0.1 * k, text=f"frame {k}")) for k in range(4)]
    assert all(f is not None for f in frames)
    out = save_animation([f for f in frames if f is not None], tmp_path / "sub" / "anim.gif", fps=10)
    assert out == tmp_path / "sub" / "anim.gif" and out.exists()
    back = iio.imread(out, index=None)
    assert back.shape[0] == 4
    assert back.shape[1:3] == (H, W)


def test_save_animation_rejects_bad_frames(tmp_path: Path) -> None:
    a = np.zeros((10, 12, 3), dtype=np.uint8)
    with pytest.raises(ValueError, match=r"frames\[1\] has shape \(10, 10, 3\), expected \(10, 12, 3\)"):
        save_animation([a, np.zeros((10, 10, 3), dtype=np.uint8)], tmp_path / "x.gif")
    with pytest.raises(ValueError, match="dtype uint8"):
        save_animation([a.astype(np.float32)], tmp_path / "x.gif")
    with pytest.raises(ValueError, match=r"shape \(H, W, 3\)"):
        save_animation([np.zeros((10, 12), dtype=np.uint8)], tmp_path / "x.gif")
    with pytest.raises(ValueError, match="at least one frame"):
        save_animation([], tmp_path / "x.gif")
    with pytest.raises(ValueError, match=r"suffix must be one of \['.gif', '.mp4'\]"):
        save_animation([a], tmp_path / "x.avi")
    with pytest.raises(ValueError, match="fps must be positive"):
        save_animation([a], tmp_path / "x.gif", fps=0)


@pytest.mark.skipif(importlib.util.find_spec("imageio_ffmpeg") is not None, reason="imageio-ffmpeg is installed")
def test_save_animation_mp4_without_ffmpeg_explains(tmp_path: Path) -> None:
    with pytest.raises(ImportError, match=r"pip install imageio-ffmpeg.*\.gif"):
        save_animation([np.zeros((16, 16, 3), dtype=np.uint8)], tmp_path / "x.mp4")


@pytest.mark.skipif(importlib.util.find_spec("imageio_ffmpeg") is None, reason="imageio-ffmpeg not installed")
def test_save_animation_mp4(tmp_path: Path) -> None:
    frames = [np.full((32, 32, 3), 20 * k, dtype=np.uint8) for k in range(5)]
    out = save_animation(frames, tmp_path / "x.mp4", fps=5)
    assert out.exists() and out.stat().st_size > 0
