"""Single-threaded time of the official Blind Augmentation code's three analyses at
512x512, for the speed ratio of BENCHMARKS.md (issue 10, item 6).

The official code (https://github.com/prakashSidd18/blind_augmentation, not vendored:
its licence is not stated) is imported from a checkout given on the command line and
called exactly as its `optimization_module.Optimization.run_optimization` calls it,
minus `torch.cuda.synchronize()` (CPU only), model saving and the FreeImage download
its utils.py makes at import (EXR output only):

* noise: `laplace_noise_generation.fit_noise_model_luma_intercept(luma, noise, pyr, n_levels=4)`
* motion blur: `blur_utils.motion_blur_analysis(image, sharp, flow, kernel_size=15)`
* defocus: `blur_utils.defocus_blur_analysis(PolynomialModel(2), image, sharp, depth, kernel_size=15)`

on the vendored astronaut photograph (tests/data/astronaut.png), with the inputs the
project's `cargo bench --bench fit` gives its accurate fits (an 8 px/frame flow, a
0.5-4 m depth ramp, Poisson-Gaussian-like noise). The analyses' cost does not depend
on the content: the MB search renders 10 exposures with a 15-tap kernel, the DoF
search 100 blur radii, whatever the frame holds.

    python3 -m venv /tmp/pyref && /tmp/pyref/bin/pip install torch torchvision matplotlib OpenEXR opencv-python-headless imageio pillow
    git clone https://github.com/prakashSidd18/blind_augmentation /tmp/official
    /tmp/pyref/bin/python benches/official/time_official.py /tmp/official [RUNS]

Prints the median wall time of RUNS (default 5) calls of each analysis, on one
thread (`THREADS=n` for n).
"""
import os, sys, time, statistics, pathlib

official = pathlib.Path(sys.argv[1]).resolve()
runs = int(sys.argv[2]) if len(sys.argv) > 2 else 5
sys.path.insert(0, str(official))
os.chdir(official)  # its modules read nothing relative, but stay in its tree

import numpy as np
import torch
from PIL import Image

threads = int(os.environ.get("THREADS", "1"))
torch.set_num_threads(threads)
torch.set_num_interop_threads(threads)

# Its utils.py fetches the FreeImage library at import (for EXR output, unused here);
# this machine has no internet for it.
import imageio
imageio.plugins.freeimage.download = lambda *a, **k: None

import blur_utils
import laplace_noise_generation as lng
from laplace_pyramid import LaplacePyramidGenerator

root = pathlib.Path(__file__).resolve().parents[2]
sharp_np = np.asarray(Image.open(root / "tests/data/astronaut.png").convert("RGB"), np.float32) / 255.0
h, w, _ = sharp_np.shape
luma_np = sharp_np @ np.array([0.2126, 0.7152, 0.0722], np.float32)
rng = np.random.default_rng(1)
noise_np = rng.normal(size=sharp_np.shape).astype(np.float32) * np.sqrt(2e-5 + 8e-4 * luma_np)[..., None]
sharp = torch.from_numpy(sharp_np).permute(2, 0, 1).contiguous()
noisy = (sharp + torch.from_numpy(noise_np).permute(2, 0, 1)).clamp(0, 1)
luma = torch.from_numpy(luma_np)
# 8 px/frame, varying across the frame like tests/common::flow_field.
yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
flow = np.stack([8.0 * (0.6 + 0.4 * xx / w), 8.0 * 0.3 * (yy / h - 0.5)], 0)
flow_t = torch.from_numpy(flow)
depth = torch.from_numpy(0.5 + 3.5 * yy / (h - 1))

def timed(name, f):
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    m = statistics.median(ts)
    print(f"{name}: median {1e3 * m:.1f} ms over {runs} runs (min {1e3 * min(ts):.1f}, max {1e3 * max(ts):.1f})", flush=True)
    return m

pyr = LaplacePyramidGenerator()
t_noise = timed("noise (fit_noise_model_luma_intercept)", lambda: lng.fit_noise_model_luma_intercept(
    luma[None, None], (noisy - sharp)[None], pyr, n_levels=4))
t_mb = timed("motion blur (motion_blur_analysis)", lambda: blur_utils.motion_blur_analysis(
    noisy, sharp, flow_t, kernel_size=15))
t_dof = timed("defocus (defocus_blur_analysis)", lambda: blur_utils.defocus_blur_analysis(
    blur_utils.PolynomialModel(degree=2), noisy, sharp, depth, kernel_size=15))
print(f"total: {1e3 * (t_noise + t_mb + t_dof):.1f} ms ({w}x{h}, torch {torch.__version__}, {threads} thread(s))")
