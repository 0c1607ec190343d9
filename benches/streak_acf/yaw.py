"""The blind exposure under a wide-angle head turn: the flow of a pure yaw through a
90° field of view (f = w/2: twice the centre's speed at the left and right edges,
turning toward the corners), each pixel blurred along its own flow by λ (33 bilinear
taps over the exposure, OpenCV remap). The whole frame does not hold one streak
length, so `acf_shape` reads its centre (the largest centred crop that does), and the
fit's reason carries both readings (BENCHMARKS.md "The derivative autocorrelation's
shape, shipped").

    python3 benches/streak_acf/yaw.py --bin target/release/blind-augment
    # needs numpy, opencv-python-headless, Pillow, scikit-image
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

import cv2
import numpy as np
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "tests", "data")
sys.path.insert(0, os.path.join(HERE, "..", "streak_gates"))
from probe import mirror_tile  # noqa: E402

W, H, SPEED = 640, 480, 40.0


def yaw_flow():
    f = W / 2
    x = np.arange(W, dtype=np.float32)[None, :] - (W - 1) / 2
    y = np.arange(H, dtype=np.float32)[:, None] - (H - 1) / 2
    om = SPEED / f
    return np.stack([np.broadcast_to(om * (f + x * x / f), (H, W)), om * x * y / f], axis=-1).astype(np.float32)


def blur(img, flow, lam, taps=33):
    if lam == 0:
        return img.copy()
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    acc = np.zeros_like(img)
    for t in (np.arange(taps) + 0.5) / taps - 0.5:
        mx = (gx + t * lam * flow[..., 0]).astype(np.float32)
        my = (gy + t * lam * flow[..., 1]).astype(np.float32)
        acc += cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return acc / taps


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    args = ap.parse_args()
    import skimage
    sk = os.path.join(os.path.dirname(skimage.__file__), "data")
    tmp = tempfile.mkdtemp()
    flow = yaw_flow()
    np.save(f"{tmp}/flow.npy", flow)
    errs = {"iso": [], "shape": []}
    crops = []
    for name in ["astronaut.png", "chelsea.png", "rocket.jpg", "camera.png", "coins.png", "moon.png",
                 "hubble_deep_field.jpg", "motorcycle_right.png", "text.png"]:
        path = os.path.join(DATA, name) if os.path.exists(os.path.join(DATA, name)) else os.path.join(sk, name)
        im = mirror_tile(np.asarray(Image.open(path).convert("L")).astype(np.float32), W, H)
        for lam in [0.0, 0.2, 0.4, 0.6]:
            for noise in [0, 2]:
                b = blur(im, flow, lam)
                if noise:
                    b = b + np.random.default_rng(int(lam * 10)).normal(0, noise, b.shape)
                Image.fromarray(np.clip(b + 0.5, 0, 255).astype(np.uint8)).save(f"{tmp}/in.png")
                subprocess.run([args.bin, "fit", "--image", f"{tmp}/in.png", "--flow", f"{tmp}/flow.npy", "--only",
                                "motion-blur", "--tier", "fast", "--threads", "2", "--out", f"{tmp}/out.json"],
                               check=True, capture_output=True)
                mb = json.load(open(f"{tmp}/out.json"))["motion_blur"]
                reason = mb["diagnostics"]["reason"]
                got = mb.get("exposure") or 0.0
                m = re.search(r"isotropy reads λ = ([\d.]+)", reason)
                shape = "from the shape" in reason
                if not shape:
                    m = re.match(r"λ = ([\d.]+) ± [\d.]+ by gradient-energy isotropy", reason)
                kind = "shape" if shape else ("isotropy" if m else "other")
                line = f"{name:24s} λ {lam:.1f} noise {noise}: {kind:8s} reported {got:.3f}"
                if m:
                    iso = float(m.group(1))
                    # Streak px at the centre's speed, relative, or to 4 px where none.
                    e = lambda v: abs(v - lam) * SPEED / max(lam * SPEED, 4.0)  # noqa: E731
                    errs["iso"].append(e(iso))
                    errs["shape"].append(e(got))
                    line += f", isotropy {iso:.3f}"
                    c = re.search(r"over a (\d+)×(\d+) px crop", reason)
                    if c:
                        crops.append(c.group(0))
                        line += f" ({c.group(0)})"
                elif "not read" in reason or not shape:
                    line += " — " + reason[:90]
                print(line, flush=True)
    for k, v in errs.items():
        v = np.array(v)
        print(f"{k:6s}: {len(v)} frames, median {np.median(v):.3f}, within 15% {np.sum(v <= 0.15)}, "
              f"beyond 30% {np.sum(v > 0.3)}")
    print("crops:", sorted(set(crops)))


if __name__ == "__main__":
    main()
