"""How much of a real scene's coarse band energy its flattest samples hold, against the
camera noise there: why the blind noise fit's levels 1-3 stay *not identifiable* on one
frame of the vtest clip (issue 10, items 1 and 4; BENCHMARKS.md "The coarse levels: the
scene's own texture in its flattest samples").

Reads tests/data/noise_vtest: frame.png (the frame the blind fit sees), mean.png (the
temporal mean of 795 frames: the scene without its noise, to ~0.2 DN at level 1) and
reference.json (the temporal noise std per level and luma bin). Per level l it builds
the project's Laplacian pyramid (5-tap binomial, clamp to edge) of the frame, of the
mean and of frame - mean, and, as the blind fit does (approximately: a Gaussian window
of std 2 at every level, structure = the luma band l + 2 squared and windowed), takes
per 1/16 luma bin the flattest fraction q of a grid of samples and the median of the
window mean of the squared band over them. Printed: the std that median means, in DN,
for the frame, for the mean (texture alone) and for frame - mean (noise alone), against
the reference's median std.

    python3 benches/noise_scenes/coarse_texture.py   # numpy, opencv-python-headless, Pillow
"""
import json
import os

import cv2
import numpy as np
from PIL import Image

D = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests", "data", "noise_vtest")
K5 = np.array([1, 4, 6, 4, 1], np.float32) / 16
LUMA = np.array([0.299, 0.587, 0.114], np.float32)
LEVELS = 4
WIN = cv2.getGaussianKernel(9, 2.0).astype(np.float32)[:, 0]


def reduce(p):
    return cv2.sepFilter2D(p, -1, K5, K5, borderType=cv2.BORDER_REPLICATE)[::2, ::2].copy()


def expand(p, shape):
    up = np.zeros(shape, np.float32)
    up[::2, ::2] = p
    return cv2.sepFilter2D(up, -1, 2 * K5, 2 * K5, borderType=cv2.BORDER_REPLICATE)


def pyramid(p, levels):
    g, b = [p], []
    for l in range(levels):
        g.append(reduce(g[-1]))
        b.append(g[l] - expand(g[l + 1], g[l].shape))
    return b, g


def wmean(a):
    return cv2.sepFilter2D(a, -1, WIN, WIN, borderType=cv2.BORDER_REPLICATE)


def main():
    frame = np.asarray(Image.open(os.path.join(D, "frame.png")).convert("RGB")).astype(np.float32) / 255
    mean = np.asarray(Image.open(os.path.join(D, "mean.png")).convert("RGB")).astype(np.float32) / 255
    ref = json.load(open(os.path.join(D, "reference.json")))
    sources = {"frame": frame, "texture (mean)": mean, "noise (frame - mean)": frame - mean}
    bands = {k: [pyramid(v[..., c], LEVELS + 2)[0] for c in range(3)] for k, v in sources.items()}
    yb, yg = pyramid(frame @ LUMA, LEVELS + 2)
    for l in range(LEVELS):
        truth = np.median([np.mean(b["std"]) for b in ref["levels"][l]["bins"]
                           if b["pixels"] > 200 and None not in b["std"]])
        shape = yg[l].shape
        luma = wmean(yg[l]) if l == 0 else wmean(expand(yg[l + 1], shape))
        structure = wmean(cv2.resize(yb[l + 2] ** 2, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR))
        var = {k: np.mean([wmean(b[c][l] ** 2) for c in range(3)], 0) for k, b in bands.items()}
        step = max(1, 8 >> l)
        grid = (slice(4, -4, step), slice(4, -4, step))
        lum, st = luma[grid], structure[grid]
        print(f"level {l}: temporal reference, median over luma bins {255 * truth:.2f} DN")
        for q in [0.01, 0.025, 0.05, 0.1, 0.2, 0.4]:
            row = []
            for k in sources:
                v = var[k][grid]
                meds = []
                for b in range(16):
                    sel = (lum >= b / 16) & (lum < (b + 1) / 16)
                    if sel.sum() < 200:
                        continue
                    order = np.argsort(st[sel])[:max(8, int(sel.sum() * q))]
                    meds.append(np.median(v[sel][order]))
                row.append(f"{k} {255 * np.sqrt(np.median(meds)):.2f}")
            print(f"  flattest {100 * q:4.1f}%: " + ", ".join(row) + " DN")


if __name__ == "__main__":
    main()
