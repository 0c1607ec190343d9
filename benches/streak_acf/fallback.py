"""The shipped fast tier's blind exposure where the streak's zeros are not identified:
the autocorrelation shape it reports against the gradient-energy isotropy reading it
replaced (both are in the fit's reason), on the two frame sets of BENCHMARKS.md "The
derivative autocorrelation's shape, shipped".

* `probe`: probe.py's frames (astronaut, chelsea, the rendered text page, the rocket:
  tests/data, mirror-tiled to 640×480; OpenCV `motion_kernel` box streaks of 0/8/16/31
  px at 0°/90°/30°; 8-bit, without and with 3 DN of noise, the same seeded sequence);
* `held`: streak_gates' held-out set (nine scikit-image photographs; 0/6/12/24 px at
  30°/120°; 0 and 2 DN of noise), on which nothing of the shape was designed;
* `real`: tests/real_blur.rs's two photographs with their stated streaks.

Uniform flow of 50 px/frame along the streak (the CLI's `fit --only motion-blur --tier
fast`). Errors are relative to the streak, or to 4 px where there is none; a frame
not identifiable scores 0 px. "Covered": the truth within two reported standard errors.
A frame the streak zeros answer prints their length and the margin of their template's
correlation over the next best template ≥ 25% away in λ.

    python3 benches/streak_acf/fallback.py --bin target/release/blind-augment
    # needs numpy, opencv-python-headless, Pillow, scikit-image (its data photographs)
"""
import argparse
import os
import re
import sys
import tempfile

import cv2
import numpy as np

from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "tests", "data")
sys.path.insert(0, os.path.join(HERE, "..", "streak_gates"))
from probe import fit, motion_kernel, mirror_tile  # noqa: E402


def load(p):
    return np.asarray(Image.open(p).convert("L")).astype(np.float32)


def frames():
    rng = np.random.default_rng(1)
    for name in ["astronaut.png", "chelsea.png", "text_page/page.png", "rocket.jpg"]:
        im = mirror_tile(load(os.path.join(DATA, name)), 640, 480)
        for angle in [0, 90, 30]:
            for length in [0, 8, 16, 31]:
                for noise in [0, 3]:
                    b = cv2.filter2D(im, -1, motion_kernel(angle, length)) if length else im
                    b = np.clip(np.round(b + noise * rng.standard_normal(b.shape)), 0, 255)
                    yield "probe", f"{name.split('/')[-1]} n{noise}", b.astype(np.uint8), angle, length
    import skimage
    sk = os.path.join(os.path.dirname(skimage.__file__), "data")
    for name in ["camera.png", "coins.png", "moon.png", "hubble_deep_field.jpg", "horse.png",
                 "chessboard_RGB.png", "motorcycle_right.png", "text.png", "color.png"]:
        im = mirror_tile(load(os.path.join(sk, name)), 640, 480)
        for noise in [0, 2]:
            for angle in [30, 120]:
                for length in [0, 6, 12, 24]:
                    b = cv2.filter2D(im, -1, motion_kernel(angle, length),
                                     borderType=cv2.BORDER_REFLECT) if length else im.copy()
                    if noise:
                        b = b + np.random.default_rng(length).normal(0, noise, b.shape)
                    yield "held", f"{name} n{noise}", np.clip(b + 0.5, 0, 255).astype(np.uint8), angle, length
    for path, angle, length in [("motion_text_opencv.jpg", 86, 31), ("motion_licenseplate_opencv.jpg", 135, 22)]:
        yield "real", path, load(os.path.join(DATA, path)).astype(np.uint8), angle, length


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp()
    stats, every = {}, {}
    for part, name, img8, angle, length in frames():
        lam, reason = fit(args.bin, tmp, img8, angle)
        # Every frame (zeros, fallback, not identifiable — scored 0 px), for
        # comparisons between settings that move frames between the paths
        # (`FIT_ARGS="--fast-effort 0.5"`, BENCHMARKS.md "The fast tier's effort").
        se_all = re.match(r"λ = [\d.]+ ± ([\d.]+)", reason)
        a = every.setdefault(part, {"err": [], "answered": 0, "covered": 0})
        a["err"].append(abs((lam or 0.0) * 50.0 - length) / max(length, 4))
        a["answered"] += lam is not None
        a["covered"] += lam is not None and se_all is not None and \
            abs(lam * 50.0 - length) <= 2 * float(se_all.group(1)) * 50.0
        shape = "from the shape of the derivative autocorrelation" in reason
        iso = re.search(r"isotropy reads λ = ([\d.]+) ± ([\d.]+)", reason) if shape else None
        if not shape and re.match(r"λ = [\d.]+ ± [\d.]+ by gradient-energy isotropy", reason):
            iso = re.match(r"λ = ([\d.]+) ± ([\d.]+)", reason)
        if iso is None:
            zeros = re.match(r"λ = ([\d.]+) ± ([\d.]+)[^;]*? from the streak's spectral zeros", reason)
            corr = re.search(r"correlation ([\d.]+), next best (-?[\d.]+)", reason)
            margin = f", margin {float(corr.group(1)) - float(corr.group(2)):.2f}" if zeros and corr else ""
            what = f"zeros {float(zeros.group(1)) * 50:5.1f} ± {float(zeros.group(2)) * 50:4.1f} px{margin}" if zeros else \
                "not identifiable" if lam is None else "other"
            print(f"{part:5s} {name:28s} {angle:3d}° L {length:2d}: not the fallback ({what})", flush=True)
            continue
        se = float(re.match(r"λ = [\d.]+ ± ([\d.]+)", reason).group(1)) * 50.0
        got, got_iso, se_iso = (lam or 0.0) * 50.0, float(iso.group(1)) * 50.0, float(iso.group(2)) * 50.0
        by_shape = re.search(r"streak ([\d.]+) px by the shape", reason)
        got_shape = float(by_shape.group(1)) if by_shape else got
        dip = re.search(r"dip along the flow at [\d.]+ px \(([-\d.]+) against ([-\d.]+) across\)", reason)
        dip_depth = f", dip {float(dip.group(1)):+.2f} vs {float(dip.group(2)):+.2f}" if dip else ""
        s = stats.setdefault(part, {"shape": 0, "dip": 0, "new": [], "iso": [], "lag": [], "covered_new": 0,
                                    "covered_iso": 0, "missed_new": 0, "missed_iso": 0})
        s["shape"] += shape
        s["dip"] += dip is not None
        s["lag"].append(abs(got_shape - length) / max(length, 4))
        s["new"].append(abs(got - length) / max(length, 4))
        s["iso"].append(abs(got_iso - length) / max(length, 4))
        s["covered_new"] += abs(got - length) <= 2 * se
        s["covered_iso"] += abs(got_iso - length) <= 2 * se_iso
        # A streak reported absent (`exposure_status`: a negligible reading, under 0.005 or
        # 0.35 px; before 2026-11-27 every reading within 3 standard errors of 0).
        s["missed_new"] += length > 0 and reason.endswith("absent")
        s["missed_iso"] += length > 0 and not got_iso > 3 * se_iso
        print(f"{part:5s} {name:28s} {angle:3d}° L {length:2d}: reported {got:5.1f} ± {se:4.1f} px "
              f"({'dip' if dip else 'shape' if shape else 'isotropy'}), shape's length {got_shape:5.1f}, isotropy "
              f"{got_iso:5.1f}{dip_depth}", flush=True)
    for part, s in stats.items():
        n = len(s["new"])
        for k in ["iso", "lag", "new"]:
            e = np.array(s[k])
            label = {"iso": "isotropy alone", "lag": "shape's length", "new": "reported     "}[k]
            cover = f"; truth within 2 standard errors {s['covered_' + k]}; a streak called absent " \
                f"{s['missed_' + k]}" if k != "lag" else ""
            print(f"{part}: {n} fallback frames ({s['shape']} read by the shape, {s['dip']} by its dip); "
                  f"{label}: median {np.median(e):.3f}, within 15% {np.sum(e <= 0.15)}, beyond 30% "
                  f"{np.sum(e > 0.3)}{cover}")
    for part, a in every.items():
        e = np.array(a["err"])
        print(f"{part}: all {len(e)} frames: median {np.median(e):.3f}, within 15% {np.sum(e <= 0.15)}, beyond 30% "
              f"{np.sum(e > 0.3)}; answered {a['answered']}; truth within 2 standard errors {a['covered']}")


if __name__ == "__main__":
    main()
