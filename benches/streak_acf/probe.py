"""Blind motion blur from the shape of the derivative autocorrelation: the prototype
(BENCHMARKS.md "A third single-frame signal measured and not kept"), since shipped as
`src/fit/motion_blur/acf_shape/` (one FFT for every length, the noise through the
crop's bilinear sampling; measured against isotropy by `fallback.py` beside this
file: BENCHMARKS.md "The derivative autocorrelation's shape, shipped").

The isotropy estimator (`src/fit/motion_blur/isotropy.rs`) blurs the frame across
the flow by a candidate box of length L and takes the L at which the gradient
energies along and across the flow balance: one number per direction, the
derivative autocorrelation at lag 0. This probe matches the whole function: with
B2 = frame * box across the flow (length L), the autocorrelation of ∂_u B2 along u
against that of ∂_v B2 along v, over lags 0…80 px, for L = 0…60 px, four ways:
`norm` (each over its lag-0 value, lags ≥ 1), `free` (a free amplitude, lags ≥ 0),
`free1` (a free amplitude, lags ≥ 1), `normw` (as `norm` over lags < 1.5 L + 10),
`freeN` (as `free`, with white noise's share of both functions subtracted: σ by
Immerkær's Laplacian estimate on the frame; along u the box-averaged rows' noise
differenced, along v the box-filtered noise differenced — white in the rotated frame,
which bilinear rotation at oblique angles is not).
`iso` is the lag-0 balance alone (the shipped estimator's principle, this
prototype's sampling: a rotation by OpenCV, not the shipped profiles).

Frames: four photographs mirror-tiled to 640×480 (astronaut, chelsea, the rendered
text page, the rocket: tests/data), box streaks by OpenCV's `motion_kernel` (the
PSF tests/data's real photographs are restored with) of 0/8/16/31 px at 0°, 90°,
30°, 8-bit, with and without 3 DN of Gaussian noise; then the two real photographs
of tests/real_blur.rs with their stated streaks.

    python3 benches/streak_acf/probe.py [--bin target/release/blind-augment]
    # needs numpy, opencv-python-headless, Pillow

With `--bin`, the shipped fast tier reads the same 8-bit frames too (`fit --only
motion-blur --tier fast`, uniform flow of 50 px/frame along the streak, as
benches/streak_gates/probe.py): column `ship` (its λ·50 whether from the zeros or
the isotropy fallback; `n/i` where it says not identifiable, scored as 0 px).
"""
import argparse
import os
import sys
import tempfile

import cv2
import numpy as np
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "tests", "data")
sys.path.insert(0, os.path.join(HERE, "..", "streak_gates"))
from probe import fit, motion_kernel, mirror_tile  # noqa: E402

VARIANTS = ["iso", "norm", "free", "free1", "normw", "freeN"]


def load(p):
    return np.asarray(Image.open(p).convert("L")).astype(np.float32)


def along_x(img, angle):
    """The frame rotated so that the flow (cos a, sin a), y down, runs along +x,
    cropped to the largest centred box that holds only frame pixels (less 8 px)."""
    h, w = img.shape
    m = cv2.getRotationMatrix2D((w / 2, h / 2), angle, 1.0)
    r = cv2.warpAffine(img, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                       borderValue=np.nan)
    for k in range(min(h, w) // 2):
        sub = r[k:h - k, int(k * w / h):w - int(k * w / h)]
        if np.isfinite(sub).all():
            return sub[8:-8, 8:-8]
    raise ValueError("no valid box")


def box_rows(img, length):
    """A box of `length` px (fractional ends) along x."""
    if length < 1:
        return img
    n = int(np.ceil(length))
    n += n % 2 == 0
    k = np.ones(n, np.float32)
    k[0] -= (n - length) / 2
    k[-1] -= (n - length) / 2
    return cv2.filter2D(img, -1, (k / k.sum())[None, :], borderType=cv2.BORDER_REFLECT)


def immerkaer_sigma(img):
    """Immerkær's fast noise estimate (σ of white noise, from the mean |Laplacian|)."""
    k = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    c = cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REFLECT)[1:-1, 1:-1]
    return float(np.sqrt(np.pi / 2) / 6 * np.mean(np.abs(c)))


def box_kernel(length):
    if length < 1:
        return np.array([1.0])
    n = int(np.ceil(length))
    n += n % 2 == 0
    k = np.ones(n)
    k[0] -= (n - length) / 2
    k[-1] -= (n - length) / 2
    return k / k.sum()


def noise_acfs(length, tmax):
    """Unit white noise's share of the two functions at candidate `length`."""
    k = box_kernel(length)
    s2 = np.sum(k ** 2)
    ru = np.zeros(tmax + 1)
    ru[0], ru[1] = 2 * s2, -s2
    r = np.correlate(k, k, "full")
    c = len(k) - 1

    def rb(t):
        return r[c + abs(t)] if abs(t) < len(k) else 0.0

    rv = np.array([2 * rb(t) - rb(t - 1) - rb(t + 1) for t in range(tmax + 1)])
    return ru, rv


def acf_x(d, tmax):
    return np.array([np.mean(d[:, :d.shape[1] - t] * d[:, t:]) for t in range(tmax + 1)])


def estimate(r, sigma, lengths=np.arange(0, 61, 1.0), tmax=80):
    scores = {v: [] for v in VARIANTS}
    for length in lengths:
        b2 = box_rows(r.T, length).T  # across the flow
        du = np.diff(b2, axis=1)[:-1, :]
        dv = np.diff(b2, axis=0)[:, :-1]
        ru, rv = acf_x(du, tmax), acf_x(dv.T, tmax)
        scores["iso"].append(abs(ru[0] / rv[0] - 1))
        scores["norm"].append(np.sum((ru[1:] / ru[0] - rv[1:] / rv[0]) ** 2))
        a = np.dot(ru, rv) / np.dot(rv, rv)
        scores["free"].append(np.sum((ru - a * rv) ** 2) / np.dot(ru, ru))
        a = np.dot(ru[1:], rv[1:]) / np.dot(rv[1:], rv[1:])
        scores["free1"].append(np.sum((ru[1:] - a * rv[1:]) ** 2) / np.dot(ru[1:], ru[1:]))
        tm = int(min(tmax, 1.5 * length + 10))
        scores["normw"].append(np.mean((ru[1:tm] / ru[0] - rv[1:tm] / rv[0]) ** 2))
        nu, nv = noise_acfs(length, tmax)
        ru2, rv2 = ru - sigma ** 2 * nu, rv - sigma ** 2 * nv
        a = np.dot(ru2, rv2) / np.dot(rv2, rv2)
        scores["freeN"].append(np.sum((ru2 - a * rv2) ** 2) / np.dot(ru2, ru2))
    return {v: float(lengths[int(np.argmin(s))]) for v, s in scores.items()}


def shipped(binary, tmp, img8, angle):
    """The shipped fast tier's streak in px (None: not identifiable): streak_gates'
    CLI call, 50 px/frame along the streak."""
    lam, _ = fit(binary, tmp, img8, angle)
    return None if lam is None else lam * 50.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp()
    variants = VARIANTS + (["ship"] if args.bin else [])
    rng = np.random.default_rng(1)
    errs = {v: {} for v in variants}
    for name in ["astronaut.png", "chelsea.png", "text_page/page.png", "rocket.jpg"]:
        im = mirror_tile(load(os.path.join(DATA, name)), 640, 480)
        for angle in [0, 90, 30]:
            for length in [0, 8, 16, 31]:
                for noise in [0, 3]:
                    b = cv2.filter2D(im, -1, motion_kernel(angle, length)) if length else im
                    b = np.clip(np.round(b + noise * rng.standard_normal(b.shape)), 0, 255).astype(np.float32)
                    got = estimate(along_x(b, angle), immerkaer_sigma(b))
                    if args.bin:
                        px = shipped(args.bin, tmp, b.astype(np.uint8), angle)
                        got["ship"] = 0.0 if px is None else px
                    for v in variants:
                        # Relative to the streak, or to 4 px where there is none.
                        errs[v].setdefault(name, []).append((got[v] - length) / max(length, 4))
                    print(f"{name:20s} {angle:3d}° L {length:2d} noise {noise}: "
                          + " ".join(f"{v} {got[v]:4.0f}" for v in variants), flush=True)
    print("median |error| (share within 15%) per variant, all frames, then per photograph:")
    for v in variants:
        allv = np.abs(np.concatenate(list(errs[v].values())))
        per = " ".join(f"{n.split('/')[-1]} {np.median(np.abs(e)):.2f}" for n, e in errs[v].items())
        print(f"  {v:6s} {np.median(allv):.3f} ({np.mean(allv <= 0.15):.2f}); {per}")
    for name, path, angle, length in [("text", "motion_text_opencv.jpg", 86, 31),
                                      ("plate", "motion_licenseplate_opencv.jpg", 135, 22)]:
        img = load(os.path.join(DATA, path))
        got = estimate(along_x(img, angle), immerkaer_sigma(img))
        if args.bin:
            # The photograph as shipped (colour, 8-bit) is what the tests fit; grey here.
            px = shipped(args.bin, tmp, img.astype(np.uint8), angle)
            got["ship"] = 0.0 if px is None else px
        print(f"{name} (stated {length} px): " + " ".join(f"{v} {got[v]:.1f}" for v in variants))


if __name__ == "__main__":
    main()
