"""Side by side, as a user would compare them: `blind-augment fit` (accurate tier)
and the official Blind Augmentation code on the same 512x512 known-answer cases,
every fit in a fresh process, interleaved, in rounds.

Cases: two real photographs of tests/data (astronaut; the rocket's left 512x427
region padded to 512 rows by reflection) x three effects, each made here by a
forward model independent of the project's `synth` (NumPy/OpenCV, as
tests/independent_forward.rs does it in Rust):

* noise: Poisson-Gaussian, var = 2e-5 + 8e-4 * luma, NumPy's generator; reference
  = the clean photograph (`--denoised`);
* motion blur: the mean of 16 bicubic samples (cv2.remap) along a flow of 6-10
  px/frame at exposure 0.5; reference = the clean photograph
  (`--motion-deblurred`, with `--flow`);
* defocus: 24 depth layers, each a Gaussian blur of sigma = |k (1/f - 1/z)| + c0
  over a 0.5-4 m depth ramp; reference = the clean photograph
  (`--defocus-deblurred`, with `--depth`).

Each round runs, per case: `blind-augment --threads 1 fit` pinned to one core
(`taskset -c 0`), then the official analysis in a fresh Python process at its
default threads (torch's: all cores) and, with --official-1t, at one thread.
Times are each fit's own: `diagnostics.fit_time_s` of the effect in the written
model (inside the process, so a cold first call is counted, the process start
is not), and the official call's wall time around the analysis alone (its
imports and torch's start-up not counted).

    python3 -m venv /tmp/pyref && /tmp/pyref/bin/pip install torch numpy opencv-python-headless pillow imageio matplotlib OpenEXR
    git clone https://github.com/prakashSidd18/blind_augmentation /tmp/official
    cargo build --release --bin blind-augment
    /tmp/pyref/bin/python benches/official/side_by_side.py /tmp/official [--rounds 3] [--official-1t]
    /tmp/pyref/bin/python benches/official/side_by_side.py --ours-only [--rounds 5] [--compare OTHER_BUILD]

Prints one line per fit and a table of medians over rounds.
"""
import argparse, json, os, pathlib, shutil, statistics, subprocess, sys, tempfile, time

import numpy as np
from PIL import Image

ROOT = pathlib.Path(__file__).resolve().parents[2]

# The official analyses, called as its optimization_module calls them (see
# time_official.py's docstring), on the case's files; prints the wall time in ms.
OFFICIAL = r'''
import os, sys, time
official, kind, case = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, official); os.chdir(official)
import numpy as np, torch
threads = int(os.environ.get("OFFICIAL_THREADS", "0"))
if threads:
    torch.set_num_threads(threads); torch.set_num_interop_threads(threads)
import imageio
imageio.plugins.freeimage.download = lambda *a, **k: None
import blur_utils, laplace_noise_generation as lng
from laplace_pyramid import LaplacePyramidGenerator
ld = lambda n: torch.from_numpy(np.load(os.path.join(case, n)))
image = ld("image.npy").permute(2, 0, 1).contiguous()
ref = ld("reference.npy").permute(2, 0, 1).contiguous()
t = time.perf_counter()
if kind == "noise":
    luma = ref[0] * 0.2126 + ref[1] * 0.7152 + ref[2] * 0.0722
    lng.fit_noise_model_luma_intercept(luma[None, None], (image - ref)[None], LaplacePyramidGenerator(), n_levels=4)
elif kind == "mb":
    blur_utils.motion_blur_analysis(image, ref, ld("flow.npy").permute(2, 0, 1).contiguous(), kernel_size=15)
else:
    blur_utils.defocus_blur_analysis(blur_utils.PolynomialModel(degree=2), image, ref, ld("depth.npy"), kernel_size=15)
print(1e3 * (time.perf_counter() - t))
'''


def photos():
    astro = np.asarray(Image.open(ROOT / "tests/data/astronaut.png").convert("RGB"), np.float32) / 255.0
    rocket = np.asarray(Image.open(ROOT / "tests/data/rocket.jpg").convert("RGB"), np.float32) / 255.0
    rocket = rocket[:, :512]
    rocket = np.concatenate([rocket, rocket[::-1][: 512 - rocket.shape[0]]], 0)
    return {"astronaut": astro, "rocket": rocket}


def luma(img):
    return img @ np.array([0.2126, 0.7152, 0.0722], np.float32)


def make_cases(out):
    import cv2

    cases = []
    rng = np.random.default_rng(20261206)
    for name, clean in photos().items():
        h, w, _ = clean.shape
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        # noise
        d = out / f"{name}-noise"
        d.mkdir()
        std = np.sqrt(2e-5 + 8e-4 * luma(clean))[..., None]
        np.save(d / "image.npy", (clean + rng.normal(size=clean.shape).astype(np.float32) * std).astype(np.float32))
        np.save(d / "reference.npy", clean)
        cases.append((d, "noise"))
        # motion blur: exposure 0.5 of a 6-10 px/frame flow
        d = out / f"{name}-mb"
        d.mkdir()
        flow = np.stack([6.0 + 4.0 * xx / w, 3.0 * (yy / h - 0.5)], -1).astype(np.float32)
        acc = np.zeros_like(clean)
        taps = 16
        for i in range(taps):
            s = 0.5 * ((i + 0.5) / taps - 0.5)
            acc += cv2.remap(clean, xx + s * flow[..., 0], yy + s * flow[..., 1], cv2.INTER_CUBIC,
                             borderMode=cv2.BORDER_REFLECT)
        np.save(d / "image.npy", (acc / taps).astype(np.float32))
        np.save(d / "reference.npy", clean)
        np.save(d / "flow.npy", flow)
        cases.append((d, "mb"))
        # defocus: thin lens, focus 1.2 m, over a 0.5-4 m ramp, 24 layers
        d = out / f"{name}-dof"
        d.mkdir()
        depth = (0.5 + 3.5 * yy / (h - 1)).astype(np.float32)
        edges = np.linspace(0.5, 4.0, 25)
        img = np.zeros_like(clean)
        for a, b in zip(edges[:-1], edges[1:]):
            z = 0.5 * (a + b)
            sigma = abs(2.0 * (1.0 / 1.2 - 1.0 / z)) + 0.3
            layer = cv2.GaussianBlur(clean, (0, 0), float(sigma), borderType=cv2.BORDER_REFLECT)
            m = (depth >= a) & (depth <= b)
            img[m] = layer[m]
        np.save(d / "image.npy", img)
        np.save(d / "reference.npy", clean)
        np.save(d / "depth.npy", depth)
        cases.append((d, "dof"))
    return cases


def ours(binary, case, kind):
    flag = {"noise": "--denoised", "mb": "--motion-deblurred", "dof": "--defocus-deblurred"}[kind]
    only = {"noise": "noise", "mb": "motion-blur", "dof": "depth-of-field"}[kind]
    args = ["taskset", "-c", "0", str(binary), "--threads", "1", "fit", "--image", str(case / "image.npy"),
            flag, str(case / "reference.npy"), "--only", only, "--out", str(case / "model.json")]
    if kind == "mb":
        args += ["--flow", str(case / "flow.npy")]
    if kind == "dof":
        args += ["--depth", str(case / "depth.npy")]
    subprocess.run(args, check=True, capture_output=True)
    model = json.loads((case / "model.json").read_text())
    key = {"noise": "noise", "mb": "motion_blur", "dof": "depth_of_field"}[kind]
    return 1e3 * model[key]["diagnostics"]["fit_time_s"]


def official(python, repo, case, kind, threads):
    env = dict(os.environ, OFFICIAL_THREADS=str(threads))
    r = subprocess.run([python, "-c", OFFICIAL, str(repo), kind, str(case)], check=True, capture_output=True,
                       text=True, env=env)
    return float(r.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("official", type=pathlib.Path, nargs="?")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--official-1t", action="store_true")
    ap.add_argument("--ours-only", action="store_true", help="time blind-augment alone (no official code needed)")
    ap.add_argument("--compare", type=pathlib.Path,
                    help="another blind-augment build, timed interleaved with --binary on every case")
    ap.add_argument("--binary", type=pathlib.Path,
                    default=pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "release/blind-augment")
    a = ap.parse_args()
    if a.official is None and not a.ours_only:
        ap.error("give the official code's folder, or --ours-only")
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="ba-side-by-side-"))
    try:
        cases = make_cases(tmp)
        cols = ["ours 1t"] + (["compared build 1t"] if a.compare else [])
        if not a.ours_only:
            cols += ["official default"] + (["official 1t"] if a.official_1t else [])
        times = {(c.name, col): [] for c, _ in cases for col in cols}
        for r in range(a.rounds):
            for case, kind in cases:
                t = ours(a.binary, case, kind)
                times[(case.name, "ours 1t")].append(t)
                if a.compare:
                    tc = ours(a.compare, case, kind)
                    times[(case.name, "compared build 1t")].append(tc)
                if a.ours_only:
                    print(f"round {r + 1} {case.name}: ours {t:.1f} ms" + (f", compared build {tc:.1f} ms" if a.compare else ""), flush=True)
                    continue
                o = official(sys.executable, a.official, case, kind, 0)
                times[(case.name, "official default")].append(o)
                line = f"round {r + 1} {case.name}: ours {t:.1f} ms, official {o:.1f} ms"
                if a.official_1t:
                    o1 = official(sys.executable, a.official, case, kind, 1)
                    times[(case.name, "official 1t")].append(o1)
                    line += f", official 1 thread {o1:.1f} ms"
                print(line, flush=True)
        print(f"\nmedian over {a.rounds} rounds, ms (each fit in a fresh process; torch default threads = "
              f"{os.cpu_count()} cores here)\n")
        print("| case | " + " | ".join(cols) + " |")
        print("|---|" + "---|" * len(cols))
        med = {k: statistics.median(v) for k, v in times.items()}
        for case, _ in cases:
            print(f"| {case.name} | " + " | ".join(f"{med[(case.name, c)]:.1f}" for c in cols) + " |")
        for kind in ["noise", "mb", "dof"]:
            names = [c.name for c, k in cases if k == kind]
            print(f"| mean {kind} | " + " | ".join(
                f"{statistics.mean(med[(n, c)] for n in names):.1f}" for c in cols) + " |")
        total = {c: sum(statistics.mean(med[(n, c)] for n in [x.name for x, k in cases if k == kind])
                        for kind in ["noise", "mb", "dof"]) for c in cols}
        print("| **total (noise + MB + DoF)** | " + " | ".join(f"**{total[c]:.1f}**" for c in cols) + " |")
        for c in cols[1:]:
            print(f"{c} / ours: {total[c] / total['ours 1t']:.2f}x")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
