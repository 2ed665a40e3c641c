"""bench/video's pure parts: the realistic scene is what its description says, the recorder's
summary is read right, and the ffmpeg anchor runs the settings the recorder's encoder uses."""

import numpy as np
import pytest

from bench.video import anchor, keepup, scene, sizes
from fxis_shm.formats import videochoice, videoencoder
from fxis_shm.formats.videotracks import VideoPlan
from fxis_shm.record.recorder import summary_table


def small(**changes) -> scene.Scene:
    return scene.Scene(**{"width": 320, "height": 240, "pan_px": 20, "period_s": 2.0, **changes})


def test_the_scene_is_the_photograph_with_noise_of_the_stated_sigma_and_repeats_for_a_seed():
    frames, clean = small().frames(4), small().frames(4, noise=False)
    assert all(f.shape == (240, 320) and f.dtype == np.uint8 for f in frames)
    noise = np.concatenate([(f.astype(float) - c).ravel() for f, c in zip(frames, clean)])
    assert noise.std() == pytest.approx(2.0, rel=0.05)
    assert clean[0].std() > 20  # a photograph, not a flat field
    assert all(np.array_equal(a, b) for a, b in zip(frames, small().frames(4)))
    assert not np.array_equal(frames[0], small(seed=36).frames(1)[0])


def test_the_window_pans_slowly_within_the_canvas():
    s = small(fps=30.0, period_s=20.0, pan_px=100)
    offsets = [s._offset(i) for i in range(600)]
    steps = [max(abs(x1 - x0), abs(y1 - y0)) for (x0, y0), (x1, y1) in zip(offsets, offsets[1:])]
    assert max(steps) <= 2 and len(set(offsets)) > 100  # it moves, at most 2 px a frame
    assert min(min(o) for o in offsets) >= 0 and max(x for x, _ in offsets) <= 200


def test_psnr_and_ssim():
    a = small().frames(1, noise=False)[0]
    assert sizes.ssim(a, a) == pytest.approx(1.0)
    shifted = np.clip(a.astype(int) + 4, 0, 255).astype(np.uint8)
    assert sizes.psnr(a, shifted) == pytest.approx(10 * np.log10(255**2 / np.mean((shifted - a.astype(float)) ** 2)))
    assert sizes.ssim(a, np.zeros_like(a)) < 0.1


def test_the_recorders_summary_is_read_per_camera():
    cams = {
        "cam0": {"topic": "/cam0/video", "frames": 565, "missed": 0, "dropped_by_camera": 1, "skipped_by_encoder": 34},
        "cam1": {"topic": "/cam1/video", "frames": 567, "missed": 2, "dropped_by_camera": 0, "skipped_by_encoder": 0},
    }
    summary = {"cameras": cams, "tuples": None, "seconds": 20.0, "image_bytes": 1, "file_bytes": 2, "out": "bag"}
    read = keepup.parse_summary(summary_table(summary), ["cam0", "cam1"])
    assert read == {
        "cam0": {"frames": 565, "missed": "0", "dropped_by_camera": "1", "skipped": 34},
        "cam1": {"frames": 567, "missed": "2", "dropped_by_camera": "0", "skipped": 0},
    }


def test_the_anchor_gives_ffmpeg_the_recorders_libx264_options():
    plan = VideoPlan(videochoice.Choice("h264", "libx264", False), 23, "veryfast", 2.0, {"scene": 30.0})
    command = anchor.ffmpeg_command(plan, "in.gray", 1360, 1024, 30.0, "out.h264")
    options = videoencoder.encoder_options(plan.choice, 23, "veryfast", 1 << 20)
    pairs = dict(zip(command, command[1:]))
    assert pairs["-x264-params"] == options["x264-params"] and "bframes=0" in options["x264-params"]
    assert (pairs["-crf"], pairs["-preset"], pairs["-bf"]) == ("23", "veryfast", "0")
    assert pairs["-force_key_frames"] == "expr:gte(t,n_forced*2)" and pairs["-s"] == "1360x1024"
