"""Temporal noise reference for tests/real_noise.rs, from a real static-camera clip.

Source: `vtest.avi` (768x576, 795 frames, 10 fps, DivX-3), OpenCV's sample data, shipped
in Debian bookworm's `opencv-doc` 4.6.0+dfsg-12 as
/usr/share/doc/opencv-doc/examples/data/vtest.avi (Apache-2.0 AND BSD-3-Clause).

    apt-get download opencv-doc && dpkg-deb -x opencv-doc_*.deb /tmp/ocvdoc
    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy opencv-python-headless pillow
    /tmp/venv/bin/python make_reference.py /tmp/ocvdoc/usr/share/doc/opencv-doc/examples/data/vtest.avi

Writes, next to this script:
* frame.png      one decoded frame (FRAME), 8-bit RGB, unchanged: the blind fit's input;
* mean.png       the temporal mean of the static observations of every pixel, 8-bit
                 RGB, in FRAME's photometry: the clean image noise is synthesised onto;
* reference.json per Laplacian level 0..3, channel and luma bin: the std of the band of
                 (frame_t - mean) over every static observation.

Independent of the estimator by construction: it uses time (795 observations of each
pixel), the estimator one frame. The pyramid is the project's (5-tap binomial, clamp to
edge, re-implemented here) so that "level l" means the same band on both sides.

Corrections, each measured on this clip (printed when run):
* global exposure drift (the camera's gain wanders by +-1.5%): each frame is mapped onto
  the median frame by an affine fit over its static pixels, and the mean is mapped back
  into FRAME's photometry;
* moving people and their shadows: a pixel is static in frame t when the blurred luma
  deviates from the temporal median by < 0.03, dilated by the band's footprint;
* the codec makes the noise temporally correlated (skipped blocks keep an I-frame's
  noise: lag-1 correlation ~0.9, ~0.1 at lag 100), so the temporal mean holds part of
  the noise; the variance of (x_t - mean) is therefore corrected by 1/(1 - tau/n), tau
  the integrated autocorrelation time per level (summed up to the first lag where the
  correlation falls below 0.05), n the pixel's static observations.
"""
import json, sys, pathlib
import numpy as np, cv2
from PIL import Image

FRAME = 400          # the single frame the blind fit sees
LEVELS = 4
BINS = 16
LUMA = np.array([0.299, 0.587, 0.114], np.float32)
K5 = np.array([1, 4, 6, 4, 1], np.float32) / 16
OUT = pathlib.Path(__file__).resolve().parent


def reduce(p):
    q = cv2.sepFilter2D(p, -1, K5, K5, borderType=cv2.BORDER_REPLICATE)
    return q[::2, ::2].copy()


def expand1(s, n, axis):
    # out[2m] = (s[m-1] + 6 s[m] + s[m+1]) / 8, out[2m+1] = (s[m] + s[m+1]) / 2, source index clamped
    s = np.moveaxis(s, axis, 0)
    pad = np.concatenate([s[:1], s, s[-1:]], 0)
    even = (pad[:-2] + 6 * pad[1:-1] + pad[2:]) / 8
    odd = (pad[1:-1] + pad[2:]) / 2
    out = np.empty((2 * s.shape[0],) + s.shape[1:], np.float32)
    out[0::2], out[1::2] = even, odd
    return np.moveaxis(out[:n], 0, axis)


def expand(p, shape):
    return expand1(expand1(p, shape[0], 0), shape[1], 1)


def bands(p):
    out = []
    for _ in range(LEVELS):
        d = reduce(p)
        out.append(p - expand(d, p.shape))
        p = d
    return out


def gauss(p, levels):
    out = [p]
    for _ in range(levels):
        out.append(reduce(out[-1]))
    return out


def main(avi):
    cap = cv2.VideoCapture(avi)
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f[..., ::-1])
    rgb8 = np.stack(frames)
    del frames
    n_frames, h, w, _ = rgb8.shape
    print(f"{avi}: {n_frames} frames {w}x{h}")
    # Frame by frame: the clip as float would take 4 GB.
    f32 = lambda t: rgb8[t].astype(np.float32) / 255
    g = np.stack([f32(t) @ LUMA for t in range(n_frames)])
    med = np.median(g, axis=0)
    moving = np.stack([cv2.GaussianBlur(np.abs(x - med), (0, 0), 2) > 0.03 for x in g])
    static0 = ~np.stack([cv2.dilate(m.astype(np.uint8), np.ones((21, 21), np.uint8)) for m in moving]).astype(bool)
    # Exposure drift: x ~ gain * median + offset over static pixels.
    coef = np.array([np.polyfit(med[s], x[s], 1) for x, s in zip(g, static0)])
    del g
    print(f"gain drift {coef[:, 0].min():.4f}..{coef[:, 0].max():.4f}, offset {coef[:, 1].min():+.4f}..{coef[:, 1].max():+.4f}")
    norm = lambda t: (f32(t) - coef[t, 1]) / coef[t, 0]
    n_static = static0.sum(0)
    # Clipped observations (a channel at 0 or 255) carry no noise; the blind fit skips
    # such footprints too. A pixel's channel is out when >= 0.5% of its static
    # observations are clipped (the dark grass's blue channel is, at luma 0.12-0.19).
    clip_count = np.zeros((h, w, 3), np.int32)
    for t in range(n_frames):
        clip_count += ((rgb8[t] == 0) | (rgb8[t] == 255)) & static0[t][..., None]
    clipped0 = clip_count >= 0.005 * np.maximum(n_static, 1)[..., None]
    print(f"clipped pixel-channels: {clipped0.mean(axis=(0, 1)).round(4)}")
    mean = np.zeros((h, w, 3), np.float64)
    for t in range(n_frames):
        mean += norm(t) * static0[t][..., None]
    mean = (mean / np.maximum(n_static, 1)[..., None]).astype(np.float32)
    print(f"static observations per pixel: median {np.median(n_static):.0f}, min {n_static.min()}")
    # Per-level static masks: the band footprint (~5 px per level-l pixel) plus margin.
    masks, clipped = [], []
    for l in range(LEVELS):
        r = 5 * 2**l + 4
        k = np.ones((2 * r + 1, 2 * r + 1), np.uint8)
        masks.append(~np.stack([cv2.dilate(m.astype(np.uint8), k)[:: 2**l, :: 2**l] for m in moving]).astype(bool))
        clipped.append(np.stack([cv2.dilate(clipped0[..., c].astype(np.uint8), k)[:: 2**l, :: 2**l] > 0 for c in range(3)]))
    # Bands of every residual frame: rbl[l][t, c] (float16: 2.8 GB instead of 5.6).
    shapes = [m.shape[1:] for m in masks]
    rbl = [np.zeros((n_frames, 3) + s, np.float16) for s in shapes]
    for t in range(n_frames):
        res = norm(t) - mean
        for c in range(3):
            for l, b in enumerate(bands(np.ascontiguousarray(res[..., c]))):
                rbl[l][t, c] = b
    rb = None
    mean_luma = gauss(np.ascontiguousarray(mean @ LUMA), LEVELS)
    levels = []
    for l in range(LEVELS):
        # Integrated autocorrelation time of this band (all channels pooled).
        tau, rho_at = 1.0, {}
        for k in range(1, n_frames // 2):
            xs, ys = [], []
            for t in range(0, n_frames - k, 5):
                m = masks[l][t] & masks[l][t + k]
                for c in range(3):
                    xs.append(rbl[l][t, c][m].astype(np.float32))
                    ys.append(rbl[l][t + k, c][m].astype(np.float32))
            x, y = np.concatenate(xs), np.concatenate(ys)
            rho = float((x * y).mean() / np.sqrt((x * x).mean() * (y * y).mean()))
            rho_at[k] = rho
            if rho < 0.05:
                break
            tau += 2 * rho
        n_l = np.maximum(masks[l].sum(0), 1)
        corr = 1.0 / np.clip(1 - tau / n_l, 0.5, 1)
        # Per-pixel temporal variance of the band, corrected for the mean's share.
        var_px = []
        for c in range(3):
            s2 = np.zeros(shapes[l], np.float64)
            for t in range(n_frames):
                s2 += np.where(masks[l][t], rbl[l][t, c].astype(np.float64) ** 2, 0)
            var_px.append(s2 / n_l * corr)
        # A bin's value is the median over its pixels of the per-pixel variance:
        # edges in the clean image flicker from frame to frame (codec ringing,
        # sub-pixel jitter; 5-15 DN at level 0 on the tape line and poles) and would
        # dominate a mean. The median of a variance estimated from k = n/tau
        # effectively independent observations is low by (1 - 2/(9k))^3
        # (Wilson-Hilferty), corrected here.
        k_eff = np.maximum(n_l / tau, 2)
        wh = (1 - 2 / (9 * k_eff)) ** 3
        yb = np.clip((mean_luma[l] * BINS).astype(int), 0, BINS - 1)
        out_bins = []
        for b in range(BINS):
            sel = (yb == b) & (n_l >= 50)
            entry = {"luma": [b / BINS, (b + 1) / BINS], "pixels": int(sel.sum())}
            if entry["pixels"] < 4:
                out_bins.append(entry)
                continue
            std, std_mean, se = [], [], []
            for c in range(3):
                ok = sel & ~clipped[l][c]
                if ok.sum() < 4:
                    std.append(None), std_mean.append(None), se.append(None)
                    continue
                v = var_px[c][ok] / wh[ok]
                m = float(np.median(v))
                std.append(float(np.sqrt(m)))
                std_mean.append(float(np.sqrt(v.mean())))
                # Standard error of the median (1.2533 sd / sqrt(n) for a normal
                # spread, sd from the IQR), counting level-l pixels / 4 as independent
                # (neighbouring band samples are correlated).
                q1, q3 = np.percentile(v, [25, 75])
                se.append(float(1.2533 * (q3 - q1) / 1.349 / np.sqrt(max(len(v) / 4, 1)) / (2 * m)))
            entry.update({"std": std, "std_mean": std_mean, "relative_stderr": se})
            out_bins.append(entry)
        print(f"level {l}: tau {tau:.1f} (rho lag1 {rho_at.get(1, 0):.3f}, last lag {max(rho_at)}), "
              f"variance correction median {np.median(corr):.4f}, median-to-mean {np.median(wh):.4f}")
        levels.append({"level": l, "tau_frames": tau, "bins": out_bins})
    # The frame's own photometry for the clean image.
    gain, off = coef[FRAME]
    clean = np.clip(mean * gain + off, 0, 1)
    Image.fromarray(rgb8[FRAME]).save(OUT / "frame.png", optimize=True)
    # 8 bits suffice: the test only bins by its luma and synthesises noise onto it.
    Image.fromarray((clean * 255 + 0.5).astype(np.uint8)).save(OUT / "mean.png", optimize=True)
    json.dump({
        "source": "OpenCV sample data vtest.avi (Debian opencv-doc 4.6.0+dfsg-12, Apache-2.0 AND BSD-3-Clause)",
        "frame": FRAME, "frames": n_frames, "width": w, "height": h,
        "method": "tests/data/noise_vtest/make_reference.py",
        "levels": levels,
    }, open(OUT / "reference.json", "w"), indent=1)
    for lv in levels:
        print(lv["level"], [(round(b["luma"][0], 3), b["pixels"], [s and round(s * 255, 2) for s in b["std"]]) for b in lv["bins"] if "std" in b])


if __name__ == "__main__":
    main(sys.argv[1])
