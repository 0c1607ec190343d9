"""Can one frame tell correlated camera noise from white by its finest band? Why the blind
noise fit still continues its unmeasured coarse levels by white noise's ratios (issue 10,
items 1 and 4; BENCHMARKS.md "The coarse levels: the noise's own correlation at level 0").

The vtest clip's noise decays far slower per level than white noise (its coarse levels
read -68...-80% under the white continuation, tests/real_noise.rs). A correlated noise
also shows in its finest band: the level-0 band's lag-1 autocorrelation is white noise's
-0.10 only for white noise. This prints, per level-0 flat fraction as in
coarse_texture.py, that autocorrelation (horizontal, along x; channel-averaged; ratio of
window sums) for the frame, the scene without noise (the temporal mean) and the noise
(frame - mean); then, for white noise low-passed by a Gaussian of std s px (the
one-parameter correlation model it would need), the same autocorrelation and the level
std ratios it implies, against the clip's noise over its static pixels.

    python3 benches/noise_scenes/level0_correlation.py   # numpy, opencv-python-headless, Pillow
"""
import os
import sys

import cv2
import numpy as np
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from coarse_texture import D, LEVELS, LUMA, pyramid, wmean  # noqa: E402


def lag1(b):
    """Window sums of b(x)·b(x+1) and of b(x)² (x along the rows)."""
    nxt = np.concatenate([b[:, 1:], b[:, -1:]], 1)
    return wmean(b * nxt), wmean(b * b)


def level_stds(p, mask=None):
    bands, _ = pyramid(p, LEVELS)
    out = []
    for l, b in enumerate(bands):
        m = np.ones_like(b, bool) if mask is None else mask[:: 2 ** l, :: 2 ** l][: b.shape[0], : b.shape[1]]
        out.append(float(np.sqrt(np.mean(b[m] ** 2))))
    return out


def main():
    frame = np.asarray(Image.open(os.path.join(D, "frame.png")).convert("RGB")).astype(np.float32) / 255
    mean = np.asarray(Image.open(os.path.join(D, "mean.png")).convert("RGB")).astype(np.float32) / 255
    sources = {"frame": frame, "scene (mean)": mean, "noise (frame - mean)": frame - mean}
    yb, yg = pyramid(frame @ LUMA, 3)
    luma = wmean(yg[0])
    structure = wmean(cv2.resize(yb[2] ** 2, (frame.shape[1], frame.shape[0]), interpolation=cv2.INTER_LINEAR))
    sums = {k: [lag1(pyramid(np.ascontiguousarray(v[..., c]), 1)[0][0]) for c in range(3)] for k, v in sources.items()}
    grid = (slice(4, -4, 8), slice(4, -4, 8))
    lum, st = luma[grid], structure[grid]
    print("level-0 band, lag-1 autocorrelation along x at the flattest samples (white noise: -0.10)")
    for q in [0.01, 0.05, 0.2, 0.5]:
        pick = np.zeros(lum.shape, bool)
        for b in range(16):
            sel = np.flatnonzero(((lum >= b / 16) & (lum < (b + 1) / 16)).ravel())
            if len(sel) >= 20:
                pick.ravel()[sel[np.argsort(st.ravel()[sel])[: max(8, int(len(sel) * q))]]] = True
        row = []
        for k, per_c in sums.items():
            num = sum(float(np.sum(ab[grid][pick])) for ab, _ in per_c)
            den = sum(float(np.sum(bb[grid][pick])) for _, bb in per_c)
            row.append(f"{k} {num / den:+.2f}")
        print(f"  flattest {100 * q:4.1f}% ({pick.sum()} samples): " + ", ".join(row))
    # The clip's noise over its static pixels (people moving: |blurred luma of frame - mean| < 0.01).
    d = frame - mean
    static = np.abs(cv2.GaussianBlur(d @ LUMA, (0, 0), 3)) < 0.01
    static = cv2.erode(static.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    print(f"the clip's noise over its static pixels ({100 * static.mean():.0f}%): level std ratios 1/0, 2/1; lag-1 autocorrelation")
    for c in range(3):
        s = level_stds(np.ascontiguousarray(d[..., c]), static)
        ab, bb = lag1(pyramid(np.ascontiguousarray(d[..., c]), 1)[0][0])
        print(f"  channel {c}: {s[1] / s[0]:.2f}, {s[2] / s[1]:.2f}; {np.sum(ab[static]) / np.sum(bb[static]):+.2f}")
    rng = np.random.default_rng(1)
    print("white noise low-passed by a Gaussian of std s: level std ratios 1/0, 2/1; lag-1 autocorrelation")
    for s in [0.0, 0.5, 0.6, 0.7, 1.0]:
        w = rng.standard_normal(frame.shape[:2]).astype(np.float32)
        if s > 0:
            w = cv2.GaussianBlur(w, (0, 0), s)
        r = level_stds(w)
        ab, bb = lag1(pyramid(w, 1)[0][0])
        print(f"  s {s:.1f}: {r[1] / r[0]:.2f}, {r[2] / r[1]:.2f}; {np.sum(ab) / np.sum(bb):+.2f}")


if __name__ == "__main__":
    main()
