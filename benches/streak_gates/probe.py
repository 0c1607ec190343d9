"""Blind motion blur's streak zeros on known box streaks: which reads are right,
which are wrong and *identified* (BENCHMARKS.md "Zeros of the ratio that are not
zeros of the streak").

For every photograph × flow angle × streak length × noise level: the photograph
mirror-tiled to 640×480, blurred by OpenCV's `motion_kernel` line PSF (the one
`deconvolution.py` restores the repository's real photographs with) of L px at the
angle, Gaussian noise of `noise` DN added, 8-bit; then
`blind-augment fit --only motion-blur --tier fast` with a uniform flow of 50
px/frame at the angle (so the streak is λ·50 px). A read is *right* when the
streak zeros identify it within 15% of L, *wrong* when they identify anything
else (L = 0 included).

    python3 benches/streak_gates/probe.py --bin target/release/blind-augment \
        --images page.png,coffee.png,/path/to/own.png --lengths 0,4,8,16,31 \
        --angles 0,90,45 --noise 0,3

Bare names are read from scikit-image's bundled `skimage/data` (0.26.0 here).
`FIT_ARGS="--fast-effort 0.5"` passes more options to every `fit` call.
Needs numpy, Pillow, opencv-python-headless, scikit-image.
"""
import argparse
import json
import os
import re
import subprocess
import tempfile

import cv2
import numpy as np
from PIL import Image


def motion_kernel(angle, d, sz=81):
    # OpenCV samples/python/deconvolution.py
    kern = np.ones((1, d), np.float32)
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    a = np.float32([[c, -s, 0], [s, c, 0]])
    sz2 = sz // 2
    a[:, 2] = (sz2, sz2) - np.dot(a[:, :2], ((d - 1) * 0.5, 0))
    k = cv2.warpAffine(kern, a, (sz, sz), flags=cv2.INTER_CUBIC)
    return k / k.sum()


def mirror_tile(img, w=640, h=480):
    while img.shape[0] < h:
        img = np.concatenate([img, img[::-1]], 0)
    while img.shape[1] < w:
        img = np.concatenate([img, img[:, ::-1]], 1)
    return img[:h, :w]


def fit(binary, tmp, img8, angle, speed=50.0):
    h, w = img8.shape[:2]
    Image.fromarray(img8).save(f"{tmp}/in.png")
    flow = np.zeros((h, w, 2), np.float32)
    flow[..., 0] = speed * np.cos(np.radians(angle))
    flow[..., 1] = speed * np.sin(np.radians(angle))
    np.save(f"{tmp}/flow.npy", flow)
    subprocess.run([binary, "fit", "--image", f"{tmp}/in.png", "--flow", f"{tmp}/flow.npy", "--only",
                    "motion-blur", "--tier", "fast", "--threads", "2", "--out", f"{tmp}/out.json",
                    *os.environ.get("FIT_ARGS", "").split()],
                   check=True, capture_output=True)
    mb = json.load(open(f"{tmp}/out.json"))["motion_blur"]
    return mb.get("exposure"), mb["diagnostics"]["reason"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--images", required=True)
    ap.add_argument("--lengths", default="0,4,8,16,31")
    ap.add_argument("--angles", default="0,90,45")
    ap.add_argument("--noise", default="0,3")
    args = ap.parse_args()
    import skimage
    sk = os.path.join(os.path.dirname(skimage.__file__), "data")
    counts = {"right": 0, "wrong": 0, "not identified": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.images.split(","):
            path = name if os.path.exists(name) else os.path.join(sk, name)
            im = mirror_tile(np.asarray(Image.open(path).convert("RGB"))).astype(np.float32)
            for noise in [float(v) for v in args.noise.split(",")]:
                for angle in [float(v) for v in args.angles.split(",")]:
                    for length in [int(v) for v in args.lengths.split(",")]:
                        b = cv2.filter2D(im, -1, motion_kernel(angle, length),
                                         borderType=cv2.BORDER_REFLECT) if length > 0 else im.copy()
                        if noise:
                            b += np.random.default_rng(length).normal(0, noise, b.shape)
                        lam, reason = fit(args.bin, tmp, np.clip(b + 0.5, 0, 255).astype(np.uint8), angle)
                        if "from the streak's spectral zeros" in reason:
                            got = lam * 50.0
                            kind = "right" if length > 0 and abs(got / length - 1) <= 0.15 else "wrong"
                            detail = f"{got:.1f} px"
                        else:
                            kind, detail = "not identified", ""
                            m = re.search(r"along-flow dip ([-0-9.NaN]+), across share ([-0-9.infNa]+)", reason)
                            if m:
                                detail = f"(dip {m.group(1)}, share {m.group(2)})"
                        counts[kind] += 1
                        print(f"{os.path.basename(name):22s} {angle:4.0f}° L {length:3d} noise {noise:.0f}: "
                              f"{kind} {detail}", flush=True)
    print(counts)


if __name__ == "__main__":
    main()
